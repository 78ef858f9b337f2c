"""``pige compensate`` with maps grows linearly with the map values (issue 47, item 4).

Counted, not timed (the times are in benchmarks/bench_scale_maps.py): weighing a parameter file of hundreds of map
values factors no matrix larger than the PIGEs' group (each map value is uncorrelated with every other: the
covariance is held as blocks, :mod:`pige_sym.compensation.covariance`), and its error moments are sparse, with a
number of non-zeros that follows the values (a map value moves the tool point only near its grid angle).  Before,
the weighing formed the dense q × q covariance, its eigen-decomposition, the dense (3n, q) design and ``DRAWS·q²``
products per prediction: 840 values took over a minute.

The fast path gives the old numbers: the oracles below are the old dense computations, written here.  The draws
of the prediction use a square root of Σ group by group (the old one took the eigenvectors of the whole matrix, in
the order and signs the eigen-solver chose): with one group of correlated values — a file without maps — the draws
are the old ones exactly; with maps the prediction moves within its Monte Carlo noise.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from pige_sym.compensation.covariance import BlockCovariance
from pige_sym.compensation.draws import DRAWS
from pige_sym.compensation.parameters import load_parameters
from pige_sym.compensation.weighing import (
    error_moments,
    estimate_of,
    predict,
    program_poses,
    travel_poses,
    weigh,
)
from pige_sym.kernels import load_kernels
from pige_sym.model.error_motions import MOTION_COMPONENTS, axis_motions, pose_factor

AC = "wC'A'bXYZ(C1)t"
PIGE = {"EY0A": 7.3, "EZ0A": -6.9, "EB0A": 17.6, "EC0A": -29.3, "EX0C": 4.0, "EY0C": -8.0, "EA0C": 9.8, "EB0C": -19.0}


def maps_file(folder: Path, c_step: float, a_nodes: int, *, seed: int = 0, per_direction: bool = False,
              correlated: bool = True) -> Path:
    """A parameter file as ``pige identify --map C,A --json`` writes it: the PIGEs with their covariance, and on a C
    grid of ``c_step`` and an A grid of ``a_nodes`` angles over −90…0° every motion's values and standard errors
    (a few undetermined: null)."""
    rng = np.random.default_rng(seed)
    names = list(PIGE)
    a = rng.normal(size=(8, 8)) * rng.uniform(0.05, 0.6, size=8)
    cov = a @ a.T + np.diag(rng.uniform(0.001, 0.01, size=8)) if correlated else np.diag(rng.uniform(0.01, 0.5, 8))
    doc: dict[str, Any] = {"machine": AC, "pige": dict(PIGE), "std": {n: float(np.sqrt(cov[i, i]))
                                                                      for i, n in enumerate(names)},
                           "pivots_mm": {"A": [0.0, 0.0, 0.0], "C": [0.0, 0.0, 0.0]}, "ball_mm": [100.0, 20.0, 60.0]}
    if correlated:
        doc["covariance"] = {"parameters": names, "matrix": cov.tolist()}
    motions: dict[str, Any] = {}
    for axis, grid, full in (("C", np.arange(0.0, 360.0, c_step), True), ("A", np.linspace(-90.0, 0.0, a_nodes),
                                                                           False)):
        entry: dict[str, Any] = {"angle_deg": grid.tolist(), "full_turn": full}
        for m in axis_motions(axis):
            t = np.radians(grid)
            v = sum(rng.normal(scale=2.0) * np.cos(h * t + rng.uniform(0, 6.3)) for h in (2, 3))
            v = v + rng.normal(scale=0.3, size=grid.size)
            s = rng.uniform(0.1, 3.0, size=grid.size)
            values: list[float | None] = [float(x) for x in v]
            values[int(rng.integers(grid.size))] = None  # undetermined: no value, nothing entered
            name = m.name + ("+" if per_direction and m.kind == "positioning" and axis == "C" else "")
            entry[name] = {"value": values, "std": [float(x) for x in s], "unit": m.unit, "kind": m.kind}
            if name.endswith("+"):
                entry[m.name + "-"] = {"value": [None if x is None else x + 1.0 for x in values],
                                       "std": [float(x) for x in s], "unit": m.unit, "kind": m.kind}
        motions[axis] = entry
    doc["error_motions"] = motions
    path = folder / f"maps_{c_step:g}_{a_nodes}_{seed}.json"
    path.write_text(json.dumps(doc), encoding="utf-8")
    return path


# --------------------------------------------------------------------------- the oracles: the old dense computations

def _value_columns_as_written(maps: Any, kern: Any, a: np.ndarray, appr: np.ndarray) -> tuple[list[str], np.ndarray,
                                                                                              np.ndarray]:
    """ErrorMaps.value_columns before issue 47: every value's dense weight at every pose (n, V)."""
    axes = tuple(kern.ROTARY_AXES)
    names, cols, comps = [], [], []
    for ax, m in maps.axes.items():
        k = axes.index(ax)
        weights = m.grid.weights(a[:, k])
        by_name = {mo.name: mo for mo in axis_motions(ax, per_direction=True)}
        phi = next(mo for mo in by_name.values() if mo.kind == "positioning")
        for name, vals in m.values.items():
            motion = by_name.get(name, phi)
            if name in by_name:
                direction = pose_factor(motion, appr[:, k])
            else:
                direction = 0.5 * (1 + appr[:, k]) if name.endswith("+") else 0.5 * (1 - appr[:, k])
            sign = -1.0 if motion.kind in ("positioning", "reversal") and ax in kern.WORKPIECE_ROTARY else 1.0
            for g, v in enumerate(vals):
                if np.isfinite(v):
                    names.append(f"{ax}:{name}@{m.grid.angles_deg[g]:g}")
                    cols.append(sign * weights[:, g] * direction)
                    comps.append(6 * k + MOTION_COMPONENTS.index(motion.component))
    return names, np.stack(cols, axis=1), np.array(comps, dtype=int)


