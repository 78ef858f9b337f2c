"""``pige cycle install``: what the cycle adds to a LinuxCNC configuration, as a plan of whole files.

The plan (:func:`plan_install`) is computed from the configuration's files and the options alone; nothing is written
until :func:`apply_plan`.  It holds, per file, its text now and after:

- **the INI**: ``SUBROUTINE_PATH`` gains ``./pige_cycle/ngc:./pige_cycle/run``; ``REMAP = M451 ...`` and ``REMAP =
  M452 ...`` after the last ``REMAP``; ``HAL_PIN_VARS = 1`` (the prolog reads ``motion.switchkins-type``) and
  ``ON_ABORT_COMMAND = O <pige_on_abort> call`` when absent; a ``[PYTHON]`` section; the lines that set the values
  the kinematics hold are commented out ("moved to ./pige_cycle/values.hal") and ``HALCMD = source
  ./pige_cycle/values.hal`` takes their place (after the last of them: the nets they set through exist by then);
- **a HAL file** beside the INI that sets one of those values: that line commented out the same way;
- ``pige_cycle/values.hal`` with the values as the configuration set them (kept as it is when it exists: it holds
  what ``M451 P2`` entered), ``pige_cycle/settings.json`` from the options, and the cycle's code
  (:mod:`~pige_sym.cycle.assets`).

A configuration already installed gives the same files again (the INI's lines are found, not added twice; the
values stay): a second install with the same options changes nothing.  Refused, with exit status 2 and nothing
written, naming what to fix: a file that is not a LinuxCNC INI, no ``[RS274NGC]``, kinematics the cycle cannot
enter values into, ``M451``/``M452`` remapped to something else, a ``[PYTHON]`` section of the configuration's own.
"""

from __future__ import annotations

import difflib
import re
from dataclasses import dataclass, field, replace
from datetime import datetime, timezone
from pathlib import Path

from pige_sym.cycle.assets import MODULE, asset_files, placeholder_procedure
from pige_sym.cycle.hal_scan import HalScan, scan_configuration
from pige_sym.cycle.ini import IniDocument, IniEdit, append_section, apply_edits, parse_ini
from pige_sym.cycle.kinematics import KinematicsSetup, ValuePin, read_kinematics
from pige_sym.cycle.layout import CODES, ON_ABORT_SUB, PROBE_SUB, Layout
from pige_sym.cycle.settings import (
    FORMAT,
    CycleSettings,
    Limits,
    MapTest,
    Probing,
    Switch,
    check_settings,
    default_timeouts,
    default_tolerances,
)
from pige_sym.cycle.values import values_text
from pige_sym.errors import InputError

MOVED = "pige cycle install: moved to ./pige_cycle/values.hal"


@dataclass
class InstallOptions:
    """The options of ``pige cycle install`` (its ``--help``; :mod:`~pige_sym.cycle.settings` for their meaning)."""

    sphere_mm: tuple[float, float, float]
    sphere_radius_mm: float
    stylus_radius_mm: float
    stylus_tool: int
    stylus_length_mm: float
    pige_command: list[str]
    kinematics: str | None = None
    machine: str | None = None
    machine_id: str | None = None
    db: str | None = None
    rtcp_on: str | None = None
    rtcp_off: str | None = None
    probing: Probing = field(default_factory=Probing)
    limits: Limits = field(default_factory=Limits)
    timeouts: dict[str, float] = field(default_factory=default_timeouts)
    tolerances: dict | None = None
    map: MapTest | None = None


@dataclass(frozen=True)
class PlannedFile:
    """One file of the plan: its text ``old`` (None: a new file) and ``new``; ``code`` for the cycle's own code."""

    path: Path
    old: str | None
    new: str
    code: bool = False


@dataclass
class InstallPlan:
    """What an install writes (module docstring): the files that change, and notes for the user."""

    ini: Path
    layout: Layout
    files: list[PlannedFile]
    notes: list[str]
    settings: CycleSettings

    def diff(self) -> str:
        """The changes as a unified diff (the cycle's code files: one line each)."""
        out = []
        for f in self.files:
            name = str(f.path.relative_to(self.layout.config))
            if f.code:
                out.append(f"{'new' if f.old is None else 'changed'}: {name} (pige's cycle code, "
                           f"{f.new.count(chr(10))} lines)\n")
                continue
            old = [] if f.old is None else f.old.splitlines(keepends=True)
            out += difflib.unified_diff(old, f.new.splitlines(keepends=True), "/dev/null" if f.old is None
                                        else f"a/{name}", f"b/{name}")
        return "".join(line if line.endswith("\n") else line + "\n" for line in out)


