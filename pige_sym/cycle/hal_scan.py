"""What a LinuxCNC configuration's HAL commands set: every ``setp``, ``sets`` and ``net``, with where it is.

The order LinuxCNC 2.9's ``linuxcnc`` script runs them: the ``[HAL] HALFILE`` files in order, then the ``[HAL]
HALCMD`` lines in order (``POSTGUI_HALFILE`` after the GUI has started: last); a ``source FILE`` command runs FILE
there (a relative path is taken from the configuration folder, where the script runs halcmd).  Words are split as halcmd
splits them (:func:`~pige_sym.compensation.controllers.hal_config.halcmd_words`); ``[SECTION]KEY`` references of
HAL files are the INI's values.  HAL files beside the INI (``.hal``) are read; library (``LIB:``) and Tcl files are
not: they are named in :attr:`HalScan.unread`, so that a value they might set is never taken for known.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path

from pige_sym.cycle.ini import IniDocument
from pige_sym.errors import InputError

_SECTION_KEY = re.compile(r"\[(\w+)\](\w+)")


@dataclass(frozen=True)
class Setting:
    """A value set by a HAL command: ``value`` as written, ``file`` and ``line`` (1-based) where."""

    value: str
    file: Path
    line: int

    @property
    def where(self) -> str:
        return f"{self.file}:{self.line}"


@dataclass
class HalScan:
    """The configuration's HAL commands (module docstring): the last ``setp`` of each pin, the last ``sets`` of each
    signal, the signal each pin is netted to, the HAL files read and those not read."""

    config: Path
    setp: dict[str, Setting] = field(default_factory=dict)
    sets: dict[str, Setting] = field(default_factory=dict)
    nets: dict[str, str] = field(default_factory=dict)
    net_where: dict[str, Setting] = field(default_factory=dict)
    files: list[Path] = field(default_factory=list)
    unread: list[str] = field(default_factory=list)
    sources: list[Setting] = field(default_factory=list)  # the ``source`` commands, with the file they name


def scan_configuration(ini: Path, doc: IniDocument) -> HalScan:
    """Every HAL command the configuration ``ini`` (read as ``doc``) runs, in LinuxCNC's order (module docstring).

    Raises
    ------
    InputError
        A line halcmd would refuse (an unterminated quote), a HAL file that cannot be read.
    """
    scan = HalScan(ini.parent)
    ini_values = {(e.section, e.key): e.value for e in reversed(doc.entries)}
    for e in doc.values("HAL", "HALFILE") + doc.values("HAL", "POSTGUI_HALFILE"):
        name = e.value.split()[0] if e.value.split() else e.value
        target = ini.parent / name
        if name.startswith("LIB:") or target.suffix != ".hal" or not target.is_file():
            scan.unread.append(name)
            continue
        _scan_file(scan, target, ini_values, depth=0)
    for e in doc.values("HAL", "HALCMD"):
        _command(scan, e.value, ini, e.line, ini_values, depth=0)
    return scan


def _scan_file(scan: HalScan, path: Path, ini_values: dict[tuple[str, str], str], depth: int) -> None:
    from pige_sym.files import read_input_text

    if depth > 8:
        raise InputError(f"{path}: HAL files source each other more than 8 deep")
    scan.files.append(path)
    for number, raw in enumerate(read_input_text(path, what="HAL file").splitlines(), start=1):
        line = _SECTION_KEY.sub(lambda m: ini_values.get((m.group(1), m.group(2)), m.group(0)), raw)
        _command(scan, line, path, number, ini_values, depth)


def _command(scan: HalScan, line: str, file: Path, number: int, ini_values: dict[tuple[str, str], str],
             depth: int) -> None:
    from pige_sym.compensation.controllers.hal_config import halcmd_words

    words = halcmd_words(line, f"{file}:{number}")
    if not words:
        return
    verb, args = words[0], words[1:]
    here = Setting(" ".join(args), file, number)
    if verb == "setp" and len(args) >= 2:
        scan.setp[args[0]] = Setting(args[1], file, number)
    elif verb == "sets" and len(args) >= 2:
        scan.sets[args[0]] = Setting(args[1], file, number)
    elif verb == "net" and args:
        for word in args[1:]:
            if word not in ("<=", "=>", "<=>"):
                scan.nets[word] = args[0]
                scan.net_where[word] = here
    elif verb == "source" and args:
        target = Path(args[0]) if Path(args[0]).is_absolute() else scan.config / args[0]
        scan.sources.append(Setting(args[0], file, number))
        if target.is_file():
            _scan_file(scan, target, ini_values, depth + 1)
        else:
            scan.unread.append(args[0])
