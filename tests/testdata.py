"""Where the checkout and ../shared are, and a minimal independent reader of the reference data.

Imported by the tests as ``from testdata import REPO`` (tests/ is on the path); not from ``conftest``, which a
conftest.py in a sub-folder (tests/linuxcnc) replaces as the module of that name.
"""

from __future__ import annotations

import json
import shlex
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

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


def run_chromium(tmp: Path, *args: str, timeout_s: float = 120) -> subprocess.CompletedProcess[str]:
    """Headless chromium with a throw-away profile in ``tmp`` and ``args`` (the caller skips without it)."""
    assert CHROMIUM is not None
    cmd = [CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
           "--disable-background-networking", "--disable-component-update", "--disable-sync", "--hide-scrollbars",
           f"--user-data-dir={tmp / 'profile'}", "--virtual-time-budget=10000", *args]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=timeout_s, check=False)


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
