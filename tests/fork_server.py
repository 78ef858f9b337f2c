"""A fork server for the ``pige`` commands the docs tests run as pasted: the imports paid once, not per command.

The README's and the docs' shell blocks start some 135 ``pige`` commands; each spent 0.2–0.5 s of CPU starting
Python and importing NumPy, SciPy, matplotlib, SQLAlchemy and pige_sym before it computed anything.  Here a
server process imports them once (:data:`PRELOAD` and every pige_sym module that does not import SymPy),
freezes them out of the garbage collector's sight (``gc.freeze``) and waits on a Unix socket.  The scratch
checkout's ``.venv/bin/pige`` is a shim (:data:`SHIM`: ``python -I -S`` and built-in modules only, about 20 ms)
that hands the server the console script it stands for, its argv, working folder, umask, environment and its
stdin/stdout/stderr descriptors (``SCM_RIGHTS``).  The server forks; the child takes the working folder,
umask, environment and descriptors, makes ``sys.std*`` on them as Python does at start-up, draws NumPy's
global random state again, and runs the console script (``runpy``: the venv's ``pige``, which calls
``pige_sym.cli:main``); it ends as the interpreter ends (threads joined, ``atexit``, streams flushed) but
without tearing its modules down (that would copy every page it shares with the server).  The server sends
the shim the child's wait status, and the shim exits with it (or with its signal, which it forwards too:
SIGINT, SIGTERM, SIGHUP).

Each command still starts from a fresh state: the child of a server that never ran a command, with the
modules imported and nothing else done.  What a fresh process would see differently, the server does not
serve: the shim then execs the real console script (the *fallback*), when

- the environment differs from the server's in any variable but :data:`FREE_VARIABLES` (those nothing reads
  while the preloaded modules import: ``PATH``, the shell's ``PWD``…, pige's own ``PIGE_HISTORY_DB`` and
  ``PIGE_KERNEL_DIR``, read when a command runs); ``MPLBACKEND``, ``PYTHON*``, ``HOME``, locale variables…
  all fall back;
- the working folder holds a ``matplotlibrc`` (matplotlib reads it from there when it is imported);
- a standard descriptor is closed, the working folder is gone, or the server does not answer.

What stays the server's: the hash seed (drawn once per server, not per command), ``sys.orig_argv``, the
process's parent, group and session; the modules a command would not have imported are there; an object
still alive at exit is not finalized (its ``__del__`` does not run; ``weakref.finalize`` and ``atexit`` do).
The server logs one line per command (``served``, ``ended`` with its CPU, or ``fallback: why``).

Run as ``python fork_server.py SOCKET`` by :class:`ForkServer` (the tests start it, and stop it: its CPU
and its children's count in the test that stops it).
"""

from __future__ import annotations

import io
import os
import re
import signal
import socket
import struct
import subprocess
import sys
import tempfile
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import IO

#: Libraries the server imports once: what the README's and docs' commands import (measured with a
#: ``sitecustomize`` listing ``sys.modules`` at exit), then every module of pige_sym but the code generator
#: (:func:`_preload`; SymPy stays out: the code generator's modules that import it are not preloaded).
PRELOAD = ("numpy", "scipy.linalg", "scipy.optimize", "scipy.sparse", "scipy.spatial", "scipy.special", "scipy.stats",
           "matplotlib", "matplotlib.pyplot", "sqlalchemy", "sqlite3", "tqdm", "platformdirs",
           "concurrent.futures", "pige_sym.cli.main")

#: Environment variables a command may set or change and still be served (none of them is read while the
#: preloaded libraries import): bash's own, the PATH, pige's, which it reads when a command runs, and pytest's
#: name of the test running.
FREE_VARIABLES = frozenset({"PWD", "OLDPWD", "SHLVL", "_", "PATH", "PIGE_HISTORY_DB", "PIGE_KERNEL_DIR",
                            "PYTEST_CURRENT_TEST"})