def plan_install(ini: Path, opts: InstallOptions) -> InstallPlan:
    """The install's plan (module docstring).

    Raises
    ------
    InputError, FileFormatError
        What the configuration or the options lack, naming the file, line or option.
    """
    from pige_sym.cycle.map_pins import with_map_pins
    from pige_sym.files import read_input_text

    ini = Path(ini).absolute()
    text = read_input_text(ini, what="INI file")
    doc = parse_ini(text, str(ini))
    if "RS274NGC" not in doc.sections:
        raise InputError(f"{ini}: no [RS274NGC] section: the cycle's remaps go there; give the INI LinuxCNC runs")
    layout = Layout(ini.resolve().parent)
    _one_configuration(layout, ini)
    scan = scan_configuration(ini, doc)
    setup = read_kinematics(doc, scan, kinematics=opts.kinematics, machine=opts.machine)
    settings = _settings(doc, setup, opts, scan)
    setup = with_map_pins(setup, settings, scan)  # the map test's pins are values the cycle holds too
    edits, notes = _ini_edits(doc, layout, setup, scan)
    files = [PlannedFile(ini, text, ini_with_python(apply_edits(doc, edits), doc, layout))]
    files += _hal_file_edits(layout, setup)
    files += _cycle_files(layout, setup, settings)
    changed = [f for f in files if f.old != f.new]
    for f in changed:
        _check_target(f.path)
    return InstallPlan(ini, layout, changed, notes, settings)


def _one_configuration(layout: Layout, ini: Path) -> None:
    """Refuse a second INI in a folder whose cycle belongs to another one (one pige_cycle/ per configuration)."""
    if not layout.settings.is_file():
        return
    from pige_sym.measurements.strict_json import load_json

    try:
        other = load_json(layout.settings, "cycle settings file").get("ini")
    except Exception:  # a settings file pige cannot read is replaced by the plan (its diff shows it)
        return
    if isinstance(other, str) and other != ini.name:
        raise InputError(f"{layout.root} belongs to {other}: the cycle is installed into one configuration per "
                         f"folder; copy {ini.name} into a folder of its own")


def _check_target(path: Path) -> None:
    if path.is_symlink() or (path.exists() and not path.is_file()):
        raise InputError(f"{path} is not a regular file: pige never replaces one")


def _settings(doc: IniDocument, setup: KinematicsSetup, opts: InstallOptions, scan: HalScan) -> CycleSettings:
    machine_id = opts.machine_id or doc.value("EMC", "MACHINE") or ""
    switch = _switch(doc, opts)
    if switch is not None:
        switch = replace(switch, analog_out=switch_output(scan))
    s = CycleSettings(FORMAT, Path(doc.name).name, setup.machine, machine_id.strip(), setup.kinematics, setup.module,
                      dict(setup.axis_sense), switch, [float(v) for v in opts.sphere_mm],
                      float(opts.sphere_radius_mm), float(opts.stylus_radius_mm), int(opts.stylus_tool),
                      float(opts.stylus_length_mm), opts.probing, opts.limits,
                      opts.tolerances or default_tolerances(),
                      opts.timeouts, opts.db or "pige_cycle/history.db", list(opts.pige_command), opts.map)
    if not s.machine_id:
        raise InputError(f"{doc.name}: no [EMC] MACHINE to name the machine in the history: give --machine-id ID")
    return check_settings(s, "pige cycle install")


def _switch(doc: IniDocument, opts: InstallOptions) -> Switch | None:
    """The codes that switch the kinematics: ``--rtcp-off``/``--rtcp-on``, else the configuration's remaps whose NGC
    procedure sets ``#<kinstype>`` (LinuxCNC's switchkins examples, e.g. the shipped M428/M429); None: no switch."""
    kins = doc.value("KINS", "KINEMATICS") or ""
    first = "sparm=identityfirst" in kins.split()
    identity_type, tcp_type = (0, 1) if first else (1, 0)
    if opts.rtcp_on or opts.rtcp_off:
        if not (opts.rtcp_on and opts.rtcp_off):
            raise InputError("give both --rtcp-off CODE (identity kinematics) and --rtcp-on CODE (TCP)")
        return Switch(opts.rtcp_off.upper(), identity_type, opts.rtcp_on.upper(), tcp_type)
    types = _switch_codes(doc)
    identity, tcp = types.get(identity_type), types.get(tcp_type)
    if identity and tcp:
        return Switch(identity, identity_type, tcp, tcp_type)
    if first:
        raise InputError(f"{doc.name}: KINEMATICS = {kins} starts in identity kinematics, and no remapped code of the "
                         "INI selects the TCP ones (a procedure setting #<kinstype>): give --rtcp-on CODE and "
                         "--rtcp-off CODE")
    return None


