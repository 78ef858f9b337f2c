"""R-test test trajectories: rotary angles (and times) for any machine with rotary axes.

Every trajectory starts with the reference pose (all rotary angles 0, t = 0).

Definitions (they reproduce the reference datasets' angles exactly):

``cone-frustum`` (ISO 10791-6 BK type, NAS 979)
    The tool direction in the workpiece frame sweeps a cone of half angle α about the
    cone axis ``a`` = workpiece Z rotated by the inclination ι about ``incl_axis``
    (right-handed).  Point j of n per turn: ``v = cos α·a + sin α·(cos φ e1 + sin φ e2)``,
    ``φ = 2πj/n`` (j = 0 … n·turns − 1), ``e1`` = workpiece X made normal to ``a``,
    ``e2 = a × e1``.  Angles from the machine's closed-form inverse (``branch`` picks the
    tilt sign; the other axis is unwrapped to move continuously).
``figure-eight``
    RTCP 8-shape: ``tilt = amp_tilt·sin(2φ + phase)``, ``rotary = amp_rotary·sin φ``,
    φ = 2πj/n, j = 0 … n − 1 (row j = 0 repeats the reference pose).
``steps`` (ISO 10791-6 K4 style)
    At each tilt of the tilt axis, the rotary axis steps forward from 0 to
    ``360 − step`` and back to 0, so every position is approached from both sides.

The *rotary* axis is the one parallel to the spindle (C for a Z spindle), the *tilt*
axis the other one.  Times follow a dwell model: each point after the reference takes
``move_s + dwell_s`` (defaults 5 s + 5 s, the paper's 5 s measurement dwell), or
``max|Δθ|/feed_deg_s + dwell_s`` when a feed is given.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from typing import Any

import numpy as np

from pige_sym.errors import InputError
from pige_sym.kernels import load_kernels
from pige_sym.measurements.rtest import read_angle_file

NAMES = ("cone-frustum", "figure-eight", "steps")


@dataclass
class Trajectory:
    """Rotary angles of a test.

    Attributes
    ----------
    name : str
    rotary_axes : tuple of str
        Column order of ``angles_deg``.
    angles_deg : ndarray, shape=(n, k) [deg]
    t_s : ndarray, shape=(n,) [s]
    description : str
        Text for the file's ``trajectory:`` metadata.
    """

    name: str
    rotary_axes: tuple[str, ...]
    angles_deg: np.ndarray
    t_s: np.ndarray
    description: str

    @property
    def approach(self) -> np.ndarray:
        """Direction of approach of each axis per row (+1, −1; 0 before the first move), shape=(n, k)."""
        return approach_directions(self.angles_deg)


def approach_directions(angles_deg: np.ndarray) -> np.ndarray:
    """Sign of the last non-zero move of each axis, shape=(n, k) of {−1, 0, +1}."""
    a = np.asarray(angles_deg, dtype=float)
    out = np.zeros(a.shape, dtype=int)
    if a.shape[0] < 2:
        return out
    step = np.sign(np.diff(a, axis=0)).astype(int)
    rows = np.arange(1, a.shape[0]).reshape((-1,) + (1,) * (a.ndim - 1))
    last = np.maximum.accumulate(np.where(step != 0, rows, 0), axis=0)  # row of the last move, 0 = none yet
    out[1:] = np.take_along_axis(np.concatenate([np.zeros_like(step[:1]), step]), last, axis=0)
    return out


def dwell_times(angles_deg: np.ndarray, *, move_s: float = 5.0, dwell_s: float = 5.0,
                feed_deg_s: float | None = None) -> np.ndarray:
    """Times of the points under the dwell model, shape=(n,) [s]; the first is 0."""
    a = np.asarray(angles_deg, dtype=float)
    if move_s < 0 or dwell_s < 0:
        raise InputError("move_s and dwell_s must be >= 0")
    if feed_deg_s is not None:
        if feed_deg_s <= 0:
            raise InputError("feed_deg_s must be > 0")
        moves = np.abs(np.diff(a, axis=0)).max(axis=1) / feed_deg_s
    else:
        moves = np.full(a.shape[0] - 1, move_s)
    return np.concatenate([[0.0], np.cumsum(moves + dwell_s)])


def _roles(kern: Any) -> tuple[int, int]:
    """(tilt index, rotary index) in ROTARY_AXES."""
    axes = kern.ROTARY_AXES
    if len(axes) != 2:
        raise InputError(
            f"machine {kern.MACHINE_CODE} has {len(axes)} rotary axis/axes: this trajectory needs two; "
            "use 'steps' or an angle file"
        )
    spindle = "ABC"[kern.SPINDLE_DIRECTION]
    parallel = [i for i, a in enumerate(axes) if a[0] == spindle]
    rot = parallel[0] if len(parallel) == 1 else 1
    return 1 - rot, rot


def cone_frustum(machine: str, *, half_angle: float = 30.0, incl: float = 10.0, incl_axis: str = "X",
                 points: int = 30, turns: float = 1.0, branch: int = 1, move_s: float = 5.0,
                 dwell_s: float = 5.0, feed_deg_s: float | None = None) -> Trajectory:
    """Cone-frustum (BK-type) trajectory; see the module docstring for the definition.

    Parameters
    ----------
    machine : str
        Machine structure code (two rotary axes).
    half_angle, incl : float [deg]
    incl_axis : {"X", "Y"}
    points : int
        Points per turn.
    turns : float
    branch : {+1, −1}
        Sign of the tilt-axis solution.
    """
    kern = load_kernels(machine)
    _roles(kern)
    if not kern.HAS_DIRECTION_SOLVER:
        raise InputError(f"machine {kern.MACHINE_CODE} has no closed-form tool-direction inverse")
    ax = incl_axis.upper()
    if ax not in ("X", "Y"):
        raise InputError(f"incl_axis must be X or Y, got {incl_axis!r}")
    if points < 3 or turns <= 0:
        raise InputError("points must be >= 3 and turns > 0")
    if not 0 < half_angle < 90:
        raise InputError("half_angle must be between 0 and 90 degrees")
    v = cone_directions(half_angle, incl, ax, points, int(round(points * turns)))
    angles = kern.angles_for_direction(v, branch=branch)
    angles = np.vstack([np.zeros(len(kern.ROTARY_AXES)), angles])
    desc = f"cone-frustum half_angle={half_angle:g} incl={incl:g} incl_axis={ax} turns={float(turns)!r}"
    return Trajectory("cone-frustum", kern.ROTARY_AXES, angles,
                      dwell_times(angles, move_s=move_s, dwell_s=dwell_s, feed_deg_s=feed_deg_s), desc)


def cone_directions(half_angle: float, incl: float, incl_axis: str, points: int, count: int) -> np.ndarray:
    """Unit tool directions of the cone frustum (module docstring), shape=(count, 3).

    Parameters
    ----------
    half_angle, incl : float [deg]
    incl_axis : {"X", "Y"}
        Upper case, checked by the caller.
    points : int
        Points per turn.
    count : int
        Points in all (``points · turns``).
    """
    iota = math.radians(incl)
    if incl_axis == "X":
        a = np.array([0.0, -math.sin(iota), math.cos(iota)])
    else:
        a = np.array([math.sin(iota), 0.0, math.cos(iota)])
    e1 = np.array([1.0, 0.0, 0.0]) - a[0] * a
    e1 /= math.sqrt(float(e1 @ e1))
    e2 = np.array([a[1] * e1[2] - a[2] * e1[1], a[2] * e1[0] - a[0] * e1[2], a[0] * e1[1] - a[1] * e1[0]])
    phi = 2 * np.pi * np.arange(count) / points
    alpha = math.radians(half_angle)
    return math.cos(alpha) * a + math.sin(alpha) * (np.cos(phi)[:, None] * e1 + np.sin(phi)[:, None] * e2)


def figure_eight(machine: str, *, amp_tilt: float = 30.0, amp_rotary: float = 60.0, phase_deg: float = 0.0,
                 points: int = 30, move_s: float = 5.0, dwell_s: float = 5.0,
                 feed_deg_s: float | None = None) -> Trajectory:
    """8-shaped RTCP trajectory (1:2 Lissajous of the two rotary axes).

    Parameters
    ----------
    amp_tilt, amp_rotary : float [deg]
        Amplitudes of the tilt axis (double frequency) and of the rotary axis.
    phase_deg : float [deg]
        Phase of the tilt motion.
    points : int
    """
    kern = load_kernels(machine)
    tilt, rot = _roles(kern)
    if points < 4:
        raise InputError("points must be >= 4")
    phi = 2 * np.pi * np.arange(points) / points
    angles = np.zeros((points + 1, 2))
    angles[1:, tilt] = amp_tilt * np.sin(2 * phi + np.radians(phase_deg))
    angles[1:, rot] = amp_rotary * np.sin(phi)
    names = kern.ROTARY_AXES
    desc = f"figure-eight amp_{names[tilt]}={amp_tilt:.1f} amp_{names[rot]}={amp_rotary:.1f}"
    if phase_deg:
        desc += f" phase={phase_deg:g}"
    return Trajectory("figure-eight", names, angles,
                      dwell_times(angles, move_s=move_s, dwell_s=dwell_s, feed_deg_s=feed_deg_s), desc)


def steps(machine: str, *, step_deg: float = 30.0, tilts: tuple[float, ...] = (0.0, -30.0, -60.0),
          move_s: float = 5.0, dwell_s: float = 5.0, feed_deg_s: float | None = None) -> Trajectory:
    """Stepped sweeps of the rotary axis forward and back at several tilts (K4 style).

    For a machine with one rotary axis, that axis is swept and ``tilts`` is ignored.
    """
    kern = load_kernels(machine)
    k = len(kern.ROTARY_AXES)
    if step_deg <= 0 or 360 % step_deg > 1e-9 and abs(360 % step_deg - step_deg) > 1e-9:
        raise InputError(f"step_deg must divide 360, got {step_deg:g}")
    fwd = np.arange(0.0, 360.0 - 1e-9, step_deg)
    sweep = np.concatenate([fwd, fwd[-2::-1]])
    rows = [np.zeros(k)]
    if k == 1:
        rows += [np.array([c]) for c in sweep]
        tilt_list: tuple[float, ...] = ()
    else:
        tilt, rot = _roles(kern)
        tilt_list = tilts
        for t in tilts:
            for c in sweep:
                r = np.zeros(k)
                r[tilt], r[rot] = t, c
                rows.append(r)
    angles = np.array(rows)
    rot_name = kern.ROTARY_AXES[-1] if k == 1 else kern.ROTARY_AXES[_roles(kern)[1]]
    desc = (f"stepped {rot_name} sweeps forward and back at tilts " + "/".join(f"{t:g}" for t in tilt_list)
            + f" step={step_deg:g}")
    return Trajectory("steps", kern.ROTARY_AXES, angles,
                      dwell_times(angles, move_s=move_s, dwell_s=dwell_s, feed_deg_s=feed_deg_s), desc)


def from_angle_file(machine: str, path: str | os.PathLike[str], *, move_s: float = 5.0,
                    dwell_s: float = 5.0) -> Trajectory:
    """Trajectory from a CSV of angles (``<axis>_deg`` columns, optional ``t_s``).

    The reference pose is prepended when the file does not start with it.
    """
    kern = load_kernels(machine)
    axes, angles, t = read_angle_file(path)
    if set(axes) != set(kern.ROTARY_AXES):
        raise InputError(f"{path}: angle columns {axes} do not match the rotary axes {kern.ROTARY_AXES} of "
                         f"{kern.MACHINE_CODE}")
    order = [axes.index(a) for a in kern.ROTARY_AXES]
    angles = angles[:, order]
    if np.abs(angles[0]).max() > 0:
        angles = np.vstack([np.zeros(len(order)), angles])
        if t is not None:
            t = np.concatenate([[0.0], t + (move_s + dwell_s if t[0] == 0 else 0.0)])
    times = t if t is not None else dwell_times(angles, move_s=move_s, dwell_s=dwell_s)
    return Trajectory("file", kern.ROTARY_AXES, angles, np.asarray(times, dtype=float), f"file {path}")


def make_trajectory(machine: str, spec: str, **options: Any) -> Trajectory:
    """Trajectory by name (``cone-frustum``, ``figure-eight``, ``steps``) or angle-file path."""
    if spec == "cone-frustum":
        return cone_frustum(machine, **options)
    if spec == "figure-eight":
        return figure_eight(machine, **options)
    if spec == "steps":
        return steps(machine, **options)
    if os.path.exists(spec):
        return from_angle_file(machine, spec, **{k: v for k, v in options.items() if k in ("move_s", "dwell_s")})
    raise InputError(f"unknown trajectory {spec!r}: use one of {', '.join(NAMES)} or an existing angle CSV file")
