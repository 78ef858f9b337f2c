"""Diagnosis: what the PIGE model gets wrong, its physical cause, and what fixing it gains.

Procedure
---------
1. **Normal equations.**  The *super design* (the PIGEs and every candidate effect,
   :mod:`pige_sym.diagnosis.candidates`) is accumulated row chunk by row chunk into per-fold
   normal equations (:mod:`pige_sym.identification.normal_sums`); no dense design of the whole file
   is ever built, so 10⁶ rows cost seconds and a few MB.
2. **Gross errors.**  Rows of the PIGE fit far beyond the robust noise level that are
   *isolated* (:mod:`pige_sym.identification.outliers`) are kept out of the search; rows that line up
   with a pose variable are structure and stay in.
3. **Candidates, reduced.**  Every candidate is reduced to the part the data determine
   jointly with the PIGEs and the effects already in the model; what is removed is
   named (e.g. "the co-rotating half … = location error of the axis") and the rest is
   fitted and reported in the catalogue's parameters.  A candidate with nothing left
   is *unidentifiable*, never found.
4. **Selection** (:mod:`pige_sym.diagnosis.selection`): forward steps on ΔBIC with the F-test and
   the 5-fold held-out RMS, swaps (an early proxy cannot block the true effect) and
   backward elimination (every accepted effect must still earn its place).  Then an
   **exact best-subset** check: every subset of up to three *screened* candidates (those
   of the greedy model and the ten strongest others whose ΔBIC passed −10 against some
   model on the forward path, one per key; a drift of the greedy model at its
   interpolated τ, step 5, so that no other effect can win by absorbing the misfit of a
   grid τ) is ranked by BIC, and the least-BIC subset in which every effect is still
   supported against the same subset without it replaces the greedy model when its BIC
   is lower by more than 2 (forward steps then continue from it).  No VIF cutoff: the
   VIF and inflated standard errors are reported.  Near-ties go to the candidate with
   fewer parameters, and every candidate that replaces a finding
   almost as well (BIC gap < 10: naming one effect rather than another needs the same
   very strong evidence as accepting it at all) is reported with it as an alternative:
   the finding is then *ambiguous* ("ambiguous: …" in its sentence), because the data
   cannot tell the two apart.  That is a property of the trajectory, not of the method,
   and no selection rule can fix it.  Largest canonical correlations after the PIGEs: on
   a single cone, two squareness pairs 0.91–0.97 and a squareness with a first-harmonic
   runout of C 0.99–1.0; with C swept at ten tilts over 0..−90° only, neighbouring
   harmonics of the tilt axis 0.999.  C swept at 19 tilts over ±90° brings the
   squareness pairs to ≤ 0.16 and the tilt-axis harmonics to 0.97 (separable at
   10–40 µrad, 1–5 µm; ``tests/test_diagnosis_grid.py`` uses it for both).  On
   head machines, with the ball on the tool axis only the tool's tilt normal to it is
   seen, so wobble harmonics h and h + 2 of the tilt axis share a two-dimensional
   subspace on any trajectory and are told apart by their other halves only.
5. **Thermal τ** is refined by interpolating the drift columns between grid points
   (exact linear combinations of the accumulated sums); its standard error comes from
   the Gauss–Newton covariance with the ∂/∂ln τ column.
6. **Outliers**, against the extended model on all rows: isolated flagged rows are
   dropped if the BIC supports it (3 parameters per row).  Flagged rows that line up with
   a pose variable (one rotary angle, or consecutive rows) are structure, not outliers:
   those of the PIGE fit become candidates ``pose_cluster`` (an offset [µm], machine
   frame, of every row at that pose; the sums are extended over those rows only) that
   compete in step 4 like the others; those left against the extended model are listed
   under ``clusters``.

Findings are listed by their ΔBIC in the final model (strongest first): ΔBIC, F and
held-out RMS compare the final model with the same model without that effect.

Conventions of the effects (frames, senses, harmonics)
------------------------------------------------------
All columns are the zeroed ball-minus-nest deviation in the machine frame
(CONVENTIONS §4: ``raw(row) − R_w(row)·raw(reference)``).  θ is the commanded angle of
the axis (right-handed about its positive direction, degrees in files, radians here);
harmonic h enters as ``cos hθ``, ``sin hθ``.

- ``angular_error_<AX>`` (h = 1..4): the axis stands at ``θ + c·cos hθ + s·sin hθ``
  [µrad]; a positive value turns the carried body further in the positive sense.
- ``wobble_<AX>`` (h = 1..4): tilt error motion of the carried body about the two
  carrier-frame axes normal to the axis (``r<a>``, ``r<b>`` [µrad], right-handed), each
  ``cos hθ``/``sin hθ``.  For h = 1 the half that turns with the axis (a tilt fixed in
  the rotating body) is a location error of the axis and is removed (named); the
  counter-rotating half is fitted.
- ``radial_runout_<AX>`` (h = 1..4): translation error motion of the carried body
  normal to the axis (``d<a>``, ``d<b>`` [µm], carrier frame); h = 1 as for wobble.
- ``backlash_<AX>``: the axis stands at ``θ + (b/2)·approach`` (approach = sign of the
  last move of that axis) [µrad].
- ``squareness_XY``/``YZ``/``ZX``: ``dx = γ·ΔY``, ``dy = γ·ΔZ``, ``dx = γ·ΔZ`` with the
  commanded linear travel from the reference pose [µrad = µm/m].
- ``setup_offset``: ball/nest set up Δ [µm] away from nominal, ``d = (R_t − R_w)·Δ``;
  on table machines this is entirely location errors (unidentifiable, named).
- ``thermal_drift``: tool-to-table offset ``v·(1 − exp(−t/τ))`` [µm], machine frame.
- ``table_drift`` (probe files only): the sphere creeps on its stand, ``v·(1 − exp(−t/τ))`` [µm] in the
  table frame (t is the pose order in an imported log).

Tool-side (head) axes use the same definitions in their own carrier frame, through
the generated kernels' error-motion Jacobian, so head and table+head machines are
diagnosed like table machines.

Residual signatures (for the plots and the evidence text): residuals against time,
against each rotary angle in the radial / tangential / axial components of that
axis (so angular harmonics show at their true order), against the direction of
approach, per row, and their autocorrelation in time.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Collection
from dataclasses import dataclass
from typing import Any

import numpy as np

from pige_sym.diagnosis.candidates import (
    Candidate,
    Layout,
    add_pose_clusters,
    build_layout,
    compact_columns,
    evaluate_rows,
)
from pige_sym.diagnosis.instrument_rows import couple_final, instrument_notes, reference_prior, screen_scale
from pige_sym.diagnosis.results import EVIDENCE, DiagnosisResult, Finding, Rejected
from pige_sym.diagnosis.selection import Model, Selector, compare, select
from pige_sym.diagnosis.thermal import refine_tau
from pige_sym.errors import InputError
from pige_sym.identification.instruments import instrument
from pige_sym.identification.least_squares import identify
from pige_sym.identification.normal_sums import NormalSums, accumulate, extend, fold_of_rows
from pige_sym.identification.outliers import Cluster, flag_rows, row_residuals, split_clusters
from pige_sym.identification.result import IdentificationResult, not_identifiable
from pige_sym.identification.spectrum import observability
from pige_sym.kernels import load_kernels
from pige_sym.measurements.measurement import Measurement
from pige_sym.measurements.probe_trigger import read_sensitivities
from pige_sym.model.effects import EffectSpec
from pige_sym.model.trajectories import approach_directions

__all__ = ["DiagnosisResult", "Finding", "Rejected", "diagnose"]


DELTA_BIC_MAX = -10.0


P_MAX = 1e-4


MIN_HELDOUT_GAIN = 0.02


MAX_CLUSTERS = 5


AMBIGUOUS_BIC = 10.0  # below this BIC gap, another candidate is reported as an alternative (not "very strong" evidence)


@dataclass
class _Setup:
    kern: Any
    m: Measurement  # machine frame
    approach: np.ndarray
    layout: Layout
    folds: np.ndarray
    screen_scale: np.ndarray | None = None  # (n, 3, 3): probe rows to equal precision (search and outlier screen)

    @property
    def data(self) -> np.ndarray:
        """The deviations the search fits, shape=(n, 3): probe rows brought to one precision (``screen_scale``)."""
        dev = self.m.deviation_um
        return dev if self.screen_scale is None else np.einsum("nij,nj->ni", self.screen_scale, dev)

    def _blocks(self, cands: list[Candidate] | None) -> list[tuple[EffectSpec, tuple[int, ...]]]:
        chosen = self.layout.candidates if cands is None else cands
        blocks = {c.cols: c.spec for c in chosen if c.mix is None}
        for kind in {c.spec.kind for c in chosen if c.mix is not None}:  # interpolated drift: its whole τ grid
            blocks |= {cols: EffectSpec(kind, {"tau_s": float(t)})
                       for cols, t in zip(self.layout.drift_cols[kind], self.layout.tau_grid_s, strict=True)}
        return [(spec, cols) for cols, spec in blocks.items()]

    def raw_design(self, cands: list[Candidate] | None = None) -> Callable[[np.ndarray], np.ndarray]:
        """``rows -> (r, 3, C)`` super-design rows filling the given candidates (default all)."""
        items = self._blocks(cands)
        return lambda rows: evaluate_rows(self.layout, items, self.kern, self.m, self.approach, rows)

    def design(self, cands: list[Candidate] | None = None) -> Callable[[np.ndarray], np.ndarray]:
        """:meth:`raw_design` with probe rows brought to one precision, as the search fits them (:attr:`data`)."""
        raw = self.raw_design(cands)
        if self.screen_scale is None:
            return raw
        scale = self.screen_scale
        return lambda rows: np.einsum("nij,njc->nic", scale[rows], raw(rows))

    def residuals(self, model: Model, rows: np.ndarray) -> np.ndarray:
        """Residuals of a fitted model on ``rows``, shape=(r, 3) [µm], from a compact design."""
        items = self._blocks(model.cands)
        used = compact_columns(self.layout, items)
        beta = (model.w @ model.fit.values)[used]

        def design(r: np.ndarray) -> np.ndarray:
            return evaluate_rows(self.layout, items, self.kern, self.m, self.approach, r, compact=True)

        return row_residuals(design, np.eye(len(used)), beta, self.m.deviation_um, rows)


def _setup(m: Measurement, candidates: list[str] | None, exclude: Collection[str] = ()) -> _Setup:
    kern = load_kernels(m.machine)
    if m.frame == "table":
        m = Measurement(**{**m.__dict__, "deviation_um": m.deviation_machine_um(kern), "frame": "machine"})
    if m.n_rows < 3:
        raise InputError(f"{m.path or 'measurement'}: {m.n_rows} rows cannot be diagnosed: measure more points")
    approach = approach_directions(m.angles_deg)
    probe = instrument(m) == "sphere-probe"
    layout = build_layout(kern, m.angles_deg, m.t_s, approach, candidates, table_drift=probe, exclude=exclude,
                          probe_sensitivity=read_sensitivities(m) if probe else None, reference_centre=probe)
    return _Setup(kern, m, approach, layout, fold_of_rows(m.n_rows), screen_scale(m) if probe else None)


def _move_rows(sums: NormalSums, setup: _Setup, rows: list[int], sign: float) -> None:
    """Add (+1) or remove (−1) rows from the normal equations."""
    if rows:
        r = np.array(sorted(rows), dtype=int)
        sums.add_rows(setup.design()(r), setup.data[r], setup.folds[r], sign)


def _screen(setup: _Setup, model: Model, rows: np.ndarray, resid: np.ndarray | None = None
            ) -> tuple[list[int], list[Cluster]]:
    """Isolated flagged rows and clusters of ``model``'s residuals (r, 3) [µm] on ``rows`` (computed if not given)."""
    if resid is None:
        resid = setup.residuals(model, rows)
    if setup.screen_scale is not None:
        resid = np.einsum("nij,nj->ni", setup.screen_scale[rows], resid)
    flagged = flag_rows(resid, rows)
    return split_clusters(flagged, setup.m.angles_deg, tuple(setup.kern.ROTARY_AXES), setup.m.n_rows, setup.m.t_s)


