"""Identification of the rotary axes' error maps (CONVENTIONS §10) jointly with the PIGEs, from several files.

``pige identify FILE… --map C,A [--map-step 15]``: R-test runs, probe imports and ballbar setups of one
machine, in any mix (:mod:`~pige_sym.identification.joint` builds each file's block).  The unknowns:

- the PIGEs and the zero-position errors (the zero-position errors always: a map's φ leaves out its mean);
- per mapped axis, each error motion of :func:`~pige_sym.model.error_motions.axis_motions` at every grid
  angle (the values of a map); a pose between two grid angles takes their linear interpolation;
- each file's constants (:mod:`~pige_sym.identification.joint`).

The map columns are the generated kernels' error-motion columns (``motion_jacobian``, the same SymPy model
as the PIGEs) times the grid's hat functions, zeroed like the data.

**What each setup sees** (§10): one measured point gives three numbers per angle, the motions have six.
Before the joint fit, every grid angle's motions are tested alone (the other values held): the
combinations the rows near that angle do not see (a null direction of their scaled columns, as the PIGEs'
rule) take the values they touch out of the map — those values are ``null``, with the combination and what
would determine it.  They stay in the fit as free unknowns (not reported), so they take what they explain
and nothing else.

**The §10 projection.** The values that remain are fitted as ``v = Q z`` with Q an orthonormal basis of
the maps orthogonal to the left-out functions over those angles (:func:`~pige_sym.model.error_motions.
complement`): the PIGEs keep their meaning, and the reported map is the §10 representative.  Its
covariance is ``Q Σ_z Qᵀ``.  A z the joint fit still cannot determine (the PIGEs' null-direction rule)
leaves its motion's map undetermined.

**Weights.** Each file's rows are divided by its noise σ, estimated in two passes: first from its own
PIGE fit, then from its share of the joint map fit's residual (its RSS over its rows times the fit's
degrees of freedom per row), so a file is not down-weighted for the map signal it carries.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from pige_sym.errors import InputError
from pige_sym.identification.joint import (
    Block,
    JointResult,
    ballbar_block,
    common_machine,
    identify_blocks,
    measurement_block,
    own_sigma,
    whitened_system,
)
from pige_sym.identification.map_check import MapLayout, Undetermined, direction_notes, local_check, range_notes
from pige_sym.identification.map_reasons import NotIdentifiable, explain, held_axes, measured_points
from pige_sym.identification.map_statistics import pige_statistics, value_covariance
from pige_sym.identification.problem import ExtraColumns
from pige_sym.identification.result import IdentificationResult, json_float
from pige_sym.kernels import load_kernels
from pige_sym.measurements.ballbar import BallbarRun, bar_directions
from pige_sym.measurements.measurement import Measurement
from pige_sym.model.error_motions import (
    MapGrid,
    Motion,
    axis_motions,
    complement,
    left_out_basis,
    make_grid,
    motion_column,
    pose_factor,
)
from pige_sym.model.trajectories import approach_directions

#: Default grid step of ``--map-step`` [deg].
DEFAULT_MAP_STEP_DEG = 15.0


@dataclass(frozen=True)
class MapSpec:
    """What to map: axes, grid step [deg], and the axes whose φ is mapped per approach direction."""

    axes: tuple[str, ...]
    step_deg: float = DEFAULT_MAP_STEP_DEG
    per_direction: tuple[str, ...] = ()


@dataclass
class AxisMap:
    """The maps of one axis: per motion, values and standard errors on the grid (NaN where undetermined).

    Attributes
    ----------
    grid : MapGrid
    motions : list of Motion
    value, std : dict of str to ndarray, shape=(n,) [µm or µrad]
    covariance : dict of str to ndarray, shape=(n, n)
        Per motion, the covariance of its determined values (NaN rows elsewhere).
    """

    grid: MapGrid
    motions: list[Motion]
    value: dict[str, np.ndarray]
    std: dict[str, np.ndarray]
    covariance: dict[str, np.ndarray] = field(default_factory=dict, repr=False)

    def directions(self) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        """``<φ>+`` and ``<φ>-`` (value, std) per approach direction, where φ is mapped per direction."""
        return {k: (self.value[k], self.std[k]) for k in self.value if k.endswith(("+", "-"))}

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"angle_deg": [float(a) for a in self.grid.angles_deg], "full_turn": self.grid.full_turn}
        for m in self.motions:
            out[m.name] = {"value": [json_float(v) for v in self.value[m.name]],
                           "std": [json_float(v) for v in self.std[m.name]], "unit": m.unit, "kind": m.kind}
        for name, (v, s) in self.directions().items():
            out[name] = {"value": [json_float(x) for x in v], "std": [json_float(x) for x in s], "unit": "urad",
                         "kind": "positioning, approached with the angle " + (
                             "increasing" if name.endswith("+") else "decreasing")}
        return out


@dataclass
class MapResult:
    """PIGEs, zero-position errors and error maps of one machine from a joint fit."""

    joint: JointResult
    maps: dict[str, AxisMap]
    undetermined: list[Undetermined]
    spec: MapSpec
    covariance: tuple[list[str], np.ndarray] | None = field(default=None, repr=False)
    not_identifiable: list[NotIdentifiable] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)

    @property
    def result(self) -> IdentificationResult:
        return self.joint.result

    def to_dict(self) -> dict[str, Any]:
        """The JSON of ``pige identify --map``: the PIGEs (as a PIGE fit writes them), ``error_motions``,
        ``map_undetermined`` and the ``covariance`` of the PIGEs and the map values when it is small enough
        (:mod:`~pige_sym.identification.map_statistics`), else of the PIGEs."""
        cov = ({"parameters": self.covariance[0], "matrix": self.covariance[1].tolist()}
               if self.covariance is not None else self.joint.result.covariance_dict())
        return self.joint.to_dict() | {
            "covariance": cov,
            "method": "joint-map",
            "error_motions": {ax: m.to_dict() for ax, m in self.maps.items()},
            "map_step_deg": self.spec.step_deg,
            "map_undetermined": [u.to_dict() for u in self.undetermined],
            "not_identifiable": [r.to_dict() for r in self.not_identifiable],
            "map_notes": list(self.notes),
        }


def identify_maps(items: Sequence[tuple[str, Measurement | BallbarRun]], spec: MapSpec) -> MapResult:
    """The joint fit of PIGEs, zero-position errors and maps (module docstring).

    Raises
    ------
    InputError
        An axis the machine does not have, or files of different machines.
    """
    machine, names, layout, blocks = map_blocks(items, spec)
    p = len(names)
    pige_only = [_without_maps(b, p) for b in blocks]
    sigmas = [own_sigma(b) for b in pige_only]
    zeros = identify_blocks(machine, names, pige_only, sigmas, items).result
    fitted_zero = [j for j in range(p) if j < n_location(machine) or np.isfinite(zeros.values[j])]
    design = design_maps(names, layout, blocks, sigmas, fitted_zero)
    joint = identify_blocks(machine, design.shared, design.blocks, sigmas, items)
    sigmas = _refined_sigmas(joint, design.blocks)
    joint = identify_blocks(machine, design.shared, design.blocks, sigmas, items)
    maps, more = map_values(joint.result.values, joint.result.covariance, layout, design.groups)
    stats = pige_statistics(joint, design.blocks, sigmas, len(fitted_zero), len(names))
    covariance = value_covariance(joint.result, layout, design.groups, maps, names, fitted_zero)
    part = _pige_part(joint, names, fitted_zero, zeros, stats)
    reasons = explain(load_kernels(machine), names, part.result.values, part.result.unidentifiable,
                      held_axes(layout, design.undetermined), measured_points(items, load_kernels(machine)))
    part.result.unidentifiable = [r.text() for r in reasons]
    notes = range_notes(layout) + direction_notes(items, layout, spec, tuple(load_kernels(machine).ROTARY_AXES))
    return MapResult(part, maps, design.undetermined + more, spec, covariance, reasons, notes)


def n_location(machine: str) -> int:
    """How many PIGEs (location errors) the machine has: the first columns of :func:`map_blocks`' names."""
    return len(load_kernels(machine).LOCATION_PARAMETERS)


