"""What a plan is asked (:class:`PlanRequest`) and what it is (:class:`Plan`): poses, schedule, predictions.

Angle file
----------
``# `` comment lines (machine, ball, criterion, predicted figures, how to use it), then
``t_s,<axis>_deg,...``; the first row is the reference pose; ``t_s`` follows the schedule of
:mod:`pige_sym.nc.rtest_program` (move, then dwell, per pose: :func:`schedule_times`).  ``pige program``,
``pige rtest-sim`` and ``pige acquire`` read it as a trajectory.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from pige_sym.errors import InputError
from pige_sym.model.trajectories import cone_frustum
from pige_sym.nc.rtest_program import DEFAULT_DWELL_S, DEFAULT_MOVE_S
from pige_sym.planning.families import (
    Limits,
)
from pige_sym.planning.prediction import (
    CRITERIA,
    Prediction,
    Setup,
)
from pige_sym.planning.reveal import RevealStatus

ROUND_DEG = 4


@dataclass
class PlanRequest:
    """What the user asks for.

    Attributes
    ----------
    setup : Setup
        Machine, ball (the start or fixed position), tool, noise, projection.
    points : int
        Measured poses after the reference pose.
    limits : Limits
    ball_region : dict of int to (float, float)
        Ball coordinate index (0 = x) -> range [mm] searched; empty: the ball stays.
    criterion : {"worst", "A", "D"}
    reveal : tuple of str
        Effects the test must be able to reveal.
    move_s, dwell_s : float [s]
        Schedule per pose (for the times and the duration).
    seed : int
    """

    setup: Setup
    points: int
    limits: Limits
    ball_region: dict[int, tuple[float, float]] = field(default_factory=dict)
    criterion: str = "worst"
    reveal: tuple[str, ...] = ()
    move_s: float = DEFAULT_MOVE_S
    dwell_s: float = DEFAULT_DWELL_S
    seed: int = 0

    def __post_init__(self) -> None:
        if self.criterion not in CRITERIA:
            raise InputError(f"unknown criterion {self.criterion!r}: use {', '.join(CRITERIA)}")
        if self.points < 3:
            raise InputError("a test needs at least 3 poses after the reference pose")


@dataclass
class Plan:
    """A planned (or graded) test with its predicted precision.

    Attributes
    ----------
    machine : str
    rotary_axes : tuple of str
    angles_deg : ndarray, shape=(n + 1, k) [deg]
        Row 0 is the reference pose.
    t_s : ndarray, shape=(n + 1,) [s]
    family : str
        Winning family (``graded`` for a graded test).
    description : str
    setup : Setup
    criterion : str
    prediction : Prediction
        PIGE-only model (what ``pige identify`` reports).
    baseline : Prediction or None
        Default cone, same points, noise and ball (None when the machine has no cone).
    default_setup_baseline : Prediction or None
        Default cone at the ``--ball`` position, when the ball was searched.
    reveal : dict of str to RevealStatus
    limits : Limits or None
    baseline_within_limits : bool or None
    planning_s : float or None
    duration_s : float [s]
        End of the last dwell under the test-program schedule.
    """

    machine: str
    rotary_axes: tuple[str, ...]
    angles_deg: np.ndarray
    t_s: np.ndarray
    family: str
    description: str
    setup: Setup
    criterion: str
    prediction: Prediction
    baseline: Prediction | None
    default_setup_baseline: Prediction | None
    reveal: dict[str, RevealStatus]
    limits: Limits | None = None
    baseline_within_limits: bool | None = None
    planning_s: float | None = None
    duration_s: float = 0.0

    @property
    def points(self) -> int:
        return int(self.angles_deg.shape[0] - 1)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary (undetermined parameters: ``None``, never a number)."""
        base = self.baseline
        out: dict[str, Any] = {
            "machine": self.machine, "family": self.family, "description": self.description,
            "criterion": self.criterion, "points": self.points, "noise_um": self.setup.noise_um,
            "projection": self.setup.projection.name if self.setup.projection else "xyz",
            "ball_mm": [float(x) for x in self.setup.ball_mm],
            "tool_mm": None if self.setup.tool_mm is None else [float(x) for x in self.setup.tool_mm],
            "std": self.prediction.std_dict(), "units": self.prediction.units,
            "undetermined": self.prediction.undetermined, "worst_std": self.prediction.worst,
            "condition": self.prediction.condition, "rank": self.prediction.rank,
            "baseline_std": None if base is None else base.std_dict(),
            "baseline_worst_std": None if base is None else base.worst,
            "baseline_within_limits": self.baseline_within_limits,
            "gain": None if base is None else base.worst / self.prediction.worst,
            "reveal": {k: v.to_dict() for k, v in self.reveal.items()},
            "duration_s": self.duration_s, "planning_s": self.planning_s,
            "limits": None if self.limits is None else self.limits.to_dict(),
            "angles_deg": {a: self.angles_deg[:, k].tolist() for k, a in enumerate(self.rotary_axes)},
        }
        if self.default_setup_baseline is not None:
            out["default_setup_baseline_std"] = self.default_setup_baseline.std_dict()
            out["default_setup_baseline_worst_std"] = self.default_setup_baseline.worst
        return out

    def angle_file_text(self) -> str:
        """The angle file (module docstring)."""
        ball = ",".join(f"{x:g}" for x in self.setup.ball_mm)
        base = self.baseline
        lines = [f"# pige plan: {self.machine}, {self.points} poses after the reference pose, criterion "
                 f"{self.criterion}, noise {self.setup.noise_um:g} um",
                 f"# ball_mm: {ball}  (give --ball {ball} to pige program / rtest-sim / acquire)",
                 f"# {self.description}",
                 f"# predicted worst std {self.prediction.worst:.4g} (default cone {base.worst:.4g})" if base
                 else f"# predicted worst std {self.prediction.worst:.4g}"]
        if self.setup.tool_mm is not None:
            lines.insert(2, f"# tool_mm: {','.join(f'{x:g}' for x in self.setup.tool_mm)}")
        lines.append(",".join(["t_s"] + [f"{a}_deg" for a in self.rotary_axes]))
        for t, row in zip(self.t_s, self.angles_deg, strict=True):
            lines.append(",".join([f"{t:.10g}"] + [f"{x:.{ROUND_DEG}f}" for x in row]))
        return "\n".join(lines) + "\n"


def schedule_times(n_rows: int, move_s: float, dwell_s: float) -> np.ndarray:
    """Arrival time of each pose under the test-program schedule, shape=(n_rows,) [s]."""
    return np.arange(n_rows) * (move_s + dwell_s)


def default_cone(setup: Setup, points: int) -> np.ndarray | None:
    """Angles of the default cone frustum with ``points`` poses, or None when the machine has none."""
    try:
        return cone_frustum(setup.machine, points=points).angles_deg
    except InputError:
        return None
