"""Every shell block of every docs/*.md runs as pasted.

Each page's ```` ```sh ```` (or ```` ```bash ````) blocks are taken from the page itself, in order, and run by
bash as one script (one shell, as a reader pasting them in turn), in a fresh folder laid out like the
checkout's root: links to ``.venv``, ``examples`` and ``tests``, and ``.venv/bin`` on ``PATH`` (the pages say:
from the checkout's root with ``pige`` on your PATH). Every command must succeed: the script
(:func:`testdata.strict_script`) checks the status of every top-level command, so ``a && b`` fails when ``a``
fails (``set -e`` alone lets it pass), and a failure names the page and line.

A block that cannot run here (it needs a serial port, a controller, another terminal) is marked on the
line before its fence with ``<!-- not-run: reason -->``; the reason is required. Pages added later are
covered without touching this file. Plain ```` ``` ```` fences are output or file contents, not run.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest
from testdata import strict_script

ROOT = Path(__file__).resolve().parents[1]
NOT_RUN = re.compile(r"^<!--\s*not-run:\s*(\S.*?)\s*-->$")
SHELL_FENCE = re.compile(r"^```(sh|bash)\s*$")


@dataclass(frozen=True)
class Block:
    """One shell block of a page: its first line number, text and the reason it is not run (or None)."""

    line: int
    text: str
    not_run: str | None


def shell_blocks(text: str) -> list[Block]:
    """The ``sh``/``bash`` fenced blocks of a Markdown text, in order."""
    lines = text.splitlines()
    blocks, i = [], 0
    while i < len(lines):
        if SHELL_FENCE.match(lines[i]):
            before = next((lines[j].strip() for j in range(i - 1, -1, -1) if lines[j].strip()), "")
            reason = NOT_RUN.match(before)
            end = next(j for j in range(i + 1, len(lines)) if lines[j].startswith("```"))
            blocks.append(Block(i + 2, "\n".join(lines[i + 1:end]), reason.group(1) if reason else None))
            i = end
        elif lines[i].startswith("```"):  # skip any other fenced block whole
            i = next(j for j in range(i + 1, len(lines)) if lines[j].startswith("```"))
        i += 1
    return blocks


def pages() -> list[Path]:
    """Every docs page that has a shell block."""
    return [p for p in sorted((ROOT / "docs").glob("*.md")) if shell_blocks(p.read_text(encoding="utf-8"))]


def run_page(page: Path, folder: Path) -> subprocess.CompletedProcess[str]:
    """Run a page's runnable blocks in ``folder`` (laid out like the checkout's root)."""
    venv = Path(sys.executable).parent.parent
    for name, target in ((".venv", venv), ("examples", ROOT / "examples"), ("tests", ROOT / "tests")):
        (folder / name).symlink_to(target)
    blocks = [b for b in shell_blocks(page.read_text(encoding="utf-8")) if b.not_run is None]
    script = "export PATH=\"$PWD/.venv/bin:$PATH\"\n" + strict_script([(page.name, b.line, b.text) for b in blocks])
    env = {k: v for k, v in os.environ.items() if k not in {"PIGE_HISTORY_DB", "PIGE_KERNEL_DIR"}}
    env["PIGE_HISTORY_DB"] = str(folder / "history-default.db")  # never the user's own history
    env["PIGE_KERNEL_DIR"] = str(folder / "kernels")
    return subprocess.run(["bash", "-c", script], cwd=folder, capture_output=True, text=True, timeout=900, env=env)


def test_blocks_and_markers_are_found() -> None:
    text = ("Intro\n```sh\necho one\n```\n```\noutput\n```\n<!-- not-run: needs a serial port -->\n\n"
            "```bash\necho two\n```\n```json\n{}\n```\n")
    blocks = shell_blocks(text)
    assert [(b.line, b.text, b.not_run) for b in blocks] == [(3, "echo one", None),
                                                             (11, "echo two", "needs a serial port")]


def _run_script(text: str, tmp_path: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run(["bash", "-c", strict_script([("page.md", 10, text)])], cwd=tmp_path, capture_output=True,
                          text=True, timeout=60)


@pytest.mark.parametrize(("text", "line"), [
    ("false && echo never\necho after", 10),
    ("echo one; true\nfor i in 1 2; do\n  test $i = 1 && false\ndone\necho after", 11),
    ("false | cat\necho after", 10),
    ("cat > f <<'EOF'\nline && not run\nEOF\nfalse\necho after", 13),
    ("echo a \\\n  && false\necho after", 10)])
def test_a_failing_command_fails_the_page_even_in_an_and_list(text: str, line: int, tmp_path: Path) -> None:
    done = _run_script(text, tmp_path)
    assert done.returncode != 0 and "after" not in done.stdout, done.stdout
    assert f"page.md line {line}: " in done.stderr, done.stderr  # the page and the line of the command


def test_a_handled_failure_and_a_here_document_pass(tmp_path: Path) -> None:
    text = ("false || echo handled\ncat > f.txt <<'EOF'\na && b\n$(not run)\nEOF\nfor s in x y; do\n"
            "  echo $s\ndone\necho \"multi\nline\" && echo after")
    done = _run_script(text, tmp_path)
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == ["handled", "x", "y", "multi", "line", "after"]
    assert (tmp_path / "f.txt").read_text() == "a && b\n$(not run)\n"


def test_a_not_run_marker_gives_its_reason_and_most_blocks_run() -> None:
    every = [(p.name, b) for p in sorted((ROOT / "docs").glob("*.md"))
             for b in shell_blocks(p.read_text(encoding="utf-8"))]
    for name, block in every:
        assert block.not_run is None or len(block.not_run) > 10, (name, block.line)
    for text in ((ROOT / "docs") / n for n in ("probe.md", "ballbar.md", "guide.md")):
        assert any(b.not_run is None for b in shell_blocks(text.read_text(encoding="utf-8"))), text.name
    # a marker must sit on a shell block: a stray one is a mistake
    for page in sorted((ROOT / "docs").glob("*.md")):
        lines = page.read_text(encoding="utf-8").splitlines()
        for i, line in enumerate(lines):
            if NOT_RUN.match(line.strip()):
                after = next(x for x in lines[i + 1:] if x.strip())
                assert SHELL_FENCE.match(after), (page.name, i + 1)


@pytest.mark.parametrize("page", pages(), ids=lambda p: p.name)
def test_every_shell_block_of_the_page_runs_as_pasted(page: Path, tmp_path: Path) -> None:
    if not (Path(sys.executable).parent / "pige").exists():
        pytest.skip("needs the pige console script (make venv)")
    done = run_page(page, tmp_path)
    assert done.returncode == 0, done.stdout[-2000:] + "\n--- stderr ---\n" + done.stderr[-3000:]
