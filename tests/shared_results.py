"""Code-generation results that one test run computes once and all its processes share.

``make test`` runs the test files in two pytest-xdist processes; ``test_gen_linuxcnc.py``,
``test_gen_linuxcnc_maps.py`` and ``test_gen_linuxcnc_hal.py`` each need the C model and the LinuxCNC component of
the same machines, which SymPy takes seconds to derive.  :func:`shared_texts` computes each once per run, whichever
process asks first, and the others read it.

* The folder is the run's own: beside the processes' temporary folders under pytest-xdist (the run's base
  temporary folder, named after ``PYTEST_XDIST_TESTRUNUID``), the session's temporary folder without it; never the
  checkout, never a later run (pytest removes old temporary folders).
* A result's key is what computed it: the producer's name and arguments, the SymPy version and the text of every
  source of ``pige_sym/codegen`` (an edited generator is never served an old result).
* One ``fcntl.flock`` per key: the first process computes and writes the file atomically (a temporary file, then
  ``os.replace``), the others wait for the lock and read it.  A process takes first the keys no other process holds,
  so two processes that need the same machines derive different ones at the same time.
"""

from __future__ import annotations

import contextlib
import fcntl
import hashlib
import json
import os
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
import sympy

import pige_sym.codegen

_SOURCES = Path(pige_sym.codegen.__file__).parent


def _generator_digest() -> str:
    h = hashlib.sha256(sympy.__version__.encode())
    for path in sorted(_SOURCES.rglob("*.py")):
        h.update(path.relative_to(_SOURCES).as_posix().encode() + b"\0" + path.read_bytes() + b"\0")
    return h.hexdigest()


def run_folder(factory: pytest.TempPathFactory) -> Path:
    """The folder this run's processes share (created on first use)."""
    base = factory.getbasetemp()
    run = os.environ.get("PYTEST_XDIST_TESTRUNUID")
    if run and base.name.startswith("popen-gw"):
        folder = base.parent / f"shared-{run}"  # pytest-xdist: the run's base folder holds each process' own
    else:
        folder = base / "shared"
    folder.mkdir(exist_ok=True)
    return folder


@contextlib.contextmanager
def _locked(path: Path, blocking: bool) -> Iterator[bool]:
    with open(path, "a") as fh:
        try:
            fcntl.flock(fh, fcntl.LOCK_EX | (0 if blocking else fcntl.LOCK_NB))
        except BlockingIOError:
            yield False
            return
        try:
            yield True
        finally:
            fcntl.flock(fh, fcntl.LOCK_UN)


def shared_texts(factory: pytest.TempPathFactory, name: str, args: list[str],
                 produce: Callable[[str], dict[str, str]]) -> dict[str, dict[str, str]]:
    """``{arg: produce(arg)}`` (file name -> text), each computed once per run by whichever process asks first.

    ``name`` names the producer (with ``args`` and the generator's sources, the key of each result).
    """
    folder, digest = run_folder(factory), _generator_digest()
    paths = {a: folder / hashlib.sha256(f"{digest}\0{name}\0{a}".encode()).hexdigest()[:32] for a in args}
    out: dict[str, dict[str, str]] = {}
    for blocking in (False, True):  # first what nobody else is computing, then wait for the rest
        for arg in args:
            if arg in out:
                continue
            path = paths[arg]
            with _locked(path.with_suffix(".lock"), blocking) as held:
                if not held:
                    continue
                if not path.exists():
                    tmp = path.with_suffix(f".{os.getpid()}.tmp")
                    tmp.write_text(json.dumps(produce(arg)), encoding="utf-8")
                    os.replace(tmp, path)
                out[arg] = json.loads(path.read_text(encoding="utf-8"))
    return {a: out[a] for a in args}
