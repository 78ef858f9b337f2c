"""The compensation stage: decide what to enter, correct the program, write the controller's entries — once.

:func:`compensate` is the one place that weighs the estimates (:mod:`~pige_sym.compensation.weighing`), rewrites
an NC program (:mod:`~pige_sym.compensation.program`) and renders a controller's entries
(:mod:`~pige_sym.compensation.controllers`); it returns a :class:`~pige_sym.compensation.result.Compensation`
that ``pige compensate``, ``pige checkup``, the report (and the LinuxCNC cycle) print from, as ``scipy``'s printers
read an ``OptimizeResult``.

What is judged where:

- a **program**: the values are weighed on its compensated poses (what the correction meets there);
- a **controller**: over the axes' travel (``travel``: axis → (min, max) [deg]; the entries act everywhere);
- neither: over the axes' travel (what to enter, e.g. for the report's answer).

A later stage may decide the entered values itself (the check-up: its PIGEs within ``--max-change``, the held
ones kept): ``decided`` (name → value or None, and why) replaces the weighing's choice, and everything predicted
and printed follows it.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import replace
from typing import Any

from pige_sym.compensation.advice import advice, undetermined_values
from pige_sym.compensation.controllers import ControllerOptions, check_before_writing, get_controller
from pige_sym.compensation.parameters import CompensationParameters
from pige_sym.compensation.result import Compensation, ControllerEntries, ProgramCorrection
from pige_sym.compensation.weighing import Weighing, every_estimate, travel_poses, weigh, with_entered
from pige_sym.constants import DEFAULT_MAX_CHANGE_DEG, DEFAULT_MAX_CHANGE_MM
from pige_sym.errors import InputError


@dataclasses.dataclass(frozen=True)
class Decision:
    """Values a later stage decided to enter (None: not entered), with the reason for each."""

    entered: Mapping[str, float | None]
    why: Mapping[str, str]


@dataclasses.dataclass(frozen=True)
class PosesRequest:
    """Poses to correct and judge the correction on, as a program would command them with RTCP on (the measured
    trajectory in the report): CONVENTIONS angles (n, k) [deg] and the intended workpiece points (n, 3) [mm]."""

    angles_deg: Any
    points_mm: Any
    description: str = "the poses"


@dataclasses.dataclass(frozen=True)
class ProgramRequest:
    """An NC program to correct and the guards of its rewrite (as ``pige compensate PROGRAM``; a limit None: the
    default)."""

    text: str
    path: str = "<program>"
    dialect: str | None = None
    pass_through: bool = False
    max_change_mm: float | None = DEFAULT_MAX_CHANGE_MM
    max_change_deg: float | None = DEFAULT_MAX_CHANGE_DEG
    rtcp_on: tuple[str, ...] = ()
    rtcp_off: tuple[str, ...] = ()
    header: bool = True


def compensate(params: CompensationParameters, *, program: ProgramRequest | None = None,
               poses: PosesRequest | None = None, controller: str | None = None,
               options: ControllerOptions | None = None,
               travel: Mapping[str, tuple[float, float]] | None = None, enter: str = "weighed",
               decided: Decision | None = None) -> Compensation:
    """The compensation of ``params`` (module docstring).

    Parameters
    ----------
    params : CompensationParameters
        The estimates as read (:func:`~pige_sym.compensation.parameters.load_parameters`).
    program : ProgramRequest, optional
        An NC program to correct.
    poses : PosesRequest, optional
        Poses to correct (RTCP on) and judge on, without a program (the report's measured trajectory).
    controller : str, optional
        A controller's entries to write (``table``, ``siemens``, ``linuxcnc``, …).
    options : ControllerOptions, optional
    travel : dict, optional
        Axis → (min, max) [deg] over which a controller's entries are judged.
    enter : {"weighed", "all"}
    decided : Decision, optional
        The values to enter, decided by a later stage (module docstring).

    Returns
    -------
    Compensation

    Raises
    ------
    InputError, NCProgramError, CompensationError
        As the program's rewrite and the controller's checks refuse (nothing is returned half made).
    """
    if enter not in ("weighed", "all"):
        raise InputError(f"enter {enter!r}: use weighed or all")
    opts = options or ControllerOptions()
    ctrl = _controller(params, controller, opts, travel, enter, decided) if controller else None
    prog = _program(params, program, enter, decided) if program is not None else None
    corrected = None
    if prog is not None and prog.report.weighing is not None:
        weighing = prog.report.weighing
    elif poses is not None:
        weighing, corrected = _poses(params, poses, enter, decided)
    elif ctrl is not None:
        weighing = ctrl.weighing
    else:
        weighing = _decide(weigh(params, travel_poses(params, dict(travel or {}))), enter, decided)
    choices = ctrl.choices if ctrl is not None else []
    decided_names = set(decided.entered) if decided is not None else set()
    undetermined = [u for u in undetermined_values(params) if u.name not in decided_names]
    return Compensation(params.machine, params.source, weighing, with_entered(params, weighing), prog, ctrl,
                        undetermined, advice(weighing, choices), corrected)


def overruled(weighing: Weighing, entered: dict[str, float | None], why: dict[str, str]) -> Weighing:
    """The weighing with the values a later stage decided (module docstring): each value named in
    ``entered`` takes that value (None: not entered) and its reason; the others stay as weighed.  What it leaves is
    predicted for the decided values."""
    chosen = {n: (entered[n] if n in entered else v) for n, v in weighing.entered.items()}
    chosen |= {n: v for n, v in entered.items() if n not in chosen}
    reasons = {n: why.get(n, weighing.why.get(n, "decided by the caller")) for n in chosen}
    predicted = dict(weighing.predicted)
    after = weighing.predicted_for({n: v for n, v in chosen.items() if v is not None})
    if after is not None:
        predicted["entered"] = after
    return replace(weighing, entered=chosen, why=reasons, predicted=predicted)


def _decide(weighing: Weighing, enter: str, decided: Decision | None) -> Weighing:
    if decided is not None:
        return overruled(weighing, dict(decided.entered), dict(decided.why))
    return every_estimate(weighing) if enter == "all" else weighing


def _controller(params: CompensationParameters, name: str, options: ControllerOptions,
                travel: Mapping[str, tuple[float, float]] | None, enter: str,
                decided: Decision | None) -> ControllerEntries:
    """Weigh over the travel, build the controller's tables once, compute what each way of entering carries and
    leaves from them, render the entries (from the same tables and, by target file, the same sections)."""
    from pige_sym.compensation.controllers.scope import controller_scope

    module = get_controller(name)
    check_before_writing(params, name, options=options)  # before the values are weighed
    weighing = _decide(weigh(params, travel_poses(params, dict(travel or {}))), enter, decided)
    entered = with_entered(params, weighing)
    check_before_writing(entered, name, options=options)  # and the values entered
    tables = list(getattr(module, "tables", lambda _p, _o: [])(entered, options))  # built once: printed and counted
    built = dataclasses.replace(options, tables=tables)
    scope = controller_scope(entered, name, built)
    rendered = dataclasses.replace(built, scope=scope)
    sections = list(getattr(module, "sections", lambda _p, _o: [])(entered, rendered))
    render_sections = getattr(module, "render_sections", None)
    text = str(render_sections(sections) if render_sections is not None else module.render(entered, rendered))
    return ControllerEntries(name, text, sections, scope.choices, scope.not_representable, weighing, entered,
                             scope.complete, tables)


def _poses(params: CompensationParameters, req: PosesRequest, enter: str,
           decided: Decision | None) -> tuple[Weighing, Any]:
    """The weighing judged on the poses, and the poses corrected with the entered values (RTCP on)."""
    import numpy as np

    from pige_sym.compensation.kinematics import compensate_poses
    from pige_sym.compensation.weighing import program_poses
    from pige_sym.model.trajectories import approach_directions

    angles = np.atleast_2d(np.asarray(req.angles_deg, dtype=float))
    points = np.atleast_2d(np.asarray(req.points_mm, dtype=float))
    weighing = _decide(weigh(params, program_poses(angles, points)), enter, decided)
    entered = with_entered(params, weighing)
    pivots = {a: np.asarray(v, dtype=float) for a, v in params.pivots_mm.items()} or None
    corrected = compensate_poses(params.machine, entered.values, angles, points, rtcp=True, pivots_mm=pivots,
                                 tool_mm=params.tool_mm, extensions=entered.extensions,
                                 approach=approach_directions(angles), error_maps=entered.error_maps)
    return weighing, corrected


def _program(params: CompensationParameters, req: ProgramRequest, enter: str,
             decided: Decision | None) -> ProgramCorrection:
    from pige_sym.compensation.program import compensate_nc

    decide = (lambda w: _decide(w, enter, decided)) if decided is not None else None
    result = compensate_nc(req.text, params, path=req.path, dialect=req.dialect, pass_through=req.pass_through,
                           max_change_mm=DEFAULT_MAX_CHANGE_MM if req.max_change_mm is None else req.max_change_mm,
                           max_change_deg=DEFAULT_MAX_CHANGE_DEG if req.max_change_deg is None else req.max_change_deg,
                           rtcp_on=req.rtcp_on,
                           rtcp_off=req.rtcp_off, header=req.header, enter=enter, decide=decide)
    return ProgramCorrection(result.text, result.report, result.poses)


def format_controller(params: Any, style: str = "table", *, carrier: int = 1,
                      current: Any = None, heidenhain_trans: str | None = None, enter: str = "weighed",
                      machine_axes: dict[str, str] | None = None, isg_unit_deg: float | None = None,
                      limits: Any = None) -> str:
    """The corrections of ``params`` in the words of controller ``style`` (docs/controller-corrections.md).

    The text of the compensation stage's entries (:func:`pige_sym.compensation.stage.compensate`): the values
    weighed by their uncertainty over the axes' travel; every controller also says what it enters, what it cannot
    represent and the tool-point error each way of entering leaves, with a 95 % bound
    (:mod:`~pige_sym.compensation.controllers.scope`).  Nothing is rendered before :func:`check_before_writing` has
    passed, on the values as given and on the values entered; every entry is held to ``limits`` (``--max-change``,
    :class:`~pige_sym.compensation.controllers.entry_checks.ChangeLimits`; None: its default).
    """
    options = ControllerOptions(carrier=carrier, current=current, heidenhain_trans=heidenhain_trans,
                                machine_axes=machine_axes, isg_unit_deg=isg_unit_deg, limits=limits)
    result = compensate(params, controller=style, options=options, enter=enter)
    assert result.controller is not None
    return result.controller.text
