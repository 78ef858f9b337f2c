"""Error motions of a rotary axis as maps on an angle grid (CONVENTIONS §10): names, grids, columns.

For a rotary axis with nominal direction u, the body it carries moves, to first order, as

    x ↦ q + (I + [ρ(θ)]×) · R(u', s·(θ + E + φ(θ))) · (x − q) + τ(θ)

(τ [µm] translations, ρ [µrad] tilts ⟂ u, φ [µrad] positioning, all in the carrier's frame).  The
generated kernels' ``motion_jacobian`` holds, per rotary axis, the un-zeroed deviation per unit
translation ``dx, dy, dz`` and per unit small rotation ``rx, ry, rz`` of the carried body, applied after
the axis' own motion: the same SymPy model as the PIGEs (:mod:`pige_sym.codegen.symbolic`).  So

- τ's component along machine axis j is column ``d<j>``; ρ's about machine axis j is ``r<j>``;
- φ turns the body about u by s·φ: its column is ``s · r<u>`` (as :mod:`pige_sym.model.effects`'
  ``angular_error``, its one-harmonic case).

A map is values at grid angles θ_1 < … < θ_n [deg], linearly interpolated (hat functions): a pose at θ
takes ``Σ_g h_g(θ) v_g``.  The grid of a full-turn axis wraps from θ_n to θ_1 + 360°; outside the grid of
any other axis the nearest end value holds.  Here an axis turns fully when its letter is C (a rotary table
or a head's C), unless the caller says otherwise.

**What a map leaves out** (§10): φ its mean; each component of τ and ρ the span of 1, cos θ, sin θ.  The
reported map is the representative orthogonal to these over the grid points that have a value
(:func:`left_out_basis`, :func:`complement`).

**Per direction.** φ may be given per approach direction: φ± = φ ± r/2 with r the reversal error
``φ⁺ − φ⁻`` (kept whole, mean included).  A pose approached with θ increasing takes φ⁺, decreasing φ⁻.

Names (§10 table): ``E<X|Y|Z>`` + axis for translations (``EXC``), ``E<A|B|C>`` + axis for rotations
(``EAC``); the positioning motion is the rotation about the axis itself (``ECC``, ``EAA``).  The reversal
map is ``<positioning>+`` minus ``<positioning>-`` and is named ``ECC:reversal``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from pige_sym.errors import InputError

_XYZ = "XYZ"
#: Motion components of the kernels' ``motion_jacobian``, per rotary axis, in column order.
MOTION_COMPONENTS = ("dx", "dy", "dz", "rx", "ry", "rz")


@dataclass(frozen=True)
class Motion:
    """One error motion of one rotary axis (CONVENTIONS §10).

    Attributes
    ----------
    axis : str
        Rotary axis name (``C``, ``A``, ``C2``).
    name : str
        ``EXC`` … ``ECC``; ``ECC:reversal`` for the reversal map of φ.
    kind : str
        ``radial``, ``axial``, ``tilt``, ``positioning`` or ``reversal``.
    component : str
        The kernels' motion component (``dx`` … ``rz``); φ and its reversal use the rotation about u.
    unit : str
        ``um`` or ``urad``.
    """

    axis: str
    name: str
    kind: str
    component: str
    unit: str

    @property
    def left_out(self) -> int:
        """How many functions of the angle the map leaves out: 1 (φ's mean), 3 (1, cos, sin) or 0 (reversal)."""
        return {"positioning": 1, "reversal": 0}.get(self.kind, 3)


def axis_direction(axis: str) -> int:
    """Index (0, 1, 2) of the machine axis a rotary axis turns about (A → X, B → Y, C → Z)."""
    letter = axis[0].upper()
    if letter not in "ABC":
        raise InputError(f"{axis!r} is not a rotary axis (A, B or C)")
    return "ABC".index(letter)


def axis_motions(axis: str, *, per_direction: bool = False) -> list[Motion]:
    """The six error motions of ``axis`` in §10's table order (radial τ, axial τ, tilts ρ, positioning φ),
    and the reversal map of φ when ``per_direction``."""
    d = axis_direction(axis)
    suffix = axis[1:]
    letter = "ABC"[d]
    radial = [j for j in range(3) if j != d]
    out = [Motion(axis, f"E{_XYZ[j]}{letter}{suffix}", "radial", "d" + "xyz"[j], "um") for j in radial]
    out.append(Motion(axis, f"E{_XYZ[d]}{letter}{suffix}", "axial", "d" + "xyz"[d], "um"))
    out += [Motion(axis, f"E{'ABC'[j]}{letter}{suffix}", "tilt", "r" + "xyz"[j], "urad") for j in radial]
    out.append(Motion(axis, f"E{letter}{letter}{suffix}", "positioning", "r" + "xyz"[d], "urad"))
    if per_direction:
        out.append(Motion(axis, f"E{letter}{letter}{suffix}:reversal", "reversal", "r" + "xyz"[d], "urad"))
    return out


def is_full_turn(axis: str) -> bool:
    """Whether an axis' grid wraps (module docstring: C axes turn fully)."""
    return axis_direction(axis) == 2


@dataclass(frozen=True)
class MapGrid:
    """The angle grid of one axis' maps.

    Attributes
    ----------
    axis : str
    angles_deg : (n,) [deg]
        Increasing; a full-turn grid lies in [θ_1, θ_1 + 360°).
    full_turn : bool
    """

    axis: str
    angles_deg: np.ndarray
    full_turn: bool

    @property
    def n(self) -> int:
        return int(self.angles_deg.size)

    def hat(self, theta_deg: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The two grid nodes each angle lies between and their hat-function weights: ``(k0, k1, w0, w1)``, each
        shape=(m,) (node indices, weights summing to 1; ``k0 == k1`` on a grid of one node).  :meth:`weights` is
        this as a dense matrix; a map's value at the angle is ``w0·v[k0] + w1·v[k1]`` (linear in the angles, however
        fine the grid)."""
        theta = np.asarray(theta_deg, dtype=float).reshape(-1)
        g = self.angles_deg
        if self.full_turn:
            nodes = np.append(g, g[0] + 360.0)
            t = g[0] + np.mod(theta - g[0], 360.0)
        else:
            nodes = g
            t = np.clip(theta, g[0], g[-1])
        if nodes.size == 1:
            zero = np.zeros(t.size, dtype=int)
            return zero, zero, np.ones(t.size), np.zeros(t.size)
        k = np.clip(np.searchsorted(nodes, t, side="right") - 1, 0, nodes.size - 2)
        span = nodes[k + 1] - nodes[k]
        frac = np.clip((t - nodes[k]) / span, 0.0, 1.0)
        return k % g.size, (k + 1) % g.size, 1.0 - frac, frac

    def weights(self, theta_deg: np.ndarray) -> np.ndarray:
        """Hat-function weights of each angle on the grid nodes, shape=(m, n): rows sum to 1 (:meth:`hat`)."""
        k0, k1, w0, w1 = self.hat(theta_deg)
        w = np.zeros((k0.size, self.n))
        rows = np.arange(k0.size)
        np.add.at(w, (rows, k0), w0)
        np.add.at(w, (rows, k1), w1)
        return w

    def interpolate(self, values: np.ndarray, theta_deg: np.ndarray) -> np.ndarray:
        """Map values (n,) at the angles, shape=(m,) (§10 linear interpolation)."""
        return np.asarray(self.weights(theta_deg) @ np.asarray(values, dtype=float))


#: The grid steps a map may have [deg]: from half a degree to half a turn.
MAP_STEP_RANGE_DEG = (0.5, 180.0)


def check_map_step(step_deg: float, axis: str | None = None, *, full_turn: bool | None = None) -> int | None:
    """``--map-step``, the one check of ``pige identify``, ``plan`` and ``program`` (a number from 0.5 to 180 deg
    that, for a full-turn ``axis``, divides 360); returns the number of grid angles of a full turn (else None).

    Raises
    ------
    InputError
    """
    lo, hi = MAP_STEP_RANGE_DEG
    if isinstance(step_deg, bool) or not isinstance(step_deg, (int, float)) or not (
            np.isfinite(step_deg) and lo <= step_deg <= hi):
        raise InputError(f"--map-step {step_deg:g}: give a step from {lo:g} to {hi:g} degrees")
    if axis is None or not (is_full_turn(axis) if full_turn is None else full_turn):
        return None
    n = 360.0 / step_deg
    if abs(n - round(n)) > 1e-9:
        raise InputError(f"--map-step {step_deg:g}: the grid of the full-turn axis {axis} must divide 360 degrees")
    return int(round(n))


def make_grid(axis: str, step_deg: float, measured_deg: np.ndarray, *, full_turn: bool | None = None) -> MapGrid:
    """The grid of ``axis``: every ``step_deg`` from 0, over a full turn or over the measured angles.

    A full-turn axis gets 0, step, …, 360 − step (``step_deg`` must divide 360); any other axis the
    multiples of the step from the one at or below the smallest measured angle to the one at or above the
    largest.
    """
    n = check_map_step(step_deg, axis, full_turn=full_turn)
    if n is not None:
        return MapGrid(axis, np.arange(n) * step_deg, True)
    a = np.asarray(measured_deg, dtype=float)
    lo = np.floor(a.min() / step_deg + 1e-9) * step_deg
    hi = np.ceil(a.max() / step_deg - 1e-9) * step_deg
    return MapGrid(axis, np.arange(round((hi - lo) / step_deg) + 1) * step_deg + lo, False)


def left_out_basis(motion: Motion, angles_deg: np.ndarray) -> np.ndarray:
    """The functions a map of ``motion`` leaves out, at the given grid angles, shape=(n, 0…3)."""
    t = np.radians(np.asarray(angles_deg, dtype=float))
    cols = [np.ones_like(t), np.cos(t), np.sin(t)][: motion.left_out]
    return np.stack(cols, axis=1) if cols else np.zeros((t.size, 0))


def complement(motion: Motion, angles_deg: np.ndarray) -> np.ndarray:
    """Orthonormal basis of the maps orthogonal to the left-out functions over these angles, shape=(n, n − r).

    ``v = Q z`` spans exactly the representatives of §10; ``Q Qᵀ`` is the unweighted least-squares
    projection that removes the left-out functions.
    """
    b = left_out_basis(motion, angles_deg)
    n = b.shape[0]
    if b.shape[1] == 0:
        return np.eye(n)
    u, s, _ = np.linalg.svd(b, full_matrices=True)
    rank = int((s > 1e-9 * max(s.max(initial=0.0), 1.0)).sum())
    return np.asarray(u[:, rank:])


def representative(motion: Motion, angles_deg: np.ndarray, values: np.ndarray) -> np.ndarray:
    """A map's §10 representative: ``values`` without their left-out part (least squares over the angles)."""
    q = complement(motion, angles_deg)
    return np.asarray(q @ (q.T @ np.asarray(values, dtype=float)))


def motion_column(kernels: object, motion: Motion, raw: np.ndarray) -> np.ndarray:
    """The un-zeroed deviation per unit ``motion`` at every pose, shape=(n, 3) [µm per µm or µrad].

    ``raw`` is the kernels' ``motion_jacobian`` (n, 3, 6k); φ (and its reversal) turn the body by s·φ
    about u, s = −1 on the workpiece side.
    """
    axes = tuple(kernels.ROTARY_AXES)  # type: ignore[attr-defined]
    if motion.axis not in axes:
        raise InputError(f"machine {kernels.MACHINE_CODE} has no rotary axis {motion.axis!r}")  # type: ignore[attr-defined]
    j = 6 * axes.index(motion.axis) + MOTION_COMPONENTS.index(motion.component)
    col = raw[:, :, j]
    if motion.kind in ("positioning", "reversal"):
        sign = -1.0 if motion.axis in kernels.WORKPIECE_ROTARY else 1.0  # type: ignore[attr-defined]
        col = sign * col
    return np.asarray(col)


def pose_factor(motion: Motion, approach: np.ndarray) -> np.ndarray:
    """Per pose, how much of the map acts: 1, or ±1/2 of the reversal map by the direction of approach."""
    a = np.asarray(approach, dtype=float)
    return 0.5 * a if motion.kind == "reversal" else np.ones_like(a)


@dataclass(frozen=True)
class AxisMaps:
    """The maps of one axis: per motion name, its values on the grid (NaN: no value, nothing acts there).

    ``values`` may hold the positioning map per direction as ``<φ>+`` and ``<φ>-``; :meth:`motion_values`
    turns them into φ's mean and its reversal map.
    """

    grid: MapGrid
    values: dict[str, np.ndarray]

    def motion_values(self) -> list[tuple[Motion, np.ndarray]]:
        """(motion, values) of every motion the maps hold, φ± as the mean and the reversal (module docstring)."""
        motions = {m.name: m for m in axis_motions(self.grid.axis, per_direction=True)}
        out = [(motions[n], np.asarray(v, dtype=float)) for n, v in self.values.items() if n in motions]
        phi = next(m for m in motions.values() if m.kind == "positioning")
        plus, minus = self.values.get(phi.name + "+"), self.values.get(phi.name + "-")
        if plus is not None and minus is not None:
            p, m = np.asarray(plus, dtype=float), np.asarray(minus, dtype=float)
            out = [(mo, v) for mo, v in out if mo.kind not in ("positioning", "reversal")]
            out += [(phi, 0.5 * (p + m)), (motions[phi.name + ":reversal"], p - m)]
        return out


class MapAction(NamedTuple):
    """How one map of one axis acts at some poses (:meth:`ErrorMaps.acting`)."""

    axis: str
    name: str
    values: np.ndarray  # (n_grid,) [µm or µrad], NaN: no value
    column: int  # the kernels' motion column it drives
    factor: np.ndarray  # (m,) per pose: the direction of approach times the sense of φ
    hat: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]  # MapGrid.hat of the poses


