"""Give ``make test``'s bytecode folder the bytecode pip already compiled for the venv.

Under ``PYTHONDONTWRITEBYTECODE`` ``make test`` runs with ``PYTHONPYCACHEPREFIX=.venv/pycache`` (the Makefile's
``TEST_ENV``), so that the suite's bytecode is kept from one run to the next and never written beside the
sources.  Python then reads bytecode only from that folder, ``<prefix>/<source folder>/<module>.<tag>.pyc``, and
ignores the ``__pycache__`` folders pip filled when it installed the venv's packages: the first ``make test`` on a
fresh clone compiled NumPy, SciPy, matplotlib, SymPy … again (about 20 s of its wall time).  ``make venv`` runs
this script once after pip: every ``__pycache__/<module>.<tag>.pyc`` under the given folders is hard-linked (copied
across file systems) to where the prefix looks for it.  A .pyc carries its source's modification time and size, so
Python still checks it against the source and compiles again whatever changed.

Usage::

    python tests/bytecode_prefix.py PREFIX FOLDER [FOLDER ...]
"""

from __future__ import annotations

import os
import shutil
import sys
from pathlib import Path


def link_bytecode(prefix: Path, folder: Path) -> int:
    """Link every ``__pycache__`` .pyc of this interpreter under ``folder`` into ``prefix``; the number linked.

    Parameters
    ----------
    prefix : Path
        The ``PYTHONPYCACHEPREFIX`` folder.
    folder : Path
        A folder of sources whose ``__pycache__`` folders hold compiled bytecode (a venv's ``lib``).
    """
    tag = sys.implementation.cache_tag
    count = 0
    for pyc in folder.resolve().rglob(f"__pycache__/*.{tag}.pyc"):
        target = prefix / pyc.parent.parent.relative_to(pyc.anchor) / pyc.name
        if target.exists():
            continue
        target.parent.mkdir(parents=True, exist_ok=True)
        try:
            os.link(pyc, target)
        except OSError:
            shutil.copy2(pyc, target)
        count += 1
    return count


def main(argv: list[str]) -> int:
    """The command line of the module docstring."""
    if len(argv) < 2:
        print(__doc__, file=sys.stderr)
        return 2
    prefix = Path(argv[0]).resolve()
    total = sum(link_bytecode(prefix, Path(f)) for f in argv[1:])
    print(f"bytecode_prefix: {total} compiled modules linked into {prefix}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
