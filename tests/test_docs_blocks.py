"""Every shell block of every docs/*.md runs as pasted.

Each page's ```` ```sh ```` (or ```` ```bash ````) blocks are taken from the page itself, in order, and run by
bash as one script (one shell, as a reader pasting them in turn), in a scratch folder laid out like the
checkout's root: a link to ``.venv``, copies of ``examples`` and ``tests``, and ``.venv/bin`` on ``PATH`` (the
pages say: from the checkout's root with ``pige`` on your PATH); history, kernels and bytecode go to scratch
folders too (:func:`testdata.scratch_checkout`), so the blocks leave nothing in the checkout, and the test checks
that they did not. Every command must succeed: the script
(:func:`testdata.strict_script`) checks the status of every top-level command, so ``a && b`` fails when ``a``
fails (``set -e`` alone lets it pass), and a failure names the page and line.

The pages' ``pige`` commands run in children of a fork server (``tests/fork_server.py``, one per module) that
imported NumPy, SciPy, matplotlib, SQLAlchemy and pige_sym once: the scratch ``.venv/bin/pige`` is its shim,
bash still runs every line as pasted, and each command still starts from a fresh state with its own argv,
folder, environment, stdin/stdout/stderr and exit status; what the server cannot serve exactly runs the real
console script (``tests/test_fork_server.py`` compares the two).  The slow test on another processor does not
use it.

A block that cannot run here (it needs a serial port, a controller, another terminal) is marked on the
line before its fence with ``<!-- not-run: reason -->``; the reason is required. Pages added later are
covered without touching this file. Plain ```` ``` ```` fences are output or file contents, not run.

Output a page quotes is checked against the run: a plain fence right after a run shell block quotes that
block's output, and a plain fence whose first line is ``$ command`` quotes that command, run in the page's
shell at that place. Every number the quote shows must be in what the run printed (a quote may leave lines
out with ``…``, not change a number).

Quotes hold on every computer.  A quoted number is either exact there — what pige prints is rounded to what the
data determine, and every combination is canonical (``pige_sym/identification/canonical.py``) — or it is quoted
with the tolerance it is checked against: ``≈0.947`` in a quote means "a number within one unit of the last digit
shown", 0.946 to 0.948 here.  Use ``≈`` only for a number that truly depends on floating-point rounding (an
optimiser's path, a sum of many terms printed to its last digits), never to paper over a wrong quote.  The slow
test :func:`test_the_quotes_hold_on_another_processor` runs the pages that quote output with NumPy's eigen-solver
answering as another processor and BLAS could (``tests/another_processor.py``: 1e-12 noise in the matrix, any
signs, any basis of a repeated eigenvalue) and checks the same quotes.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest
from fork_server import ForkServer, started

from testdata import changed_files, checkout_files, scratch_checkout, scratch_env, strict_script

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


@dataclass(frozen=True)
class Quote:
    """Output a page quotes: its first line, text, and what printed it (``command``: its ``$`` line, run at
    this place; else ``block``: the line of the shell block just above)."""

    line: int
    text: str
    command: str | None
    block: int | None


def quotes(text: str) -> list[Quote]:
    """The plain fences of a page that quote output (module docstring), in order."""
    lines = text.splitlines()
    out: list[Quote] = []
    i, last_run = 0, None  # last_run: (fence end, first line) of the shell block just closed, when it runs
    while i < len(lines):
        if lines[i].startswith("```"):
            end = next(j for j in range(i + 1, len(lines)) if lines[j].startswith("```"))
            body = lines[i + 1:end]
            right_after = last_run is not None and not any(x.strip() for x in lines[last_run[0] + 1:i])
            if lines[i].strip() == "```" and body and body[0].startswith("$ "):
                out.append(Quote(i + 2, "\n".join(body[1:]), body[0][2:], None))
            elif lines[i].strip() == "```" and right_after and last_run is not None:
                out.append(Quote(i + 2, "\n".join(body), None, last_run[1]))
            is_run = SHELL_FENCE.match(lines[i]) and not NOT_RUN.match(
                next((lines[j].strip() for j in range(i - 1, -1, -1) if lines[j].strip()), ""))
            last_run = (end, i + 2) if is_run else None
            i = end
        i += 1
    return out


NUMBER = re.compile(r"(?<![\w.])(≈?)([-+]?\d+(?:\.\d+)?)(?![\w.])")


def missing_numbers(quote: str, printed: str) -> list[str]:
    """The numbers of ``quote`` that ``printed`` does not contain (as whole numbers, not digits of others); a
    number written ``≈x`` is there when one within a unit of ``x``'s last digit is (module docstring)."""
    seen = {n for _, n in NUMBER.findall(printed)}
    values = [float(n) for n in seen]
    missing = []
    for approx, n in NUMBER.findall(quote):
        if not approx:
            if n not in seen:
                missing.append(n)
            continue
        unit = 10.0 ** -len(n.partition(".")[2])
        if not any(abs(v - float(n)) <= unit * (1 + 1e-9) for v in values):
            missing.append("≈" + n)
    return missing