def _param_names(model: Model) -> list[str]:
    """Reported names of the extension parameters, ``<id>.<param>`` (``<id>@h<h>.<param>`` if an id repeats)."""
    ids = [c.spec.id for c in model.cands]
    out = []
    for c in model.cands:
        pre = c.spec.id if ids.count(c.spec.id) == 1 else f"{c.spec.id}@h{c.spec.harmonic}"
        out += [f"{pre}.{p}" for p in c.spec.param_names]
    return out


def _catalogue_transform(model: Model, n_pige: int) -> np.ndarray:
    """Matrix from model coefficients to PIGEs + catalogue parameters, shape=(P + Σq, K)."""
    q = sum(len(c.spec.param_names) for c in model.cands)
    t = np.zeros((n_pige + q, model.w.shape[1]))
    t[:n_pige, :n_pige] = np.eye(n_pige)
    row = n_pige
    for red, blk in zip(model.reductions, model.blocks, strict=True):
        t[row: row + red.basis.shape[0], blk] = red.basis
        row += red.basis.shape[0]
    return t


def _identification(setup: _Setup, model: Model, resid: np.ndarray) -> IdentificationResult:
    """The model's estimate as an IdentificationResult (PIGEs, then catalogue parameters)."""
    lay, f = setup.layout, model.fit
    p = len(lay.pige)
    t = _catalogue_transform(model, p)
    names = list(lay.pige) + _param_names(model)
    units = dict(lay.units)
    ext = iter(names[p:])
    for c in model.cands:
        for q in c.spec.param_names:
            units[next(ext)] = c.spec.units[q]
    ident = np.concatenate([np.isfinite(f.vif[:p]), np.ones(t.shape[0] - p, dtype=bool)])
    sigma2 = f.sigma2
    values = np.where(ident, t @ f.values, np.nan)
    cov = t @ f.cov_unit @ t.T * sigma2
    std = np.where(ident, np.sqrt(np.clip(np.diag(cov), 0, None)), np.nan)
    null_space, combos = not_identifiable(f.null_space, list(model.names), units)
    m = setup.m
    k = model.w.shape[1]
    cond = float(f.svals[0] / f.svals[f.rank - 1]) if f.rank == k and f.rank > 0 else float("inf")
    return IdentificationResult(
        machine=setup.kern.MACHINE_CODE, method="diagnosis", projection="xyz", loss="linear", parameters=names,
        units={n: units.get(n, "") for n in names}, values=values, std=std, covariance=cov, identifiable=ident,
        rms_um=math.sqrt(f.rss / max(f.n_obs, 1)), sigma_um=math.sqrt(sigma2) if math.isfinite(sigma2) else math.nan,
        dof=max(f.n_obs - f.rank, 0), n_rows=m.n_rows, n_obs=f.n_obs, rank=f.rank, condition=cond,
        singular_values=f.svals, observability=observability(f.svals, f.n_obs), unidentifiable=combos,
        outlier_rows=[], residuals_um=resid, ball_mm=[float(x) for x in m.ball_mm],
        pivots_mm={a: [float(x) for x in v] for a, v in m.pivots_mm.items()},
        tool_mm=None if m.tool_mm is None else [float(x) for x in m.tool_mm], vif=None,
        axis_sense=dict(m.axis_sense), null_space=null_space,
    )


