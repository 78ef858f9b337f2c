"""Compensating an NC program: plan, guard, rewrite, read back, report.

1. **Interpret** the program in its dialect (detected, or ``dialect``), with controller-specific
   RTCP codes added (``rtcp_on``/``rtcp_off``).
2. **Plan**: the compensable linear moves (:attr:`Block.compensable`), except the move that
   ends where an arc starts (the arc's centre is given relative to that point, so it stays
   exactly as programmed) and moves under a work offset other than the one of the first
   compensated move (the parameters hold for one set-up).  Every other block that moves an
   axis is listed with the reason it passes through.
3. **Weigh** the estimates by their uncertainty (:mod:`pige_sym.compensation.weighing`), judged on the
   planned poses: a weakly determined parameter is entered in part or not at all, and the tool-point error
   the correction leaves is predicted with a 95 % bound (``enter="all"`` enters every estimate as it is).
4. **Compensate** all planned poses at once (:func:`pige_sym.compensation.kinematics.compensate_poses`) with
   the orientation-pole guard (no rotary axis turned by more than ``max_change_deg`` to fix
   the orientation; such poses are listed as *orientation limited*, their position is still
   corrected); a rotary command is never moved across a multiple of 360° (on a roll-over axis that
   could turn the table a full revolution), that pose's orientation is left and listed too.
5. **Guard**: a pose whose correction exceeds ``max_change_mm`` / ``max_change_deg`` refuses the
   whole program (like the change limits of a controller's own calibration cycle).
6. **Rewrite** (:mod:`pige_sym.nc.rewrite`) and **read back** (:mod:`pige_sym.nc.verify`); the
   report holds per changed block the words before/after, the predicted tool-point error
   [µm] and orientation error [µrad] before/after on the identified machine, and the change.
"""

from __future__ import annotations

import gc
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from pige_sym.compensation.parameters import CompensationParameters
from pige_sym.compensation.weighing import Weighing
from pige_sym.constants import DEFAULT_MAX_CHANGE_DEG as DEFAULT_MAX_CHANGE_DEG
from pige_sym.constants import DEFAULT_MAX_CHANGE_MM as DEFAULT_MAX_CHANGE_MM
from pige_sym.errors import InputError
from pige_sym.measurements.axis_sense import METADATA_KEY as SENSE_KEY
from pige_sym.measurements.axis_sense import format_axis_sense, to_commanded, to_conventions
from pige_sym.nc.detect import detect_dialect
from pige_sym.nc.dialects import Dialect, get_dialect
from pige_sym.nc.dialects.base import kinematics_switch_codes
from pige_sym.nc.interpreter import Program, interpret
from pige_sym.nc.program_header import program_axis_sense
from pige_sym.nc.rewrite import Rewrite, header_position, rewrite_program
from pige_sym.nc.state import Block
from pige_sym.nc.verify import verify


@dataclass(slots=True)
class BlockChange:
    """One changed block of the change report.

    Attributes
    ----------
    line_in, line_out : int
    words : list of dict
        ``{"axis", "old", "new"}`` per changed or added word.
    rtcp : bool
    tool_point_error_before_um, tool_point_error_after_um : float
        Predicted |tool point − intended point| on the identified machine [µm].
    orientation_error_before_urad, orientation_error_after_urad : float
        Predicted tool-direction error [µrad] (NaN when the machine has no direction solver).
    change_mm, change_deg : float
        Largest change of a linear [mm] / rotary [deg] axis position.
    orientation_limited : bool
        Near the orientation pole: the orientation correction was limited.
    """

    line_in: int
    line_out: int
    words: list[dict[str, str]]
    rtcp: bool
    tool_point_error_before_um: float
    tool_point_error_after_um: float
    orientation_error_before_urad: float
    orientation_error_after_urad: float
    change_mm: float
    change_deg: float
    orientation_limited: bool


