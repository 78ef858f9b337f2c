"""Where the checkout and ../shared are, and a minimal independent reader of the reference data.

Imported by the tests as ``from testdata import REPO`` (tests/ is on the path); not from ``conftest``, which a
conftest.py in a sub-folder (tests/linuxcnc) replaces as the module of that name.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared"
REFERENCE = SHARED / "reference"


def reference_files(pattern: str) -> list[Path]:
    """Reference CSVs matching a glob, or [] when ../shared is absent."""
    return sorted(REFERENCE.glob(pattern)) if REFERENCE.is_dir() else []


def refused_in_one_line(code: int, err: str, *fragments: str) -> None:
    """Assert a command was refused as bad input (exit 2) with one line on stderr naming every fragment."""
    assert code == 2, err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    for f in fragments:
        assert f in err, (f, err)


def require_shared() -> None:
    if not REFERENCE.is_dir():
        pytest.skip("../shared/reference is absent (a user's clone has none)")


def load_reference(path: Path) -> tuple[dict[str, str], dict[str, np.ndarray], dict]:
    """Minimal independent reader of a reference CSV: (metadata, columns, truth)."""
    meta: dict[str, str] = {}
    rows = []
    header: list[str] = []
    for line in path.read_text().splitlines():
        if line.startswith("#"):
            if ":" in line:
                k, v = line[1:].split(":", 1)
                meta[k.strip()] = v.strip()
            continue
        if not line.strip():
            continue
        if not header:
            header = line.split(",")
            continue
        rows.append([float(x) for x in line.split(",")])
    arr = np.array(rows)
    cols = {h: arr[:, i] for i, h in enumerate(header)}
    truth = json.loads(path.with_name(path.stem + ".truth.json").read_text())
    return meta, cols, truth
