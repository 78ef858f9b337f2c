"""The catalogue effects of a set of ballbar setups, fitted jointly across the setups.

A ballbar row is one projection of the deviation; one setup sees few of an effect's directions, several
setups together see more, as for the PIGEs.  For a set of ballbar files (every file a ballbar setup of
one machine) the catalogue's effects are searched on the *joint* whitened system of
:mod:`pige_sym.identification.joint` (shared PIGEs, a constant per relative file): an effect's columns in
a file are its zeroed R-test deviation at the tool ball's table point projected on the bar,
``n_i·C_i`` (the same first-order model :mod:`pige_sym.simulation.ballbar` simulates), stacked over the
files and divided by each file's σ.

Candidates: harmonics 1–4 of the angular error, 2–4 of the wobble and radial runout (their first
harmonic is mostly a location error in disguise) of every rotary axis a setup sweeps, the three
squareness pairs.  Thermal drift is not searched (each setup restarts its clock; a
drift shared across setups has no common time axis in the files) and backlash needs reversals that the
sweeps do not make.

Forward selection, like the R-test diagnosis' first stage: each candidate is reduced to the part the set
determines jointly with the current model (the Schur complement of its columns, scaled to unit diagonal;
eigen-directions with ``λ ≤ NULL_LAMBDA`` are removed and named), fitted, and the best one accepted when
``ΔBIC = (RSS₁ − RSS₀)/s² + k ln n ≤ DELTA_BIC_MAX`` and the F test's ``p ≤ P_MAX``, with
``s² = max(RSS₁/dof, 1)`` on rows whitened by each file's σ (floored: the first-order model's own error
on exact lengths, far below the floor, is no evidence of an effect); at most
``MAX_EFFECTS``.  The PIGEs are then estimated jointly with the accepted effects.  A file that sees an
effect strongly has its σ inflated by it in its own PIGE-only fit (and would be under-weighted, its
standard errors overstated): when effects are found, each file's σ is estimated again from its residual
in the extended fit and the search repeated once with those weights.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from pige_sym.diagnosis.candidates import Candidate, Reduction, reduce_candidate
from pige_sym.diagnosis.results import EVIDENCE, Finding
from pige_sym.identification.joint import Block, JointResult, identify_blocks, whitened_system
from pige_sym.kernels import load_kernels
from pige_sym.measurements.ballbar import BallbarRun, bar_directions
from pige_sym.model.effects import EffectContext, EffectSpec

DELTA_BIC_MAX = -10.0
P_MAX = 1e-4
MAX_EFFECTS = 3
HARMONICS = (1, 2, 3, 4)
#: 1/VIF at or below which a direction counts as undetermined.  Stricter than the R-test diagnosis' 1e-7:
#: one projection per pose leaves many directions barely seen, and a barely seen direction fits noise by
#: trading with the PIGEs (measured: a wobble_A h1 found in 1 of 100 unchanged sets, EC0A moved by 6σ).
NULL_LAMBDA = 1e-3
AMBIGUOUS_BIC = 10.0  # another candidate this close is listed as an alternative (as in the R-test diagnosis)


@dataclass
class Reduced:
    """A candidate reduced to its determined part jointly with a model (``c = reduction.basis·θ``)."""

    spec: EffectSpec
    columns: np.ndarray  # (n, q) whitened catalogue columns, stacked over the setups
    reduction: Reduction
    per_run: list[np.ndarray]  # each setup's unwhitened catalogue columns (r, q) [µm per unit]

    @property
    def basis(self) -> np.ndarray:
        return self.reduction.basis

    @property
    def complete(self) -> bool:
        """Nothing removed: the effect's catalogue parameters are all determined."""
        return self.reduction.null.size == 0

    def design(self, cols: np.ndarray) -> np.ndarray:
        """Its fitted columns from catalogue columns: the catalogue ones when complete, else ``cols·basis``."""
        return cols if self.complete else cols @ self.basis


def candidates(runs: Sequence[BallbarRun]) -> list[EffectSpec]:
    """The catalogue effects a set of ballbar setups can show (module docstring)."""
    axes = tuple(runs[0].rotary_axes)
    moving = [ax for k, ax in enumerate(axes) if any(np.ptp(r.angles_deg[:, k]) > 1e-9 for r in runs)]
    specs = [EffectSpec(f"{kind}_{ax}", {"harmonic": h}) for ax in moving
             for kind in ("angular_error", "wobble", "radial_runout") for h in HARMONICS
             if h > 1 or kind == "angular_error"]
    return specs + [EffectSpec(f"squareness_{pair}") for pair in ("XY", "YZ", "ZX")]


def projected_columns(spec: EffectSpec, run: BallbarRun) -> np.ndarray:
    """The effect's length change per unit parameter in one setup, shape=(n, q) [µm per unit]."""
    ctx = EffectContext(load_kernels(run.machine), run.angles_deg, run.t_s, run.table_ball_mm + run.offset_mm)
    return np.einsum("ni,niq->nq", bar_directions(ctx.rot_w, run.offset_mm), spec.columns(ctx))