@dataclass
class CompensationReport:
    """What ``pige compensate`` did to a program (printed, and as JSON with ``--json``)."""

    program: str
    dialect: str
    machine: str
    parameters_from: str
    lines: int
    moves: int
    compensated: int
    changes: list[BlockChange]
    passed_through: list[dict[str, Any]]
    orientation_limited_lines: list[int]
    notes: list[str]
    max_change_mm: float
    max_change_deg: float
    limits: dict[str, float]
    verified: bool
    not_compensated_parameters: list[str] = field(default_factory=list)
    weighing: Weighing | None = None

    def to_dict(self) -> dict[str, Any]:
        out = asdict(self)
        del out["weighing"]
        w = self.weighing.to_dict() if self.weighing is not None else {}
        return out | {"entered": w.get("entered"), "predicted_after_um": w.get("predicted_after_um"),
                      "weighing": w or None}


@dataclass
class CompensationResult:
    """The compensated text, its report and the compensated poses of the chosen blocks (None: nothing chosen)."""

    text: str
    report: CompensationReport
    poses: Any = None


def with_rtcp_codes(dialect: Dialect, on: tuple[str, ...] = (), off: tuple[str, ...] = ()) -> Dialect:
    """The dialect with controller-specific RTCP codes (``M428``) declared (:func:`kinematics_switch_codes`)."""
    extra = kinematics_switch_codes(dialect, on, off)
    return dialect.with_codes(extra) if extra else dialect


def plan(program: Program) -> tuple[list[Block], list[dict[str, Any]]]:
    """The blocks to compensate, and every other moving block with why it passes through."""
    chosen: list[Block] = []
    passed: list[dict[str, Any]] = []
    excluded: dict[int, str] = {}
    last_mover: Block | None = None
    offset: str | None = None
    movers = [b for b in program.blocks if b.kind]
    for b in movers:
        if b.kind == "pass" and b.state.motion in ("G2", "G3") and last_mover is not None and last_mover.compensable:
            excluded[last_mover.line_no] = f"start point of the arc at line {b.line_no} (kept as programmed)"
        last_mover = b
        if b.kind == "move" and not b.reason:  # compensable
            if offset is None:
                offset = b.state.offset
            elif b.state.offset != offset:
                excluded[b.line_no] = (f"work offset {b.state.offset or 'none'} differs from "
                                       f"{offset or 'none'} of the first compensated block")
    for b in movers:
        if b.kind == "move" and not b.reason and b.line_no not in excluded:
            chosen.append(b)
        else:
            passed.append({"line": b.line_no, "reason": excluded.get(b.line_no) or b.reason})
    return chosen, passed


def compensate_nc(text: str, params: Any, *, path: str = "<program>", dialect: str | None = None,
                  pass_through: bool = False, max_change_mm: float = DEFAULT_MAX_CHANGE_MM,
                  max_change_deg: float = DEFAULT_MAX_CHANGE_DEG, rtcp_on: tuple[str, ...] = (),
                  rtcp_off: tuple[str, ...] = (), header: bool = True, enter: str = "weighed",
                  decide: Callable[[Weighing], Weighing] | None = None) -> CompensationResult:
    """Compensate a program with identified parameters (module docstring).

    Parameters
    ----------
    text : str
        The program, line endings as in the file.
    params : CompensationParameters
    max_change_mm, max_change_deg : float
        Change limits [mm], [deg].
    enter : {"weighed", "all"}
        Enter the values weighed by their uncertainty (:mod:`~pige_sym.compensation.weighing`), or every
        estimate as it is.
    decide : callable, optional
        Turns the weighing into the values to enter (the compensation stage's decision, e.g. a check-up's);
        replaces ``enter``.

    Raises
    ------
    NCProgramError
        A block that cannot be read or is refused (with its line).
    CompensationError
        A correction beyond the limits, or a failed read-back.
    InputError
        Parameters beyond physical bounds (:func:`~pige_sym.compensation.controllers.entry_checks.check_parameters`).
    """
    was_enabled = gc.isenabled()
    gc.disable()  # ~10^6 short-lived objects, no cycles: the collector would only rescan them (~20 %)
    try:
        return _compensate_nc(text, params, path, dialect, pass_through, max_change_mm, max_change_deg, rtcp_on,
                              rtcp_off, header, enter, decide)
    finally:
        if was_enabled:
            gc.enable()