def switch_output(scan: HalScan) -> int | None:
    """N of the ``motion.analog-out-N`` netted to ``motion.switchkins-type`` (the shipped sims: ``net :kinstype-select
    <= motion.analog-out-03 => motion.switchkins-type``), or None (another writer, or no net)."""
    signal = scan.nets.get("motion.switchkins-type")
    outs = [pin for pin, sig in scan.nets.items() if sig == signal and pin.startswith("motion.analog-out-")]
    if signal is None or len(outs) != 1 or not outs[0].removeprefix("motion.analog-out-").isdigit():
        return None
    return int(outs[0].removeprefix("motion.analog-out-"))


def _switch_codes(doc: IniDocument) -> dict[int, str]:
    """switchkins type -> the remapped M-code whose NGC procedure selects it."""
    folders = [Path(doc.name).resolve().parent / d for d in (doc.value("RS274NGC", "SUBROUTINE_PATH") or "").split(":")
               if d.strip()]
    out: dict[int, str] = {}
    for e in doc.values("RS274NGC", "REMAP"):
        words = e.value.split()
        ngc = next((w.split("=", 1)[1] for w in words[1:] if w.startswith("ngc=")), None)
        if not words or ngc is None:
            continue
        for folder in folders:
            path = folder / f"{ngc}.ngc"
            if path.is_file():
                m = re.search(r"#<kinstype>\s*=\s*(\d+)", path.read_text(encoding="utf-8", errors="replace"))
                if m and words[0].upper() not in out.values():
                    out.setdefault(int(m.group(1)), words[0].upper())
                break
    return out


def remap_line(code: str) -> str:
    """The INI line that remaps ``code`` (:mod:`~pige_sym.cycle.linuxcnc_remap`)."""
    name = CODES[code]
    argspec = "pq" if code == "M451" else "p"  # Q: the map test's setup (M451 P3 Q<k>)
    return f"REMAP = {code} modalgroup=10 argspec={argspec} prolog={name}_prolog ngc={name} epilog={name}_epilog"


def _ini_edits(doc: IniDocument, layout: Layout, setup: KinematicsSetup,
               scan: HalScan) -> tuple[list[IniEdit], list[str]]:
    edits: list[IniEdit] = []
    notes: list[str] = []
    edits += _subroutine_path(doc, layout)
    edits += _remaps(doc)
    edits += _rs274ngc_keys(doc, notes, scan)
    edits += _moved_values(doc, layout, setup, scan)
    _python(doc, layout)  # refuses a [PYTHON] section of the configuration's own
    return edits, notes


def _section_end(doc: IniDocument, section: str) -> int:
    return doc.sections[section][1]


def _subroutine_path(doc: IniDocument, layout: Layout) -> list[IniEdit]:
    ours = [layout.relative(layout.ngc), layout.relative(layout.current)]
    found = doc.values("RS274NGC", "SUBROUTINE_PATH")
    if not found:
        return [IniEdit(doc.sections["RS274NGC"][0], "insert_after", f"SUBROUTINE_PATH = {':'.join(ours)}",
                        "the cycle's procedures")]
    dirs = [d for d in found[0].value.split(":") if d]
    missing = [d for d in ours if d not in dirs]
    if not missing:
        return []
    raw = doc.lines[found[0].line - 1]
    key = raw[:raw.index("=")]
    return [IniEdit(found[0].line, "replace", f"{key}= {':'.join(dirs + missing)}", "the cycle's procedures")]