def reduce(spec: EffectSpec, model: np.ndarray, cols: np.ndarray, names: list[str], units: dict[str, str],
           per_run: list[np.ndarray]) -> Reduced:
    """The part of ``cols`` the set determines jointly with the columns ``model`` (named ``names``):
    :func:`pige_sym.diagnosis.candidates.reduce_candidate` on the joint rows, at this module's ``NULL_LAMBDA``."""
    z = np.hstack([model, cols])
    k, q = model.shape[1], cols.shape[1]
    w = np.vstack([np.eye(k), np.zeros((q, k))])
    cand = Candidate(spec, spec.id, tuple(range(k, k + q)))
    return Reduced(spec, cols, reduce_candidate(z.T @ z, w, cand, names, units, null_lambda=NULL_LAMBDA), per_run)


def _rss(x: np.ndarray, y: np.ndarray) -> tuple[float, int, np.ndarray]:
    sol, _, rank, _ = np.linalg.lstsq(x, y, rcond=None)
    r = y - x @ sol
    return float(r @ r), int(rank), sol


def _finding(red: Reduced, x: np.ndarray, y: np.ndarray, before: tuple[float, int, np.ndarray],
             names: list[str], n_pige: int) -> Finding:
    """The evidence of a reduced candidate added to the design ``x`` (whitened units; σ-scaled RMS);
    ``before`` is ``x``'s own fit (RSS, rank, coefficients)."""
    from scipy.special import fdtrc  # F survival function (scipy.stats.f.sf without its import cost)

    rss0, rank0, base = before
    ext = np.hstack([x, red.columns @ red.basis])
    rss1, rank1, sol = _rss(ext, y)
    n, k = y.size, rank1 - rank0
    dof = max(n - rank1, 1)
    s2 = max(rss1 / dof, 1.0)  # rows whitened by σ ≥ the floor: a misfit below it is no evidence
    fstat = ((rss0 - rss1) / max(k, 1)) / s2
    cov = np.linalg.pinv(ext.T @ ext) * (rss1 / dof)
    theta, cov_t = sol[x.shape[1]:], cov[x.shape[1]:, x.shape[1]:]
    values, std = red.basis @ theta, np.sqrt(np.clip(np.diag(red.basis @ cov_t @ red.basis.T), 0, None))
    shift = {nm: float(sol[j] - base[j]) for j, nm in enumerate(names[:n_pige])}
    spec = red.spec
    evidence = EVIDENCE[spec.kind].format(axis=spec.axis, h=int(spec.options.get("harmonic", 1)))
    return Finding(
        effect=spec.id, options=dict(spec.options), params=dict(zip(spec.param_names, values.tolist(), strict=True)),
        std=dict(zip(spec.param_names, std.tolist(), strict=True)), units=dict(spec.units),
        delta_bic=(rss1 - rss0) / s2 + k * math.log(n), f_statistic=fstat,
        p_value=float(fdtrc(max(k, 1), dof, fstat)) if fstat > 0 else 1.0,  # as stats.f.sf
        rms_um_before=math.sqrt(rss0 / n), rms_um_after=math.sqrt(rss1 / n), heldout_rms_um_before=math.nan,
        heldout_rms_um_after=math.nan, pige_shift=shift,
        evidence=f"{evidence}, seen jointly in the ballbar setups (explains {1 - rss1 / rss0:.0%} of the "
                 "whitened residual)", explained=1 - rss1 / rss0 if rss0 > 0 else 0.0,
        removed=list(red.reduction.removed), basis=red.basis.tolist(), null=red.reduction.null.T.tolist(),
        absorbed=red.reduction.absorbed_terms(names),
    )


