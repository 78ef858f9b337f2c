"""Today's LinuxCNC trt kinematics values, read from ``--current``: ``PIN=VALUE,...``, a HAL file or an INI.

Read from HAL files and from the INI's ``[HAL] HALCMD`` lines (halcmd's own words, one command per line,
``#`` starts a comment)::

    setp <module>.<pin> <value>            the pin's value
    net <signal> [<=|=>|<=>] <pin> ...     the pins connected to a signal (arrows are optional)
    sets <signal> <value>                  the signal's value (what a connected input pin reads)
    loadrt <module> [args]                 the kinematics module loaded
    source <file.hal>                      that file's commands, there (``pige cycle install``'s values file)

and from the INI: ``[KINS] KINEMATICS = <module> [args]`` and ``[HAL] HALFILE`` / ``POSTGUI_HALFILE``, whose
files are read when they are ``.hal`` files beside the INI (``[SECTION]KEY`` references substituted);
library (``LIB:``) and Tcl files are not read and are named as unread.  Only the pins of the trt kinematics
(``xyzac-trt-kins.*``, ``xyzbc-trt-kins.*``) are kept.  A pin connected to a signal refuses ``setp``
("pin '…' is connected to a signal"): its value is the signal's.

Words are halcmd's (``strip_comments`` and ``tokenize`` of ``src/hal/utils/halcmd.c``, LinuxCNC 2.9): a ``#``
outside quotes ends the line, words are separated by blanks outside quotes, and quotes group blanks into a
word and stay part of it (halcmd keeps them); an unterminated quote is refused, as halcmd refuses the line.
Every step reads a line once (time linear in its length, also for a line of megabytes).

A path that does not exist is refused as a missing file; ``PIN=VALUE,...`` is read only when ``--current``
is not a path.  Values are not bounded here: :meth:`HalConfig.pin_value` bounds each one where it is used.
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass, field
from pathlib import Path

from pige_sym.errors import InputError

TRT_PIN = re.compile(r"^(xyz[ab]c-trt-kins)\.([a-z-]+)$")
TRT_MODULE = re.compile(r"^xyz[ab]c-trt-kins$")
#: The blanks of halcmd (C ``isspace`` in the C locale).
_BLANKS = " \t\n\v\f\r"
#: One piece of a halcmd line: a run of plain characters, a quoted run, a run of blanks, ``#``, or a quote
#: that is not closed (each alternative reads its characters once: no backtracking).
_PIECE = re.compile(r"""[^ \t\n\v\f\r'"#]+|'[^']*'|"[^"]*"|[ \t\n\v\f\r]+|#|['"]""")
#: A ``[SECTION]KEY`` reference to an INI value (halcmd's ``replace_vars``).
_SECTION_KEY = re.compile(r"\[(\w+)\](\w+)")
#: The trt pins that are bits, not lengths (trtfuncs.c, trtKinematicsSetup).
BIT_PINS = ("conventional-directions",)


@dataclass(frozen=True)
class PinValue:
    """What a configuration says one pin holds: ``value`` [mm], ``where`` it is set (file:line, or why it is 0)
    and the ``signal`` it comes through (empty for ``setp``)."""

    value: float
    where: str
    signal: str = ""

    @property
    def source(self) -> str:
        """Where the value comes from, in words."""
        return f"signal {self.signal}, {self.where}" if self.signal else self.where


@dataclass
class HalConfig:
    """What a configuration holds for the trt kinematics.

    Attributes
    ----------
    source : str or None
        The file read (None for ``PIN=VALUE,...``).
    module : str or None
        The trt kinematics module it loads or whose pins it names, with ``module_where`` (file:line).
    pins : dict of str to float
        ``setp`` values by pin name (without the module prefix) [mm], each set at ``pin_where[pin]``.
    nets : dict of str to str
        The signal each connected pin is on.
    signals : dict of str to float
        ``sets`` values by signal, each set at ``signal_where[signal]``.
    unread : list of str
        HAL files the configuration loads that were not read.
    """

    source: str | None
    module: str | None = None
    module_where: str = ""
    pins: dict[str, float] = field(default_factory=dict)
    nets: dict[str, str] = field(default_factory=dict)
    signals: dict[str, float] = field(default_factory=dict)
    unread: list[str] = field(default_factory=list)
    pin_where: dict[str, str] = field(default_factory=dict)
    signal_where: dict[str, str] = field(default_factory=dict)
    depth: int = 0  # ``source`` nesting while reading

    @property
    def name(self) -> str:
        """How the configuration is named in messages: its file, or ``PIN=VALUE``."""
        return self.source if self.source is not None else "PIN=VALUE"

    def name_module(self, module: str, where: str) -> None:
        """Record the kinematics module; a second, different one is refused."""
        if self.module is not None and module != self.module:
            raise InputError(f"--current {self.source}: {where} names {module} but {self.module_where} names "
                             f"{self.module}: give the configuration of one machine")
        if self.module is None:
            self.module, self.module_where = module, where

    def pin_value(self, pin: str) -> PinValue | None:
        """The value ``pin`` holds in this configuration, bounded, or None when the configuration does not say.

        A netted pin holds its signal's ``sets`` value; a pin a completely read file does not mention holds 0
        (a new HAL pin starts at 0, ``src/hal/hal_lib.c``).

        Raises
        ------
        InputError
            A length beyond ±``MAX_POSITION_MM`` (no machine is that large) or a bit other than 0 or 1,
            naming the file and line that set it.
        """
        if pin in self.nets:
            signal = self.nets[pin]
            if signal not in self.signals:
                return None
            found = PinValue(self.signals[signal], self.signal_where.get(signal, self.name), signal)
        elif pin in self.pins:
            found = PinValue(self.pins[pin], self.pin_where.get(pin, self.name))
        elif self.source is None or self.unread:
            return None
        else:
            found = PinValue(0.0, f"not set in {self.source}: a HAL pin starts at 0")
        _check_bound(pin, found)
        return found


def _check_bound(pin: str, found: PinValue) -> None:
    from pige_sym.measurements.schema import MAX_POSITION_MM

    via = f" (through signal {found.signal})" if found.signal else ""
    if pin in BIT_PINS:
        if found.value not in (0.0, 1.0):
            raise InputError(f"--current {found.where}: {pin} = {found.value:.10g}{via}: the pin is a bit, 0 or 1")
    elif not abs(found.value) <= MAX_POSITION_MM:
        raise InputError(f"--current {found.where}: {pin} = {found.value:.10g} mm{via} is not a position on a "
                         f"machine (|value| <= {MAX_POSITION_MM:g} mm): give the value the configuration really holds")


def read_current(spec: str) -> HalConfig:
    """``--current``: ``PIN=VALUE,...`` or the path of a HAL or INI file (module docstring).

    Raises
    ------
    InputError, FileFormatError
        A path that does not exist, a file pige cannot read or a line halcmd would refuse.
    """
    from pige_sym.options import parse_number_assignments

    if not os.path.lexists(spec):
        if "=" not in spec or os.sep in spec or spec.lower().endswith((".ini", ".hal")):
            raise InputError(f"--current {spec}: no such file; give the machine's INI or HAL file, or today's pin "
                             "values as PIN=VALUE,...")
        pins = {k.lower(): float(v) for k, v in parse_number_assignments(spec, "--current").items()}
        return HalConfig(None, pins=pins, pin_where=dict.fromkeys(pins, f"PIN=VALUE {spec}"))
    config = HalConfig(spec)
    text = _read_text(spec)
    if Path(spec).suffix.lower() == ".ini" or re.search(r"^[ \t]*\[(?:KINS|HAL|EMC)\]", text, re.M):
        _read_ini(config, Path(spec), text)
    else:
        _read_hal(config, spec, text.splitlines(), {})
    if config.module is None:
        raise InputError(f"--current {spec}: no trt kinematics in it (no 'loadrt xyzac-trt-kins', KINEMATICS = "
                         "xyzac-trt-kins, xyzbc-trt-kins or their pins): give the configuration of the machine")
    return config


def _read_text(path: str) -> str:
    """A configuration file's text (a regular UTF-8 file, else refused naming it)."""
    from pige_sym.errors import FileFormatError
    from pige_sym.files import open_regular_file

    with open_regular_file(path) as fh:
        data = fh.read()
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise FileFormatError(path, None, f"not a UTF-8 text file ({exc.reason})") from None