def _couple(setup: _Setup, model: Model, result: IdentificationResult, outliers: list[int]) -> None:
    """Replace a probe file's final estimate by the generalised least squares with its rows' correlation."""
    transform = _catalogue_transform(model, len(setup.layout.pige))
    couple_final(setup.m, setup.layout, model, setup.raw_design(model.cands), transform, result, outliers)


def _alternatives(selector: Selector, final: Model, i: int) -> list[str]:
    """Candidates that replace the i-th effect almost as well (BIC gap < AMBIGUOUS_BIC): the data barely tell
    them apart (e.g. neighbouring harmonics over a short tilt range)."""
    c = final.cands[i]
    others = {x.key for j, x in enumerate(final.cands) if j != i}
    best: dict[str, float] = {}
    for alt in selector.layout.candidates:
        if alt.key == c.key or alt.key in others:
            continue
        trial = selector.model(final.cands[:i] + final.cands[i + 1:] + [alt])
        gap = trial.bic - final.bic
        name = alt.key if alt.spec.kind != "thermal_drift" else "thermal_drift"
        if trial.reductions[-1].basis.shape[1] and gap < AMBIGUOUS_BIC and gap < best.get(name, math.inf):
            best[name] = gap
    return [f"{name} fits almost as well (ΔBIC {gap:+.1f})" for name, gap in sorted(best.items(), key=lambda x: x[1])]


