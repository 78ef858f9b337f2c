"""The fork server the docs tests run ``pige`` in (``tests/fork_server.py``): a served command behaves as the same
console script started fresh by bash.

The oracle is the script itself: a small console script (:data:`FAKE`: exit statuses, stdin, environment,
working folder and umask, signals, a traceback, a broken pipe, random state) runs once through the shim and the
server and once as a fresh process, in the same bash command line, and the two must agree: exit status, stdout
and stderr.  The real ``pige`` is compared the same way on a refused command (exit 2).  What the server cannot
serve exactly (an environment variable it did not start with, a ``matplotlibrc`` in the working folder, a
closed descriptor, no server) falls back to the real script: the result is the same, and the server's log says so.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest
from fork_server import SHIM, ForkServer, started, sympy_free_modules

from testdata import scratch_env, strict_script

#: The console script served, and started fresh as the oracle.
FAKE = '''#!{python}
import os, signal, sys, time
cmd, arg = sys.argv[1], (sys.argv[2:] or [""])[0]
if cmd == "exit":
    sys.exit(int(arg))
if cmd == "cat":
    sys.stdout.write(sys.stdin.read().upper())
if cmd == "env":
    print(repr(os.environ.get(arg)))
if cmd == "where":
    print(os.getcwd(), oct(os.umask(0)), os.path.basename(sys.argv[0]))
if cmd == "signal":
    os.kill(os.getpid(), int(arg))
if cmd == "raise":
    raise ValueError("boom")
if cmd == "many":
    for i in range(200000):
        print(i)
if cmd == "sleep":
    time.sleep(float(arg))
if cmd == "random":
    import numpy
    print(numpy.random.random(), os.getpid())
if cmd == "interleave":
    for i in range(3):
        print("out", i)
        print("err", i, file=sys.stderr)
if cmd == "message":
    sys.exit("refused: " + arg)
'''


@pytest.fixture(scope="module")
def setup(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[ForkServer, Path, dict[str, str]]]:
    """A server running :data:`FAKE`; a folder whose ``served/pige`` is its shim and ``fresh/pige`` the script."""
    root = tmp_path_factory.mktemp("fork")
    for name in ("served", "fresh", "work"):
        (root / name).mkdir()
    fake = root / "fresh" / "pige"
    fake.write_text(FAKE.format(python=sys.executable))
    fake.chmod(0o755)
    env = scratch_env(root, root / "pycache")
    env.pop("PYTHONPYCACHEPREFIX")  # the suite's bytecode as the test process has it: none compiled again
    env.update({k: v for k, v in os.environ.items() if k == "PYTHONPYCACHEPREFIX"})
    with started(root / "server", env, only=("numpy", "pige_sym.cli.main")) as server:  # the docs tests: all
        server.write_shim(root / "served" / "pige", real=str(fake))
        yield server, root, env


def both(setup: tuple[ForkServer, Path, dict[str, str]], line: str) -> tuple[subprocess.CompletedProcess[str], ...]:
    """``line`` run by bash with the served ``pige`` first on PATH, then with the fresh one."""
    server, root, env = setup
    out = []
    for kind in ("served", "fresh"):
        run_env = {**env, "PATH": f"{root / kind}{os.pathsep}{env['PATH']}"}
        out.append(subprocess.run(["bash", "-c", line], cwd=root / "work", env=run_env, capture_output=True,
                                  text=True, timeout=60))
    return tuple(out)


def served_lines(server: ForkServer) -> list[str]:
    return [x for x in server.log.read_text().splitlines() if x.startswith(("served", "fallback"))]


@pytest.mark.parametrize("line", [
    "pige exit 0; echo $?", "pige exit 2; echo $?", "pige exit 3 || echo failed $?", "pige exit 256; echo $?",
    "printf 'abc\\ndef' | pige cat", "printf 'x' > in.txt; pige cat < in.txt", "echo hi | pige cat | pige cat",
    "x=$(echo sub | pige cat); echo \"got $x\"", "pige cat <<< 'here string'",
    "mkdir -p sub && cd sub && umask 027 && pige where",
    "PIGE_HISTORY_DB=/tmp/x.db pige env PIGE_HISTORY_DB", "pige env PIGE_KERNEL_DIR", "pige env NOT_SET",
    "pige signal 15; echo $?", "pige signal 9; echo $?", "pige signal 2; echo $?",
    "pige message 'no such file'; echo $?", "pige interleave 2>&1", "pige interleave 2>&1 > /dev/null",
    "pige many | head -2; echo ${PIPESTATUS[0]}", "pige sleep 10 & p=$!; sleep 0.5; kill $p; wait $p; echo $?",
])
def test_a_served_command_behaves_as_a_fresh_one(setup: tuple[ForkServer, Path, dict[str, str]], line: str) -> None:
    before = len(served_lines(setup[0]))
    served, fresh = both(setup, line)
    assert (served.returncode, served.stdout) == (fresh.returncode, fresh.stdout)
    assert re.sub(r"\d+ (Killed|Terminated)", "PID", served.stderr) == re.sub(r"\d+ (Killed|Terminated)", "PID",
                                                                          fresh.stderr)  # bash names the pid
    assert any(x.startswith("served") for x in served_lines(setup[0])[before:]), served_lines(setup[0])[before:]


def test_a_traceback_and_its_status(setup: tuple[ForkServer, Path, dict[str, str]]) -> None:
    served, fresh = both(setup, "pige raise; echo status $?")
    assert served.stdout == fresh.stdout == "status 1\n"
    assert served.stderr == fresh.stderr and served.stderr.splitlines()[-1] == "ValueError: boom"  # runpy's frames cut


def test_each_command_starts_from_a_fresh_state(setup: tuple[ForkServer, Path, dict[str, str]]) -> None:
    served, _ = both(setup, "pige random; pige random")
    (r1, pid1), (r2, pid2) = (line.split() for line in served.stdout.splitlines())
    assert r1 != r2 and pid1 != pid2  # NumPy's global random state drawn again, as a new process draws it


def test_a_failing_served_command_stops_the_page(setup: tuple[ForkServer, Path, dict[str, str]]) -> None:
    script = strict_script([("page.md", 7, "pige exit 0\npige exit 2 && echo never\necho after")])
    served, fresh = both(setup, script)
    assert served.returncode == fresh.returncode == 2 and "after" not in served.stdout
    assert "page.md line 8: " in served.stderr and served.stderr == fresh.stderr


@pytest.mark.parametrize(("line", "why"), [
    ("MPLBACKEND=pdf pige env MPLBACKEND", "environment differs in MPLBACKEND"),
    ("export PYTHONHASHSEED=3; pige env PYTHONHASHSEED", "environment differs in PYTHONHASHSEED"),
    ("touch matplotlibrc; pige where; rm matplotlibrc", "a matplotlibrc in the working folder"),
])
def test_what_it_cannot_serve_exactly_runs_fresh(setup: tuple[ForkServer, Path, dict[str, str]], line: str,
                                                 why: str) -> None:
    before = len(served_lines(setup[0]))
    served, fresh = both(setup, line)
    assert (served.returncode, served.stdout, served.stderr) == (fresh.returncode, fresh.stdout, fresh.stderr)
    assert [x.split(": ")[1] for x in served_lines(setup[0])[before:]] == [why]


def test_a_closed_descriptor_or_no_server_runs_fresh(setup: tuple[ForkServer, Path, dict[str, str]],
                                                     tmp_path: Path) -> None:
    before = len(served_lines(setup[0]))
    served, fresh = both(setup, "pige where <&-; echo $?")
    assert (served.returncode, served.stdout) == (fresh.returncode, fresh.stdout)
    assert len(served_lines(setup[0])) == before  # the shim did not ask
    _, root, env = setup
    (tmp_path / "pige").write_text(SHIM.format(python=sys.executable, socket=str(tmp_path / "gone.sock"),
                                               real=str(root / "fresh" / "pige")))
    (tmp_path / "pige").chmod(0o755)
    done = subprocess.run(["bash", "-c", "pige exit 3; echo $?"], env={**env, "PATH": f"{tmp_path}:{env['PATH']}"},
                          capture_output=True, text=True, timeout=60, check=True)
    assert done.stdout == "3\n"


def test_the_real_pige_refuses_as_it_does_fresh(setup: tuple[ForkServer, Path, dict[str, str]],
                                                tmp_path: Path) -> None:
    if not (Path(sys.executable).parent / "pige").exists():
        pytest.skip("needs the pige console script (make venv)")
    server, _, env = setup
    server.write_shim(tmp_path / "pige")
    before = server.counts()[0]
    runs = [subprocess.run(["bash", "-c", f"{pige} identify missing.csv; echo $?; {pige} --version"],
                           cwd=tmp_path, env=env, capture_output=True, text=True, timeout=120)
            for pige in (tmp_path / "pige", Path(sys.executable).parent / "pige")]
    assert server.counts()[0] == before + 2
    assert runs[0].stdout == runs[1].stdout and runs[0].stdout.splitlines()[0] == "2"
    assert runs[0].stderr == runs[1].stderr and "missing.csv" in runs[0].stderr


def test_the_preloaded_modules_leave_sympy_out() -> None:
    free = sympy_free_modules()
    assert "pige_sym.cli.main" in free and "pige_sym.codegen.machine_code" in free
    assert "pige_sym.codegen.symbolic" not in free and "pige_sym.codegen.emit" not in free
