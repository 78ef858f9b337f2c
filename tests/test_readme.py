"""The README runs as written: its "A first session", check-up, touch-probe and ballbar shell blocks, in order, in a
fresh folder.

The blocks are taken from the README itself (so they cannot drift), run by bash from a scratch folder laid out
like the checkout's root (the README says: from the checkout's root; :func:`testdata.scratch_checkout`: a link to
``.venv``, copies of ``examples`` and ``tests``, history, kernels and bytecode in scratch folders), and every
command must succeed: :func:`testdata.strict_script` checks every top-level command's status (``a && b``
included, which ``set -e`` lets pass).  They must leave the checkout as it was.  Their ``pige`` commands run in
children of a fork server that imported the libraries once (``tests/fork_server.py``; as in test_docs_blocks),
and every one of them must have run there (none fell back to a fresh process).
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest
from fork_server import started

from testdata import changed_files, checkout_files, scratch_checkout, scratch_env, strict_script

ROOT = Path(__file__).resolve().parents[1]


def _blocks(heading: str) -> list[tuple[str, int, str]]:
    """The ``sh`` blocks of a README section: (page, line of the block's first line, text)."""
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    start = text.index(heading)
    end = text.find("\n## ", start + len(heading))
    return [("README.md", text.count("\n", 0, start + m.start(1)) + 1, m.group(1))
            for m in re.finditer(r"```sh\n(.*?)```", text[start:end if end != -1 else len(text)], re.S)]


def test_the_first_session_and_the_probe_demo_run_as_pasted(tmp_path: Path,
                                                            tmp_path_factory: pytest.TempPathFactory) -> None:
    venv = Path(sys.executable).parent.parent
    if not (venv / "bin" / "pige").exists():
        pytest.skip("needs the pige console script (make venv)")
    pycache = Path(os.environ.get("PYTHONPYCACHEPREFIX") or tmp_path / "pycache")
    home = tmp_path_factory.mktemp("fork-server")
    with started(home, scratch_env(home, pycache)) as server:
        _run_and_check(scratch_checkout(tmp_path, pycache, server), tmp_path)
        served, fallbacks = server.counts()
    assert served >= 30 and not fallbacks, (served, fallbacks)  # the pige commands ran in the fork server


def _run_and_check(env: dict[str, str], tmp_path: Path) -> None:
    """Run the README's blocks with ``env`` in ``tmp_path`` (a scratch checkout) and check what they made."""
    blocks = _blocks("## A first session") + _blocks("## The check-up") + \
        _blocks("## Calibrating with a touch probe") + _blocks("## Calibrating with a ballbar")
    assert len(blocks) >= 5
    script = strict_script(blocks)
    before = checkout_files()
    done = subprocess.run(["bash", "-c", script], cwd=tmp_path, capture_output=True, text=True, timeout=600, env=env)
    assert done.returncode == 0, done.stderr[-3000:]
    assert not changed_files(before, checkout_files()), "the README's blocks changed the checkout"
    session = tmp_path / "session"
    for name in ("rtest.mpf", "run.csv", "diagnosis.json", "rtest_comp.mpf", "after.csv", "history.db",
                 "report/report.html"):
        assert (session / name).exists(), name
    assert "measured before/after" in done.stdout
    demo = tmp_path / "probe-demo"
    assert (demo / "probe.csv").exists() and (demo / "report" / "report.html").exists()
    assert "rank 8/8" in done.stdout and (session / "bb_axial_A.csv").exists()
    assert "check-up of VF2-5AX" in done.stdout and "verdict DRIFTED" in done.stdout  # the C axis line moved 3 um
    assert "drifted (exit status 1)" in done.stdout