def _finding(selector: Selector, final: Model, i: int, tau_std: dict[str, float]) -> Finding:
    """The evidence of the i-th effect of the final model against the final model without it."""
    c, red, blk = final.cands[i], final.reductions[i], final.blocks[i]
    small = selector.without(final, i)
    cmp = compare(small, final)
    f = final.fit
    names = list(c.spec.param_names)
    vals = red.basis @ f.values[blk]
    cov = red.basis @ f.cov_unit[blk, blk] @ red.basis.T * f.sigma2
    std = np.sqrt(np.clip(np.diag(cov), 0, None))
    emb = c.embedding(selector.layout.n_columns)
    alone = np.diag(emb.T @ selector.sums.total_gram @ emb)
    vif = np.where(alone > 0, np.diag(cov) / f.sigma2 * alone, np.inf)
    params = dict(zip(names, vals.tolist(), strict=True))
    stds = dict(zip(names, std.tolist(), strict=True))
    units = dict(c.spec.units)
    if c.spec.kind in tau_std:
        params["tau_s"], stds["tau_s"], units["tau_s"] = float(c.spec.options["tau_s"]), tau_std[c.spec.kind], "s"
    shift = {n: float(final.fit.values[j] - small.fit.values[j]) for j, n in enumerate(selector.layout.pige)}
    explained = 1.0 - f.rss / small.fit.rss if small.fit.rss > 0 else 0.0
    evidence = EVIDENCE[c.spec.kind].format(axis=c.spec.axis, h=int(c.spec.options.get("harmonic", 1)))
    absorbed = red.absorbed_terms(list(selector.layout.pige))
    return Finding(
        effect=c.spec.id, options=dict(c.spec.options), params=params, std=stds, units=units,
        delta_bic=cmp.delta_bic, f_statistic=cmp.f_statistic, p_value=cmp.p_value,
        rms_um_before=math.sqrt(small.fit.rss / small.fit.n_obs), rms_um_after=math.sqrt(f.rss / f.n_obs),
        heldout_rms_um_before=small.fit.heldout_rms, heldout_rms_um_after=f.heldout_rms, pige_shift=shift,
        evidence=f"{evidence} (explains {explained:.0%} of the residual)", explained=explained,
        vif=dict(zip(names, vif.tolist(), strict=True)), removed=list(red.removed),
        basis=red.basis.tolist(), null=red.null.T.tolist(), absorbed=absorbed,
        alternatives=_alternatives(selector, final, i),
    )


