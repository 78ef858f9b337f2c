"""Where the checkout and ../shared are, and a minimal independent reader of the reference data.

Imported by the tests as ``from testdata import REPO`` (tests/ is on the path); not from ``conftest``, which a
conftest.py in a sub-folder (tests/linuxcnc) replaces as the module of that name.
"""

from __future__ import annotations

import json
import os
import shlex
import shutil
import subprocess
import sys
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import pytest

if TYPE_CHECKING:
    from fork_server import ForkServer

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared"
REFERENCE = SHARED / "reference"
CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")


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


def figures_not_drawn(monkeypatch: pytest.MonkeyPatch) -> None:
    """The reports made while ``monkeypatch`` holds draw no figure (the page's figure slots empty; every table,
    sentence, command and JSON field unchanged): for a test that reads a report's words or JSON only, of a kind
    whose figures another test draws and checks (test_report.py, test_report_print.py, test_report_joint.py,
    test_maps.py).  A figure is 60-90 % of a report's CPU."""
    import pige_sym.report.html as page

    monkeypatch.setattr(page, "draw_figures", lambda rep, folder: [])
    monkeypatch.setattr(page, "draw_report_figures", lambda data, folder: [])


def simulated_probe_file(folder: Path, seed: int, effect: str, *extra: str) -> Path:
    """``folder/probe.csv``: a LinuxCNC probing program, the virtual machine's log of it (``seed``, ``effect``,
    ``extra`` simulate options) and its import, as a user makes them."""
    from pige_sym.cli.main import main

    sphere = ["--sphere", "100,20,60", "--sphere-radius", "12.7", "--stylus-radius", "1.5"]
    kins = ["--rtcp-off", "M429", "--rtcp-on", "M428", "--stylus-tool", "99", "--stylus-length", "120"]
    assert main(["program", "--instrument", "sphere-probe", "--dialect", "linuxcnc", *kins, *sphere,
                 "--out", str(folder / "probe.ngc")]) == 0
    assert main(["simulate", "--instrument", "sphere-probe", "--dialect", "linuxcnc", *kins, *sphere, "--program",
                 str(folder / "probe.ngc"), "--seed", str(seed), *extra, "--effect", effect,
                 "--out", str(folder / "probe_log.txt")]) == 0
    assert main(["import-probe", str(folder / "probe_log.txt"), "--format", "linuxcnc", *sphere[2:],
                 "--out", str(folder / "probe.csv")]) == 0
    return folder / "probe.csv"


def top_level_commands(text: str) -> list[tuple[int, str]]:
    """The top-level commands of a shell text, each with its first line (0-based): lines are joined while bash
    cannot yet parse them whole (an open loop, quote, ``$(``, here-document) or a line ends with ``\\``."""
    lines = text.splitlines()
    out, start = [], 0
    for end in range(len(lines)):
        chunk = "\n".join(lines[start:end + 1])
        if end + 1 < len(lines):
            if lines[end].rstrip().endswith("\\"):
                continue
            parsed = subprocess.run(["bash", "-n", "-c", chunk], capture_output=True, text=True, check=False)
            if parsed.returncode != 0 or "here-document" in parsed.stderr:
                continue
        out.append((start, chunk))
        start = end + 1
    return out


def strict_script(blocks: list[tuple[str, int, str]]) -> str:
    """A bash script that runs ``blocks`` ((page, line, text): the page, the line number of the text's first
    line, shell text) in one shell and stops at the first command that fails, naming its page and line on stderr.

    ``set -e`` alone does not stop at ``a && b`` when ``a`` fails (bash leaves every command of an ``&&``/``||``
    list but the last to the list), so every top-level command's status is checked after it runs: a list fails
    when its status is not 0 (``a || echo handled`` passes, ``a && b`` with ``a`` failing does not), and
    ``pipefail`` makes a pipeline fail with any of its commands."""
    parts = ["set -e -o pipefail",
             "trap 'echo \"$PIGE_DOCS_AT: failed (exit status $?)\" >&2' ERR"]
    for page, line, text in blocks:
        lines = text.splitlines()
        for first, command in top_level_commands(text):
            at = f"{page} line {line + first}: {lines[first].strip()[:60]}"
            parts += [f"PIGE_DOCS_AT={shlex.quote(at)}", command,
                      'PIGE_DOCS_RC=$?; if [ "$PIGE_DOCS_RC" -ne 0 ]; then echo "$PIGE_DOCS_AT: failed (exit status '
                      '$PIGE_DOCS_RC: a command of an && list)" >&2; exit "$PIGE_DOCS_RC"; fi']
    return "\n".join(parts) + "\n"