def map_blocks(items: Sequence[tuple[str, Measurement | BallbarRun]],
               spec: MapSpec) -> tuple[str, list[str], MapLayout, list[Block]]:
    """The machine, the names of the PIGEs and zero-position errors, the maps' layout and every file's block
    (those columns, then the map columns) of the joint map fit.

    Raises
    ------
    InputError
        An axis the machine does not have, or files of different machines.
    """
    machine = common_machine(items)
    kern = load_kernels(machine)
    bad = [a for a in spec.axes if a not in kern.ROTARY_AXES]
    if bad or not spec.axes:
        raise InputError(f"--map {','.join(spec.axes) or '(none)'}: give rotary axes of {machine} "
                         f"({', '.join(kern.ROTARY_AXES)})")
    layout = _layout(items, spec, tuple(kern.ROTARY_AXES), tuple(kern.TOOL_ROTARY))
    names = list(kern.LOCATION_PARAMETERS) + list(kern.ZERO_PARAMETERS)
    return machine, names, layout, [_block(x, lab, layout, kern) for lab, x in items]


@dataclass
class MapDesign:
    """The joint map fit's system before anything is solved: what :func:`identify_maps` fits and the planner
    predicts from (:mod:`pige_sym.identification.map_design`).

    Attributes
    ----------
    shared : list of str
        The fitted columns: the PIGEs and zero-position errors fitted, z per motion, the left-out functions,
        the held values.
    blocks : list of Block
        Every file's block in those columns (projected, the left-out functions orthogonalised).
    groups : dict
        Per motion its reported grid indices, Q and z columns (:func:`_projection`).
    undetermined : list of Undetermined
        What the per-angle check refused (:func:`_local_check`).
    """

    shared: list[str]
    blocks: list[Block]
    groups: dict[str, Any]
    undetermined: list[Undetermined]