def _number(text: str, where: str) -> float:
    from pige_sym.options import parse_number

    return parse_number(text, where)


def halcmd_words(line: str, where: str) -> list[str]:
    """The words halcmd makes of one line (module docstring), in time linear in the line's length.

    Raises
    ------
    InputError
        An unterminated quote (halcmd: "unterminated quoted string"), naming ``where``.
    """
    words: list[str] = []
    word: list[str] = []
    for match in _PIECE.finditer(line):
        piece = match.group()
        if piece == "#":
            break
        if piece[0] in _BLANKS:
            if word:
                words.append("".join(word))
                word = []
        elif piece in ("'", '"'):
            raise InputError(f"--current {where}: unterminated quoted string (halcmd refuses the line)")
        else:
            word.append(piece)
    if word:
        words.append("".join(word))
    return words


def _read_hal(config: HalConfig, name: str, lines: list[str], ini: dict[tuple[str, str], str],
              first: int = 1) -> None:
    for number, raw in enumerate(lines, start=first):
        if not raw.strip(_BLANKS):
            continue
        where = f"{name}:{number}"
        line = _SECTION_KEY.sub(lambda m: ini.get((m.group(1), m.group(2)), m.group(0)), raw) if "[" in raw else raw
        words = halcmd_words(line, where)
        if words and words[0] == "source" and len(words) >= 2:
            _source(config, words[1], ini)
        elif words:
            _command(config, words, where)