#: The shim written as the scratch venv's ``pige``; ``{python}``, ``{socket}``, ``{real}`` filled in.
SHIM = '''#!{python} -IS
"""pige, served by the test fork server (tests/fork_server.py) at {socket}; else the real {real}.

Only built-in modules (_socket, _signal): the shim starts in about 20 ms."""
import os
import sys

REAL = {real!r}


def fallback():
    os.execv(REAL, [REAL, *sys.argv[1:]])


def main():
    import _signal
    import _socket
    try:
        for fd in (0, 1, 2):
            os.fstat(fd)
        cwd = os.getcwdb()
        link = _socket.socket(_socket.AF_UNIX, _socket.SOCK_STREAM)
        link.connect({socket!r})
    except OSError:
        fallback()
    umask = os.umask(0o22)
    os.umask(umask)
    ignored = b"1" if _signal.getsignal(_signal.SIGINT) == _signal.SIG_IGN else b"0"
    fields = [os.fsencode(REAL), cwd, b"%d" % umask, ignored, b"%d" % len(sys.argv), *map(os.fsencode, sys.argv),
              *(k + b"=" + v for k, v in os.environb.items())]
    payload = b"\\0".join(fields)
    payload = len(payload).to_bytes(4, "big") + payload
    fds = b"".join(fd.to_bytes(4, sys.byteorder) for fd in (0, 1, 2))  # C ints
    pending = [b""]

    def line():
        while b"\\n" not in pending[0]:
            chunk = link.recv(64)
            if not chunk:
                return b""
            pending[0] += chunk
        first, _, pending[0] = pending[0].partition(b"\\n")
        return first

    try:  # until the server answers, nothing ran: any failure falls back
        sent = link.sendmsg([payload], [(_socket.SOL_SOCKET, _socket.SCM_RIGHTS, fds)])
        if sent < len(payload):
            link.sendall(payload[sent:])
        first = line()
    except OSError:
        fallback()
    if not first.startswith(b"P"):
        fallback()
    child = int(first[1:])
    for sig in (_signal.SIGINT, _signal.SIGTERM, _signal.SIGHUP):
        if _signal.getsignal(sig) != _signal.SIG_IGN:
            _signal.signal(sig, lambda n, _f: os.kill(child, n))
    status = int(line()[1:] or b"-1")
    if status < 0:
        sys.exit(255)
    if os.WIFSIGNALED(status):
        sig = os.WTERMSIG(status)
        if sig not in (_signal.SIGKILL, _signal.SIGSTOP):
            _signal.signal(sig, _signal.SIG_DFL)
        os.kill(os.getpid(), sig)
        sys.exit(128 + sig)
    sys.exit(os.waitstatus_to_exitcode(status))


main()
'''


def _read_request(conn: socket.socket) -> tuple[bytes, list[int]]:
    """One request: the payload (its 4-byte length first) and the three descriptors that came with it."""
    data, fds, _flags, _addr = socket.recv_fds(conn, 1 << 20, 3)
    size = struct.unpack("!I", data[:4])[0]
    while len(data) < size + 4:
        more = conn.recv(1 << 20)
        if not more:
            raise EOFError("the shim hung up")
        data += more
    return data[4:], fds


def _decode(payload: bytes) -> dict:
    """The shim's fields: the console script it stands for, cwd, umask, SIGINT ignored, argv, environment."""
    fields = payload.split(b"\0")
    argc = int(fields[4])
    env = dict(item.partition(b"=")[::2] for item in fields[5 + argc:] if item)
    return {"real": os.fsdecode(fields[0]), "cwd": fields[1], "umask": int(fields[2]),
            "sigint_ignored": fields[3] == b"1", "argv": [os.fsdecode(a) for a in fields[5:5 + argc]], "env": env}


def why_not_served(request: dict, server_env: dict[bytes, bytes]) -> str | None:
    """Why a fresh process could differ from a child of this server for ``request``, or None."""
    differ = {k for k in request["env"].keys() | server_env.keys() if request["env"].get(k) != server_env.get(k)}
    differ -= {os.fsencode(v) for v in FREE_VARIABLES}
    if differ:
        return "environment differs in " + ", ".join(sorted(os.fsdecode(k) for k in differ))
    if os.path.exists(os.path.join(request["cwd"], b"matplotlibrc")):
        return "a matplotlibrc in the working folder"
    return None


def _stdio(fd: int, like: io.TextIOWrapper, unbuffered: bool) -> io.TextIOWrapper:
    """A text stream on ``fd`` as Python makes ``sys.std*`` at start-up (``create_stdio``): the encoding and
    errors of the server's own (``like``: the same environment made them), unbuffered writes under
    ``PYTHONUNBUFFERED``, else stdout line-buffered on a terminal and stderr always."""
    write = fd != 0
    raw_only = unbuffered and write
    buffer = open(fd, "wb" if write else "rb", buffering=0 if raw_only else -1, closefd=False)
    stream = io.TextIOWrapper(buffer, encoding=like.encoding, errors=like.errors, newline="\n",  # type: ignore[arg-type]
                              line_buffering=not unbuffered and write and (os.isatty(fd) or fd == 2),
                              write_through=unbuffered)
    stream.mode = "w" if write else "r"  # type: ignore[misc]
    return stream