def _outlier_step(setup: _Setup, selector: Selector, final: Model, all_rows: np.ndarray, suspects: list[int],
                  delta_bic_max: float) -> tuple[Selector, Model, Finding | None, Rejected, list[Cluster]]:
    """Judge isolated rows against the extended model on all rows (module docstring, step 6)."""
    sums = selector.sums
    _move_rows(sums, setup, suspects, +1.0)  # all rows back
    everything = Selector(sums, setup.layout) if suspects else selector  # unchanged sums: keep the cache
    full = everything.model(final.cands)
    isolated, clusters = _screen(setup, full, all_rows)
    if not isolated:
        why = "no isolated row lies beyond the robust noise level of the extended model"
        return everything, full, None, Rejected("outliers", {}, why), clusters
    kept_sums = NormalSums(sums.gram.copy(), sums.rhs.copy(), sums.yy.copy(), sums.n_obs.copy())
    _move_rows(kept_sums, setup, isolated, -1.0)
    cleaned = Selector(kept_sums, setup.layout)
    after = cleaned.model(final.cands)
    n = full.fit.n_obs
    bic_after = n * math.log(max(after.fit.rss, 1e-300) / n) + (after.fit.rank + after.extra + 3 * len(isolated)) * \
        math.log(n)
    dbic = bic_after - full.bic
    if dbic > delta_bic_max:
        why = f"rows {isolated} stand out but dropping them is not supported (ΔBIC {dbic:.1f})"
        return everything, full, None, Rejected("outliers", {}, why, dbic), clusters
    finding = Finding(
        effect="outliers", options={}, params={"rows": float(len(isolated))}, std={"rows": 0.0},
        units={"rows": "count"}, delta_bic=dbic, f_statistic=float("nan"), p_value=float("nan"),
        rms_um_before=math.sqrt(full.fit.rss / full.fit.n_obs), rms_um_after=math.sqrt(after.fit.rss / after.fit.n_obs),
        heldout_rms_um_before=full.fit.heldout_rms, heldout_rms_um_after=after.fit.heldout_rms,
        pige_shift={p: float(after.fit.values[j] - full.fit.values[j]) for j, p in enumerate(setup.layout.pige)},
        evidence=f"isolated rows {isolated} lie far beyond the robust noise level of the extended model",
        explained=float("nan"),
    )
    return cleaned, after, finding, Rejected("outliers", {}, "accepted"), clusters