def _compensate_nc(text: str, params: Any, path: str, dialect: str | None, pass_through: bool,
                   max_change_mm: float, max_change_deg: float, rtcp_on: tuple[str, ...], rtcp_off: tuple[str, ...],
                   header: bool, enter: str, decide: Callable[[Weighing], Weighing] | None = None,
                   ) -> CompensationResult:
    from pige_sym.errors import CompensationError
    from pige_sym.kernels import load_kernels

    if not (max_change_mm > 0 and max_change_deg > 0 and np.isfinite([max_change_mm, max_change_deg]).all()):
        raise InputError("--max-change: both limits must be positive finite numbers")
    from pige_sym.compensation.controllers.entry_checks import check_parameters

    check_parameters(params)  # a program is written for a controller too: the same bounds before anything is made
    kern = load_kernels(params.machine)
    axes = tuple(kern.ROTARY_AXES)
    program_axis_sense(text, axes, path, params.axis_sense, given_by=f"the parameter file {params.source}",
                       fix="a program is compensated with parameters of the same commanded sense (CONVENTIONS §9): "
                           "use parameters identified from measurements made in the program's sense, or write the "
                           "program again in theirs")  # a pige program's header must agree
    d = with_rtcp_codes(get_dialect(dialect or detect_dialect(text, path)), rtcp_on, rtcp_off)
    program = interpret(text, d, axes, path=path, pass_through=pass_through)
    chosen, passed = plan(program)
    weighing, entered = _weighed(params, chosen, enter, decide)
    poses = _compensated_poses(entered, chosen, max_change_deg)
    _guard(chosen, poses, max_change_mm, max_change_deg, path, CompensationError)
    new_commanded = to_commanded(poses.new_angles_deg, params.axis_sense, axes)
    new_poses = np.hstack([poses.new_xyz_mm, new_commanded]).tolist() if chosen else []
    targets = dict(zip([b.line_no for b in chosen], map(tuple, new_poses), strict=True))
    rw = rewrite_program(program, targets, header=_header(params, weighing) if header else None)
    check = verify(program, rw.text, {c.line_in for c in rw.changed}, rw.header_lines, header_position(program),
                   max_mm=max_change_mm + 1e-4, max_deg=max_change_deg + 1e-4, pass_through=pass_through,
                   targets=targets)
    if not check.ok:
        raise CompensationError(f"{path}: the compensated program did not read back as intended, nothing written: "
                                + "; ".join(check.problems[:5]))
    for line, why in rw.skipped.items():
        passed.append({"line": line, "reason": why})
    report = CompensationReport(
        path, d.name, params.machine, params.source, len(program.blocks), sum(b.kind == "move" for b in program.blocks),
        len(rw.changed), _changes(params, chosen, poses, rw, check.read_back),
        sorted(passed, key=lambda p: p["line"]),
        [chosen[i].line_no for i in np.flatnonzero(poses.orientation_limited).tolist()],
        program.notes + _rtcp_note(program, chosen) + _arc_start_notes(program, check.read_back, rw.header_lines),
        check.max_change_mm, check.max_change_deg, {"mm": max_change_mm, "deg": max_change_deg}, True,
        list(params.ignored), weighing)
    return CompensationResult(rw.text, report, poses if chosen else None)