def _moments_as_written(params: Any, names: list[str], poses: Any) -> np.ndarray:
    """error_moments before issue 47: the dense (3n, q) design and its normal matrix."""
    from pige_sym.compensation.kinematics import raw_offset

    kern = load_kernels(params.machine)
    pivots = {a: np.asarray(v, dtype=float) for a, v in params.pivots_mm.items()} or None
    a, pts = poses.angles_deg, poses.points_mm
    mnames, weights, comps = _value_columns_as_written(params.error_maps, kern, a, poses.approach)
    base = kern.motion_jacobian(a, np.zeros(3), pivots, params.tool_mm)
    per_point = base + sum(pts[:, j, None, None] * (kern.motion_jacobian(a, e, pivots, params.tool_mm) - base)
                           for j, e in enumerate(np.eye(3)))
    maps = {n: per_point[:, :, comps[i]] * weights[:, i, None] for i, n in enumerate(mnames)}
    cols = []
    for name in names:
        if name in maps:
            cols.append(maps[name].reshape(-1))
            continue
        p = np.zeros((a.shape[0], len(kern.PARAMETERS)))
        p[:, kern.PARAMETERS.index(name)] = 1.0
        cols.append(raw_offset(kern, a, pts, p, pivots, params.tool_mm).reshape(-1))
    d = np.stack(cols, axis=1)
    return d.T @ d / a.shape[0]


def _dense_covariance_as_written(params: Any, names: list[str]) -> np.ndarray:
    """weighing._covariance before issue 47: the file's covariance of the PIGEs, the map values' variances."""
    maps = set(params.error_maps.values())
    plain = [n for n in names if n not in maps]
    cov, _ = params.covariance_of(plain)
    out = np.zeros((len(names), len(names)))
    idx = [names.index(n) for n in plain]
    out[np.ix_(idx, idx)] = cov
    for i, n in enumerate(names):
        if n in maps:
            axis, rest = n.split(":", 1)
            motion, angle = rest.split("@")
            grid = params.error_maps.axes[axis].grid.angles_deg
            g = int(np.flatnonzero(np.isclose(grid, float(angle)))[0])
            out[i, i] = params.error_map_std[axis][motion][g] ** 2
    return out


def _predict_dense(estimate: np.ndarray, blocks: BlockCovariance, moments: np.ndarray, entered: np.ndarray,
                   ) -> tuple[float, float]:
    """The old predict's formula (the draws' quadratic form, einsum) with the block roots assembled densely."""
    roots, std = blocks.roots()
    root = np.zeros((blocks.size, blocks.size))
    root[blocks.single, blocks.single] = std
    for idx, r in roots:
        root[np.ix_(idx, idx)] = r
    rng = np.random.default_rng(0)
    left = (estimate - entered)[None, :] + rng.standard_normal((DRAWS, estimate.size)) @ root.T
    rms = np.sqrt(np.clip(np.einsum("si,ij,sj->s", left, moments, left), 0.0, None))
    return float(rms.mean()), float(np.quantile(rms, 0.95))


# ------------------------------------------------------------------------------------------------------ the tests

@pytest.mark.parametrize("per_direction", [False, True])
def test_the_sparse_moments_and_pose_motions_are_the_dense_ones(tmp_path: Path, per_direction: bool) -> None:
    params = load_parameters(maps_file(tmp_path, 30.0, 5, per_direction=per_direction), allow_missing=True)
    names = list(estimate_of(params))
    kern = load_kernels(AC)
    for poses in (travel_poses(params), program_poses(*_program(kern))):
        m = error_moments(params, names, poses)
        expected = _moments_as_written(params, names, poses)
        dense = m.toarray()
        assert np.abs(dense - expected).max() <= 1e-12 * np.abs(expected).max()
        vnames, w, comps = _value_columns_as_written(params.error_maps, kern, poses.angles_deg, poses.approach)
        values = params.error_maps.values()
        old = np.zeros((poses.angles_deg.shape[0], 12))
        np.add.at(old.T, comps, (w * np.array([values[n] for n in vnames])).T)
        new = params.error_maps.pose_motions(kern, poses.angles_deg, poses.approach)
        assert np.abs(new - old).max() <= 1e-12 * np.abs(old).max()