#: Folders of the checkout a test run writes by itself (caches, the venv): not what a pasted command may change.
CACHES = frozenset({".git", ".venv", "__pycache__", ".pytest_cache", ".hypothesis", ".mypy_cache", ".ruff_cache"})


def scratch_env(folder: Path, pycache: Path) -> dict[str, str]:
    """The environment of commands pasted in the scratch layout ``folder`` (:func:`scratch_checkout`): this
    environment with ``folder/.venv/bin`` first on ``PATH``, the history and the generated kernels in ``folder``
    (never the user's), and the bytecode of every Python the commands start under ``pycache``
    (``PYTHONPYCACHEPREFIX``: never beside the checkout's sources)."""
    env = {k: v for k, v in os.environ.items() if k not in {"PIGE_HISTORY_DB", "PIGE_KERNEL_DIR",
                                                              "PYTHONDONTWRITEBYTECODE"}}
    env["PATH"] = f"{folder / '.venv' / 'bin'}{os.pathsep}{env.get('PATH', '')}"
    env["PIGE_HISTORY_DB"] = str(folder / "history-default.db")
    env["PIGE_KERNEL_DIR"] = str(folder / "kernels")
    env["PYTHONPYCACHEPREFIX"] = str(pycache)
    return env


def scratch_checkout(folder: Path, pycache: Path, server: ForkServer | None = None) -> dict[str, str]:
    """Lay ``folder`` out like the checkout's root for commands pasted from the docs, so that they cannot write
    into the checkout, and return their environment (:func:`scratch_env`; ``pycache``: one folder a test module
    shares, so its pages compile pige once).

    ``.venv`` is a link to this interpreter's venv (its ``pige``); ``examples`` and ``tests`` are copies (a
    command writing beside an example writes into the copy).  With a fork ``server``
    (:class:`fork_server.ForkServer`) ``.venv`` is a folder of links to the venv's entries instead, and its
    ``bin/pige`` the server's shim: the same venv, whose ``pige`` commands the server runs.
    """
    venv = Path(sys.executable).parent.parent
    if server is None:
        (folder / ".venv").symlink_to(venv)
    else:
        (folder / ".venv" / "bin").mkdir(parents=True)
        for entry in venv.iterdir():
            if entry.name != "bin":
                (folder / ".venv" / entry.name).symlink_to(entry)
        for entry in (venv / "bin").iterdir():
            if entry.name != "pige":
                (folder / ".venv" / "bin" / entry.name).symlink_to(entry)
        server.write_shim(folder / ".venv" / "bin" / "pige")
    for name in ("examples", "tests"):
        shutil.copytree(REPO / name, folder / name, ignore=shutil.ignore_patterns(*CACHES))
    return scratch_env(folder, pycache)


def checkout_files() -> dict[str, tuple[int, int]]:
    """Every file of the checkout but the caches (:data:`CACHES`, ``*.egg-info``): relative path → (size, mtime
    [ns]); what a test compares before and after commands that must leave the checkout as it was."""
    out: dict[str, tuple[int, int]] = {}
    for top, dirs, files in os.walk(REPO):
        dirs[:] = [d for d in dirs if d not in CACHES and not d.endswith(".egg-info")]
        for name in files:
            st = os.lstat(os.path.join(top, name))
            out[os.path.relpath(os.path.join(top, name), REPO)] = (st.st_size, st.st_mtime_ns)
    return out


def changed_files(before: dict[str, tuple[int, int]], after: dict[str, tuple[int, int]]) -> list[str]:
    """The paths :func:`checkout_files` lists as added, removed or modified between two listings."""
    return sorted(p for p in before.keys() | after.keys() if before.get(p) != after.get(p))
