"""Writing files safely, and JSON out: the one helper for each.

Rules every command follows (docs/formats.md, "What it refuses and why"):

- an existing output is never replaced without ``force``;
- an output is never one of the command's inputs (same file, also through links);
- only regular files are ever replaced: a symlink, FIFO, socket or device node at the output
  path is refused even with ``force``;
- the output's folder must exist (or be creatable) and be writable, checked *before* long work
  by :func:`check_output`;
- the text is written to a temporary file in the same folder, flushed to disk and renamed over
  the target, so a reader sees the old file or the new one, never half of one.

JSON: :func:`to_json` turns dataclass dicts with NumPy values into strict JSON (non-finite
floats become ``null``, never ``NaN``).
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import shutil
import signal
import stat
import tempfile
import threading
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from typing import IO, Any

from pige_sym.errors import FileFormatError, InputError

PathLike = str | os.PathLike[str]


def _same_file(a: Path, b: Path) -> bool:
    try:
        return a.exists() and b.exists() and os.path.samefile(a, b)
    except OSError:
        return False


def check_output(path: PathLike, *, force: bool = False, inputs: Iterable[PathLike] = (), what: str = "output") -> Path:
    """Refuse an output path that would clobber something; returns it as a Path.

    Parameters
    ----------
    path : path
        The file to be written.
    force : bool
        Allow replacing an existing *regular* file.
    inputs : iterable of paths
        The command's inputs; the output may be none of them.
    what : str
        Name of the option in messages (``--out``, ``--raw-log``, …).

    Raises
    ------
    InputError
        With one line that says what to change.
    """
    p = Path(path)
    for source in inputs:
        src = Path(source)
        if _same_file(p, src) or p.resolve() == src.resolve():
            raise InputError(f"{what} {p} is also an input of this command: choose another file")
    if p.is_symlink():
        raise InputError(f"{what} {p} is a symbolic link: pige never replaces one; write to the real path")
    if p.exists():
        mode = p.stat().st_mode
        if stat.S_ISDIR(mode):
            raise InputError(f"{what} {p} is a directory: give a file name")
        if not stat.S_ISREG(mode):
            raise InputError(f"{what} {p} is not a regular file (FIFO, socket or device): pige never replaces one")
        if not force:
            raise InputError(f"{what} {p} exists: pass --force to replace it, or choose another name")
    _check_writable_ancestor(p.parent if str(p.parent) else Path("."), p, what, "directory")
    return p


def _dangling_link(p: Path) -> str | None:
    """Why ``p`` cannot be a folder pige creates: a symbolic link whose target does not exist (None otherwise)."""
    if not p.is_symlink() or p.exists():
        return None
    try:
        target = os.readlink(p)
    except OSError:
        target = "?"
    return (f"{p} is a symbolic link to {target}, which does not exist: pige never creates what a link points "
            "to; create that folder, or give another")


def _check_writable_ancestor(start: Path, path: Path, what: str, noun: str) -> None:
    """Refuse ``path`` when its nearest existing ancestor (from ``start`` up) is not a writable ``noun``, or when a
    dangling symbolic link stands on the way (creating the folders would fail, or follow the link)."""
    existing = start
    while not existing.exists() and existing != existing.parent:
        dangling = _dangling_link(existing)
        if dangling:
            raise InputError(f"{what} {path}: {dangling}")
        existing = existing.parent
    if not existing.is_dir():
        raise InputError(f"{what} {path}: {existing} is not a {noun}")
    if not os.access(existing, os.W_OK | os.X_OK):
        raise InputError(f"{what} {path}: the folder {existing} is not writable")


def make_folder(folder: PathLike, *, what: str = "--out") -> Path:
    """Create an output folder and its parents (nothing when it exists; a link to a folder is followed).

    Raises
    ------
    InputError
        A dangling symbolic link on the way (pige never creates what a link points to), or the folder cannot
        be created; one line naming ``what`` and the folder.
    """
    p = Path(folder)
    for q in (p, *p.parents):
        dangling = _dangling_link(q)
        if dangling:
            raise InputError(f"{what}: {dangling}")
    try:
        p.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"{what}: cannot create the folder {p} ({exc.strerror or exc})") from None
    return p


def check_output_folder(path: PathLike, *, force: bool = False, inputs: Iterable[PathLike] = (),
                        names: Iterable[str] = (), what: str = "--out") -> Path:
    """Refuse an output folder that cannot be written, or whose ``names`` would be replaced without ``force``.

    Called before long work (the folder itself is written by :func:`staged_folder`, which checks again).
    An input inside an entry that would be replaced is refused even with ``force``.

    Raises
    ------
    InputError
        With one line that says what to change.
    """
    out = Path(path)
    if out.exists() and not out.is_dir():
        raise InputError(f"{what} {out} exists and is not a folder: give a folder name")
    _check_writable_ancestor(out, out, what, "folder")
    if out.is_dir():
        _check_replaced(out, list(names), force, inputs, what)
    return out


def _check_replaced(out: Path, names: list[str], force: bool, inputs: Iterable[PathLike], what: str) -> None:
    taken = [n for n in names if (out / n).exists() or (out / n).is_symlink()]
    if taken and not force:
        raise InputError(f"{what} {out} already holds {taken[0]}: pass --force to replace what pige writes there, "
                         "or choose another folder")
    for n in taken:
        target = out / n
        if target.is_symlink() or not (target.is_dir() or target.is_file()):
            raise InputError(f"{what}: {target} is a symbolic link or not a regular file: pige never replaces one")
        for source in inputs:
            src = Path(source).resolve()
            if src == target.resolve() or target.resolve() in src.parents:
                raise InputError(f"{what}: {target} holds the input {source}: choose another folder")


@contextlib.contextmanager
def staged_folder(path: PathLike, *, force: bool = False, inputs: Iterable[PathLike] = (),
                  what: str = "--out") -> Iterator[Path]:
    """Write a folder of outputs all at once; yields the temporary folder to write into.

    Everything is written into a hidden temporary folder (beside ``path`` when it does not exist, inside it
    when it does).  On success the temporary folder is renamed to ``path``, or, when ``path`` exists, each of
    its entries is moved into it (entries already there are replaced only with ``force``; other files in
    the folder are left alone).  SIGINT and SIGTERM wait while the folder is created and while the entries
    move, so an interrupt leaves the old outputs or the new ones, never a mixture; an error or interrupt in
    between removes the temporary folder (SIGTERM raises ``KeyboardInterrupt`` meanwhile, so ``kill`` cleans
    up too).
    """
    out = Path(path)
    check_output_folder(out, force=force, inputs=inputs, what=what)
    host = out if out.is_dir() else out.parent
    tmp: Path | None = None
    with _terminate_as_interrupt():
        try:
            with _deferred_interrupts():
                tmp = _make_stage(host, out, what)
            yield tmp
            with _deferred_interrupts():
                raise_if_interrupted()
                _commit(tmp, out, force, list(inputs), what)
        except BaseException:
            if tmp is not None:
                shutil.rmtree(tmp, ignore_errors=True)
            raise


#: Set by pige's interrupt handlers that raise KeyboardInterrupt wherever the program is (SIGINT while a command
#: runs, SIGTERM while a folder is staged).  Python ignores an exception raised in a finaliser (``__del__``, a weakref
#: callback: it prints "Exception ignored ... KeyboardInterrupt" and goes on), so an interrupt can be lost on its way
#: up; the latch keeps it, and nothing is published after one (:func:`raise_if_interrupted`).
_INTERRUPTED = threading.Event()


def note_interrupt() -> None:
    """Remember that an interrupt reached the process (called by the handlers that raise KeyboardInterrupt)."""
    _INTERRUPTED.set()


def clear_interrupt() -> None:
    """Forget a noted interrupt: a command starts or ends, or code that catches KeyboardInterrupt on purpose has
    handled it (the acquisition, which then writes its summary)."""
    _INTERRUPTED.clear()


def interrupt_noted() -> bool:
    """Whether an interrupt was noted since the command started (its KeyboardInterrupt may have been lost)."""
    return _INTERRUPTED.is_set()


def raise_if_interrupted() -> None:
    """Raise KeyboardInterrupt (once) when an interrupt was noted: called just before an output is published, so an
    interrupt whose KeyboardInterrupt was swallowed on the way still stops the output from appearing."""
    if _INTERRUPTED.is_set():
        _INTERRUPTED.clear()
        raise KeyboardInterrupt


def _make_stage(host: Path, out: Path, what: str) -> Path:
    try:
        host.mkdir(parents=True, exist_ok=True)
        tmp = Path(tempfile.mkdtemp(prefix=f".{out.name or 'out'}.pige-partial-", dir=host))
        os.chmod(tmp, 0o777 & ~_umask())  # what mkdir would give (mkdtemp gives 0700)
    except OSError as exc:
        raise InputError(f"{what} {out}: cannot write there ({exc.strerror or exc})") from None
    return tmp


def _in_main_thread() -> bool:
    return threading.current_thread() is threading.main_thread()


@contextlib.contextmanager
def _terminate_as_interrupt() -> Iterator[None]:
    """SIGTERM raises KeyboardInterrupt in the main thread while the block runs (elsewhere: nothing changes)."""
    if not _in_main_thread() or not hasattr(signal, "SIGTERM"):
        yield
        return

    def _raise(signum: int, frame: object) -> None:
        note_interrupt()
        raise KeyboardInterrupt

    old = signal.signal(signal.SIGTERM, _raise)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, old)


@contextlib.contextmanager
def _deferred_interrupts() -> Iterator[None]:
    """SIGINT and SIGTERM are noted while the block runs and raise KeyboardInterrupt after it.

    Python runs signal handlers in the main thread whichever thread the signal reached, so noting them
    there holds them back reliably (a thread's signal mask would not: BLAS threads take the signal).
    """
    if not _in_main_thread():
        yield
        return
    got: list[int] = []

    def _note(signum: int, frame: object) -> None:
        got.append(signum)

    kinds = [signal.SIGINT] + ([signal.SIGTERM] if hasattr(signal, "SIGTERM") else [])
    old = {k: signal.signal(k, _note) for k in kinds}
    try:
        yield
    finally:
        for k, handler in old.items():
            signal.signal(k, handler)
    if got:
        raise KeyboardInterrupt


def _commit(tmp: Path, out: Path, force: bool, inputs: list[PathLike], what: str) -> None:
    """Move the staged entries into place (:func:`staged_folder`)."""
    entries = sorted(tmp.iterdir(), key=lambda e: (e.is_file(), e.name))  # files (the page) last
    try:
        if tmp.parent != out:  # the folder did not exist: one rename
            try:
                os.rename(tmp, out)
                return
            except OSError:  # created meanwhile: move the entries into it
                out.mkdir(exist_ok=True)
        _check_replaced(out, [e.name for e in entries], force, inputs, what)
        clash = [e.name for e in entries if (out / e.name).exists() and (out / e.name).is_dir() != e.is_dir()]
        if clash:
            raise InputError(f"{what}: {out / clash[0]} is a {'folder' if (out / clash[0]).is_dir() else 'file'} "
                             "where the report writes the other kind: move it away")
        trash = Path(tempfile.mkdtemp(prefix=".pige-replaced-", dir=tmp))
        for e in entries:
            target = out / e.name
            if e.is_dir() and target.exists():
                os.rename(target, trash / e.name)
            os.replace(e, target)
        shutil.rmtree(tmp, ignore_errors=True)
    except OSError as exc:
        raise InputError(f"{what} {out}: cannot write there ({exc.strerror or exc})") from None


def _umask() -> int:
    """The process's umask, read from ``/proc/self/status`` where it exists (setting the umask to read it would
    race with other threads creating files); elsewhere by setting it and putting it back."""
    try:
        with open("/proc/self/status", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError):
        pass
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def new_file_mode() -> int:
    """Mode of a newly created file under the process's umask (``0o666 & ~umask``)."""
    return 0o666 & ~_umask()