def _remaps(doc: IniDocument) -> list[IniEdit]:
    remaps = doc.values("RS274NGC", "REMAP")
    after = remaps[-1].line if remaps else doc.sections["RS274NGC"][0]
    new: list[str] = []
    replaced: list[IniEdit] = []
    for code in CODES:
        mine = [e for e in remaps if e.value.split() and e.value.split()[0].upper() == code]
        given = " ".join(mine[0].value.split()) if mine else None
        if given == remap_line(code)[len("REMAP = "):]:
            continue
        if given is not None and given == remap_line(code)[len("REMAP = "):].replace("argspec=pq", "argspec=p"):
            replaced.append(IniEdit(mine[0].line, "replace", remap_line(code), "Q: the map test's setup"))
            continue  # an earlier install's, before M451 P3 Q<k>
        if mine:
            raise InputError(f"{doc.name}:{mine[0].line}: {code} is remapped already ({mine[0].value}): the cycle "
                             f"remaps {code}; remove that line, or that code's remap")
        new.append(remap_line(code))
    return replaced + ([IniEdit(after, "insert_after", "\n".join(new), "the cycle's codes")] if new else [])


#: the ON_ABORT_COMMANDs an install writes: pige_cycle_abort's call itself when the switch's output is known (it
#: sets the output from Python: nothing is left for LinuxCNC to execute again after the handler, see
#: docs/linuxcnc-cycle.md §6), else the NGC handler, which puts the mode back with the configuration's code
ABORT_COMMANDS = ("o <pige_cycle_abort> call", f"o <{ON_ABORT_SUB}> call")


def abort_command(scan: HalScan) -> str:
    return "O <pige_cycle_abort> call" if switch_output(scan) is not None else f"O <{ON_ABORT_SUB}> call"


def _rs274ngc_keys(doc: IniDocument, notes: list[str], scan: HalScan) -> list[IniEdit]:
    out = []
    end = _section_end(doc, "RS274NGC")
    pins = doc.value("RS274NGC", "HAL_PIN_VARS")
    if pins is None:
        out.append(IniEdit(end, "insert_after", "HAL_PIN_VARS = 1", "the prolog reads motion.switchkins-type"))
    elif pins.strip() != "1":
        raise InputError(f"{doc.name}: [RS274NGC] HAL_PIN_VARS = {pins}: the cycle reads motion.switchkins-type "
                         "(#<_hal[...]>): set it to 1")
    abort = doc.value("RS274NGC", "ON_ABORT_COMMAND")
    ours = abort_command(scan)
    given = None if abort is None else " ".join(abort.split()).lower()
    if abort is None:
        out.append(IniEdit(end, "insert_after", f"ON_ABORT_COMMAND = {ours}", "the kinematics mode after an abort"))
    elif given in ABORT_COMMANDS and given != ours.lower():  # an earlier install's
        line = doc.values("RS274NGC", "ON_ABORT_COMMAND")[0].line
        out.append(IniEdit(line, "replace", f"ON_ABORT_COMMAND = {ours}", "the kinematics mode after an abort"))
    elif given != ours.lower():
        notes.append(f"[RS274NGC] ON_ABORT_COMMAND is the configuration's own ({abort}): call o<{ON_ABORT_SUB}> from "
                     "it (first, before anything that synchronises) so that an abort in the middle of the cycle stops "
                     "pige's step and leaves the kinematics mode as it was found")
    return out


def _python(doc: IniDocument, layout: Layout) -> None:
    if "PYTHON" not in doc.sections:
        return
    top = doc.value("PYTHON", "TOPLEVEL")
    if top is not None and Path(top) == Path(layout.relative(layout.python / "toplevel.py")):
        return
    raise InputError(f"{doc.name}: the configuration has its own [PYTHON] section (TOPLEVEL {top}): pige does not "
                     "edit another program's Python; docs/linuxcnc-cycle.md says how to add the cycle's handlers to "
                     f"it (PATH_APPEND = {layout.relative(layout.python)}, 'from {MODULE} import *' in your remap "
                     "module)")


def python_section(layout: Layout) -> list[str]:
    return [f"PATH_PREPEND = {layout.relative(layout.python)}",
            f"TOPLEVEL = {layout.relative(layout.python / 'toplevel.py')}"]


def _source_line(layout: Layout) -> str:
    return f"HALCMD = source {layout.relative(layout.values)}"