def _become_command(request: dict, fds: list[int]) -> Callable[[], None]:
    """In the forked child: take the shim's state, and return what runs the console script it stands for."""
    real = request["real"]
    signal.signal(signal.SIGCHLD, signal.SIG_DFL)
    signal.set_wakeup_fd(-1)
    signal.signal(signal.SIGINT, signal.SIG_IGN if request["sigint_ignored"] else signal.default_int_handler)
    for target, fd in enumerate(fds):
        os.dup2(fd, target)
        os.close(fd)
    os.chdir(request["cwd"])
    os.umask(request["umask"])
    os.environb.clear()
    os.environb.update(request["env"])
    unbuffered = sys.stdout.write_through  # the server's stdout, made as the environment says
    for name, fd in (("stdin", 0), ("stdout", 1), ("stderr", 2)):
        stream = _stdio(fd, getattr(sys, name), unbuffered)
        setattr(sys, name, stream)
        setattr(sys, f"__{name}__", stream)
    if "numpy.random" in sys.modules:
        sys.modules["numpy.random"].seed()  # a fresh global state, as a new process draws (random reseeds itself)
    sys.argv = list(request["argv"])
    sys.path[0] = os.path.dirname(os.path.realpath(real))
    return lambda: _exit(_run_script(real))


def _run_script(real: str) -> int:
    """Run the console script ``real`` as ``__main__``; its exit status as the interpreter would make it."""
    import runpy

    try:
        runpy.run_path(real, run_name="__main__")
    except SystemExit as e:
        if e.code is None or isinstance(e.code, int):
            return e.code or 0
        print(e.code, file=sys.stderr)
        return 1
    except BaseException as e:  # noqa: BLE001 (the interpreter's own handling: the traceback, status 1)
        tb = e.__traceback__  # from the script's frame on, as a fresh interpreter shows it (not runpy's)
        while tb is not None and tb.tb_frame.f_code.co_filename != real:
            tb = tb.tb_next
        sys.excepthook(type(e), e.with_traceback(tb or e.__traceback__), tb or e.__traceback__)
        return -signal.SIGINT if isinstance(e, KeyboardInterrupt) else 1
    return 0


def _exit(status: int) -> None:
    """End the child as the interpreter ends, but for tearing its modules down: the non-daemon threads joined,
    the ``atexit`` functions run (``weakref.finalize`` among them), the standard streams flushed (status 120
    when that fails), then ``os._exit``.  Tearing down the preloaded modules would write to every page of
    memory the child shares with the server (some 80 MB copied: 0.17 s of CPU a command, measured); a fresh
    process's teardown frees what it imported, which nothing observes but an object's ``__del__``."""
    import atexit
    import threading

    threading._shutdown()  # type: ignore[attr-defined]
    atexit._run_exitfuncs()
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except Exception as e:  # noqa: BLE001 (reported as the interpreter does)
            import traceback

            try:
                sys.stderr.write(f"Exception ignored in: {stream!r}\n")
                traceback.print_exception(type(e), e, None)
            except Exception:  # noqa: BLE001,S110 (stderr is the stream that failed)
                pass
            status = 120
    if status == -signal.SIGINT:
        signal.signal(signal.SIGINT, signal.SIG_DFL)
        os.kill(os.getpid(), signal.SIGINT)
    os._exit(status & 0xFF)


def _reap(children: dict[int, socket.socket], log: IO[str], block: bool = False) -> None:
    """Send every finished child's wait status to its shim (``block``: wait for every child to finish)."""
    while children:
        try:
            pid, status, usage = os.wait4(-1, 0 if block else os.WNOHANG)
        except ChildProcessError:
            return
        if pid == 0:
            return
        cpu = usage.ru_utime + usage.ru_stime
        log.write(f"ended: {pid} status {status} minflt {usage.ru_minflt} CPU {cpu:.3f} s\n")
        conn = children.pop(pid, None)
        if conn is not None:
            try:
                conn.sendall(b"S%d\n" % status)
            except OSError:
                log.write(f"shim of {pid} gone\n")
            conn.close()