def _program(kern: Any) -> tuple[np.ndarray, np.ndarray]:
    """Angles between the grid angles and beyond the A grid, points around the table: a program's poses."""
    rng = np.random.default_rng(5)
    a = np.column_stack([rng.uniform(-95.0, 5.0, 400), np.sort(rng.uniform(-30.0, 400.0, 400))])
    return a, np.array([120.0, 0.0, 80.0]) + rng.normal(scale=20.0, size=(400, 3))


def test_the_entered_values_and_predictions_are_the_dense_ones(tmp_path: Path) -> None:
    params = load_parameters(maps_file(tmp_path, 30.0, 5, seed=3), allow_missing=True)
    w = weigh(params, travel_poses(params))
    names = list(w.estimate)
    x = np.array([w.estimate[n] for n in names])
    cov = _dense_covariance_as_written(params, names)
    assert np.abs(w.covariance.toarray() - cov).max() == 0.0
    from pige_sym.compensation.weighing import prior_variances

    tau2 = prior_variances(x, cov)  # the dense path (a matrix: split into its groups the same way)
    old = np.where(tau2 > 0, tau2 * np.linalg.solve(np.diag(tau2) + cov, x), 0.0)
    new = np.array([w.entered[n] for n in names])
    np.testing.assert_allclose(new, old, rtol=1e-10, atol=1e-12 * np.abs(x).max())
    assert (new == 0).sum() > 5 and (new != 0).sum() > 20, "some values entered, some not"
    for entered in (np.zeros_like(x), new, x):
        got = predict(x, w.covariance, w.moments, entered)
        expected = _predict_dense(x, w.covariance, w.moments.toarray(), entered)
        np.testing.assert_allclose([got.expected_um, got.p95_um], expected, rtol=1e-9)
    assert w.predicted["entered"] == predict(x, w.covariance, w.moments, new)


def test_without_maps_the_draws_are_the_old_ones(tmp_path: Path) -> None:
    """One group of correlated PIGEs: the same draws as the old whole-matrix eigen-decomposition, the same numbers."""
    params = load_parameters(maps_file(tmp_path, 30.0, 4, seed=4), allow_missing=True)
    params.error_maps = None
    w = weigh(params, travel_poses(params))
    names = list(w.estimate)
    x = np.array([w.estimate[n] for n in names])
    cov = w.covariance.toarray()
    assert len(w.covariance.groups) == 1 and w.covariance.single.size == 0
    for entered in (np.zeros_like(x), np.array([w.entered[n] for n in names])):
        rng = np.random.default_rng(0)  # the old predict, as written
        vals, vecs = np.linalg.eigh(cov)
        root = vecs * np.sqrt(np.clip(vals, 0.0, None))
        left = (x - entered)[None, :] + rng.standard_normal((DRAWS, x.size)) @ root.T
        rms = np.sqrt(np.clip(np.einsum("si,ij,sj->s", left, w.moments, left), 0.0, None))
        got = predict(x, cov, w.moments, entered)
        np.testing.assert_allclose([got.expected_um, got.p95_um], [rms.mean(), np.quantile(rms, 0.95)], rtol=1e-12)


def test_weighing_many_map_values_factors_no_large_matrix(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """600 map values: every eigen-decomposition and solve is of the PIGEs' group (8 × 8) at most."""
    largest = [0]
    for name in ("eigh", "solve", "inv", "slogdet", "cholesky"):
        original = getattr(np.linalg, name)

        def counted(m: Any, *args: Any, _f: Any = original, **kwargs: Any) -> Any:
            largest[0] = max(largest[0], np.shape(m)[-1])
            return _f(m, *args, **kwargs)

        monkeypatch.setattr(np.linalg, name, counted)
    params = load_parameters(maps_file(tmp_path, 5.0, 31, seed=7), allow_missing=True)
    w = weigh(params, travel_poses(params))
    monkeypatch.undo()
    assert len(w.estimate) > 600 and largest[0] <= 8, (len(w.estimate), largest)


def test_the_moments_hold_what_the_poses_touch(tmp_path: Path) -> None:
    """On 200 judged poses each pose moves with the 8 PIGEs and two grid angles of each of the 12 motions: the
    moments hold at most 200·32² non-zeros, however fine the grid (2,700 values: q² = 7.3 million)."""
    kern = load_kernels(AC)
    a, pts = _program(kern)
    poses = program_poses(a[:200], pts[:200])
    for step, a_nodes in ((5.0, 31), (1.0, 91)):
        params = load_parameters(maps_file(tmp_path, step, a_nodes, seed=8), allow_missing=True)
        names = list(estimate_of(params))
        m = error_moments(params, names, poses)
        assert m.shape == (len(names), len(names)) and m.nnz <= 200 * 32**2, (len(names), m.nnz)
    assert len(names) > 2700
