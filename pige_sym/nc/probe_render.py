"""Render a sphere-probing plan (:mod:`pige_sym.nc.probe_program`) in a controller's own language.

Per pose: retract to ``safe_z``; position the rotary axes; per contact: rapid over the start at the
clearance plane, down to the start, the probing move to the target, back to the start, up to the
clearance plane; the contact is logged right after its probing move.  Coordinates are written with four
decimals (0.1 µm).  The log line of every dialect but LinuxCNC is
``PIGE P<pose> K<contact> X.. Y.. Z.. <axis1>.. <axis2>..`` (:mod:`pige_sym.measurements.probe_log`).
"""

from __future__ import annotations

import numpy as np

from pige_sym.errors import InputError
from pige_sym.nc.probe_program import HEIDENHAIN_FORMAT, HEIDENHAIN_LOG, PROBE_DIALECTS, Contact, ProbePlan
from pige_sym.nc.program import format_number

LINUXCNC_LOG = "pige_probe.txt"
SIEMENS_LOG = "PIGE_PROBE"
NO_CONTACT_ALARM = 65000  # Siemens user alarm number raised when a probing move ends without contact


def _num(v: float, dialect: str) -> str:
    if dialect == "heidenhain":
        return f"{v:+.4f}"
    return format_number(float(v), 4, point=dialect == "fanuc")


def _xyz(p: np.ndarray, dialect: str, axes: str = "XYZ") -> str:
    return " ".join(f"{a}{_num(p['XYZ'.index(a)], dialect)}" for a in axes)


def _rapid(words: str, dialect: str) -> str:
    if dialect == "heidenhain":
        return f"L {words} R0 FMAX"
    return f"G0 {words}"


def _header(plan: ProbePlan, dialect: str) -> list[str]:
    s = plan.setup
    title = (f"pige_sym sphere probing: {s.machine}, sphere R{s.sphere_radius_mm:g} at "
             f"{', '.join(f'{v:g}' for v in s.sphere_mm)}, stylus r{s.stylus_radius_mm:g}, pivot "
             f"{', '.join(f'{v:g}' for v in s.pivot_mm)}, {len(plan.angles_deg)} poses, {plan.description}")
    rtcp = "RTCP off; tool length = stylus centre; coordinates = those of --sphere and --pivot"
    if dialect == "linuxcnc":
        clean = title.replace("(", "[").replace(")", "]")
        return [f"({clean})", f"({rtcp})", "G21 G90 G17 G40 G49 G80 G94",
                f"(PROBEOPEN {LINUXCNC_LOG})"]
    if dialect == "fanuc":
        clean = title.replace("(", "[").replace(")", "]")
        return ["%", "O1001", f"({clean})", f"({rtcp})",
                "G21 G90 G17 G40 G49 G80 G94", "POPEN"]
    if dialect == "siemens":
        return ["DEF INT PIGE_ERR", f"; {title}", f"; machine: {s.machine}", f"; {rtcp}", "G90 G17 G71 G40",
                "TRAFOOF"]
    return ["0 BEGIN PGM PIGEPROBE MM", f"; {title}", f"; machine: {s.machine}", f"; {rtcp}",
            f"; log: FN 16 with the format file {HEIDENHAIN_FORMAT}"]


def _log_line(dialect: str, pose: int, k: int, angles: str) -> list[str]:
    if dialect == "fanuc":
        return [f"DPRNT[PIGE*P#101[40]*K#102[20]*X#5061[44]*Y#5062[44]*Z#5063[44]*{angles}]"]
    if dialect == "siemens":
        return [f'WRITE(PIGE_ERR,"{SIEMENS_LOG}","PIGE P{pose} K{k} X"<<$AA_MW[X]<<" Y"<<$AA_MW[Y]<<" Z"'
                f'<<$AA_MW[Z]<<" {angles}")']
    if dialect == "heidenhain":
        return [f"FN 16: F-PRINT {HEIDENHAIN_FORMAT} / {HEIDENHAIN_LOG}"]
    return []  # LinuxCNC logs the trip itself


