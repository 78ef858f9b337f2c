"""Ballbar setups (ISO 10791-6 style rotary-axis tests) and their exact simulation.

A setup sweeps one rotary axis with the others held, the table ball at ``table_ball_mm`` and the tool ball
at ``table_ball + offset``; the offset is ``L0`` along the setup's direction at the table ball:

- ``radial``: away from the swept axis line (perpendicular to it, through the table ball);
- ``tangential``: along the table ball's motion (axis direction × radial);
- ``axial``: along the swept axis.

Sweeps: the rotary-table axis (C) turns 0 → 360° in 10° steps with the tilt axis at ``tilt_deg``; the tilt
axis (A or B) sweeps 0 → ``tilt_range`` in 5° steps with C at 0.  :func:`simulate_ballbar` computes the
length exactly, ``|T − P| − L0`` with ``T`` the commanded tool ball (the nominal position of the table point
``table_ball + offset``, linear axes perfect) and ``P`` the true table ball
(:mod:`pige_sym.simulation.exact_table`), plus Gaussian noise; ``zero: relative`` subtracts the first reading.

Error maps (CONVENTIONS §10) are added to first order un-zeroed, as the PIGEs' exact length is (an absolute
file's bar knows its length at the reference pose too; a relative file subtracts its first reading).  Effects
beyond the PIGEs (:mod:`pige_sym.model.effects`) are added to first order: the R-test deviation they cause at
the tool ball's table point ``Q = table_ball + offset`` (ball minus table point, zeroed at the reference pose
as R-test data are), projected on the bar direction
``n_i = R_w(θ_i)·offset/L0``.  To first order the bar sees ``n_i·(δT − δP)`` and ``T − P = d(Q) + (Q − P)``
turned by the table, whose length a rotation does not change; zeroing at the reference pose removes
``n_i·R_w(θ_i)·d_raw(0) = n_0·d_raw(0)``, the same constant at every pose, so a ``relative`` file is exact to
first order and an ``absolute`` file counts the effects from the reference pose (where the bar was set).
``outliers`` add their size along a random direction, projected.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pige_sym.errors import InputError
from pige_sym.kernels import load_kernels
from pige_sym.measurements.ballbar import SETUPS, BallbarRun, bar_directions
from pige_sym.model.effects import EffectContext, EffectInstance
from pige_sym.model.error_motions import ErrorMaps
from pige_sym.simulation.exact_table import nominal_table_point, table_point
from pige_sym.simulation.simulator import add_effects

DEFAULT_TABLE_BALL_MM = (100.0, 0.0, 50.0)
DEFAULT_LENGTH_MM = 100.0


@dataclass(frozen=True)
class BallbarSetup:
    """One setup: kind, swept axis, geometry [mm] and poses [deg]."""

    kind: str
    axis: str
    table_ball_mm: np.ndarray
    offset_mm: np.ndarray
    angles_deg: np.ndarray
    rotary_axes: tuple[str, ...]

    @property
    def label(self) -> str:
        return f"{self.kind} {self.axis}"


def ballbar_setup(machine: str, kind: str, axis: str, *, table_ball_mm: tuple[float, float, float] =
                  DEFAULT_TABLE_BALL_MM, length_mm: float = DEFAULT_LENGTH_MM, tilt_deg: float = 0.0,
                  tilt_range_deg: float = -90.0) -> BallbarSetup:
    """The setup of ``kind`` sweeping ``axis`` (module docstring).

    Raises
    ------
    InputError
        Unknown kind or axis, a tool-side axis, or a table ball on the swept axis line (no radius).
    """
    kern = load_kernels(machine)
    axes = tuple(kern.ROTARY_AXES)
    if kind not in SETUPS:
        raise InputError(f"--setup {kind!r}: use {', '.join(SETUPS)}")
    if axis not in axes or axis not in kern.WORKPIECE_ROTARY or kern.TOOL_ROTARY:
        raise InputError(f"--axis {axis}: ballbar setups sweep a workpiece-side rotary axis of a table machine "
                         f"({', '.join(axes)} on {kern.MACHINE_CODE})")
    u = np.eye(3)["ABC".index(axis[0])]
    p = np.asarray(table_ball_mm, dtype=float)
    radial = p - (p @ u) * u
    if np.linalg.norm(radial) < 1.0:
        raise InputError(f"the table ball {p.tolist()} lies on the {axis} axis line: give --table-ball off it")
    radial /= np.linalg.norm(radial)
    direction = {"radial": radial, "tangential": np.cross(u, radial), "axial": u}[kind]
    if axis[0] == "C":
        sweep = np.arange(0.0, 360.0 + 1e-9, 10.0)
        other = [tilt_deg for a in axes if a != axis]
        angles = np.column_stack([sweep if a == axis else np.full(sweep.size, other[0]) for a in axes])
    else:
        step = 5.0 if tilt_range_deg >= 0 else -5.0
        sweep = np.arange(0.0, tilt_range_deg + step / 2, step)
        angles = np.column_stack([sweep if a == axis else np.zeros(sweep.size) for a in axes])
    return BallbarSetup(kind, axis, p, length_mm * direction, angles, axes)


def effect_lengths(machine: str, setup: BallbarSetup, effects: list[EffectInstance], t_s: np.ndarray,
                   rng: np.random.Generator) -> tuple[np.ndarray, list[int]]:
    """Length change the effects add at each pose, shape=(n,) [µm], and the rows given an outlier.

    First order (module docstring): the zeroed R-test deviation at ``table_ball + offset`` projected on the
    bar direction at each pose.
    """
    kern = load_kernels(machine)
    point = setup.table_ball_mm + setup.offset_mm
    ctx = EffectContext(kern, setup.angles_deg, t_s, point)
    dev, outlier_rows = add_effects(np.zeros((setup.angles_deg.shape[0], 3)), effects, ctx, rng)
    return np.einsum("ni,ni->n", bar_directions(ctx.rot_w, setup.offset_mm), dev), outlier_rows


def simulate_ballbar(machine: str, setup: BallbarSetup, *, pige: dict[str, float], noise_um: float = 0.2,
                     seed: int | None = None, zero: str = "relative",
                     effects: list[EffectInstance] | None = None, error_maps: ErrorMaps | None = None) -> BallbarRun:
    """The file a setup produces on a machine with errors ``pige`` [µm, µrad], ``effects`` and ``error_maps``.

    The PIGEs' length is exact (``|T − P| − L0``), the effects' and the maps' first order (module docstring).
    """
    return simulate_ballbar_with_outliers(machine, setup, pige=pige, noise_um=noise_um, seed=seed, zero=zero,
                                          effects=effects, error_maps=error_maps)[0]


def simulate_ballbar_with_outliers(machine: str, setup: BallbarSetup, *, pige: dict[str, float],
                                   noise_um: float = 0.2, seed: int | None = None, zero: str = "relative",
                                   effects: list[EffectInstance] | None = None,
                                   error_maps: ErrorMaps | None = None) -> tuple[BallbarRun, list[int]]:
    """:func:`simulate_ballbar` and the rows that received an ``outliers`` effect (for the truth sidecar)."""
    kern = load_kernels(machine)
    rng = np.random.default_rng(seed)
    tool = nominal_table_point(kern.MACHINE_CODE, setup.angles_deg, setup.table_ball_mm + setup.offset_mm)
    ball = table_point(kern.MACHINE_CODE, setup.angles_deg, setup.table_ball_mm, pige)
    length = float(np.linalg.norm(setup.offset_mm))
    n = setup.angles_deg.shape[0]
    t = np.arange(n, dtype=float) * 2.0
    dl = (np.linalg.norm(tool - ball, axis=1) - length) * 1e3
    outlier_rows: list[int] = []
    if effects:
        extra, outlier_rows = effect_lengths(kern.MACHINE_CODE, setup, effects, t, rng)
        dl = dl + extra
    if error_maps is not None:  # un-zeroed, as the PIGEs' exact length: an absolute file counts the reference pose
        point = setup.table_ball_mm + setup.offset_mm
        dev = error_maps.raw_deviation(kern, setup.angles_deg, point)
        dl = dl + np.einsum("ni,ni->n", bar_directions(kern.workpiece_rotation(setup.angles_deg), setup.offset_mm), dev)
    dl = dl + rng.normal(0.0, noise_um, n)
    if zero == "relative":
        dl = dl - dl[0]
    meta = {"setup": setup.kind, "axis": setup.axis, "source": "pige simulate --instrument ballbar",
            "trajectory": f"{setup.label} sweep, {n} poses"}
    run = BallbarRun(kern.MACHINE_CODE, setup.table_ball_mm.copy(), setup.offset_mm.copy(), zero, t,
                     setup.angles_deg.copy(), setup.rotary_axes, dl, meta)
    return run, outlier_rows