def atomic_write_text(path: PathLike, text: str | Iterable[str], *, encoding: str = "utf-8",
                      newline: str | None = None, verify: Callable[[Path], None] | None = None) -> Path:
    """Write ``text`` (a string, or pieces of one) to ``path`` through a temporary file and a rename (same folder).

    ``verify``, when given, is called with the temporary file once it is written; if it raises, the temporary
    file is removed and nothing replaces ``path`` (a writer that reads its output back before publishing it).

    The caller decides whether replacing is allowed (:func:`check_output`); this function only
    refuses to replace anything that is not a regular file.  Missing parent folders are created.
    The file gets the mode a plain ``open`` would give it (``0666`` less the umask: ``0644`` under
    ``022``, so a DNC account or a web server can read a compensated program), and a replaced file
    keeps its own mode.
    """
    p = Path(path)
    if p.is_symlink() or (p.exists() and not p.is_file()):
        raise InputError(f"{p} is not a regular file: pige never replaces one")
    make_folder(p.parent if str(p.parent) else Path("."), what=f"cannot write {p}")
    mode = new_file_mode() if not p.exists() else p.stat().st_mode & 0o7777
    tmp: Path | None = None
    try:
        with _deferred_interrupts():  # the temporary file exists only once the clean-up below knows its name
            fd, name = tempfile.mkstemp(prefix=f".{p.name}.", suffix=".tmp", dir=p.parent)
            tmp = Path(name)
            try:
                fh = os.fdopen(fd, "w", encoding=encoding, newline=newline)
            except BaseException:
                os.close(fd)
                raise
        with fh:
            os.fchmod(fh.fileno(), mode)
            for piece in [text] if isinstance(text, str) else text:
                fh.write(piece)
            fh.flush()
            os.fsync(fh.fileno())
        if verify is not None:
            verify(tmp)
        with _deferred_interrupts():
            raise_if_interrupted()
            os.replace(tmp, p)
    except OSError as exc:
        _remove_quietly(tmp)
        raise InputError(f"cannot write {p}: {exc.strerror or exc}") from exc
    except BaseException:
        _remove_quietly(tmp)
        raise
    return p