def _probe(c: Contact, dialect: str, feed: float) -> list[str]:
    target = _xyz(c.target, dialect)
    if dialect == "linuxcnc":
        return [f"G38.2 {target} F{_num(feed, dialect)}"]
    if dialect == "fanuc":
        miss = "+".join(f"ABS[#{5061 + i}-{_num(c.target[i], dialect)}]" for i in range(3))
        return [f"G31 {target} F{_num(feed, dialect)}",
                f"IF[[{miss}]LT0.001]THEN#3000=1(PIGE NO CONTACT)"]
    if dialect == "siemens":
        return [f"MEAS=1 G1 {target} F{_num(feed, dialect)}", "STOPRE", "IF $AC_MEA[1]==0",
                f"SETAL({NO_CONTACT_ALARM})", "ENDIF"]
    q = {"X": 11, "Y": 12, "Z": 13}[c.axis]
    pre = [f"FN 0: Q{11 + i} = {_num(c.start[i], dialect)}" for i in range(3)]
    return [*pre, f"TCH PROBE 0.0 REF PLANE Q{q} {c.axis}{'+' if c.sign > 0 else '-'}",
            f"TCH PROBE 0.1 {_xyz(c.target, dialect)}"]


def _pose_lines(plan: ProbePlan, i: int, dialect: str) -> list[str]:
    s = plan.setup
    rot = " ".join(f"{a}{_num(v, dialect)}" for a, v in zip(plan.rotary_axes, plan.angles_deg[i], strict=True))
    out = [_rapid(f"Z{_num(plan.safe_z_mm, dialect)}", dialect), _rapid(rot, dialect)]
    if dialect == "fanuc":
        out += [f"#101={i}"] + [f"#{103 + k}={_num(v, dialect)}" for k, v in enumerate(plan.angles_deg[i])]
        angles = "*".join(f"{a}#{103 + k}[34]" for k, a in enumerate(plan.rotary_axes))
    elif dialect == "heidenhain":
        out += [f"FN 0: Q1 = +{i}"] + [f"FN 0: Q{14 + k} = {_num(v, dialect)}"
                                       for k, v in enumerate(plan.angles_deg[i])]
        angles = ""
    else:
        angles = " ".join(f"{a}{v:.6f}" for a, v in zip(plan.rotary_axes, plan.angles_deg[i], strict=True))
    clear = _num(plan.clear_z_mm[i], dialect)
    for k, c in enumerate(plan.contacts[i]):
        if dialect == "fanuc":
            out.append(f"#102={k}")
        elif dialect == "heidenhain":
            out.append(f"FN 0: Q2 = +{k}")
        out += [_rapid(_xyz(c.start, dialect, "XY"), dialect), _rapid(_xyz(c.start, dialect, "Z"), dialect)]
        out += _probe(c, dialect, s.probe_feed_mm_min)
        out += _log_line(dialect, i, k, angles)
        out += [_rapid(_xyz(c.start, dialect), dialect), _rapid(f"Z{clear}", dialect)]
    return out


def render_probe_program(plan: ProbePlan, dialect: str) -> str:
    """The probing program of a plan in one dialect (module docstring)."""
    if dialect not in PROBE_DIALECTS:
        raise InputError(f"--dialect {dialect!r}: use one of {', '.join(PROBE_DIALECTS)}")
    lines = _header(plan, dialect)
    for i in range(len(plan.angles_deg)):
        lines += _pose_lines(plan, i, dialect)
    lines.append(_rapid(f"Z{_num(plan.safe_z_mm, dialect)}", dialect))
    if dialect == "linuxcnc":
        lines += ["(PROBECLOSE)", "M2"]
    elif dialect == "fanuc":
        lines += ["PCLOS", "M30", "%"]
    elif dialect == "siemens":
        lines += ["M30"]
    else:
        lines += ["END PGM PIGEPROBE MM"]
        start = int(lines[0].split()[0])
        lines = [lines[0]] + [f"{start + n} {ln}" for n, ln in enumerate(lines[1:], 1)]
    return "\n".join(lines) + "\n"


def heidenhain_format_file(plan: ProbePlan) -> str:
    """The FN 16 format file (``PROBE.A``) the Heidenhain program prints each contact with."""
    axes = plan.rotary_axes
    fields = " ".join(f"{a}%+10.4LF" for a in axes)
    params = ", ".join(["Q1", "Q2", "Q11", "Q12", "Q13", *(f"Q{14 + k}" for k in range(len(axes)))])
    return f'"PIGE P%5.0LF K%2.0LF X%+10.4LF Y%+10.4LF Z%+10.4LF {fields}", {params};\n'
