"""Render a sphere-probing plan (:mod:`pige_sym.nc.probe_program`) in a controller's own language.

Per pose: retract to ``safe_z``; position the rotary axes; per contact: rapid over the start at the
clearance plane, down to the start, the probing move to the target, back to the start, up to the
clearance plane; the contact is logged right after its probing move.  Coordinates are written with four
decimals (0.1 µm).  The log line of every dialect but LinuxCNC is
``PIGE P<pose> K<contact> X.. Y.. Z.. <axis1>.. <axis2>..`` (:mod:`pige_sym.measurements.probe_log`).
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from pige_sym.constants import PROBE_DIALECTS
from pige_sym.errors import InputError
from pige_sym.measurements.axis_sense import METADATA_KEY as SENSE_KEY
from pige_sym.measurements.axis_sense import format_axis_sense, to_commanded
from pige_sym.nc.probe_header import PROBE_FORMAT
from pige_sym.nc.probe_program import (
    HEIDENHAIN_FORMAT,
    HEIDENHAIN_LOG,
    Contact,
    ProbePlan,
    table_frames,
)
from pige_sym.nc.probe_safety import (
    Confirm,
    confirm_lines,
    confirmation_moves,
    epilogue,
    guard_lines,
    heidenhain_error_block,
    prologue,
)
from pige_sym.nc.program import format_number
from pige_sym.nc.program_header import header_lines

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


def header_items(plan: ProbePlan, dialect: str) -> dict[str, str]:
    """What the program states in its header (:mod:`pige_sym.nc.program_header`; read by ``import-probe``)."""
    s = plan.setup
    pivots = s.pivots
    per_axis: dict[str, np.ndarray] = dict(pivots) if isinstance(pivots, Mapping) else \
        {a: pivots for a in plan.rotary_axes}
    items = {"format": PROBE_FORMAT, "machine": s.machine, "dialect": dialect}
    sense = format_axis_sense(s.axis_sense, plan.rotary_axes)
    if sense:
        items[SENSE_KEY] = sense
    items |= {f"pivot_{a}_mm": _vec(per_axis[a]) for a in plan.rotary_axes}
    items |= {"sphere_mm": _vec(s.sphere_mm), "sphere_radius_mm": f"{s.sphere_radius_mm:.12g}",
              "stylus_radius_mm": f"{s.stylus_radius_mm:.12g}"}
    if s.tool_mm is not None:
        items["tool_mm"] = _vec(s.tool_mm)
    if s.checkup:
        items["checkup"] = ",".join(s.checkup)
    if s.machine_id is not None:
        items["machine_id"] = s.machine_id
    return items | s.controller.header_items()


def _vec(v: np.ndarray) -> str:
    # 12 digits: the read-back compares the header with the options to 2e-6, so 6 digits refused a pivot of -14.990659
    return ", ".join(f"{float(x):.12g}" for x in v)


def _header(plan: ProbePlan, dialect: str) -> list[str]:
    s = plan.setup
    title = (f"pige_sym sphere probing: {s.machine}, sphere R{s.sphere_radius_mm:g} at "
             f"{', '.join(f'{v:g}' for v in s.sphere_mm)}, stylus r{s.stylus_radius_mm:g}, "
             f"{len(plan.angles_deg)} poses, {plan.description}")
    ctrl = s.controller
    state = (f"{ctrl.kinematics} kinematics; tool {ctrl.stylus_tool}, length {ctrl.stylus_length_mm:g} mm = "
             f"stylus centre; coordinates in {ctrl.work_offset} = those of --sphere and --pivot")
    stated = header_lines(header_items(plan, dialect), dialect)
    pro = prologue(ctrl, dialect, plan.rotary_axes)
    if dialect == "linuxcnc":
        clean = title.replace("(", "[").replace(")", "]")
        return [f"({clean})", f"({state})", *stated, "G21 G90 G17 G40 G49 G80 G94", *pro]
    if dialect == "fanuc":
        clean = title.replace("(", "[").replace(")", "]")
        return ["%", "O1001", f"({clean})", f"({state})", *stated, "G21 G90 G17 G40 G49 G80 G94",
                f"G43 H{ctrl.stylus_tool}", *pro]
    if dialect == "siemens":
        return ["DEF INT PIGE_ERR", f"; {title}", f"; machine: {s.machine}", f"; {state}", *stated,
                "G90 G17 G71 G40", "TRAFOOF", *pro]
    return ["0 BEGIN PGM PIGEPROBE MM", f"; {title}", f"; machine: {s.machine}", f"; {state}", *stated,
            f"; log: FN 16 with the format file {HEIDENHAIN_FORMAT}", *pro]


def _log_open(dialect: str) -> list[str]:
    return {"linuxcnc": [f"(PROBEOPEN {LINUXCNC_LOG})"], "fanuc": ["POPEN"]}.get(dialect, [])


def _confirmation(plan: ProbePlan, dialect: str) -> list[str]:
    """The reference-pose confirmation (:func:`~pige_sym.nc.probe_safety.confirmation_moves`), before the log."""
    s = plan.setup
    zero = np.zeros(len(plan.rotary_axes))
    out = [_rapid(f"Z{_num(plan.safe_z_mm, dialect)}", dialect),
           _rapid(" ".join(f"{a}{_num(v, dialect)}" for a, v in zip(plan.rotary_axes, zero, strict=True)), dialect)]
    label = 910

    def fmt(v: float) -> str:
        return _num(v, dialect)

    for move in confirmation_moves(plan.centres_mm[0], s.r_eff_mm, s.clearance_mm, s.controller.window_mm,
                                   plan.safe_z_mm):
        if isinstance(move, Confirm):
            out += confirm_lines(move, dialect, fmt, s.probe_feed_mm_min, s.controller.window_mm, label)
            out.append(_rapid(_xyz(move.start, dialect), dialect))
            label += 2
        elif move[0] == "guard":
            out += guard_lines(move[1], dialect, fmt, label)
            label += 1
        else:
            out.append(_rapid(_xyz(move[1], dialect), dialect))
    return out


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


def _rotary_words(plan: ProbePlan, theta: np.ndarray, dialect: str) -> str:
    commanded = to_commanded(theta, plan.setup.axis_sense, plan.rotary_axes)
    return " ".join(f"{a}{_num(v, dialect)}" for a, v in zip(plan.rotary_axes, commanded, strict=True))


#: Largest rotary step of one positioning in TCP kinematics [deg]: the probe waits above the sphere, along
#: the machine's vertical at the middle of the step, so it stays high above the sphere's top all along.
TCP_STEP_DEG = 45.0


def _tcp_retracts(plan: ProbePlan, theta_from: np.ndarray, theta_to: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    """TCP kinematics: per rotary step, the work point the probe waits at, and the angles it turns to."""
    s = plan.setup
    steps = max(int(np.ceil(np.abs(theta_to - theta_from).max() / TCP_STEP_DEG)), 1)
    height = plan.safe_z_mm - float(plan.centres_mm[:, 2].max())
    out = []
    for k in range(1, steps + 1):
        mid = theta_from + (theta_to - theta_from) * (k - 0.5) / steps
        rot, _ = table_frames(s.machine, mid[None], s.pivots)
        out.append((np.asarray(s.sphere_mm, dtype=float) + height * rot[0].T @ np.array([0.0, 0.0, 1.0]),
                    theta_from + (theta_to - theta_from) * k / steps))
    return out


def _pose_start(plan: ProbePlan, i: int, dialect: str) -> tuple[list[str], str]:
    """Retract, rotary positioning and the pose's log parameters; and the angles of its log line."""
    s = plan.setup
    commanded = to_commanded(plan.angles_deg[i], s.axis_sense, plan.rotary_axes)
    rot = _rotary_words(plan, plan.angles_deg[i], dialect)
    out = [_rapid(f"Z{_num(plan.safe_z_mm, dialect)}", dialect), _rapid(rot, dialect)]
    if dialect == "fanuc":
        out += [f"#101={i}"] + [f"#{103 + k}={_num(v, dialect)}" for k, v in enumerate(commanded)]
        return out, "*".join(f"{a}#{103 + k}[34]" for k, a in enumerate(plan.rotary_axes))
    if dialect == "heidenhain":
        out += [f"FN 0: Q1 = +{i}"] + [f"FN 0: Q{14 + k} = {_num(v, dialect)}" for k, v in enumerate(commanded)]
        return out, ""
    return out, " ".join(f"{a}{v:.6f}" for a, v in zip(plan.rotary_axes, commanded, strict=True))