def _weighed(params: CompensationParameters, chosen: list[Block], enter: str,
             decide: Callable[[Weighing], Weighing] | None = None) -> tuple[Weighing | None, CompensationParameters]:
    """The weighing judged on the planned poses, and the parameters to compensate with (module docstring)."""
    from pige_sym.compensation.kinematics import workpiece_points
    from pige_sym.compensation.weighing import every_estimate, program_poses, weigh, with_entered
    from pige_sym.kernels import load_kernels

    if enter not in ("weighed", "all"):
        raise InputError(f"enter {enter!r}: use weighed or all")
    if not chosen:
        return None, params
    kern = load_kernels(params.machine)
    axes = tuple(kern.ROTARY_AXES)
    after = np.array([b.after for b in chosen], dtype=float).reshape(-1, 3 + len(axes))
    angles, points = to_conventions(after[:, 3:], params.axis_sense, axes), after[:, :3].copy()
    rtcp = np.array([b.rtcp for b in chosen], dtype=bool)
    if (~rtcp).any():
        pivots = {a: np.asarray(v, dtype=float) for a, v in params.pivots_mm.items()} or None
        points[~rtcp] = workpiece_points(kern, angles[~rtcp], points[~rtcp], pivots, params.tool_mm)
    weighing = weigh(params, program_poses(angles, points))
    if decide is not None:
        weighing = decide(weighing)
    elif enter == "all":
        weighing = every_estimate(weighing)
    return weighing, with_entered(params, weighing)


def _rtcp_note(program: Program, chosen: list[Block]) -> list[str]:
    """A note when no RTCP code precedes the first compensated block (the reset state, off, is assumed)."""
    if not chosen or chosen[0].state.rtcp_programmed:
        return []
    return [f"no RTCP code before line {chosen[0].line_no}: X/Y/Z are taken as machine coordinates (RTCP off, "
            "the reset state); if RTCP is switched on outside this program, declare its code (--rtcp-on)"]


def _arc_start_notes(program: Program, out: Program | None, header_lines: int) -> list[str]:
    """Arcs whose start the compensation of an earlier block moved (their end stays as programmed).

    The centre (I/J/K) is relative to the start, so the end radius differs by up to the shift; a
    controller accepts that within its circle end-point tolerance and stops with an alarm beyond it.
    """
    if out is None:
        return []
    at = header_position(program)
    blocks = out.blocks[:at] + out.blocks[at + header_lines:] if header_lines else out.blocks
    notes = []
    for a, b in zip(program.blocks, blocks, strict=True):
        if a.kind == "pass" and a.state.motion in ("G2", "G3") and None not in a.before and None not in b.before:
            shift = max(abs(x - y) for x, y in zip(a.before[:3], b.before[:3], strict=True))  # type: ignore[operator]
            if shift > 1e-4:
                notes.append(f"the arc at line {a.line_no} starts {shift * 1e3:.1f} um from its programmed start "
                             "(an earlier block was compensated); its end is as programmed")
    return notes


def _header(params: Any, weighing: Weighing | None) -> list[str]:
    head = [f"compensated by pige_sym for {params.machine}, parameters {params.source}"]
    if weighing is not None and weighing.covariance_from != "none":
        partial = [f"{n}={v:.4g}" for n, v in weighing.entered.items()
                   if v is not None and not weighing.why[n].startswith("entered as estimated")]
        if partial:
            head.append("weighed by uncertainty, entered: " + ", ".join(partial))
    sense = format_axis_sense(params.axis_sense)
    if sense:
        head.append(f"pige {SENSE_KEY}: {sense}")
    for ext in params.extensions:
        opts = "".join(f" {k}={v:g}" for k, v in ext.spec.options.items())
        head.append(f"compensated extension: {ext.spec.id}{opts}: "
                    + ", ".join(f"{k}={v:.4g}" for k, v in ext.params.items()))
    if params.ignored:
        head.append("not compensated: " + ", ".join(params.ignored))
    return head


