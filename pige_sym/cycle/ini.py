"""A LinuxCNC INI file read line by line, and edited without touching a line that is not edited.

LinuxCNC's INI grammar (``src/libnml/inifile/inifile.cc``, 2.9): a line ``[NAME]`` opens a section; ``KEY = VALUE``
inside a section is an entry (blanks around the key and the value are dropped, the same key may repeat:
``REMAP``, ``HALCMD``, ``HALFILE``); a line whose first non-blank character is ``#`` or ``;`` is a comment; blank
lines are ignored.  Anything else (a line without ``=`` inside a section, text before the first section) makes the
file something pige does not read as an INI.

Edits (:class:`IniEdit`) replace, insert or comment out whole lines by their number; :func:`apply_edits` applies
them from the bottom up so that line numbers stay valid, and keeps every other line byte for byte (line endings
included).
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field

from pige_sym.errors import InputError

_SECTION = re.compile(r"^\s*\[([A-Za-z0-9_]+)\]\s*$")


@dataclass(frozen=True)
class Entry:
    """``KEY = VALUE`` at ``line`` (1-based) of ``section``."""

    section: str
    key: str
    value: str
    line: int


@dataclass
class IniDocument:
    """An INI file's lines (with their endings) and its entries."""

    name: str
    lines: list[str]
    entries: list[Entry] = field(default_factory=list)
    sections: dict[str, tuple[int, int]] = field(default_factory=dict)  # name -> (header line, last line)

    def values(self, section: str, key: str) -> list[Entry]:
        """Every entry ``KEY`` of ``[SECTION]`` in file order."""
        return [e for e in self.entries if e.section == section and e.key == key]

    def value(self, section: str, key: str) -> str | None:
        """The first value of ``[SECTION]KEY`` (LinuxCNC reads the first), or None."""
        found = self.values(section, key)
        return found[0].value if found else None

    def newline(self) -> str:
        """The file's line ending (of its first line)."""
        first = self.lines[0] if self.lines else "\n"
        return "\r\n" if first.endswith("\r\n") else "\n"

    def text(self) -> str:
        return "".join(self.lines)


def parse_ini(text: str, name: str) -> IniDocument:
    """Read ``text`` as a LinuxCNC INI (module docstring).

    Raises
    ------
    InputError
        A line that is not a section, an entry, a comment or blank (naming the file and line), or no section.
    """
    doc = IniDocument(name, text.splitlines(keepends=True))
    section = ""
    for number, raw in enumerate(doc.lines, start=1):
        line = raw.strip()
        if not line or line[0] in "#;":
            continue
        m = _SECTION.match(line)
        if m:
            section = m.group(1)
            if section in doc.sections:
                first = doc.sections[section][0]
                raise InputError(f"{name}:{number}: section [{section}] again (first at line {first}): pige edits "
                                 "an INI whose sections appear once")
            doc.sections[section] = (number, number)
            continue
        key, sep, value = line.partition("=")
        if not section or not sep or not key.strip():
            raise InputError(f"{name}:{number}: {line[:60]!r} is not a LinuxCNC INI line ([SECTION], KEY = VALUE "
                             "or a comment): give the machine's INI file")
        doc.entries.append(Entry(section, key.strip(), value.strip(), number))
        doc.sections[section] = (doc.sections[section][0], number)
    if not doc.sections:
        raise InputError(f"{name}: no [SECTION] in it: not a LinuxCNC INI file; give the machine's INI file")
    return doc


@dataclass(frozen=True)
class IniEdit:
    """One edit: at ``line`` (1-based), ``replace`` the line, ``insert_after`` it, or ``comment`` it out.

    ``text`` is the new line(s) without the line ending (several joined by ``\\n``); ``why`` says what it is for.
    """

    line: int
    action: str
    text: str
    why: str


def apply_edits(doc: IniDocument, edits: list[IniEdit]) -> str:
    """The file's text with ``edits`` applied (module docstring); two edits replacing one line are refused."""
    nl = doc.newline()
    lines = list(doc.lines)
    if lines and not lines[-1].endswith(("\n", "\r")):
        lines[-1] += nl
    replaced = [e.line for e in edits if e.action in ("replace", "comment")]
    if len(replaced) != len(set(replaced)):
        raise AssertionError(f"two edits of one line in {doc.name}")  # pragma: no cover - a programming error
    order = {"insert_after": 0, "replace": 1, "comment": 1}
    for e in sorted(edits, key=lambda e: (e.line, order[e.action]), reverse=True):
        new = [t + nl for t in e.text.split("\n")]
        i = e.line - 1
        if e.action == "insert_after":
            lines[i + 1:i + 1] = new
        elif e.action == "replace":
            lines[i:i + 1] = new
        elif e.action == "comment":
            lines[i:i + 1] = [f"# {e.text}: {lines[i].rstrip(chr(13) + chr(10))}{nl}"]
        else:  # pragma: no cover - a programming error
            raise AssertionError(e.action)
    return "".join(lines)


def append_section(text: str, doc: IniDocument, section: str, entries: list[str]) -> str:
    """``text`` with a new ``[SECTION]`` and its ``KEY = VALUE`` lines at the end."""
    nl = doc.newline()
    if text and not text.endswith(("\n", "\r")):
        text += nl
    body = "".join(f"{e}{nl}" for e in entries)
    return f"{text}{nl}[{section}]{nl}{body}"