MARK = "@@pige-docs {}@@"


def pages() -> list[Path]:
    """Every docs page that has a shell block."""
    return [p for p in sorted((ROOT / "docs").glob("*.md")) if shell_blocks(p.read_text(encoding="utf-8"))]


def run_page(page: Path, folder: Path, pycache: Path, processor: int | None = None,
             server: ForkServer | None = None) -> subprocess.CompletedProcess[str]:
    """Run a page's runnable blocks and its quoted ``$`` commands in page order in ``folder`` (a scratch layout of
    the checkout's root, :func:`testdata.scratch_checkout`; bytecode under ``pycache``); each one's output starts
    with a line :data:`MARK` of its first line number.  With ``processor`` (a seed) every Python they start
    answers eigen-problems as another processor could (``tests/processor_site``).  With a fork ``server`` its
    ``pige`` commands run in children of that server (:mod:`fork_server`: the imports paid once)."""
    env = scratch_checkout(folder, pycache, server)
    if processor is not None:
        env["PYTHONPATH"] = os.pathsep.join(x for x in (str(folder / "tests" / "processor_site"),
                                                         env.get("PYTHONPATH")) if x)
        env["PIGE_TEST_PROCESSOR_SEED"] = str(processor)
    text = page.read_text(encoding="utf-8")
    runs = sorted([(b.line, b.text) for b in shell_blocks(text) if b.not_run is None]
                  + [(q.line, q.command) for q in quotes(text) if q.command is not None])
    script = strict_script(
        [x for line, run in runs for x in ((page.name, line, f"echo '{MARK.format(line)}'"), (page.name, line, run))])
    return subprocess.run(["bash", "-c", script], cwd=folder, capture_output=True, text=True, timeout=900, env=env)


