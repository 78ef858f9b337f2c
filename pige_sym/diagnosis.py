"""Diagnosis: what the PIGE model gets wrong, its physical cause, and what fixing it gains.

Procedure
---------
1. **Outliers.**  A robust (soft-L1) PIGE fit flags rows whose residual norm is far
   beyond the robust noise level; if dropping them is supported by BIC, the finding
   ``outliers`` is recorded and those rows are left out of everything that follows.
2. **Candidates.**  Every effect of :mod:`pige_sym.effects` applicable to the machine
   and the data is a candidate model extension, built through the kinematic chain:
   angular positioning error of each rotary axis (harmonics 1–4), tilt (wobble) and
   radial error motions (harmonics 1–3), backlash (only when the data approach
   positions from both sides), thermal drift (time constant scanned on a grid,
   counted as one more parameter), linear-axis squareness, setup offset.
3. **Identifiability first.**  A candidate is fitted jointly with the PIGEs (and the
   extensions already accepted).  If the joint design is rank-deficient, or a
   candidate parameter's variance inflation factor exceeds ``vif_max`` (it is
   confounded), the candidate is reported as *unidentifiable*, naming the
   confounded combination — never as found.
4. **Evidence.**  For each identifiable candidate: ΔBIC = BIC(extended) − BIC(current)
   with ``BIC = N ln(RSS/N) + k ln N``; the nested F-test; and the held-out RMS by
   leave-one-row-out cross-validation (exact for linear least squares:
   ``e₍ᵢ₎ = (I − H_ii)⁻¹ eᵢ`` with H_ii the row's block of the hat matrix).
5. **Greedy acceptance.**  The candidate with the lowest ΔBIC is accepted if
   ΔBIC ≤ ``delta_bic_max`` (−10: very strong evidence), the F-test p-value is below
   ``p_max`` (1e-4, conservative for ~30 candidates) and the held-out RMS drops by at
   least ``min_heldout_gain`` (2 %).  Repeat until no candidate passes.

Residual signatures (for the plots and the evidence text): residuals against time,
against each rotary angle in the radial / tangential / axial components of that
axis (so angular harmonics show at their true order), against the direction of
approach, per row, and their autocorrelation in time.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from scipy import stats
from tqdm import tqdm

from pige_sym.effects import EffectContext, EffectSpec
from pige_sym.errors import InputError
from pige_sym.identification import ExtraColumns, IdentificationResult, build_problem, identify
from pige_sym.io import Measurement
from pige_sym.kernels import load_kernels

DELTA_BIC_MAX = -10.0
P_MAX = 1e-4
MIN_HELDOUT_GAIN = 0.02
VIF_MAX = 30.0
TAU_FRACTIONS = (0.05, 0.1, 0.2, 0.35, 0.5, 1.0, 2.0, 5.0)

_EVIDENCE = {
    "thermal_drift": "a smooth trend of the residual with time (warm-up), not with the angles",
    "angular_error": "a tangential residual about {axis} at harmonic {h} of the {axis} angle",
    "wobble": "a residual from a tilt of the {axis} axis that repeats {h}x per revolution",
    "radial_runout": "a radial residual of the {axis} axis that repeats {h}x per revolution",
    "backlash": "a residual that changes sign with the direction of approach of {axis}",
    "squareness": "a residual proportional to the commanded linear travel",
    "setup_offset": "a residual that turns with the table",
}


@dataclass
class Finding:
    """An accepted model extension with its evidence."""

    effect: str
    options: dict[str, float]
    params: dict[str, float]
    std: dict[str, float]
    units: dict[str, str]
    delta_bic: float
    f_statistic: float
    p_value: float
    rms_um_before: float
    rms_um_after: float
    heldout_rms_um_before: float
    heldout_rms_um_after: float
    pige_shift: dict[str, float]
    evidence: str
    explained: float

    def to_dict(self) -> dict[str, Any]:
        return {
            "effect": self.effect, "options": self.options, "params": self.params, "std": self.std,
            "units": self.units, "delta_bic": self.delta_bic, "f_statistic": self.f_statistic,
            "p_value": self.p_value, "rms_um_before": self.rms_um_before, "rms_um_after": self.rms_um_after,
            "heldout_rms_um_before": self.heldout_rms_um_before, "heldout_rms_um_after": self.heldout_rms_um_after,
            "pige_shift": self.pige_shift, "evidence": self.evidence, "explained_fraction": self.explained,
        }

    def sentence(self) -> str:
        """One-line verdict."""
        vals = ", ".join(f"{k}={v:.3g}±{self.std[k]:.2g} {self.units[k]}" for k, v in self.params.items())
        opts = "".join(f" {k}={v:g}" for k, v in self.options.items())
        big = max(self.pige_shift.items(), key=lambda kv: abs(kv[1]), default=None)
        # E<direction>0<axis>: a linear direction (X, Y, Z) is a position error in µm, else µrad
        unit = "um" if big and big[0][1:2] in ("X", "Y", "Z") else "urad"
        moved = f"; moves {big[0]} by {big[1]:+.3g} {unit}" if big and abs(big[1]) > 0 else ""
        return (f"{self.effect}{opts}: {self.evidence}; {vals}; held-out RMS {self.heldout_rms_um_before:.3g} → "
                f"{self.heldout_rms_um_after:.3g} um (ΔBIC {self.delta_bic:.1f}){moved}")


@dataclass
class Rejected:
    """A candidate that was tried and not accepted, and why."""

    effect: str
    options: dict[str, float]
    reason: str
    delta_bic: float | None = None
    p_value: float | None = None

    def to_dict(self) -> dict[str, Any]:
        return {"effect": self.effect, "options": self.options, "reason": self.reason,
                "delta_bic": self.delta_bic, "p_value": self.p_value}


@dataclass
class DiagnosisResult:
    """Outcome of a diagnosis."""

    machine: str
    baseline_rms_um: float
    baseline_bic: float
    baseline_heldout_rms_um: float
    findings: list[Finding]
    rejected: list[Rejected]
    final: IdentificationResult
    baseline: IdentificationResult
    outlier_rows: list[int]
    plots: list[str] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        final = self.final.to_dict()
        return {
            "machine": self.machine,
            "baseline": {"rms_um": self.baseline_rms_um, "bic": self.baseline_bic,
                         "heldout_rms_um": self.baseline_heldout_rms_um},
            "findings": [f.to_dict() for f in self.findings],
            "rejected": [r.to_dict() for r in self.rejected],
            "pige": final["pige"], "std": final["std"], "units": final["units"],
            "unidentifiable": final["unidentifiable"], "rank": final["rank"], "condition": final["condition"],
            "rms_um": final["rms_um"], "outlier_rows": self.outlier_rows, "method": "diagnosis",
            "ball_mm": final["ball_mm"], "pivots_mm": final["pivots_mm"], "tool_mm": final["tool_mm"],
            "plots": self.plots,
        }

    def verdict(self) -> str:
        if not self.findings:
            return (f"No effect beyond the PIGEs is supported by the data (residual RMS {self.baseline_rms_um:.3g} um, "
                    f"{len(self.rejected)} candidates tried).")
        return "\n".join(f"- {f.sentence()}" for f in self.findings)


@dataclass
class _Fit:
    result: IdentificationResult
    rss: float
    n_obs: int
    k: int
    heldout_rms: float
    residual_rows: np.ndarray


def _bic(rss: float, n: int, k: int) -> float:
    return n * math.log(max(rss, 1e-300) / n) + k * math.log(n)


def _fit(m: Measurement, rows: np.ndarray, extra: ExtraColumns | None) -> _Fit:
    res = identify(m, extra=extra, rows=rows)
    prob = build_problem(m, "xyz", extra=extra, rows=rows, explicit=True)
    assert prob.design is not None and prob.data is not None
    a = prob.design[rows]  # (r, 3, P)
    vals = np.nan_to_num(np.where(np.isfinite(res.values), res.values, 0.0))
    e = prob.data[rows] - a @ vals
    rss = float((e**2).sum())
    # leave-one-row-out residuals: e_(i) = (I - H_ii)^-1 e_i
    flat = a.reshape(-1, a.shape[2])
    pinv = np.linalg.pinv(flat.T @ flat)
    loo = np.empty_like(e)
    for i in range(a.shape[0]):
        h = a[i] @ pinv @ a[i].T
        try:
            loo[i] = np.linalg.solve(np.eye(3) - h, e[i])
        except np.linalg.LinAlgError:
            loo[i] = np.inf
    heldout = math.sqrt(float((loo**2).mean()))
    return _Fit(res, rss, prob.n_obs, res.rank, heldout, e)


def _candidates(m: Measurement, kern: Any) -> list[EffectSpec]:
    out: list[EffectSpec] = []
    duration = float(m.t_s[-1] - m.t_s[0])
    if duration > 0:
        out += [EffectSpec("thermal_drift", {"tau_s": f * duration}) for f in TAU_FRACTIONS]
    appr = EffectContext(kern, m.angles_deg, m.t_s, m.ball_mm).approach
    assert appr is not None
    for k, ax in enumerate(kern.ROTARY_AXES):
        if np.ptp(m.angles_deg[:, k]) < 1e-9:
            continue
        out += [EffectSpec(f"angular_error_{ax}", {"harmonic": h}) for h in (1, 2, 3, 4)]
        out += [EffectSpec(f"wobble_{ax}", {"harmonic": h}) for h in (1, 2, 3)]
        out += [EffectSpec(f"radial_runout_{ax}", {"harmonic": h}) for h in (1, 2, 3)]
        if (appr[:, k] > 0).any() and (appr[:, k] < 0).any():
            out.append(EffectSpec(f"backlash_{ax}"))
    out += [EffectSpec(f"squareness_{p}") for p in ("XY", "YZ", "ZX")]
    out.append(EffectSpec("setup_offset"))
    return out


def _extra(specs: list[EffectSpec], ctx: EffectContext) -> ExtraColumns | None:
    if not specs:
        return None
    names, units, cols = [], {}, []
    for s in specs:
        c = s.columns(ctx)
        for p in s.param_names:
            names.append(f"{s.id}.{p}")
            units[f"{s.id}.{p}"] = s.units[p]
        cols.append(c)
    return ExtraColumns(names, units, np.concatenate(cols, axis=2))


def diagnose(m: Measurement, *, delta_bic_max: float = DELTA_BIC_MAX, p_max: float = P_MAX,
             min_heldout_gain: float = MIN_HELDOUT_GAIN, vif_max: float = VIF_MAX,
             candidates: list[str] | None = None, progress: bool = False) -> DiagnosisResult:
    """Diagnose a measurement (see the module docstring).

    Parameters
    ----------
    m : Measurement
    candidates : list of str, optional
        Restrict to these catalogue ids.
    progress : bool
        Show a progress bar (stderr) over the candidates of each greedy round.

    Returns
    -------
    DiagnosisResult
    """
    kern = load_kernels(m.machine)
    if m.frame == "table":
        m = Measurement(**{**m.__dict__, "deviation_um": m.deviation_machine_um(kern), "frame": "machine"})
    ctx = EffectContext(kern, m.angles_deg, m.t_s, m.ball_mm, m.pivots_mm or None, m.tool_mm)
    rows = np.arange(1, m.n_rows)
    base = _fit(m, rows, None)
    findings: list[Finding] = []
    rejected: list[Rejected] = []

    # rows a robust fit flags are kept out of the search; whether they are outliers is
    # decided at the end, against the extended model (a missing effect can look like outliers)
    suspects = list(identify(m, loss="soft_l1").outlier_rows)
    all_rows = rows
    rows = np.setdiff1d(all_rows, suspects)
    current = _fit(m, rows, None)
    baseline_fit = current
    accepted: list[EffectSpec] = []
    pool = [c for c in _candidates(m, kern) if candidates is None or c.id in candidates]
    while pool:
        best: tuple[float, EffectSpec, _Fit, float, float] | None = None
        tried: dict[str, Rejected] = {}
        for spec in tqdm(pool, desc=f"diagnosis round {len(accepted) + 1}", unit="candidate", leave=False,
                         disable=not progress):
            extra = _extra(accepted + [spec], ctx)
            fit = _fit(m, rows, extra)
            q = len(spec.param_names) + (1 if spec.kind == "thermal_drift" else 0)
            names = fit.result.parameters
            cand_idx = [names.index(f"{spec.id}.{p}") for p in spec.param_names]
            vif = fit.result.vif if fit.result.vif is not None else np.full(len(names), np.inf)
            confounded = [names[j] for j in cand_idx if not np.isfinite(vif[j]) or vif[j] > vif_max]
            key = spec.id
            if fit.result.rank < len(names) or confounded:
                combos = "; ".join(fit.result.unidentifiable) or f"VIF > {vif_max:g} for {', '.join(confounded)}"
                tried.setdefault(key, Rejected(key, dict(spec.options), f"unidentifiable with the PIGEs: {combos}"))
                continue
            dbic = _bic(fit.rss, current.n_obs, current.k + q) - _bic(current.rss, current.n_obs, current.k)
            dof = max(fit.n_obs - current.k - q, 1)
            f_stat = ((current.rss - fit.rss) / q) / (fit.rss / dof) if fit.rss > 0 else float("inf")
            p_val = float(stats.f.sf(f_stat, q, dof))
            prev = tried.get(key)
            if prev is None or prev.delta_bic is None or dbic < prev.delta_bic:
                tried[key] = Rejected(key, dict(spec.options), "", dbic, p_val)
            if best is None or dbic < best[0]:
                best = (dbic, spec, fit, f_stat, p_val)
        if best is None:
            rejected += list(tried.values())
            break
        dbic, spec, fit, f_stat, p_val = best
        gain = 1.0 - fit.heldout_rms / current.heldout_rms if current.heldout_rms > 0 else 0.0
        if dbic > delta_bic_max or p_val > p_max or gain < min_heldout_gain:
            for r in tried.values():
                if not r.reason:
                    r.reason = (f"not significant (ΔBIC {r.delta_bic:.1f}, p {r.p_value:.2g})"
                                if r.effect != spec.id else
                                f"best candidate but not significant (ΔBIC {dbic:.1f}, p {p_val:.2g}, "
                                f"held-out gain {gain:.1%})")
            rejected += list(tried.values())
            break
        if spec.kind == "thermal_drift":
            spec, fit, tau_std = _refine_tau(m, rows, accepted, spec, ctx, fit)
        names = fit.result.parameters
        params = {p: fit.result.value(f"{spec.id}.{p}") for p in spec.param_names}
        std = {p: float(fit.result.std[names.index(f"{spec.id}.{p}")]) for p in spec.param_names}
        units = dict(spec.units)
        if spec.kind == "thermal_drift":
            params["tau_s"], std["tau_s"], units["tau_s"] = float(spec.options["tau_s"]), tau_std, "s"
        explained = 1.0 - fit.rss / current.rss if current.rss > 0 else 0.0
        h = int(spec.options.get("harmonic", 1))
        evidence = _EVIDENCE[spec.kind].format(axis=spec.axis, h=h)
        findings.append(Finding(
            effect=spec.id, options=dict(spec.options), params=params, std=std, units=units, delta_bic=dbic,
            f_statistic=f_stat, p_value=p_val, rms_um_before=math.sqrt(current.rss / current.n_obs),
            rms_um_after=math.sqrt(fit.rss / fit.n_obs), heldout_rms_um_before=current.heldout_rms,
            heldout_rms_um_after=fit.heldout_rms, pige_shift=_shift(current.result, fit.result),
            evidence=f"{evidence} (explains {explained:.0%} of the residual)", explained=explained,
        ))
        accepted.append(spec)
        current = fit
        pool = [c for c in pool if c.id != spec.id]
    # outliers, against the extended model, on all rows
    extra = _extra(accepted, ctx)
    final_all = _fit(m, all_rows, extra)
    outliers = list(identify(m, loss="soft_l1", extra=extra).outlier_rows)
    current = final_all
    if outliers:
        kept = np.setdiff1d(all_rows, outliers)
        after = _fit(m, kept, extra)
        # each dropped row counts as 3 free parameters in the BIC on the full data
        dbic = _bic(after.rss, final_all.n_obs, after.k + 3 * len(outliers)) - _bic(
            final_all.rss, final_all.n_obs, final_all.k)
        if dbic <= delta_bic_max:
            findings.append(Finding(
                effect="outliers", options={}, params={"rows": float(len(outliers))}, std={"rows": 0.0},
                units={"rows": "count"}, delta_bic=dbic, f_statistic=float("nan"), p_value=float("nan"),
                rms_um_before=math.sqrt(final_all.rss / final_all.n_obs),
                rms_um_after=math.sqrt(after.rss / after.n_obs), heldout_rms_um_before=final_all.heldout_rms,
                heldout_rms_um_after=after.heldout_rms, pige_shift=_shift(final_all.result, after.result),
                evidence=f"rows {outliers} lie far beyond the robust noise level of the fit", explained=float("nan"),
            ))
            current = after
        else:
            rejected.append(Rejected("outliers", {}, f"rows {outliers} flagged by the robust fit but dropping them "
                                     f"is not supported (ΔBIC {dbic:.1f})", dbic))
            outliers = []
    else:
        rejected.append(Rejected("outliers", {}, "the robust fit flags no row"))
    if not suspects:
        baseline_fit = base
    return DiagnosisResult(
        machine=kern.MACHINE_CODE, baseline_rms_um=math.sqrt(baseline_fit.rss / baseline_fit.n_obs),
        baseline_bic=_bic(baseline_fit.rss, baseline_fit.n_obs, baseline_fit.k),
        baseline_heldout_rms_um=baseline_fit.heldout_rms, findings=findings,
        rejected=_dedupe(rejected), final=current.result, baseline=base.result, outlier_rows=sorted(outliers),
    )


def _refine_tau(m: Measurement, rows: np.ndarray, accepted: list[EffectSpec], spec: EffectSpec,
                ctx: EffectContext, fit: _Fit) -> tuple[EffectSpec, _Fit, float]:
    """Refine the thermal time constant (1-D search on log τ) and propagate its uncertainty.

    Returns the refined spec, a fit whose standard errors include the τ direction
    (Gauss–Newton covariance with the ∂/∂τ column), and the standard error of τ [s].
    """
    from scipy.optimize import minimize_scalar

    tau0 = float(spec.options["tau_s"])

    def rss(log_tau: float) -> float:
        s2 = EffectSpec(spec.id, {"tau_s": float(np.exp(log_tau))})
        return _fit(m, rows, _extra(accepted + [s2], ctx)).rss

    opt = minimize_scalar(rss, bounds=(np.log(tau0) - 1.2, np.log(tau0) + 1.2), method="bounded",
                          options={"xatol": 1e-3})
    tau = float(np.exp(opt.x))
    best = EffectSpec(spec.id, {"tau_s": tau})
    extra = _extra(accepted + [best], ctx)
    assert extra is not None
    fit = _fit(m, rows, extra)
    v = np.array([fit.result.value(f"{spec.id}.{p}") for p in best.param_names])
    h = 1e-4 * tau
    dcols = EffectSpec(spec.id, {"tau_s": tau + h}).columns(ctx) - EffectSpec(spec.id, {"tau_s": tau - h}).columns(ctx)
    tau_col = (dcols / (2 * h)) @ v
    aug = ExtraColumns(extra.names + [f"{spec.id}.tau_s"], extra.units | {f"{spec.id}.tau_s": "s"},
                       np.concatenate([extra.columns, tau_col[:, :, None]], axis=2))
    with_tau = identify(m, extra=aug, rows=rows)
    fit.result.std = np.concatenate([with_tau.std[:-1]])
    tau_std = float(with_tau.std[-1])
    return best, fit, tau_std


def _dedupe(rejected: list[Rejected]) -> list[Rejected]:
    seen: dict[str, Rejected] = {}
    for r in rejected:
        seen[r.effect] = r
    return list(seen.values())


def _shift(before: IdentificationResult, after: IdentificationResult) -> dict[str, float]:
    out = {}
    for j, p in enumerate(before.parameters):
        if p in after.parameters and "." not in p:
            out[p] = float(after.value(p) - before.values[j])
    return out


# ---------------------------------------------------------------------------------------------
# residual signatures and plots


def axis_frames(m: Measurement, kern: Any) -> dict[str, np.ndarray]:
    """Per workpiece-side rotary axis and row, unit vectors (radial, tangential, axial) in M, shape=(n, 3, 3).

    Axial is the axis direction at the pose, radial points from the axis line to the
    nest (ball) position, tangential = axial × radial.  (Tool-side axes: not yet.)
    """
    structure = m.structure
    angles = dict(zip(kern.ROTARY_AXES, np.radians(m.angles_deg).T, strict=True))
    nest = kern.linear_commands(m.angles_deg, m.ball_mm, m.pivots_mm or None, m.tool_mm)
    out = {}
    n = m.n_rows

    def rot(axis: str, sign: int) -> np.ndarray:
        d = "ABC".index(axis[0])
        th = sign * angles[axis]
        c, s = np.cos(th), np.sin(th)
        r = np.tile(np.eye(3), (n, 1, 1))
        i, j = [(1, 2), (2, 0), (0, 1)][d]
        r[:, i, i], r[:, i, j], r[:, j, i], r[:, j, j] = c, -s, s, c
        return r

    wp = [a for a in structure.workpiece_axes if a.kind == "rotary"]
    for idx, ax in enumerate(wp):
        carrier = np.tile(np.eye(3), (n, 1, 1))  # nominal rotation of the axis' carrier into M
        for outer in wp[idx + 1:]:
            carrier = rot(outer.name, -1) @ carrier
        u = carrier[:, :, ax.direction]
        p = np.einsum("nij,j->ni", carrier, (m.pivots_mm or {}).get(ax.name, np.zeros(3)))
        rvec = nest - p
        rvec = rvec - (rvec * u).sum(axis=1, keepdims=True) * u
        norm = np.linalg.norm(rvec, axis=1, keepdims=True)
        radial = np.where(norm > 1e-9, rvec / np.where(norm > 1e-9, norm, 1.0), 0.0)
        tang = np.cross(u, radial)
        out[ax.name] = np.stack([radial, tang, u], axis=1)
    return out


def residual_plots(m: Measurement, result: DiagnosisResult, out_dir: str | Path) -> list[str]:
    """Write the residual-signature plots (PNG) of the baseline PIGE fit; returns their paths."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    kern = load_kernels(m.machine)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    resid = result.baseline.residuals_um
    if resid.size == 0:
        raise InputError("no residuals to plot")
    paths = []
    t = m.t_s
    fig, ax = plt.subplots(figsize=(7, 3.5))
    for i, c in enumerate("xyz"):
        ax.plot(t, resid[:, i], ".-", label=f"d{c}")
    ax.set_xlabel("t [s]")
    ax.set_ylabel("residual [µm]")
    ax.set_title("PIGE-fit residual vs time")
    ax.legend()
    fig.tight_layout()
    paths.append(str(out / "residual_time.png"))
    fig.savefig(paths[-1], dpi=90)
    plt.close(fig)
    frames = axis_frames(m, kern)
    for k, axis in enumerate(kern.ROTARY_AXES):
        if axis not in frames:
            continue
        comp = np.einsum("nci,ni->nc", frames[axis], resid)
        fig, ax = plt.subplots(figsize=(7, 3.5))
        for i, name in enumerate(("radial", "tangential", "axial")):
            ax.plot(m.angles_deg[:, k], comp[:, i], "o", ms=3, label=name)
        ax.set_xlabel(f"{axis} [deg]")
        ax.set_ylabel("residual [µm]")
        ax.set_title(f"residual in the frame of axis {axis}")
        ax.legend()
        fig.tight_layout()
        paths.append(str(out / f"residual_{axis}.png"))
        fig.savefig(paths[-1], dpi=90)
        plt.close(fig)
    appr = EffectContext(kern, m.angles_deg, m.t_s, m.ball_mm).approach
    assert appr is not None
    fig, axs = plt.subplots(1, 2, figsize=(9, 3.5))
    norms = np.linalg.norm(resid, axis=1)
    axs[0].bar(np.arange(len(norms)), norms)
    for r in result.outlier_rows:
        axs[0].bar([r], [norms[r]], color="red")
    axs[0].set_xlabel("row")
    axs[0].set_ylabel("|residual| [µm]")
    axs[0].set_title("per row (red: outliers)")
    r = resid[1:] - resid[1:].mean(axis=0)
    ac = [1.0] + [float((r[:-lag] * r[lag:]).sum() / max((r * r).sum(), 1e-300)) for lag in range(1, min(15, len(r)))]
    axs[1].stem(range(len(ac)), ac)
    axs[1].set_xlabel("lag [rows]")
    axs[1].set_title("autocorrelation in time")
    fig.tight_layout()
    paths.append(str(out / "residual_rows.png"))
    fig.savefig(paths[-1], dpi=90)
    plt.close(fig)
    if (appr != 0).any():
        fig, ax = plt.subplots(figsize=(7, 3.5))
        for k, axis in enumerate(kern.ROTARY_AXES):
            if axis in frames:
                tang = np.einsum("ni,ni->n", frames[axis][:, 1], resid)
                for sgn, mk in ((1, "^"), (-1, "v")):
                    sel = appr[:, k] == sgn
                    ax.plot(m.angles_deg[sel, k], tang[sel], mk, label=f"{axis} approached {'+' if sgn > 0 else '-'}")
        ax.set_xlabel("angle [deg]")
        ax.set_ylabel("tangential residual [µm]")
        ax.set_title("residual by direction of approach")
        ax.legend()
        fig.tight_layout()
        paths.append(str(out / "residual_approach.png"))
        fig.savefig(paths[-1], dpi=90)
        plt.close(fig)
    result.plots = paths
    return paths
