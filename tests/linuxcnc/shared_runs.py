"""What several LinuxCNC test files share, made once per test session even when the files run in separate processes.

``make test-linuxcnc`` runs every file of tests/linuxcnc in its own pytest-xdist worker (``--dist loadfile``, one
worker per file: docs/testing.md), so the files' simulations go side by side.  A result that several files use
(the AC and BC tables' probing runs: test_linuxcnc_loop checks them, the check-up and the corrections start from
them; the true table's component source, which takes SymPy seconds; a compiled HAL component) is made by
:func:`once`: the first process to ask makes it while it holds an exclusive lock (``fcntl.flock``) on
``<key>.lock`` in the session's shared folder and leaves it pickled beside the lock; a process that asks meanwhile
waits on the lock and reads the pickle.  Threads of one process wait the same way (each opens the lock file
itself), and a process reads a pickle once.  Outside pytest, or before :func:`set_folder`, :func:`once` makes the
value in the process.

A value that raised is not kept: the next one to ask tries again (and fails the same way in its own test).
"""

from __future__ import annotations

import fcntl
import hashlib
import os
import pickle
import re
import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar

T = TypeVar("T")
_FOLDER: Path | None = None
_MEMO: dict[str, Any] = {}
_MEMO_LOCK = threading.Lock()


def session_folder(basetemp: Path) -> Path:
    """The folder every worker of this test session shares: the session's base temporary folder (a worker's
    ``basetemp`` is ``pytest-N/popen-gwK``: its parent) or, without xdist, the one process' own."""
    return basetemp.parent if os.environ.get("PYTEST_XDIST_WORKER") else basetemp


def set_folder(folder: Path | None) -> None:
    """Where :func:`once` keeps its locks and pickles for this session (None: make every value in the process)."""
    global _FOLDER
    if folder is not None:
        folder.mkdir(parents=True, exist_ok=True)
    _FOLDER = folder


def file_stem(key: str) -> str:
    """A file name for ``key``: its readable part and a hash (keys may hold any character)."""
    readable = re.sub(r"[^A-Za-z0-9_.-]+", "_", key)[:60]
    return f"{readable}-{hashlib.sha256(key.encode()).hexdigest()[:12]}"


def once(key: str, make: Callable[[], T]) -> T:
    """``make()``, made once per test session across processes and threads (module docstring)."""
    with _MEMO_LOCK:
        if key in _MEMO:
            return _MEMO[key]  # type: ignore[no-any-return]
    if _FOLDER is None:
        value = make()
    else:
        stem = _FOLDER / file_stem(key)
        kept = stem.with_suffix(".pickle")
        with open(stem.with_suffix(".lock"), "a") as lock:
            fcntl.flock(lock, fcntl.LOCK_EX)
            try:
                if kept.is_file():
                    value = pickle.loads(kept.read_bytes())
                else:
                    value = make()
                    part = stem.with_suffix(".part")
                    part.write_bytes(pickle.dumps(value))
                    part.replace(kept)
            finally:
                fcntl.flock(lock, fcntl.LOCK_UN)
    with _MEMO_LOCK:
        return _MEMO.setdefault(key, value)  # type: ignore[no-any-return]
