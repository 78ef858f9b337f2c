"""A throw-away PostgreSQL server for the tests: one per test process, a fresh database per test module.

``postgres_url`` (module scope) is a database of its own on a server that the process starts the first time a
module asks for one (``initdb`` is the costly part: about 1.2 s of CPU and, on a loaded machine, seconds of wall
time) and stops when the process ends.  Each module gets a new, empty database (``CREATE DATABASE``), as it got a
new server before, so no module sees another's tables.  Both fixtures skip cleanly when no server can start.
``tests/conftest.py`` imports them, so every test module can ask for ``postgres_url``.
"""

from __future__ import annotations

import glob
import itertools
import os
import shutil
import socket
import subprocess
import tempfile
from collections.abc import Iterator
from pathlib import Path

import pytest

_DATABASES = itertools.count(1)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _pg_bin() -> Path | None:
    found = sorted(glob.glob("/usr/lib/postgresql/*/bin/initdb"))
    if found:
        return Path(found[-1]).parent
    exe = shutil.which("initdb")
    return Path(exe).parent if exe else None


def _run_as(root: Path) -> list[str]:
    """The command prefix that runs the server's programs (as the postgres user when the tests run as root)."""
    if os.geteuid() != 0:  # the server refuses to run as root: run it as the postgres user
        return []
    runuser = shutil.which("runuser")
    try:
        import pwd

        pw = pwd.getpwnam("postgres")
    except KeyError:
        pytest.skip("running as root and there is no postgres user to run the server")
    if runuser is None:
        pytest.skip("running as root without runuser")
    os.chown(root, pw.pw_uid, pw.pw_gid)
    return [runuser, "-u", "postgres", "--"]


@pytest.fixture(scope="session")
def postgres_server() -> Iterator[str]:
    """The URL of this process's PostgreSQL server on 127.0.0.1, in a temporary directory (its ``postgres``
    database is left alone: tests use ``postgres_url``)."""
    pytest.importorskip("psycopg", reason="psycopg is not installed (pip install 'pige_sym[postgres]')")
    bindir = _pg_bin()
    if bindir is None:
        pytest.skip("PostgreSQL server binaries not found (apt-get install postgresql)")
    root = Path(tempfile.mkdtemp(prefix="pige-pg-"))
    try:
        prefix = _run_as(root)
    except BaseException:
        shutil.rmtree(root, ignore_errors=True)
        raise
    data, port = root / "data", _free_port()
    log = root / "server.log"

    def run(*cmd: str) -> subprocess.CompletedProcess[str]:
        return subprocess.run([*prefix, *cmd], capture_output=True, text=True, timeout=120, check=False)

    init = run(str(bindir / "initdb"), "-D", str(data), "-U", "pige", "-A", "trust", "--no-sync", "-E", "UTF8")
    if init.returncode != 0:
        shutil.rmtree(root, ignore_errors=True)
        pytest.skip(f"initdb failed: {init.stderr.strip()[-300:]}")
    start = run(str(bindir / "pg_ctl"), "-D", str(data), "-l", str(log), "-w", "-t", "60", "-o",
                f"-c listen_addresses=127.0.0.1 -p {port} -k {root} -c fsync=off", "start")
    if start.returncode != 0:
        text = log.read_text() if log.exists() else start.stderr
        shutil.rmtree(root, ignore_errors=True)
        pytest.skip(f"PostgreSQL did not start: {text.strip()[-300:]}")
    try:
        yield f"postgresql://pige@127.0.0.1:{port}"
    finally:
        run(str(bindir / "pg_ctl"), "-D", str(data), "-m", "immediate", "-w", "stop")
        shutil.rmtree(root, ignore_errors=True)


@pytest.fixture(scope="module")
def postgres_url(postgres_server: str) -> Iterator[str]:
    """A new, empty database on this process's server for one test module; dropped after it."""
    import psycopg

    name = f"pige_test_{os.getpid()}_{next(_DATABASES)}"
    with psycopg.connect(f"{postgres_server}/postgres", autocommit=True) as conn:
        conn.execute(f"CREATE DATABASE {name}")
    try:
        yield f"{postgres_server}/{name}"
    finally:
        with psycopg.connect(f"{postgres_server}/postgres", autocommit=True) as conn:
            conn.execute(f"DROP DATABASE IF EXISTS {name} WITH (FORCE)")