def _compensated_poses(params: Any, chosen: list[Block], max_change_deg: float) -> Any:
    from pige_sym.compensation.kinematics import compensate_poses
    from pige_sym.kernels import load_kernels
    from pige_sym.model.trajectories import approach_directions

    axes = tuple(load_kernels(params.machine).ROTARY_AXES)
    after = np.array([b.after for b in chosen], dtype=float).reshape(-1, 3 + len(axes))
    angles, xyz = to_conventions(after[:, 3:], params.axis_sense, axes), after[:, :3]
    rtcp = np.array([b.rtcp for b in chosen], dtype=bool)
    pivots = {a: np.asarray(v, dtype=float) for a, v in params.pivots_mm.items()} or None
    # directions of approach matter only to a compensated reversal error (backlash)
    maps = params.error_maps
    per_direction = params.extensions or (maps is not None and any(
        m.kind == "reversal" for ax in maps.axes.values() for m, _ in ax.motion_values()))
    approach = approach_directions(angles) if len(chosen) and per_direction else np.zeros_like(angles)
    return compensate_poses(params.machine, params.values, angles, xyz, rtcp=rtcp, pivots_mm=pivots,
                            tool_mm=params.tool_mm, extensions=params.extensions, approach=approach,
                            max_angle_step_deg=max_change_deg, keep_turn=True, error_maps=maps)


def _guard(chosen: list[Block], poses: Any, max_mm: float, max_deg: float, path: str, error: type) -> None:
    d_mm = np.abs(poses.new_xyz_mm - poses.xyz_mm).max(axis=1, initial=0.0)
    d_deg = np.abs(poses.new_angles_deg - poses.angles_deg).max(axis=1, initial=0.0)
    bad = np.flatnonzero((d_mm > max_mm) | (d_deg > max_deg))
    if bad.size:
        i = int(bad[0])
        raise error(f"{path}:{chosen[i].line_no}: the correction ({d_mm[i]:.4f} mm, {d_deg[i]:.4f} deg) exceeds "
                    f"--max-change {max_mm:g} mm / {max_deg:g} deg ({bad.size} block(s)); check the parameters "
                    "(and their set-up: pivots, tool) or raise the limit")


def _changes(params: Any, chosen: list[Block], poses: Any, rw: Rewrite, out_prog: Program | None,
             ) -> list[BlockChange]:
    """Per changed block: words, predicted errors before/after (from the read-back) and change."""
    from pige_sym.compensation.kinematics import predicted_errors

    if not rw.changed or out_prog is None:
        return []
    index = {b.line_no: i for i, b in enumerate(chosen)}
    rows = [index[c.line_in] for c in rw.changed]
    new = out_prog.after_array()[[c.line_out - 1 for c in rw.changed]]  # line numbers count from 1
    new[:, 3:] = to_conventions(new[:, 3:], params.axis_sense, out_prog.rotary_axes)
    a, xyz, rtcp = poses.angles_deg[rows], poses.xyz_mm[rows], np.asarray(poses.rtcp, dtype=bool)[rows]
    from pige_sym.model.trajectories import approach_directions

    approach = approach_directions(a) if params.extensions or params.error_maps is not None else np.zeros_like(a)
    tp0, or0 = predicted_errors(params, a, xyz, rtcp, a, xyz, approach)
    tp1, or1 = predicted_errors(params, a, xyz, rtcp, new[:, 3:], new[:, :3], approach)
    d_mm = np.abs(new[:, :3] - xyz).max(axis=1).tolist()
    d_deg = np.abs(new[:, 3:] - a).max(axis=1, initial=0.0).tolist()
    limited = np.asarray(poses.orientation_limited)[rows].tolist()
    return list(map(BlockChange, [c.line_in for c in rw.changed], [c.line_out for c in rw.changed],
                    [c.words for c in rw.changed], rtcp.tolist(), tp0.tolist(), tp1.tolist(), or0.tolist(),
                    or1.tolist(), d_mm, d_deg, limited))


def compensate_program(program_text: str, params: CompensationParameters, *, path: str = "<program>",
                       dialect: str | None = None, pass_through: bool = False, **guards: Any) -> str:
    """Compensated program text, in the program's own dialect (:mod:`pige_sym.compensation.program`).

    ``guards``: ``max_change_mm``, ``max_change_deg``, ``rtcp_on``, ``rtcp_off``, ``header``.
    """
    return compensate_nc(program_text, params, path=path, dialect=dialect, pass_through=pass_through,
                         **guards).text