def _add_clusters(setup: _Setup, sums: NormalSums, clusters: list[Cluster]) -> NormalSums:
    """Make the largest pose clusters of the PIGE fit candidates (``pose_cluster``) and extend the sums."""
    chosen = sorted(clusters, key=lambda c: -len(c.rows))[:MAX_CLUSTERS]
    if not chosen:
        return sums
    new = add_pose_clusters(setup.layout, [c.options for c in chosen])
    rows = np.array(sorted(set().union(*(c.pose_rows for c in chosen))), dtype=int)
    x = setup.design()(rows)
    return extend(sums, 3 * len(new), x, setup.data[rows], setup.folds[rows])


def _rejections(reasons: dict[str, str], layout: Layout, final: Model) -> list[Rejected]:
    """One entry per effect id not in the final model: its best-scoring variant's reason."""
    by_label = {c.label: c for c in layout.candidates}
    in_model = {c.spec.id for c in final.cands}
    out: dict[str, Rejected] = {}
    for label, why in reasons.items():
        c = by_label.get(label)
        if c is None or c.spec.id in in_model:
            continue
        prev = out.get(c.spec.id)
        dbic = _dbic_of(why)
        if prev is None or (dbic is not None and (prev.delta_bic is None or dbic < prev.delta_bic)):
            out[c.spec.id] = Rejected(c.spec.id, dict(c.spec.options), why, dbic)
    return list(out.values())


def _dbic_of(reason: str) -> float | None:
    """The ΔBIC a rejection reason states (``ΔBIC -3.4``), or None."""
    import re

    found = re.search(r"ΔBIC (-?\d+(?:\.\d+)?)", reason)
    return None if found is None else float(found.group(1))