def search_effects(pool: list[tuple[EffectSpec, np.ndarray, list[np.ndarray]]], x: np.ndarray, y: np.ndarray,
                   names: list[str], n_pige: int, units: dict[str, str]) -> tuple[list[Finding], list[Reduced]]:
    """Forward selection of catalogue effects on the joint whitened system (module docstring).

    Parameters
    ----------
    pool : list of (EffectSpec, ndarray, list of ndarray)
        The candidates, their whitened columns (n, q) stacked like the rows of ``x``, and each setup's
        unwhitened ones.
    x : ndarray, shape=(n, K)
        Whitened joint design: PIGE columns, then each file's constant.
    y : ndarray, shape=(n,)
    names : list of str
        Names of the columns of ``x``.
    n_pige : int
        The first ``n_pige`` columns are PIGEs.
    units : dict of str to str
        Units of the PIGEs (to name what absorbs a removed direction).

    Returns
    -------
    list of Finding
        The accepted effects, in order of acceptance.
    list of Reduced
        Their reduced columns (to extend the design).
    """
    accepted: list[Finding] = []
    chosen: list[Reduced] = []
    current, current_names = x, list(names)
    for _ in range(MAX_EFFECTS):
        before = _rss(current, y)
        tried: list[tuple[Finding, Reduced]] = []
        for spec, cols, per_run in pool:
            if any(c.spec.id == spec.id for c in chosen):
                continue
            red = reduce(spec, current, cols, current_names, units, per_run)
            if red.basis.shape[1] == 0:
                continue
            tried.append((_finding(red, current, y, before, current_names, n_pige), red))
        best = min(tried, key=lambda fr: fr[0].delta_bic, default=None)
        if best is None or best[0].delta_bic > DELTA_BIC_MAX or best[0].p_value > P_MAX:
            break
        best[0].alternatives = [_alternative(f, best[0]) for f, _ in sorted(tried, key=lambda fr: fr[0].delta_bic)[1:]
                                if f.delta_bic - best[0].delta_bic < AMBIGUOUS_BIC]
        accepted.append(best[0])
        chosen.append(best[1])
        current = np.hstack([current, best[1].design(best[1].columns)])
        current_names += _names(best[1])
    return accepted, chosen


def _alternative(f: Finding, best: Finding) -> str:
    harmonic = f" (harmonic {int(f.options['harmonic'])})" if "harmonic" in f.options else ""
    return f"{f.effect}{harmonic} fits almost as well (ΔBIC {f.delta_bic - best.delta_bic:+.1f})"


def _names(red: Reduced) -> list[str]:
    """Column names of a reduced effect: its catalogue parameters when nothing was removed."""
    if red.complete:
        return [f"{red.spec.id}.{p}" for p in red.spec.param_names]
    return [f"{red.spec.id}.direction{j + 1}" for j in range(red.basis.shape[1])]


def _extended_blocks(blocks: list[Block], reduced: list[Reduced]) -> list[Block]:
    """The blocks with the accepted effects' (unwhitened) columns after the PIGE columns."""
    return [Block(b.label, b.instrument, np.hstack([b.design, *(red.design(red.per_run[i]) for red in reduced)]),
                  b.data, b.nuisance, b.nuisance_names) for i, b in enumerate(blocks)]


def diagnose_ballbar_set(machine: str, items: Sequence[tuple[str, BallbarRun]], blocks: list[Block],
                         sigmas: list[float], pige_names: list[str],
                         sigma_floor_um: float) -> tuple[list[Finding], JointResult | None]:
    """Effects of a set of ballbar setups and the PIGEs estimated jointly with them (module docstring).

    Parameters
    ----------
    machine : str
    items : sequence of (label, BallbarRun)
    blocks : list of Block
        The setups' joint blocks (:func:`pige_sym.identification.joint.file_blocks`).
    sigmas : list of float
        Their σ from their own fits [µm].
    pige_names : list of str
        The shared columns of the blocks.
    sigma_floor_um : float
        Smallest σ used [µm]: below it the first-order model's own error (exact lengths, second order in
        the PIGEs) would pass for effects in noise-free simulations.

    Returns
    -------
    list of Finding
        Accepted effects (empty: the PIGE model stands).
    JointResult or None
        The joint fit with the accepted effects' columns (their parameters named ``<id>.<param>``, or
        ``<id>.direction<j>`` for a partly determined effect), or None without effects.
    """
    runs = [run for _, run in items]
    raw = [(spec, [projected_columns(spec, run) for run in runs]) for spec in candidates(runs)]  # once
    names = pige_names + [n for b in blocks for n in b.nuisance_names]
    units = {n: u for n, u in load_kernels(machine).UNITS.items() if n in pige_names}
    found: list[Finding] = []
    sigmas = [max(s, sigma_floor_um) for s in sigmas]
    for _ in range(2):  # σ of each file again from the fit with the effects: a file that sees an effect
        x, y = whitened_system(blocks, sigmas)  # strongly had its σ inflated by it in its PIGE-only fit
        pool = [(spec, np.vstack([c / s for c, s in zip(per_run, sigmas, strict=True)]), per_run)
                for spec, per_run in raw]
        found, reduced = search_effects(pool, x, y, names, len(pige_names), units)
        if not found:
            return [], None
        ext_names = pige_names + [n for red in reduced for n in _names(red)]
        result = identify_blocks(machine, ext_names, _extended_blocks(blocks, reduced), sigmas, items)
        refit = [max(f.rms_um * math.sqrt(result.result.n_obs / max(result.result.dof, 1)), sigma_floor_um)
                 for f in result.files]
        if np.allclose(refit, sigmas, rtol=0.05):
            break
        sigmas = refit
    for red in reduced:
        if red.complete:
            result.result.units |= {f"{red.spec.id}.{p}": u for p, u in red.spec.units.items()}
    return found, result
