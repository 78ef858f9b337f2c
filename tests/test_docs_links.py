"""Every reference in the docs resolves inside the repository.

Checked for README.md, every docs/*.md and benchmarks/*.md:
- a Markdown link ``[text](target)`` to a relative file names a file or folder of the checkout, and its
  ``#anchor`` (GitHub's heading slug) is a heading of the target;
- a repository path written in the prose or a code span (``pige_sym/…``, ``tests/…``, ``docs/…``,
  ``benchmarks/…``, ``examples/…``, ``generated/…``) exists;
- nothing points to a conventions file outside the repository (the conventions are docs/conventions.md);
- every "CONVENTIONS §N" that code, tests or docs cite is a numbered section of docs/conventions.md.

The checker is tested on its own small examples, so a broken link cannot pass unseen.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
LINK = re.compile(r"(?<!!)\[[^\]\n]*\]\(([^)\s]+)\)")
REPO_PATH = re.compile(r"(?<![\w./-])((?:pige_sym|tests|docs|benchmarks|examples|generated|\.ci)/[\w./*-]*[\w/*])")
#: Paths the docs name that exist only elsewhere, with where.
NOT_IN_A_CHECKOUT = {"pige_sym/generated": "the kernels' folder inside an installed wheel"}
CITATION = re.compile(r"CONVENTIONS\s*§\s*(\d+)(?:\s*[–-]\s*§?\s*(\d+))?")
FENCE = re.compile(r"^```.*?^```", re.S | re.M)


def markdown_files() -> list[Path]:
    """The Markdown files whose references are checked."""
    files = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md")), *sorted((ROOT / "benchmarks").glob("*.md"))]
    return [f for f in files if f.exists()]


def slug(heading: str) -> str:
    """GitHub's anchor of a heading: lower case, punctuation dropped, spaces to hyphens."""
    text = re.sub(r"[`*_]", "", heading.strip().lower())
    text = re.sub(r"[^\w\- ]", "", text)
    return text.replace(" ", "-")


def anchors(path: Path) -> set[str]:
    """Every heading anchor of a Markdown file (fenced blocks excluded)."""
    text = FENCE.sub("", path.read_text(encoding="utf-8"))
    return {slug(m.group(1)) for m in re.finditer(r"^#{1,6}\s+(.*)$", text, re.M)}


def broken_references(path: Path, root: Path = ROOT) -> list[str]:
    """What in ``path`` does not resolve: ``["line N: reason", ...]``."""
    text = path.read_text(encoding="utf-8")
    problems = []
    for number, line in enumerate(text.splitlines(), 1):
        for target in LINK.findall(line):
            if re.match(r"[a-z]+:", target):  # http:, https:, mailto:
                continue
            file_part, _, anchor = target.partition("#")
            dest = (path.parent / file_part).resolve() if file_part else path
            if not dest.exists() or root.resolve() not in (dest, *dest.parents):
                problems.append(f"line {number}: link {target} does not resolve inside the repository")
            elif anchor and dest.suffix == ".md" and anchor not in anchors(dest):
                problems.append(f"line {number}: link {target}: no heading #{anchor} in {dest.name}")
        for ref in REPO_PATH.findall(line):
            if ref not in NOT_IN_A_CHECKOUT and not any(root.glob(ref)):
                problems.append(f"line {number}: {ref} is not in the repository")
        if re.search(r"CONVENTIONS\.md|shared/docs", line):
            problems.append(f"line {number}: cites a conventions file outside the repository (docs/conventions.md)")
    return problems


def convention_sections() -> set[int]:
    """The numbers of docs/conventions.md's numbered sections."""
    text = (ROOT / "docs" / "conventions.md").read_text(encoding="utf-8")
    return {int(n) for n in re.findall(r"^## (\d+)\. ", text, re.M)}


@pytest.mark.parametrize("path", markdown_files(), ids=lambda p: str(p.relative_to(ROOT)))
def test_every_reference_resolves_inside_the_repository(path: Path) -> None:
    assert broken_references(path) == []


def test_every_cited_convention_section_exists() -> None:
    sections = convention_sections()
    assert sections == set(range(1, 11))
    cited = []
    for folder in ("pige_sym", "tests", "benchmarks", "docs"):
        for file in (ROOT / folder).rglob("*"):
            if file.suffix in {".py", ".md"} and "generated" not in file.parts:
                for match in CITATION.finditer(file.read_text(encoding="utf-8")):
                    numbers = [int(n) for n in match.groups() if n]
                    cited += [(file.name, n) for n in range(numbers[0], numbers[-1] + 1)]
    assert cited, "no citation found: the pattern is wrong"
    assert [c for c in cited if c[1] not in sections] == []


def test_the_report_and_the_cli_cite_the_conventions_in_the_repository() -> None:
    for folder in ("report", "cli"):
        for file in (ROOT / "pige_sym" / folder).glob("*.py"):
            assert "CONVENTIONS.md" not in file.read_text(encoding="utf-8"), file


def test_the_checker_finds_broken_links_paths_and_anchors(tmp_path: Path) -> None:
    (tmp_path / "docs").mkdir()
    (tmp_path / "docs" / "b.md").write_text("# Title\n\n## 2. Frames and motion\n", encoding="utf-8")
    (tmp_path / "pige_sym").mkdir()
    (tmp_path / "pige_sym" / "x.py").write_text("", encoding="utf-8")
    doc = tmp_path / "docs" / "a.md"
    doc.write_text(
        "[ok](b.md#2-frames-and-motion) [ok](https://example.org) `pige_sym/x.py` pige_sym/x.py. `pige_sym/*.py`\n"
        "[bad](c.md) [bad](b.md#3-nothing) `pige_sym/y.py` [out](../../elsewhere.md)\n"
        "```\nnot a heading\n```\nsee ../shared/docs/CONVENTIONS.md\n", encoding="utf-8")
    problems = broken_references(doc, tmp_path)
    assert [p.split(":")[0] for p in problems] == ["line 2"] * 4 + ["line 6"]
    assert "c.md" in problems[0] and "#3-nothing" in problems[1] and "pige_sym/y.py" in problems[3]