def _contact_number(k: int, dialect: str) -> list[str]:
    return [f"#102={k}"] if dialect == "fanuc" else [f"FN 0: Q2 = +{k}"] if dialect == "heidenhain" else []


def _pose_lines(plan: ProbePlan, i: int, dialect: str) -> list[str]:
    if plan.setup.controller.kinematics == "tcp":
        return _pose_lines_tcp(plan, i, dialect)
    if plan.frames is not None:
        return _pose_lines_head(plan, i, dialect)
    s = plan.setup
    out, angles = _pose_start(plan, i, dialect)
    clear = _num(plan.clear_z_mm[i], dialect)
    for k, c in enumerate(plan.contacts[i]):
        out += _contact_number(k, dialect)
        out += [_rapid(_xyz(c.start, dialect, "XY"), dialect), _rapid(_xyz(c.start, dialect, "Z"), dialect)]
        out += _probe(c, dialect, s.probe_feed_mm_min)
        out += _log_line(dialect, i, k, angles)
        out += [_rapid(_xyz(c.start, dialect), dialect), _rapid(f"Z{clear}", dialect)]
    return out


def _pose_lines_head(plan: ProbePlan, i: int, dialect: str) -> list[str]:
    """A pose of a head machine (:mod:`pige_sym.nc.probe_program`): every point is the stylus centre minus the
    head's offset ``h`` (the program commands the linear axes); the probe comes over the first start at the safe
    height, down to the clearance plane normal to the stylus axis, and to every start along the stylus axis;
    the probing moves run along or across the stylus axis (``G38.2``/``G31``/``MEAS`` with X, Y and Z); the
    retract goes back along the move and up to the clearance plane."""
    s = plan.setup
    assert plan.head_mm is not None
    h = plan.head_mm[i]
    out, angles = _pose_start(plan, i, dialect)
    for k, c in enumerate(plan.contacts[i]):
        assert c.above is not None
        above, start = c.above - h, c.start - h
        out += _contact_number(k, dialect)
        out += [_rapid(_xyz(above, dialect, "XY"), dialect), _rapid(_xyz(above, dialect, "Z"), dialect)] if k == 0 \
            else [_rapid(_xyz(above, dialect), dialect)]
        down = [] if np.allclose(start, above, atol=1e-9) else [_rapid(_xyz(start, dialect), dialect)]
        shifted = Contact(start, c.target - h, c.axis, c.sign, above)
        out += down + _probe(shifted, dialect, s.probe_feed_mm_min)
        out += _log_line(dialect, i, k, angles)
        out += [_rapid(_xyz(start, dialect), dialect), *([_rapid(_xyz(above, dialect), dialect)] if down else [])]
    return out