def diagnose(m: Measurement, *, delta_bic_max: float = DELTA_BIC_MAX, p_max: float = P_MAX,
             min_heldout_gain: float = MIN_HELDOUT_GAIN, candidates: list[str] | None = None,
             progress: bool = False, exclude: Collection[str] = ()) -> DiagnosisResult:
    """Diagnose a measurement (see the module docstring).

    Parameters
    ----------
    m : Measurement
    delta_bic_max, p_max, min_heldout_gain : float
        Evidence an extension needs (:mod:`pige_sym.diagnosis.selection`).
    candidates : list of str, optional
        Restrict to these catalogue ids.
    exclude : collection of str
        Leave out these catalogue ids (``pige diagnose --map``: the maps hold every harmonic of their motions).
    progress : bool
        Show a progress bar (stderr) over the candidate evaluations.

    Returns
    -------
    DiagnosisResult
    """
    setup = _setup(m, candidates, exclude)
    lay, dev = setup.layout, setup.data
    all_rows = np.arange(1, setup.m.n_rows)
    sums = accumulate(setup.design(), dev, all_rows, setup.folds, lay.n_columns)
    if lay.nuisance and setup.screen_scale is not None:
        reference_prior(sums, len(lay.pige), setup.screen_scale[0])
    base_model = Selector(sums, lay).model([])
    base_resid = _residuals(setup, base_model)
    suspects, clusters0 = _screen(setup, base_model, all_rows, base_resid[1:])
    if candidates is None or "pose_cluster" in candidates:
        sums = _add_clusters(setup, sums, clusters0)
    _move_rows(sums, setup, suspects, -1.0)
    selector = Selector(sums, lay)
    from tqdm import tqdm

    with tqdm(desc="diagnosis", unit="fit", disable=not progress, leave=False) as bar:
        final, reasons = select(selector, lay.candidates, delta_bic_max=delta_bic_max, p_max=p_max,
                                min_gain=min_heldout_gain, progress=bar.update,
                                refine=lambda sel, model: refine_tau(sel, model)[0])
    selector, final, out_finding, out_note, clusters = _outlier_step(setup, selector, final, all_rows, suspects,
                                                                     delta_bic_max)
    final, tau_std = refine_tau(selector, final)
    findings = sorted((_finding(selector, final, i, tau_std) for i in range(len(final.cands))),
                      key=lambda f: f.delta_bic)
    if instrument(m) == "sphere-probe":  # a probe log has no clock: t is the pose's order (conventions §7)
        for f in findings:
            f.units |= {"tau_s": "poses"} if "tau_s" in f.units else {}
    outlier_rows: list[int] = []
    if out_finding is not None:
        findings.append(out_finding)
        outlier_rows = [int(x) for x in out_finding.evidence.split("[")[1].split("]")[0].split(",")]
    rejected = _rejections(reasons, lay, final)
    if out_finding is None:
        rejected.append(out_note)
    final_resid = _residuals(setup, final)
    final_result = _identification(setup, final, final_resid)
    final_result.outlier_rows = outlier_rows
    baseline = _identification(setup, base_model, base_resid)
    notes = instrument_notes(m, findings)
    if notes and not findings:
        # the PIGE model stands: its estimate with the instrument's correlations (honest standard errors)
        final_result = baseline = identify(m)
        final_result.method = "diagnosis"
    elif notes:
        _couple(setup, final, final_result, outlier_rows)
    bf = base_model.fit
    return DiagnosisResult(
        machine=setup.kern.MACHINE_CODE, baseline_rms_um=math.sqrt(bf.rss / bf.n_obs), baseline_bic=base_model.bic,
        baseline_heldout_rms_um=bf.heldout_rms, findings=findings, rejected=rejected, final=final_result,
        baseline=baseline, outlier_rows=outlier_rows,
        clusters=[f"rows {c.rows} ({c.where}) deviate together: structured signal kept as data, not outliers"
                  for c in clusters] + notes,
    )


def _residuals(setup: _Setup, model: Model) -> np.ndarray:
    """Residuals of a model on every row, reference row (zero) included, shape=(n, 3) [µm]."""
    rows = np.arange(1, setup.m.n_rows)
    out = np.zeros((setup.m.n_rows, 3))
    out[1:] = setup.residuals(model, rows)
    return out