#: A module-level import statement (at the start of a line: one in a function or under ``if TYPE_CHECKING`` is
#: indented and does not run when the module is imported).
MODULE_IMPORT = re.compile(r"^(?:from[ \t]+(\.*[\w.]*)[ \t]+import[ \t]+(\([^)]*\)|[^\n#]+)|import[ \t]+([^\n#]+))",
                           re.M)


def _module_imports(source: str, name: str, is_package: bool) -> set[str]:
    """The modules a module's source imports when it is imported (:data:`MODULE_IMPORT`), absolute."""
    found: set[str] = set()
    for base, names, plain in MODULE_IMPORT.findall(source):
        if plain:
            found.update(part.split(" as ")[0].strip() for part in plain.split(","))
            continue
        if base.startswith("."):
            level = len(base) - len(base.lstrip("."))
            parent = name.split(".")[:name.count(".") + 1 - level + is_package]
            base = ".".join(parent + ([base.lstrip(".")] if base.lstrip(".") else []))
        found.add(base)
        found.update(f"{base}.{part.split(' as ')[0].strip()}" for part in names.strip("()").split(","))
    return found


def sympy_free_modules() -> list[str]:
    """pige_sym's modules whose import does not import SymPy (its code generator's do), in walking order."""
    import importlib.util
    import pkgutil

    package = importlib.util.find_spec("pige_sym")
    assert package is not None and package.submodule_search_locations is not None
    imports: dict[str, set[str]] = {}
    for info in pkgutil.walk_packages(list(package.submodule_search_locations), "pige_sym."):
        spec = importlib.util.find_spec(info.name)
        if spec is not None and spec.origin and spec.origin.endswith(".py"):
            source = Path(spec.origin).read_text(encoding="utf-8")
            imports[info.name] = _module_imports(source, info.name, info.ispkg)
    heavy = {"sympy"}
    changed = True
    while changed:
        changed = False
        for name, needs in imports.items():
            parents = {".".join(name.split(".")[:i]) for i in range(2, name.count(".") + 1)}
            if name not in heavy and any(n.split(".")[0] == "sympy" or n in heavy for n in needs | parents):
                heavy.add(name)
                changed = True
    return [name for name in imports if name not in heavy and name != "pige_sym.__main__"]


def _preload(only: list[str] | None = None) -> None:
    """Import :data:`PRELOAD` and pige_sym's modules but those that import SymPy (or ``only`` those named); a
    module that fails to import is left to the commands (they fail on it as a fresh process would)."""
    import importlib

    for name in PRELOAD if only is None else only:
        importlib.import_module(name)
    for name in sympy_free_modules() if only is None else []:
        try:
            importlib.import_module(name)
        except Exception as e:  # noqa: BLE001 (logged; the command meets it again)
            sys.stderr.write(f"not preloaded: {name}: {e!r}\n")
    if "sympy" in sys.modules:
        sys.stderr.write("preloaded SymPy: a module imports a module that imports it\n")


def _fork_for(conn: socket.socket, server_env: dict[bytes, bytes], log: IO[str]) -> tuple[int, dict, list[int]]:
    """Read a shim's request on ``conn``: fork its child (pid 0 in the child), or answer ``F`` (pid -1)."""
    try:
        payload, fds = _read_request(conn)
        request = _decode(payload)
    except (OSError, EOFError, ValueError, struct.error) as e:
        log.write(f"bad request: {e}\n")
        return -1, {}, []
    reason = why_not_served(request, server_env) if len(fds) == 3 else "no descriptors"
    if reason is not None:
        log.write(f"fallback: {reason}: {request['argv'][1:3]}\n")
        conn.sendall(b"F\n")
        for fd in fds:
            os.close(fd)
        return -1, request, []
    sys.stdout.flush()
    log.flush()
    pid = os.fork()
    if pid:
        for fd in fds:
            os.close(fd)  # only the child holds the shim's descriptors: a pipe ends when the command does
        log.write(f"served: {pid} {request['argv'][1:3]}\n")
        log.flush()
        conn.sendall(b"P%d\n" % pid)
    return pid, request, fds