def _remove_quietly(path: Path | None) -> None:
    """Remove a temporary file pige made (nothing when None or gone); an interrupt meanwhile waits for it."""
    if path is not None:
        with _deferred_interrupts():
            path.unlink(missing_ok=True)


def open_regular_file(path: PathLike) -> IO[bytes]:
    """Open a regular file for binary reading; a FIFO, socket, device or folder is refused.

    The file is opened without blocking (a FIFO would otherwise wait for a writer), checked
    with ``fstat`` on the open descriptor (no race with a rename), then switched to blocking.

    Raises
    ------
    FileFormatError
        Naming the file and the problem.
    """
    p = str(path)
    try:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
    except FileNotFoundError:
        raise FileFormatError(p, None, "file not found") from None
    except OSError as exc:
        raise FileFormatError(p, None, f"cannot read: {exc.strerror or exc}") from None
    mode = os.fstat(fd).st_mode
    if not stat.S_ISREG(mode):
        os.close(fd)
        what = "a directory" if stat.S_ISDIR(mode) else "not a regular file (FIFO, socket or device)"
        raise FileFormatError(p, None, f"{what}: pige reads regular files only")
    if hasattr(os, "set_blocking"):
        os.set_blocking(fd, True)
    return os.fdopen(fd, "rb")


