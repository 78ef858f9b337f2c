"""The changes a check-up says to enter: each re-measured PIGE's change since the values in force, weighed.

**The values in force** (:attr:`~.reference.ChartState.in_force`) are what the controller holds, as pige printed
it to be entered: the last full calibration's correction (``pige compensate``; when it was entered, or when the
check-ups measure the machine itself) plus the check-ups' corrections entered since (``--corrected``).  A check-up
measures ``x``: the machine's own error when it probes in identity kinematics (the values in force do not move it:
the change since them is ``x − v``), what the controller's kinematics leave of it otherwise (an R-test, TCP probing:
the change is ``x`` itself) (:func:`~.reference.measures_machine`, :attr:`~.reference.ChartState.level`).  Its
covariance is the check-up's (its held values' error included).

**What is entered.**  The changes of the re-measured PIGEs, weighed as ``pige compensate`` weighs them
(:func:`~pige_sym.compensation.weighing.entered_values`: a change the data do not show beyond its uncertainty is not
entered); a change beyond ``--max-change`` (position errors in mm, orientation errors in degrees) is not entered
(no drift to correct between calibrations: calibrate fully).  The held PIGEs stay at the values in force: never
entered, never printed as a value.  An entry that adds (``x-rot-point: add …``) adds the change, never the value
again.

**The prediction** of what the entries leave at the tool counts every PIGE's uncertainty: the joint covariance of
the changes and of the held values' error (``θ_H``, the full calibration's ``Σ_H``), ``[[C, −KΣ_H], [−Σ_H Kᵀ,
Σ_H]]``, ``C`` the changes' covariance and ``K`` the check-up's sensitivity to its held values
(:class:`~pige_sym.identification.subset.SubsetFit`).

The check-up decides which values are entered; the compensation stage (:func:`pige_sym.compensation.stage.compensate`
with that decision) predicts what they leave and, with ``--controller``, writes the entries as ``pige compensate
--controller`` does (:attr:`Changes.compensation` is the stage's result object): entries that add, the changes;
absolute entries (pige's kinematics component) as the change to add to the value they hold, the held pins named;
``table`` the axis lines as the check-up finds them (the values in force plus the changes).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np


@dataclass
class Changes:
    """What to enter [µm, µrad] (module docstring).

    Attributes
    ----------
    entered : dict of str to float or None
        Per re-measured PIGE the change to enter (None: beyond ``--max-change``, not entered).
    why : dict of str to str
    in_force : dict of str to float
        Every location PIGE's value in force (what the controller holds).
    change : dict of str to float
        Per re-measured PIGE the measured change since its value in force (module docstring).
    held : dict of str to float
        The PIGEs the check-up held, at their values in force (never entered).
    names : list of str
        The order of ``covariance``: the re-measured PIGEs, then the held.
    covariance : ndarray, shape=(P, P)
        Joint covariance of the changes and the held values' error (module docstring).
    """

    entered: dict[str, float | None]
    why: dict[str, str]
    in_force: dict[str, float] = field(default_factory=dict)
    change: dict[str, float] = field(default_factory=dict)
    held: dict[str, float] = field(default_factory=dict)
    names: list[str] = field(default_factory=list)
    covariance: np.ndarray | None = field(default=None, repr=False)
    controller: str | None = None
    controller_text: str = ""
    notes: list[str] = field(default_factory=list)
    compensation: Any = None  # the compensation stage's result (pige_sym.compensation.result.Compensation)

    def std(self, name: str) -> float:
        """The standard error of a change (or of a held value's error) [µm, µrad]."""
        if self.covariance is None or name not in self.names:
            return math.nan
        i = self.names.index(name)
        return float(math.sqrt(max(self.covariance[i, i], 0.0)))

    def to_dict(self) -> dict[str, Any]:
        return {"entered": dict(self.entered), "why": dict(self.why), "in_force": dict(self.in_force),
                "change": dict(self.change), "change_std": {n: self.std(n) for n in self.change},
                "held": dict(self.held), "held_std": {n: self.std(n) for n in self.held},
                "controller": self.controller, "controller_text": self.controller_text or None,
                "notes": list(self.notes),
                "compensation": None if self.compensation is None else self.compensation.to_dict()}


def joint_covariance(fit: Any, held_covariance: np.ndarray) -> np.ndarray:
    """``[[C, −KΣ_H], [−Σ_H Kᵀ, Σ_H]]`` (module docstring), ``C`` the fit's covariance (its held values' error
    included)."""
    c = np.asarray(fit.covariance, dtype=float)
    sigma = np.asarray(held_covariance, dtype=float)
    if fit.sensitivity is None or sigma.size == 0:
        return c
    cross = -np.asarray(fit.sensitivity) @ sigma
    return np.block([[c, cross], [cross.T, sigma]])


def checkup_changes(fit: Any, m: Any, opts: Any, state: Any) -> Changes:
    """The changes of a check-up fit (module docstring); ``opts`` a :class:`~.routine.CheckupOptions`, ``state`` its
    :class:`~.reference.ChartState`."""
    from pige_sym.compensation.controllers.entry_checks import ChangeLimits
    from pige_sym.compensation.weighing import entered_values

    free = list(fit.parameters)
    change = np.asarray(fit.values, dtype=float) - np.array([state.level[n] for n in free])
    cov = joint_covariance(fit, state.held_covariance)
    weighed = entered_values(change, cov[: len(free), : len(free)])
    limits = ChangeLimits(*opts.max_change)
    entered: dict[str, float | None] = {}
    why: dict[str, str] = {}
    for name, x, c in zip(free, change, weighed, strict=True):
        bound = limits.bound(fit.units[name])
        if abs(c) > bound:
            entered[name] = None
            why[name] = (f"not entered: {c:+.4g} {fit.units[name]} is beyond --max-change ({bound:.4g}): no drift to "
                         "correct between calibrations; calibrate fully")
        else:
            entered[name] = float(c)
            share = c / x if x else 0.0
            why[name] = ("not entered: within its uncertainty" if c == 0.0 else "entered as measured"
                         if abs(share - 1.0) < 0.05 else f"entered in part ({share:.0%}): weakly determined")
    out = Changes(entered, why, dict(state.in_force), dict(zip(free, change.tolist(), strict=True)),
                  {n: state.in_force.get(n, 0.0) for n in state.held}, free + list(state.held), cov, opts.controller)
    if opts.controller:  # the stage writes the entries (without a controller there is nothing more to print)
        out.compensation = _compensation(fit, m, out, opts)
        out.controller_text = out.compensation.controller.text
    return out


def _compensation(fit: Any, m: Any, changes: Changes, opts: Any) -> Any:
    """The compensation stage on the check-up's decision (module docstring): the changes as parameters with their
    joint covariance, the re-measured PIGEs entered as decided, the held ones not (``table``: every value the value
    in force plus the change, the axis lines as the check-up finds them)."""
    from pige_sym.compensation.controllers import ControllerOptions
    from pige_sym.compensation.controllers.entry_checks import ChangeLimits
    from pige_sym.compensation.parameters import CompensationParameters
    from pige_sym.compensation.stage import Decision, compensate
    from pige_sym.kernels import load_kernels

    kern = load_kernels(fit.machine)
    names = changes.names
    absolute = opts.controller == "table"
    base = {n: changes.in_force.get(n, 0.0) if absolute else 0.0 for n in names}
    params = CompensationParameters(
        kern.MACHINE_CODE, {n: base[n] + changes.change.get(n, 0.0) for n in names}, {n: kern.UNITS[n] for n in names},
        None if m.tool_mm is None else [float(x) for x in m.tool_mm],
        {a: [float(x) for x in v] for a, v in m.pivots_mm.items()}, m.path or "the check-up", [],
        axis_sense=dict(m.axis_sense), std={n: changes.std(n) for n in names},
        covariance=(tuple(names), np.asarray(changes.covariance)), ball_mm=[float(x) for x in m.ball_mm],
        in_force=None if absolute else dict(changes.in_force), held=dict(changes.held))
    entered: dict[str, float | None] = {}
    for n in names:
        v = changes.entered.get(n)
        entered[n] = base[n] + (v or 0.0) if absolute else v
    held = {n: "held by the check-up at its value in force: not entered" for n in changes.held}
    options = ControllerOptions(carrier=opts.carrier, current=opts.current, heidenhain_trans=opts.heidenhain_trans,
                                limits=ChangeLimits(*opts.max_change))
    return compensate(params, controller=opts.controller, options=options,
                      decided=Decision(entered, dict(changes.why) | held))