def _pose_lines_tcp(plan: ProbePlan, i: int, dialect: str) -> list[str]:
    """A pose in LinuxCNC's TCP kinematics: every point in work coordinates (the nominal table motion of the
    pose undone), every move with X, Y and Z, the rotary axes turned in steps above the sphere."""
    s = plan.setup
    before = plan.angles_deg[i - 1] if i else np.zeros(len(plan.rotary_axes))
    out = []
    for wait, theta in _tcp_retracts(plan, before, plan.angles_deg[i]):
        out += [_rapid(_xyz(wait, dialect), dialect), _rapid(_rotary_words(plan, theta, dialect), dialect)]
    rot, t = table_frames(s.machine, plan.angles_deg[i][None], s.pivots)

    def work(p: np.ndarray) -> str:
        return _xyz(rot[0].T @ (p - t[0]), dialect)

    for c in plan.contacts[i]:
        above = np.array([c.start[0], c.start[1], plan.clear_z_mm[i]])
        out += [_rapid(work(above), dialect), _rapid(work(c.start), dialect),
                f"G38.2 {work(c.target)} F{_num(s.probe_feed_mm_min, dialect)}",
                _rapid(work(c.start), dialect), _rapid(work(above), dialect)]
    return out


def _end_tcp(plan: ProbePlan, dialect: str) -> list[str]:
    """TCP kinematics: the last retract, straight above the sphere at the safe height, then the rotary axes back to
    the reference pose in steps above the sphere: the program ends where it must start (its first check), so it
    runs again as it is (``pige cycle`` calls it again and again)."""
    last = plan.angles_deg[-1]
    out = [_rapid(_xyz(_tcp_retracts(plan, last, last)[0][0], dialect), dialect)]
    for wait, theta in _tcp_retracts(plan, last, np.zeros(len(plan.rotary_axes))):
        out += [_rapid(_xyz(wait, dialect), dialect), _rapid(_rotary_words(plan, theta, dialect), dialect)]
    return out