def design_maps(names: list[str], layout: MapLayout, blocks: list[Block], sigmas: list[float],
                fitted_zero: list[int]) -> MapDesign:
    """The per-angle check, the §10 projection and the orthogonalised left-out functions (module docstring) of
    :func:`map_blocks`' blocks weighted by ``sigmas`` [µm], with the PIGE and zero-position columns
    ``fitted_zero``."""
    p = len(names)
    undetermined, kept = local_check(blocks, sigmas, p, layout)
    live = np.zeros(len(layout.columns), dtype=bool)
    for b in blocks:
        live |= np.any(b.design[:, p:] != 0, axis=0)
    projection, new_names, groups = _projection(layout, kept, live, fitted_zero)
    fitted = [Block(b.label, b.instrument, projection.apply(b.design, p), b.data, b.nuisance, b.nuisance_names)
              for b in blocks]
    shared = [names[j] for j in fitted_zero] + new_names
    nuisance = [j for j, n in enumerate(shared) if n.endswith(":left-out")]
    return MapDesign(shared, _orthogonalised(fitted, sigmas, nuisance, len(fitted_zero)), groups, undetermined)


def _layout(items: Sequence[tuple[str, Any]], spec: MapSpec, axes: tuple[str, ...],
            tool_side: tuple[str, ...] = ()) -> MapLayout:
    grids: dict[str, MapGrid] = {}
    motions: dict[str, list[Motion]] = {}
    columns: list[tuple[Motion, int]] = []
    for ax in spec.axes:
        k = axes.index(ax)
        measured = np.concatenate([np.asarray(x.angles_deg, dtype=float)[:, k] for _, x in items])
        grids[ax] = make_grid(ax, spec.step_deg, measured)
        motions[ax] = axis_motions(ax, per_direction=ax in spec.per_direction)
        columns += [(m, g) for m in motions[ax] for g in range(grids[ax].n)]
    measured_all = {ax: np.concatenate([np.asarray(x.angles_deg, dtype=float)[:, axes.index(ax)] for _, x in items])
                    for ax in spec.axes}
    return MapLayout(grids, motions, columns, tuple(a for a in spec.axes if a in tool_side), measured_all)