def _moved_values(doc: IniDocument, layout: Layout, setup: KinematicsSetup, scan: HalScan) -> list[IniEdit]:
    """Comment out the INI lines that set the values, and source the values file after the last of them."""
    if any(Path(s.value) == Path(layout.relative(layout.values)) for s in scan.sources):
        return []  # installed: the values are in values.hal
    ini = Path(doc.name).resolve()
    in_ini = [p for p in setup.pins if p.where is not None and _where(p)[0] == ini]
    out = [IniEdit(line, "comment", MOVED, "the value lives in values.hal") for line in sorted({_where(p)[1]
                                                                                                for p in in_ini})]
    halcmds = doc.values("HAL", "HALCMD")
    after = max([_where(p)[1] for p in in_ini], default=halcmds[-1].line if halcmds else
                doc.sections["HAL"][1] if "HAL" in doc.sections else 0)
    if after == 0:
        raise InputError(f"{doc.name}: no [HAL] section to source the values file from")
    for p in setup.pins:
        net = scan.net_where.get(p.pin)
        if p.signal and net is not None and net.file == ini and net.line > after:
            raise InputError(f"{net.where}: {p.pin} is netted to {p.signal} after the line that sets it: move the net "
                             "before the sets line, then install")
    return out + [IniEdit(after, "insert_after", _source_line(layout), "the values file")]


def _where(pin: ValuePin) -> tuple[Path, int]:
    file, _, line = (pin.where or "").rpartition(":")
    return Path(file).resolve(), int(line)


def _hal_file_edits(layout: Layout, setup: KinematicsSetup) -> list[PlannedFile]:
    """The HAL files beside the INI that set a value: those lines commented out."""
    from pige_sym.files import read_input_text

    by_file: dict[Path, list[int]] = {}
    for p in setup.pins:
        if p.where is None:
            continue
        file, line = _where(p)
        if file.suffix == ".hal" and file != layout.values.resolve():
            by_file.setdefault(file, []).append(line)
    out = []
    for file, lines in by_file.items():
        old = read_input_text(file, what="HAL file")
        new = old.splitlines(keepends=True)
        for n in set(lines):
            new[n - 1] = f"# {MOVED}: {new[n - 1]}"
        out.append(PlannedFile(file, old, "".join(new)))
    return out


def _cycle_files(layout: Layout, setup: KinematicsSetup, settings: CycleSettings) -> list[PlannedFile]:
    from pige_sym.cycle.settings import settings_text

    out = []
    if not layout.values.exists():
        out.append(PlannedFile(layout.values, None, values_text(setup, {p.pin: p.value for p in setup.pins})))
    out.append(_planned(layout.settings, settings_text(settings)))
    for path, text in asset_files(layout, settings).items():
        out.append(_planned(path, text, code=True))
    placeholder = layout.current / f"{PROBE_SUB}.ngc"
    if not placeholder.exists():
        out.append(PlannedFile(placeholder, None, placeholder_procedure(), code=True))
    return out


def _planned(path: Path, new: str, *, code: bool = False) -> PlannedFile:
    from pige_sym.files import read_input_text

    old = read_input_text(path) if path.is_file() else None
    return PlannedFile(path, old, new, code)


def ini_with_python(plan_text: str, doc: IniDocument, layout: Layout) -> str:
    """The INI's new text with the cycle's ``[PYTHON]`` section (when it has none)."""
    if "PYTHON" in doc.sections:
        return plan_text
    return append_section(plan_text, doc, "PYTHON", python_section(layout))


def apply_plan(plan: InstallPlan) -> list[str]:
    """Write the plan's files, each existing one backed up first (``<file>.pige-backup-<UTC time>``); returns what
    was done, one line per file."""
    from pige_sym.files import atomic_write_text

    stamp = datetime.now(timezone.utc).strftime("%Y%m%dT%H%M%SZ")
    done = []
    for f in plan.files:
        _check_target(f.path)
        if f.old is not None:
            backup = _backup_name(f.path, stamp)
            backup.write_bytes(f.path.read_bytes())
            done.append(f"backed up {f.path} as {backup.name}")
        atomic_write_text(f.path, f.new, newline="")
        done.append(f"wrote {f.path}")
    for folder in (plan.layout.runs, plan.layout.current):
        folder.mkdir(parents=True, exist_ok=True)
    return done


def _backup_name(path: Path, stamp: str) -> Path:
    candidate = path.with_name(f"{path.name}.pige-backup-{stamp}")
    n = 1
    while candidate.exists():
        n += 1
        candidate = path.with_name(f"{path.name}.pige-backup-{stamp}-{n}")
    return candidate