def read_input_bytes(path: PathLike, *, limit: int | None = None, what: str = "file") -> bytes:
    """The bytes of an input file (at most ``limit + 1`` when given), through :func:`open_regular_file`.

    The one way pige reads a whole input: a FIFO, socket, device or folder is refused before anything
    is read (no hang), and an unreadable file is a located refusal, not an ``OSError``.

    Raises
    ------
    FileFormatError
        Naming the file and the problem (``what`` names the kind of file in the message).
    """
    with open_regular_file(path) as fh:
        try:
            return fh.read() if limit is None else fh.read(limit + 1)
        except OSError as exc:
            raise FileFormatError(str(path), None, f"cannot read this {what}: {exc.strerror or exc}") from None


def read_input_text(path: PathLike, *, what: str = "file") -> str:
    """The UTF-8 text of an input file, exactly (line endings and a BOM kept; :func:`read_input_bytes`).

    Raises
    ------
    FileFormatError
        Not a regular readable file, or not UTF-8 (with the line of the first bad byte).
    """
    raw = read_input_bytes(path, what=what)
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = raw[:exc.start].count(b"\n") + 1
        raise FileFormatError(str(path), line, f"not a UTF-8 text {what} ({exc.reason}): save it as UTF-8") from None


def peek_input(path: PathLike, size: int = 4096) -> bytes:
    """The first ``size`` bytes of a regular file, or ``b""`` for anything else (missing, unreadable, FIFO, folder).

    For sniffing a file's kind (its format line): it never blocks and never raises; the reader that
    follows refuses what is not a readable regular file, with its message.
    """
    try:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
    except OSError:
        return b""
    try:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            return b""
        return os.read(fd, size)
    except OSError:
        return b""
    finally:
        os.close(fd)


def json_ready(x: Any) -> Any:
    """Python values for JSON: NumPy scalars/arrays converted, non-finite floats → None, recursively."""
    import numpy as np

    if isinstance(x, dict):
        return {str(k): json_ready(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [json_ready(v) for v in x]
    if isinstance(x, np.ndarray):
        return json_ready(x.tolist())
    if isinstance(x, (np.floating, float)):
        return float(x) if math.isfinite(float(x)) else None
    if isinstance(x, (np.integer,)):
        return int(x)
    if isinstance(x, np.bool_):
        return bool(x)
    if isinstance(x, Path):
        return str(x)
    return x


def to_json(x: Any, *, indent: int | None = 1) -> str:
    """Strict JSON text of ``x`` (see :func:`json_ready`); never contains NaN or Infinity."""
    return json.dumps(json_ready(x), indent=indent, allow_nan=False, ensure_ascii=False)
