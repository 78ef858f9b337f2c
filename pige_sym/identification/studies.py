"""Studies: excitation projection (the paper's Tables 3–6) and Sobol sensitivity.

Projection study
----------------
For a machine and a trajectory, and for each excitation projection (x, y, z, a
sweep of directions in a plane, full xyz), the design's rank, scaled condition
number and undetermined combinations are computed (they do not depend on the
preset values), then many random presets (the simulator's Fourier-series
generator) are simulated with noise and identified with the double-differential
scheme.  A preset *succeeds* when every PIGE gets a value and lies within 4
standard errors of the preset (optionally also with a standard error below
``accuracy`` µm/µrad).  Success rates, not one lucky case, are reported, with the
stage-by-stage results of the first preset (preset vs identified, error).

Sobol study
-----------
First-order and total Sobol indices of the mean-square projected deviation over
the trajectory (µm²) with respect to each PIGE, every PIGE uniform on
``[-h, +h]`` (µm or µrad), per projection.  The output is a quadratic form
``f(x) = xᵀ M x`` with ``M = AᵀA / m`` (``A`` the projected Jacobian, ``m`` its
rows), so the indices are exact in closed form for independent inputs with zero
mean: with ``s_i = h_i²/3`` and ``Var(x_i²) = 4 h_i⁴/45``,

* ``V_i = M_ii² · 4 h_i⁴/45`` (first order: ``E[f | x_i]`` keeps only ``M_ii x_i²``),
* ``V_Ti = V_i + 4 s_i Σ_{j≠i} M_ij² s_j`` (the cross terms ``2 M_ij x_i x_j``),
* ``V = Σ_i V_i + 2 Σ_{i≠j} M_ij² s_i s_j`` (all terms are uncorrelated),

``S1_i = V_i / V`` and ``ST_i = V_Ti / V`` (NaN when ``V = 0``: nothing to
share).  Given a sample size, ``scipy.stats.sobol_indices`` (Saltelli/Jansen
Monte-Carlo estimators) computes the same indices instead; the tests check the
two agree.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from pige_sym.constants import DEFAULT_BALL_MM
from pige_sym.errors import InputError
from pige_sym.identification.least_squares import identify
from pige_sym.identification.spectrum import NULL_RTOL, RANK_RTOL
from pige_sym.kernels import load_kernels
from pige_sym.measurements.measurement import missing_tool
from pige_sym.model.projection import Projection, direction_sweep, parse_projection
from pige_sym.model.trajectories import Trajectory
from pige_sym.simulation.simulator import random_pige, simulate

DEFAULT_PROJECTIONS = ("x", "y", "z", "xyz")


@dataclass
class ProjectionRow:
    """Result of one projection."""

    projection: str
    rank: int
    n_parameters: int
    condition: float
    unobserved: list[str]
    unidentifiable: list[str]
    success_rate: float
    determined_rate: dict[str, float]
    max_abs_error: dict[str, float]
    example_stages: list[dict[str, Any]] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        return {
            "projection": self.projection, "rank": self.rank, "n_parameters": self.n_parameters,
            "condition": None if not np.isfinite(self.condition) else self.condition,
            "unobserved": self.unobserved, "unidentifiable": self.unidentifiable,
            "success_rate": self.success_rate, "determined_rate": self.determined_rate,
            "max_abs_error": self.max_abs_error, "example_stages": self.example_stages,
        }


@dataclass
class ProjectionStudy:
    """Projection study of one machine and trajectory."""

    machine: str
    trajectory: str
    presets: int
    noise_um: float
    rows: list[ProjectionRow]
    verdict: str

    def to_dict(self) -> dict[str, Any]:
        return {"machine": self.machine, "trajectory": self.trajectory, "presets": self.presets,
                "noise_um": self.noise_um, "rows": [r.to_dict() for r in self.rows], "verdict": self.verdict}

    def format(self) -> str:
        lines = [f"projection study: {self.machine}, {self.trajectory}, {self.presets} random presets, "
                 f"noise {self.noise_um} um", "",
                 f"{'projection':<16}{'rank':>6}{'condition':>12}{'success':>9}   undetermined"]
        for r in self.rows:
            cond = f"{r.condition:.3g}" if np.isfinite(r.condition) else "inf"
            und = ", ".join(r.unobserved + [c.replace(" is not identifiable", "") for c in r.unidentifiable]) or "-"
            lines.append(f"{r.projection:<16}{r.rank:>3}/{r.n_parameters:<2}{cond:>12}{r.success_rate:>8.0%}   {und}")
        weak = [r for r in self.rows if len(r.unobserved) + len(r.unidentifiable) > r.n_parameters - r.rank]
        if weak:
            lines += ["", "why more undetermined combinations than missing rank: the rank counts singular values above "
                      f"{RANK_RTOL:g} of the largest (exact rank deficiency); a combination is listed as undetermined "
                      f"when its singular value is at most {NULL_RTOL:g} of the largest, i.e. the data determine it "
                      f"more than {1 / NULL_RTOL:.0f} times more weakly than the best-determined direction, so "
                      f"noise decides its value ({', '.join(r.projection for r in weak)})."]
        lines += ["", self.verdict]
        return "\n".join(lines)


def _verdict(machine: str, rows: list[ProjectionRow]) -> str:
    by = {r.projection: r for r in rows}
    kern = load_kernels(machine)
    tilt = [a for a in kern.ROTARY_AXES if a[0] != "ABC"[kern.SPINDLE_DIRECTION]]
    parts = []
    if "x" in by and "y" in by:
        x, y = by["x"], by["y"]
        better = "y" if (y.rank, y.success_rate) > (x.rank, x.success_rate) else "x"
        parts.append(f"x: rank {x.rank}/{x.n_parameters}, y: rank {y.rank}/{y.n_parameters} — {better} is the more "
                     f"favourable single projection.")
        if tilt:
            axis = tilt[0]
            d = "xyz"["ABC".index(axis[0])]
            parts.append(f"The tilt axis {axis} turns about {d.upper()}: its position errors lie in the plane normal "
                         f"to {d.upper()} and its motion moves the nest there, so a projection along {d} sees them "
                         f"little or not at all ({', '.join(getattr(by.get(d), 'unobserved', []) or ['-'])} "
                         f"unobserved).")
        full = by.get("xyz")
        if full is not None:
            all_single_deficient = all(by[p].rank < by[p].n_parameters for p in ("x", "y", "z") if p in by)
            if all_single_deficient and full.rank == full.n_parameters:
                parts.append("In our model no single projection determines all 8 PIGEs (each leaves a combination "
                             "undetermined), whatever the number of differentials; the full 3-D deviation does "
                             f"(rank {full.rank}, condition {full.condition:.3g}).")
    return " ".join(parts)


def projection_study(machine: str, trajectory: Trajectory, *, projections: list[str] | None = None,
                     sweep: int = 0, presets: int = 50, noise_um: float = 0.25, seed: int = 0,
                     ball_mm: Any = DEFAULT_BALL_MM, tool_mm: Any = None, accuracy: float = np.inf,
                     progress: bool = True) -> ProjectionStudy:
    """Run the projection study (module docstring).

    Parameters
    ----------
    projections : list of str
        Default x, y, z, xyz.
    sweep : int
        Also this many directions spread over 180° in the XY plane.
    presets : int
        Random presets (each simulated with noise and identified per projection).
    accuracy : float [µm or µrad]
        Optional: largest standard error that still counts as accurately identified
        (default: no limit; success then means every PIGE determined and consistent
        with the preset within 4 standard errors).
    """
    projs: list[Projection] = [parse_projection(p) for p in (projections or DEFAULT_PROJECTIONS)]
    projs += direction_sweep(sweep) if sweep else []
    kern = load_kernels(machine)
    names = list(kern.LOCATION_PARAMETERS)
    sims = []
    for i in range(presets):
        truth = random_pige(machine, seed + i)
        sims.append(simulate(machine, trajectory, pige=truth, ball_mm=ball_mm, tool_mm=tool_mm, noise_um=noise_um,
                             seed=10_000 + seed + i))
    rows = []
    total = len(projs) * presets
    from tqdm import tqdm

    with tqdm(total=total, desc="projection study", disable=not progress, unit="fit") as bar:
        for proj in projs:
            ok = 0
            determined = dict.fromkeys(names, 0)
            max_err = dict.fromkeys(names, 0.0)
            first = None
            for sim in sims:
                res = identify(sim.measurement, method="double-differential", projection=proj)
                first = first or res
                good = True
                for j, p in enumerate(names):
                    v, s = res.values[j], res.std[j]
                    if np.isfinite(v):
                        determined[p] += 1
                        err = abs(v - sim.truth["pige"][p])
                        max_err[p] = max(max_err[p], err)
                        good &= bool(err < 4 * s and s < accuracy)
                    else:
                        good = False
                ok += good
                bar.update(1)
            assert first is not None
            # the same definitions as `pige identify`: zero columns are unobserved, the rest of the
            # undetermined directions are the identification's own combinations
            unobserved = [p for p in first.unobserved if p in names]
            combos = [c for c in first.unidentifiable if not any(c == f"{u} [{kern.UNITS[u]}] is not identifiable"
                                                                 for u in unobserved)]
            stages = [s.to_dict() | {"preset": {p: sims[0].truth["pige"][p] for p in s.solved}} for s in first.stages]
            rows.append(ProjectionRow(
                projection=proj.name, rank=first.rank, n_parameters=len(names), condition=first.condition,
                unobserved=unobserved, unidentifiable=combos, success_rate=ok / presets,
                determined_rate={p: c / presets for p, c in determined.items()}, max_abs_error=max_err,
                example_stages=stages,
            ))
    return ProjectionStudy(kern.MACHINE_CODE, trajectory.description, presets, noise_um, rows, _verdict(machine, rows))


@dataclass
class SobolStudy:
    """First and total Sobol indices per projection."""

    machine: str
    trajectory: str
    parameters: list[str]
    projections: list[str]
    first_order: np.ndarray  # (n_proj, P)
    total_order: np.ndarray  # (n_proj, P)
    n_samples: int | None  # None: exact closed form

    @property
    def method(self) -> str:
        """How the indices were computed, in words."""
        if self.n_samples is None:
            return "exact (closed form of a quadratic form in independent uniform PIGEs)"
        return f"Monte-Carlo estimate (scipy.stats.sobol_indices), {self.n_samples} base samples"

    def to_dict(self) -> dict[str, Any]:
        return {"machine": self.machine, "trajectory": self.trajectory, "n_samples": self.n_samples,
                "method": "exact" if self.n_samples is None else "monte-carlo",
                "output": "mean-square projected deviation over the trajectory [um^2]",
                "indices": {pr: {"first": dict(zip(self.parameters, self.first_order[i].tolist(), strict=True)),
                                 "total": dict(zip(self.parameters, self.total_order[i].tolist(), strict=True))}
                            for i, pr in enumerate(self.projections)}}

    def format(self) -> str:
        lines = [f"Sobol indices: {self.machine}, {self.trajectory}, output = mean-square projected deviation",
                 f"method: {self.method}", "",
                 f"{'parameter':<10}" + "".join(f"{p + ' S1':>10}{p + ' ST':>10}" for p in self.projections)]
        for j, name in enumerate(self.parameters):
            lines.append(f"{name:<10}" + "".join(f"{self.first_order[i, j]:>10.3f}{self.total_order[i, j]:>10.3f}"
                                                 for i in range(len(self.projections))))
        return "\n".join(lines)


def sobol_study(machine: str, trajectory: Trajectory, *, projections: list[str] | None = None,
                ranges: dict[str, float] | None = None, default_range: float = 15.0, n: int | None = None,
                ball_mm: Any = DEFAULT_BALL_MM, tool_mm: Any = None, seed: int = 0) -> SobolStudy:
    """Sobol indices of the mean-square projected deviation w.r.t. each PIGE (module docstring).

    Parameters
    ----------
    n : int or None
        ``None`` (default): the exact closed form.  A power of two: the Monte-Carlo
        estimate of ``scipy.stats.sobol_indices`` with that base sample size.
    """
    kern = load_kernels(machine)
    why = missing_tool(kern.MACHINE_CODE, tool_mm)
    if why:
        raise InputError(why)
    names = list(kern.LOCATION_PARAMETERS)
    projs = [parse_projection(p) for p in (projections or DEFAULT_PROJECTIONS)]
    jac = kern.jacobian(trajectory.angles_deg, None, ball_mm, None, tool_mm)[1:, :, :8]  # (n, 3, 8)
    pj = [p.apply_model(jac).reshape(-1, 8) for p in projs]
    half = np.array([float((ranges or {}).get(p, default_range)) for p in names])
    if n is None:
        first, total = np.array([exact_sobol_quadratic(a.T @ a / len(a), half) for a in pj]).transpose(1, 0, 2)
    else:
        first, total = _monte_carlo_sobol(pj, half, n, seed)
    return SobolStudy(kern.MACHINE_CODE, trajectory.description, names, [p.name for p in projs],
                      first, total, n)


def exact_sobol_quadratic(m: np.ndarray, half: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """First and total Sobol indices of ``xᵀ M x``, ``x_i`` independent uniform on ``±half_i``.

    Parameters
    ----------
    m : (P, P) symmetric matrix
    half : (P,) half ranges, same units as ``x``

    Returns
    -------
    first, total : (P,) each; NaN when the output does not vary at all.
    """
    s = half**2 / 3.0
    v_first = np.diag(m) ** 2 * 4.0 * half**4 / 45.0
    cross = m**2 * np.outer(s, s)
    np.fill_diagonal(cross, 0.0)
    v_total = v_first + 4.0 * cross.sum(axis=1)
    v = v_first.sum() + 2.0 * cross.sum()
    if not v > 0.0:
        return np.full_like(half, np.nan), np.full_like(half, np.nan)
    return v_first / v, v_total / v


def _monte_carlo_sobol(pj: list[np.ndarray], half: np.ndarray, n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """``scipy.stats.sobol_indices`` of the same outputs, ``n`` base samples."""
    from scipy import stats

    dists = [stats.uniform(loc=-h, scale=2 * h) for h in half]

    def func(x: np.ndarray) -> np.ndarray:
        # x: (8, N) -> (n_proj, N)
        return np.array([((a @ x) ** 2).mean(axis=0) for a in pj])

    res = stats.sobol_indices(func=func, n=n, dists=dists, rng=np.random.default_rng(seed))
    return np.atleast_2d(res.first_order), np.atleast_2d(res.total_order)