@pytest.fixture(scope="module")
def pycache(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """One bytecode folder for the pages this worker runs (pige compiled once, outside the checkout): the
    session's scratch ``PYTHONPYCACHEPREFIX`` when conftest set one, else a folder of this module's."""
    session = os.environ.get("PYTHONPYCACHEPREFIX")
    return Path(session) if session and Path(session).is_dir() else tmp_path_factory.mktemp("docs-pycache")


@pytest.fixture(scope="module")
def pige_server(tmp_path_factory: pytest.TempPathFactory, pycache: Path) -> Iterator[ForkServer]:
    """One fork server for the pages' ``pige`` commands (:mod:`fork_server`), stopped (and its CPU counted) when
    the module ends; started with a scratch layout's environment (the pages' differs only where it may)."""
    home = tmp_path_factory.mktemp("fork-server")
    with started(home, scratch_env(home, pycache)) as server:
        yield server


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


def test_the_scratch_layout_keeps_what_the_blocks_write_out_of_the_checkout(tmp_path: Path) -> None:
    if not (Path(sys.executable).parent / "pige").exists():
        pytest.skip("needs the pige console script (make venv)")
    before = checkout_files()
    (tmp_path / "root").mkdir()
    env = scratch_checkout(tmp_path / "root", tmp_path / "pycache")
    text = ("echo x >> examples/tolerances.json\necho y > tests/new_file.txt\nrm tests/testdata.py\n"
            "python -c 'import pige_sym.cli.main'\npige --help > /dev/null")
    done = subprocess.run(["bash", "-c", strict_script([("page.md", 1, text)])], cwd=tmp_path / "root", env=env,
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert not changed_files(before, checkout_files())
    assert (tmp_path / "root" / "tests" / "new_file.txt").exists()  # written into the copy
    assert any((tmp_path / "pycache").rglob("pige_sym/cli/main.*.pyc"))  # the bytecode in the scratch prefix


@pytest.mark.parametrize("page", pages(), ids=lambda p: p.name)
def test_every_shell_block_of_the_page_runs_as_pasted(page: Path, tmp_path: Path, pycache: Path,
                                                     pige_server: ForkServer) -> None:
    if not (Path(sys.executable).parent / "pige").exists():
        pytest.skip("needs the pige console script (make venv)")
    before = checkout_files()
    served = pige_server.counts()[0]
    done = run_page(page, tmp_path, pycache, server=pige_server)
    assert done.returncode == 0, done.stdout[-2000:] + "\n--- stderr ---\n" + done.stderr[-3000:]
    assert not changed_files(before, checkout_files()), f"{page.name}'s blocks changed the checkout"
    assert any(pycache.rglob("pige_sym/**/*.pyc")), "the blocks' bytecode did not go to the scratch folder"
    _check_quotes(page, done.stdout)
    runs = [b.text for b in shell_blocks(page.read_text(encoding="utf-8")) if b.not_run is None]
    if re.search(r"^\s*pige ", "\n".join(runs), re.M):
        assert pige_server.counts()[0] > served, "the page's pige commands did not run in the fork server"


def _check_quotes(page: Path, stdout: str) -> None:
    """Every quote of the page against what its command or block printed (module docstring)."""
    printed = dict(zip(map(int, re.findall(MARK.format(r"(\d+)"), stdout)),
                       re.split(MARK.format(r"\d+"), stdout)[1:], strict=True))
    for q in quotes(page.read_text(encoding="utf-8")):
        run = printed[q.line if q.command is not None else q.block]
        assert not missing_numbers(q.text, run), (f"{page.name} line {q.line} quotes numbers the run does not print: "
                                                  f"{missing_numbers(q.text, run)}\n--- printed ---\n{run[-3000:]}")


@pytest.mark.slow
@pytest.mark.parametrize("page", [p for p in pages() if quotes(p.read_text(encoding="utf-8"))], ids=lambda p: p.name)
def test_the_quotes_hold_on_another_processor(page: Path, tmp_path: Path, pycache: Path) -> None:
    if not (Path(sys.executable).parent / "pige").exists():
        pytest.skip("needs the pige console script (make venv)")
    done = run_page(page, tmp_path, pycache, processor=11)
    assert done.returncode == 0, done.stdout[-2000:] + "\n--- stderr ---\n" + done.stderr[-3000:]
    probe = subprocess.run([sys.executable, "-c", "import numpy; print(numpy.linalg.eigh.__module__)"],
                           env={**os.environ, "PYTHONPATH": str(tmp_path / "tests" / "processor_site"),
                                "PIGE_TEST_PROCESSOR_SEED": "11"}, capture_output=True, text=True, check=True)
    assert probe.stdout.strip() == "another_processor", probe  # the pages' Pythons answered as another processor
    _check_quotes(page, done.stdout)


def test_quotes_are_found_and_their_numbers_checked() -> None:
    text = ("```sh\necho 1.5\n```\n```\nvalue 1.5\n```\n\nprose\n```\nnot a quote 9\n```\n"
            "<!-- not-run: needs a serial port here -->\n```sh\necho 2\n```\n```\nnot run 2\n```\n"
            "```\n$ pige identify run.csv --projection x\nrank 4/8  EA0C - 0.193·EB0C\n```\n")
    assert [(q.line, q.text, q.command, q.block) for q in quotes(text)] == [
        (5, "value 1.5", None, 2), (20, "rank 4/8  EA0C - 0.193·EB0C", "pige identify run.csv --projection x", None)]
    assert missing_numbers("rank 4/8  EA0C - 0.193·EB0C, RMS 1.029 um", "rank 4/8 EA0C - 0.193·EB0C RMS 1.080") == \
        ["1.029"]
    assert missing_numbers("held-out 1.08 um", "held-out 11.08 um, 1.080") == ["1.08"]  # whole numbers only


def test_a_number_quoted_with_its_tolerance_matches_within_a_unit_of_its_last_digit() -> None:
    assert missing_numbers("RMS ≈0.947 um, rank 4", "RMS 0.948 um, rank 4") == []
    assert missing_numbers("RMS ≈0.947 um", "RMS 0.949 um") == ["≈0.947"]
    assert missing_numbers("≈12 s and ≈-1.5", "13 s and -1.4") == []
    assert missing_numbers("0.947", "0.948") == ["0.947"]  # without ≈: exactly