def map_columns(kern: Any, layout: MapLayout, angles_deg: np.ndarray, raw: np.ndarray,
                approach: np.ndarray) -> np.ndarray:
    """Un-zeroed deviation per unit map value at every pose, shape=(n, 3, M) [µm per µm or µrad]."""
    axes = tuple(kern.ROTARY_AXES)
    weights = {ax: grid.weights(angles_deg[:, axes.index(ax)]) for ax, grid in layout.grids.items()}
    cols = np.empty((angles_deg.shape[0], 3, len(layout.columns)))
    for j, (m, g) in enumerate(layout.columns):
        k = axes.index(m.axis)
        factor = weights[m.axis][:, g] * pose_factor(m, approach[:, k])
        cols[:, :, j] = motion_column(kern, m, raw) * factor[:, None]
    return cols


def _block(x: Measurement | BallbarRun, label: str, layout: MapLayout, kern: Any) -> Block:
    """The file's block with the PIGE and zero-position columns, then the map columns."""
    angles = np.asarray(x.angles_deg, dtype=float)
    approach = approach_directions(angles)
    if isinstance(x, BallbarRun):
        point = x.table_ball_mm + x.offset_mm
        raw = kern.motion_jacobian(angles, point)
        cols = map_columns(kern, layout, angles, raw, approach)
        base = ballbar_block(x, label, True)
        lengths = np.einsum("ni,nim->nm", bar_directions(kern.workpiece_rotation(angles), x.offset_mm), cols)
        return Block(label, base.instrument, np.hstack([base.design, lengths]), base.data, base.nuisance,
                     base.nuisance_names)
    raw = kern.motion_jacobian(angles, x.ball_mm, x.pivots_mm or None, x.tool_mm)
    cols = map_columns(kern, layout, angles, raw, approach)
    zeroed = cols - np.einsum("nij,jm->nim", kern.workpiece_rotation(angles), cols[0])
    units = {n: m.unit for n, (m, _) in zip(layout.names(), layout.columns, strict=True)}
    return measurement_block(x, label, True, ExtraColumns(layout.names(), units, zeroed))


def _without_maps(b: Block, p: int) -> Block:
    return Block(b.label, b.instrument, b.design[:, :p], b.data, b.nuisance, b.nuisance_names)


@dataclass
class _Projection:
    """The fitted columns from a block's (PIGEs and zero-position errors, map values) columns: the PIGE columns
    ``fitted_zero``, then per piece its map columns times its matrix (z per motion, then each motion's left-out
    functions), then the held map columns — ``design @ T`` for the sparse T, piece by piece (T itself would be
    (p + M)², M the map values)."""

    fitted_zero: list[int]
    pieces: list[tuple[np.ndarray, np.ndarray]]
    held: np.ndarray

    def apply(self, design: np.ndarray, p: int) -> np.ndarray:
        """The fitted columns of ``design`` (r, p + M), shape=(r, fitted)."""
        return np.hstack([design[:, self.fitted_zero], *(design[:, p + idx] @ mat for idx, mat in self.pieces),
                          design[:, p + self.held]])


def _projection(layout: MapLayout, kept: np.ndarray, live: np.ndarray,
                fitted_zero: list[int]) -> tuple[_Projection, list[str], dict[str, Any]]:
    """The column map from (PIGEs, map values) to (the PIGEs fitted, z per motion, the left-out functions of each
    motion, the held values), the new names, and per motion its reported grid indices, Q and z columns.

    The left-out functions (named ``<motion>:left-out``) are fitted beside the map so that what of them the
    PIGEs do not describe (a counter-rotating first harmonic, an axial one) does not bias it
    (:func:`_orthogonalised`); they are not reported.  A held value no row sees (``live`` false: no measured pose
    near its angle) is left out of the fit: its column is zero, it would take nothing and only add an unknown.
    """
    parts: list[tuple[np.ndarray, np.ndarray]] = []
    names: list[str] = []
    left: list[tuple[np.ndarray, np.ndarray]] = []
    left_names: list[str] = []
    groups: dict[str, Any] = {}
    col_of = {(m.name, g): j for j, (m, g) in enumerate(layout.columns)}
    start = len(fitted_zero)
    for ax, grid in layout.grids.items():
        for m in layout.motions[ax]:
            nodes = [g for g in range(grid.n) if kept[col_of[(m.name, g)]]]
            q = complement(m, grid.angles_deg[nodes]) if len(nodes) > m.left_out else np.zeros((len(nodes), 0))
            basis = left_out_basis(m, grid.angles_deg[nodes]) if q.shape[1] else np.eye(len(nodes))
            idx = np.array([col_of[(m.name, g)] for g in nodes], dtype=int)
            parts.append((idx, q))
            left.append((idx, basis))
            names += [f"{m.name}:z{i}" for i in range(q.shape[1])]
            left_names += [f"{m.name}:left-out"] * basis.shape[1]
            groups[m.name] = {"motion": m, "nodes": nodes, "q": q, "columns": list(range(start, start + q.shape[1]))}
            start += q.shape[1]
    held = np.flatnonzero(~kept & live)
    all_names = layout.names()
    names += left_names + [f"{all_names[j]}:held" for j in held]
    return _Projection(list(fitted_zero), parts + left, held), names, groups