def serve(path: str, only: list[str] | None = None) -> Callable[[], None]:
    """Serve on the Unix socket ``path`` until stdin ends (the test that started it closed it, or died); returns
    only in a forked child, what runs its command."""
    import gc
    import selectors

    _preload(only)
    gc.collect()
    gc.freeze()  # the preloaded objects out of the collector's sight: a child's collections neither scan nor copy them
    server_env = dict(os.environb)
    log = sys.stderr
    wake_r, wake_w = os.pipe()
    os.set_blocking(wake_w, False)
    signal.set_wakeup_fd(wake_w)
    signal.signal(signal.SIGCHLD, lambda *_: None)
    listener = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    listener.bind(path)
    listener.listen(64)
    children: dict[int, socket.socket] = {}
    select = selectors.DefaultSelector()
    for watched in (listener, wake_r, 0):
        select.register(watched, selectors.EVENT_READ)
    print("ready", flush=True)
    while True:
        for key, _ in select.select():
            if key.fileobj == 0:
                if not os.read(0, 512):
                    _reap(children, log, block=True)
                    raise SystemExit(0)
                continue
            if key.fileobj == wake_r:
                os.read(wake_r, 512)
                _reap(children, log)
                continue
            conn, _ = listener.accept()
            pid, request, fds = _fork_for(conn, server_env, log)
            if pid == 0:
                for other in (listener, *children.values(), conn):
                    other.close()
                select.close()
                for fd in (wake_r, wake_w):
                    os.close(fd)
                return _become_command(request, fds)
            if pid < 0:
                conn.close()
                continue
            children[pid] = conn
            _reap(children, log)


class ForkServer:
    """A fork server process for the venv's ``pige``: started with ``env`` (the blocks' environment), stopped by
    :meth:`stop`, which reaps it, so its CPU and its children's count in the test that stops it."""

    def __init__(self, folder: Path, env: dict[str, str], python: str = sys.executable,
                 only: tuple[str, ...] | None = None) -> None:
        """``only``: the modules to preload instead of :func:`_preload`'s (the server's own tests)."""
        folder.mkdir(parents=True, exist_ok=True)
        self.socket = str(folder / "pige.sock")
        if len(os.fsencode(self.socket)) > 100:  # a Unix socket's path has room for 107 bytes
            self.socket = os.path.join(tempfile.mkdtemp(prefix="pige-fork-"), "pige.sock")
        self.real = str(Path(python).parent / "pige")
        self.python = python
        self.log = folder / "server.log"
        with open(self.log, "wb") as log:
            self.process = subprocess.Popen([python, str(Path(__file__).resolve()), self.socket,
                                             *([] if only is None else [",".join(only)])],
                                            cwd=folder, env=env, stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                            stderr=log, start_new_session=True)
        assert self.process.stdout is not None
        ready = self.process.stdout.readline()
        if ready.strip() != b"ready":
            self.stop()
            raise RuntimeError(f"the fork server did not start: {self.log.read_text()[-2000:]}")

    def write_shim(self, path: Path, real: str | None = None) -> None:
        """Write the shim as ``path`` (an executable ``pige``): it stands for the console script ``real`` (the
        venv's ``pige`` by default), which the server's children run."""
        path.write_text(SHIM.format(python=self.python, socket=self.socket, real=real or self.real))
        path.chmod(0o755)

    def counts(self) -> tuple[int, list[str]]:
        """How many commands it served, and the fallbacks' lines."""
        lines = self.log.read_text().splitlines()
        return sum(x.startswith("served:") for x in lines), [x for x in lines if x.startswith("fallback:")]

    def stop(self) -> None:
        """End the server (its stdin closed: it waits for a command still running, then exits) and reap it; a
        server that does not end within 30 s is killed with what it still runs (its process group)."""
        assert self.process.stdin is not None and self.process.stdout is not None
        self.process.stdin.close()
        try:
            self.process.wait(timeout=30)
        except subprocess.TimeoutExpired:
            os.killpg(self.process.pid, signal.SIGKILL)
            self.process.wait()
        self.process.stdout.close()
        if os.path.exists(self.socket):
            os.unlink(self.socket)


@contextmanager
def started(folder: Path, env: dict[str, str], only: tuple[str, ...] | None = None) -> Iterator[ForkServer]:
    """A :class:`ForkServer` in ``folder`` for the duration of a ``with`` (a test module's fixture)."""
    server = ForkServer(folder, env, only=only)
    try:
        yield server
    finally:
        server.stop()


if __name__ == "__main__":
    serve(sys.argv[1], sys.argv[2].split(",") if len(sys.argv) > 2 else None)()