def render_probe_program(plan: ProbePlan, dialect: str) -> str:
    """The probing program of a plan in one dialect (module docstring)."""
    if dialect not in PROBE_DIALECTS:
        raise InputError(f"--dialect {dialect!r}: use one of {', '.join(PROBE_DIALECTS)}")
    plan.setup.controller.check(dialect)
    if plan.setup.controller.kinematics == "tcp" and plan.frames is not None:
        raise InputError("--kinematics tcp: probing in TCP kinematics is written for table machines; a head or mixed "
                         "machine probes with RTCP off (--kinematics identity)")
    if dialect == "heidenhain" and plan.frames is not None:
        raise InputError("--dialect heidenhain: a head turns the stylus, so most probing moves are inclined, which a "
                         "TNC probes with touch-probe cycle 4 (measuring in 3-D); no source at hand settles that "
                         "cycle's syntax, so pige does not write it: use --dialect linuxcnc, fanuc or siemens for a "
                         "head or mixed machine (Heidenhain's own KinematicsOpt cycles 451/452 calibrate heads)")
    lines = _header(plan, dialect) + _confirmation(plan, dialect) + _log_open(dialect)
    for i in range(len(plan.angles_deg)):
        lines += _pose_lines(plan, i, dialect)
    if plan.setup.controller.kinematics == "tcp":
        lines += _end_tcp(plan, dialect)
    else:
        lines.append(_rapid(f"Z{_num(plan.safe_z_mm, dialect)}", dialect))
    end = epilogue(plan.setup.controller, dialect)
    if dialect == "linuxcnc":
        lines += ["(PROBECLOSE)", *end, "M2"]
    elif dialect == "fanuc":
        lines += ["PCLOS", "M30", "%"]
    elif dialect == "siemens":
        lines += ["M30"]
    else:
        lines += [*heidenhain_error_block(), "END PGM PIGEPROBE MM"]
        start = int(lines[0].split()[0])
        lines = [lines[0]] + [f"{start + n} {ln}" for n, ln in enumerate(lines[1:], 1)]
    return "\n".join(lines) + "\n"


def heidenhain_format_file(plan: ProbePlan) -> str:
    """The FN 16 format file (``PROBE.A``) the Heidenhain program prints each contact with."""
    axes = plan.rotary_axes
    fields = " ".join(f"{a}%+10.4LF" for a in axes)
    params = ", ".join(["Q1", "Q2", "Q11", "Q12", "Q13", *(f"Q{14 + k}" for k in range(len(axes)))])
    return f'"PIGE P%5.0LF K%2.0LF X%+10.4LF Y%+10.4LF Z%+10.4LF {fields}", {params};\n'