@dataclass(frozen=True)
class ErrorMaps:
    """Error maps of some rotary axes of a machine (CONVENTIONS §10), axis → :class:`AxisMaps`."""

    axes: dict[str, AxisMaps]

    def to_dict(self) -> dict[str, Any]:
        """``{axis: {"angle_deg": [...], "full_turn": bool, <motion>: {"value": [...]}}}`` (``error_motions``)."""
        def listed(v: np.ndarray) -> list[float | None]:
            return [None if not np.isfinite(x) else float(x) for x in v]

        return {ax: {"angle_deg": m.grid.angles_deg.tolist(), "full_turn": m.grid.full_turn,
                     **{n: {"value": listed(v)} for n, v in m.values.items()}} for ax, m in self.axes.items()}

    def values(self) -> dict[str, float]:
        """Every map value with a number, named ``<axis>:<motion>@<angle>`` (``C:EXC@30``) [µm, µrad]."""
        return {f"{ax}:{n}@{g:g}": float(v) for ax, m in self.axes.items() for n, vals in m.values.items()
                for g, v in zip(m.grid.angles_deg, vals, strict=True) if np.isfinite(v)}

    def with_values(self, values: dict[str, float]) -> ErrorMaps:
        """The same grids holding ``values`` (named as :meth:`values`; a value not given has none)."""
        return ErrorMaps({ax: AxisMaps(m.grid, {n: np.array([values.get(f"{ax}:{n}@{g:g}", np.nan)
                                                             for g in m.grid.angles_deg]) for n in m.values})
                          for ax, m in self.axes.items()})

    def acting(self, kernels: Any, angles_deg: np.ndarray, approach: np.ndarray | None = None) -> list[MapAction]:
        """How each map acts at the poses (m of them), per axis and map name (:class:`MapAction`)."""
        from pige_sym.model.trajectories import approach_directions

        a = np.atleast_2d(np.asarray(angles_deg, dtype=float))
        appr = approach_directions(a) if approach is None else np.atleast_2d(approach)
        axes = tuple(kernels.ROTARY_AXES)
        out: list[MapAction] = []
        for ax, maps in self.axes.items():
            k = axes.index(ax)
            hat = maps.grid.hat(a[:, k])
            by_name = {m.name: m for m in axis_motions(ax, per_direction=True)}
            phi = next(m for m in by_name.values() if m.kind == "positioning")
            for name, vals in maps.values.items():
                motion = by_name.get(name, phi)
                if name in by_name:
                    direction = pose_factor(motion, appr[:, k])
                else:  # φ per direction: ECC+ acts approached with θ increasing, ECC- decreasing, half each at rest
                    direction = 0.5 * (1 + appr[:, k]) if name.endswith("+") else 0.5 * (1 - appr[:, k])
                sign = -1.0 if motion.kind in ("positioning", "reversal") and ax in kernels.WORKPIECE_ROTARY else 1.0
                out.append(MapAction(ax, name, np.asarray(vals, dtype=float),
                                     6 * k + MOTION_COMPONENTS.index(motion.component), sign * direction, hat))
        return out

    def value_weights(self, kernels: Any, angles_deg: np.ndarray, approach: np.ndarray | None = None,
                      ) -> tuple[list[str], Any, np.ndarray]:
        """How each map value acts: its name (:meth:`values`), its weight at each pose (m, V) as a sparse matrix
        (``scipy.sparse.csr_array``: two grid nodes per pose and map, interpolation, direction of approach and the sense
        of φ included) and the kernels' motion column it drives (V,)."""
        from scipy.sparse import coo_array

        names: list[str] = []
        comps: list[int] = []
        rows, cols, data = [], [], []
        n = np.atleast_2d(np.asarray(angles_deg, dtype=float)).shape[0]
        for ax, name, vals, comp, factor, (k0, k1, w0, w1) in self.acting(kernels, angles_deg, approach):
            column = np.full(vals.size, -1)
            finite = np.flatnonzero(np.isfinite(vals))
            column[finite] = len(names) + np.arange(finite.size)
            grid = self.axes[ax].grid.angles_deg
            names += [f"{ax}:{name}@{grid[g]:g}" for g in finite]
            comps += [comp] * finite.size
            for node, w in ((k0, w0), (k1, w1)):
                keep = np.flatnonzero(column[node] >= 0)
                rows.append(keep)
                cols.append(column[node][keep])
                data.append(factor[keep] * w[keep])
        shape = (n, len(names))
        if not names:
            return names, coo_array(shape).tocsr(), np.zeros(0, dtype=int)
        w = coo_array((np.concatenate(data), (np.concatenate(rows), np.concatenate(cols))), shape=shape)
        return names, w.tocsr(), np.array(comps, dtype=int)

    def pose_motions(self, kernels: Any, angles_deg: np.ndarray, approach: np.ndarray | None = None) -> np.ndarray:
        """The carried bodies' error motions at each pose in the kernels' columns (``MOTION_PARAMETERS``: per
        axis dx, dy, dz [µm], rx, ry, rz [µrad]), shape=(n, 6k); a value without a number adds nothing.  Two grid
        nodes per pose and map (:meth:`MapGrid.hat`): linear in the poses and in the map's values."""
        a = np.atleast_2d(np.asarray(angles_deg, dtype=float))
        out = np.zeros((a.shape[0], 6 * len(kernels.ROTARY_AXES)))
        for _, _, vals, comp, factor, (k0, k1, w0, w1) in self.acting(kernels, a, approach):
            v = np.where(np.isfinite(vals), vals, 0.0)
            out[:, comp] += factor * (w0 * v[k0] + w1 * v[k1])
        return out

    def raw_deviation(self, kernels: Any, angles_deg: np.ndarray, point_mm: Any, pivots_mm: Any = None,
                      tool_mm: Any = None, approach: np.ndarray | None = None) -> np.ndarray:
        """Un-zeroed tool point minus workpiece point the maps add at each pose, shape=(n, 3) [µm] (first
        order, through the kernels' error-motion columns)."""
        a = np.atleast_2d(np.asarray(angles_deg, dtype=float))
        raw = kernels.motion_jacobian(a, point_mm, pivots_mm, tool_mm)
        return np.asarray(np.einsum("nij,nj->ni", raw, self.pose_motions(kernels, a, approach)))

    def deviation(self, kernels: Any, angles_deg: np.ndarray, point_mm: Any, pivots_mm: Any = None,
                  tool_mm: Any = None, approach: np.ndarray | None = None) -> np.ndarray:
        """The same zeroed like an R-test or probe row (row 0 the reference pose), shape=(n, 3) [µm]."""
        raw = self.raw_deviation(kernels, angles_deg, point_mm, pivots_mm, tool_mm, approach)
        rot = kernels.workpiece_rotation(np.atleast_2d(np.asarray(angles_deg, dtype=float)))
        return np.asarray(raw - np.einsum("nij,j->ni", rot, raw[0]))