def _orthogonalised(blocks: list[Block], sigmas: list[float], columns: list[int], p: int) -> list[Block]:
    """``blocks`` with ``columns`` replaced by their part the first ``p`` columns and the files' constants do
    not describe (least squares over every file's whitened rows): that part of a left-out function is the
    PIGEs' and the set-up's, the rest is fitted beside the map."""
    if not columns:
        return blocks
    stacked, _ = whitened_system(blocks, sigmas)
    n_shared = blocks[0].design.shape[1]
    basis = np.hstack([stacked[:, :p], stacked[:, n_shared:]])
    coef = np.linalg.lstsq(basis, stacked[:, columns], rcond=None)[0]
    out, offset = [], 0
    for b in blocks:
        q = b.nuisance.shape[1]
        design = b.design.copy()
        design[:, columns] -= b.design[:, :p] @ coef[:p] + b.nuisance @ coef[p + offset:p + offset + q]
        offset += q
        out.append(Block(b.label, b.instrument, design, b.data, b.nuisance, b.nuisance_names))
    return out


def _refined_sigmas(joint: JointResult, blocks: list[Block]) -> list[float]:
    """Each file's σ from its share of the joint residual (module docstring)."""
    n_total = sum(b.data.size for b in blocks)
    per_row = joint.result.dof / max(n_total, 1)
    out = []
    for f, b in zip(joint.files, blocks, strict=True):
        rss = f.rms_um**2 * b.data.size
        out.append(math.sqrt(max(rss / max(per_row * b.data.size, 1.0), 1e-8)))
    return out


def map_values(values: np.ndarray, covariance: np.ndarray, layout: MapLayout,
               groups: dict[str, Any]) -> tuple[dict[str, AxisMap], list[Undetermined]]:
    """Each axis' maps from the fitted z (``v = Q z``, ``Σ_v = Q Σ_z Qᵀ``): ``values`` (NaN: undetermined) and
    ``covariance`` of :class:`MapDesign`'s shared columns [µm, µrad]."""
    maps: dict[str, AxisMap] = {}
    more: list[Undetermined] = []
    for ax, grid in layout.grids.items():
        value, std, cov = {}, {}, {}
        for m in layout.motions[ax]:
            gr = groups[m.name]
            v = np.full(grid.n, np.nan)
            s = np.full(grid.n, np.nan)
            c = np.full((grid.n, grid.n), np.nan)
            cols = gr["columns"]
            z = values[cols]
            if gr["nodes"] and cols and np.isfinite(z).all():
                q = gr["q"]
                sz = covariance[np.ix_(cols, cols)]
                nodes = gr["nodes"]
                v[nodes] = q @ z
                cv = q @ sz @ q.T
                c[np.ix_(nodes, nodes)] = cv
                s[nodes] = np.sqrt(np.clip(np.diag(cv), 0.0, None))
            elif gr["nodes"] and cols:
                more.append(Undetermined(m.name, None, "its map is not determined jointly with the PIGEs and the "
                                         "other maps (a combination of the fit's unknowns is not seen)",
                                         "measure with more setups or angles (the map test's plan says which)"))
            elif gr["nodes"]:
                more.append(Undetermined(m.name, None, f"only {len(gr['nodes'])} grid angle(s) have a value: after "
                                         f"leaving out the {m.left_out} functions of §10 nothing is left",
                                         "determine its other angles first (their reasons are given)"
                                         if len(gr["nodes"]) < grid.n else
                                         f"measure more angles of {ax} (the map test's plan puts poses at every "
                                         "grid angle)"))
            value[m.name], std[m.name], cov[m.name] = v, s, c
        for m in layout.motions[ax]:
            if m.kind == "reversal":
                _per_direction(covariance, groups, m, value, std)
        maps[ax] = AxisMap(grid, layout.motions[ax], value, std, cov)
    return maps, more