def _source(config: HalConfig, name: str, ini: dict[tuple[str, str], str]) -> None:
    """halcmd's ``source FILE``: its commands there (a relative path from the configuration's folder, where LinuxCNC
    runs halcmd; a ``.hal`` file, at most 8 deep), else the file named as unread."""
    folder = Path(config.source).parent if config.source else Path(".")
    target = Path(name) if Path(name).is_absolute() else folder / name
    config.depth += 1
    try:
        if config.depth > 8 or target.suffix != ".hal" or not target.is_file():
            config.unread.append(name)
            return
        _read_hal(config, str(target), _read_text(str(target)).splitlines(), ini)
    finally:
        config.depth -= 1


def _command(config: HalConfig, words: list[str], where: str) -> None:
    verb, args = words[0], words[1:]
    if verb == "loadrt" and args and TRT_MODULE.match(args[0]):
        config.name_module(args[0], where)
    elif verb == "setp" and len(args) >= 2 and TRT_PIN.match(args[0]):
        module, pin = TRT_PIN.match(args[0]).groups()  # type: ignore[union-attr]
        config.name_module(module, where)
        config.pins[pin] = _number(args[1], f"--current {where}: {args[0]}")
        config.pin_where[pin] = where
    elif verb == "sets" and len(args) >= 2:
        config.signals[args[0]] = _number(args[1], f"--current {where}: signal {args[0]}")
        config.signal_where[args[0]] = where
    elif verb == "net" and args:
        for word in args[1:]:
            m = TRT_PIN.match(word)
            if m:
                config.name_module(m.group(1), where)
                config.nets[m.group(2)] = args[0]


def _read_ini(config: HalConfig, path: Path, text: str) -> None:
    """The INI's [KINS] KINEMATICS, [HAL] HALCMD lines and the HAL files it loads (module docstring)."""
    section = ""
    values: dict[tuple[str, str], str] = {}
    halcmd: list[tuple[int, str]] = []
    files: list[str] = []
    for number, raw in enumerate(text.splitlines(), start=1):
        line = raw.strip()
        if not line or line[0] in "#;":
            continue
        m = re.match(r"^\[(\w+)\]$", line)
        if m:
            section = m.group(1)
            continue
        key, sep, value = line.partition("=")
        if not sep:
            continue
        key, value = key.strip(), value.strip()
        values.setdefault((section, key), value)
        if section == "KINS" and key == "KINEMATICS" and value.split() and TRT_MODULE.match(value.split()[0]):
            config.name_module(value.split()[0], f"{path}:{number}")
        elif section == "HAL" and key == "HALCMD":
            halcmd.append((number, value))
        elif section == "HAL" and key in ("HALFILE", "POSTGUI_HALFILE", "SHUTDOWN"):
            files.append(value.split()[0] if value.split() else value)
    for name in files:
        target = path.parent / name
        if name.startswith("LIB:") or target.suffix != ".hal" or not target.is_file():
            config.unread.append(name)
            continue
        _read_hal(config, str(target), _read_text(str(target)).splitlines(), values)
    for number, value in halcmd:
        _read_hal(config, str(path), [value], values, first=number)