def error_maps_from(data: dict[str, Any] | None) -> ErrorMaps | None:
    """The validated ``error_motions`` of a file (:func:`pige_sym.measurements.error_motions_file.read_error_motions`:
    axis → ``{"angle_deg", "full_turn", "value", "std"}``) as :class:`ErrorMaps`; None when there are none.

    A positioning map given per direction (``ECC+`` and ``ECC-``) is kept as those two: the file's ``ECC`` and
    ``ECC:reversal`` beside them are their mean and difference (``pige identify --map-per-direction`` writes all
    four), and kept too they would correct φ twice.
    """
    if not data:
        return None
    return ErrorMaps({ax: AxisMaps(MapGrid(ax, np.asarray(m["angle_deg"], dtype=float), bool(m["full_turn"])),
                                   {n: np.asarray(v, dtype=float) for n, v in _primary_maps(ax, m["value"]).items()})
                      for ax, m in data.items()})


def _primary_maps(axis: str, values: dict[str, Any]) -> dict[str, Any]:
    """``values`` without φ and its reversal where φ⁺ and φ⁻ are given (:func:`error_maps_from`)."""
    phi = next(m.name for m in axis_motions(axis) if m.kind == "positioning")
    if phi + "+" in values and phi + "-" in values:
        return {n: v for n, v in values.items() if n not in (phi, phi + ":reversal")}
    return dict(values)