def _per_direction(cov: np.ndarray, groups: dict[str, Any], reversal: Motion,
                   value: dict[str, np.ndarray], std: dict[str, np.ndarray]) -> None:
    """``φ± = φ ± r/2`` with their standard errors (the two maps' cross-covariance included)."""
    mean_name = reversal.name.split(":")[0]
    gm, gr = groups[mean_name], groups[reversal.name]
    common = [g for g in gm["nodes"] if g in gr["nodes"]]
    n = value[mean_name].size
    im = [gm["nodes"].index(g) for g in common]
    ir = [gr["nodes"].index(g) for g in common]
    qm, qr = gm["q"][im], gr["q"][ir]
    cm, cr = gm["columns"], gr["columns"]
    if not common or not cm or not cr:
        return
    var_m = np.einsum("ij,jk,ik->i", qm, cov[np.ix_(cm, cm)], qm)
    var_r = np.einsum("ij,jk,ik->i", qr, cov[np.ix_(cr, cr)], qr)
    cross = np.einsum("ij,jk,ik->i", qm, cov[np.ix_(cm, cr)], qr)
    for sign, suffix in ((1.0, "+"), (-1.0, "-")):
        v, s = np.full(n, np.nan), np.full(n, np.nan)
        v[common] = value[mean_name][common] + sign * 0.5 * value[reversal.name][common]
        s[common] = np.sqrt(np.clip(var_m + 0.25 * var_r + sign * cross, 0.0, None))
        value[mean_name + suffix], std[mean_name + suffix] = v, s


def _pige_part(joint: JointResult, names: list[str], fitted: list[int], zeros: IdentificationResult,
               stats: tuple[int, float, dict[str, float], np.ndarray]) -> JointResult:
    """The joint result restricted to the PIGEs and zero-position errors (the map unknowns reported apart); a
    zero-position error the files cannot determine has no value, as in the fit of the PIGEs and zero-position
    errors alone (``zeros``), whose combinations say why; the PIGEs then hold it (CONVENTIONS §10).

    ``stats``: the rank, condition, observability and singular values of the PIGEs given the maps
    (:func:`~.map_statistics.pige_statistics`), not the joint system's, whose held values make it singular by design.
    """
    r = joint.result
    k = len(fitted)
    values = np.full(len(names), np.nan)
    std = np.full(len(names), np.nan)
    cov = np.full((len(names), len(names)), np.nan)
    values[fitted], std[fitted] = r.values[:k], r.std[:k]
    cov[np.ix_(fitted, fitted)] = r.covariance[:k, :k]
    unfitted = {names[j] for j in range(len(names)) if j not in fitted}
    said = [(c, text) for c, text in zip(zeros.null_space, zeros.unidentifiable, strict=True)
            if unfitted.intersection(c.names())]
    said += [(c, text) for c, text in zip(r.null_space, r.unidentifiable, strict=True)
             if not any(mark in n for n in c.names() for mark in (":z", ":held", ":left-out"))]
    sub = IdentificationResult(
        machine=r.machine, method="joint-map", projection=r.projection, loss=r.loss, parameters=list(names),
        units=dict(zeros.units), values=values, std=std, covariance=cov, identifiable=np.isfinite(values),
        rms_um=r.rms_um, sigma_um=r.sigma_um, dof=r.dof, n_rows=r.n_rows, n_obs=r.n_obs, rank=stats[0],
        condition=stats[1], singular_values=stats[3], observability=stats[2],
        unidentifiable=[text for _, text in said], outlier_rows=r.outlier_rows, residuals_um=r.residuals_um,
        ball_mm=r.ball_mm, pivots_mm=r.pivots_mm, tool_mm=r.tool_mm, unobserved=[n for n in r.unobserved if n in names],
        axis_sense=r.axis_sense, null_space=[c for c, _ in said])
    return JointResult(sub, joint.files, joint.variance_factor)
