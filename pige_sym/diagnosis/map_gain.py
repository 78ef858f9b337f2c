"""Does a map explain what the PIGE model misses? The held-out gain of the error maps (CONVENTIONS §10).

``pige diagnose FILES --map C,A``: the files' rows are fitted twice, with the PIGEs (and zero-position errors,
and each file's constants) alone, and with the maps too (the model of :mod:`pige_sym.identification.maps`:
same columns, same §10 projection, same weights).  Both are cross-validated by pose: the poses of every file
are dealt into ``FOLDS`` folds; each fold's rows are predicted from a fit of the others (least squares, the
minimum-norm solution where a combination is not determined, as a user of the fit would get).  The held-out
RMS of the two, in units of each file's noise σ, and the gain ``1 − map/PIGEs`` say whether the map explains
the residual.  A probe file's rows are its whitened rows (they share the reference pose's error, so a pose's
rows are not independent of the others': the folds are by pose all the same).

**Is a motion's map more than its noise?** Before anything is said of a motion's shape, its values v (the
determined grid angles) are tested against 0 with their covariance Σ: ``χ² = vᵀ Σ⁺ v`` on the rank of Σ (the
determined values less the §10 left-out functions) degrees of freedom, at ``ALPHA`` per motion.  A map within its
noise is said to be so, and no harmonic of it is named.

**What the one-harmonic candidates explain.** The diagnosis' catalogue holds one harmonic h of an error
motion at a time (``angular_error`` = φ, ``wobble`` = ρ, ``radial_runout`` = radial τ).  For each motion whose map
is more than its noise, the share of its sum of squares that the best single harmonic 2–4 holds (least squares of
cos hθ, sin hθ over the determined grid angles, where at least three values remain beside the left-out functions)
is reported with the candidate that carries that harmonic, when the map explains the residual and that harmonic's
two coefficients are themselves beyond their noise (χ² on 2 degrees of freedom, ``ALPHA``): where the share is
near 1 the diagnosis' effect already describes the map, where it is small only the map does.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from pige_sym.identification.joint import Block, whitened_system
from pige_sym.identification.maps import MapResult, MapSpec, design_maps, identify_maps, map_blocks, n_location
from pige_sym.measurements.ballbar import BallbarRun
from pige_sym.measurements.measurement import Measurement

#: Folds of the cross-validation by pose.
FOLDS = 5
#: The catalogue effect that holds one harmonic of each kind of motion.
CANDIDATE = {"positioning": "angular_error", "tilt": "wobble", "radial": "radial_runout"}
#: Significance of a motion's map, and of a harmonic of it (module docstring).
ALPHA = 0.01


@dataclass
class HarmonicShare:
    """How much of one motion's map a single harmonic holds, and whether the map (and that harmonic) stand out of
    the noise: ``chi2`` on ``dof`` of the map against 0, ``p_value`` its probability if the map were 0;
    ``harmonic_p`` the same of the harmonic's two coefficients."""

    motion: str
    harmonic: int
    share: float
    candidate: str | None
    chi2: float = math.nan
    dof: int = 0
    p_value: float = math.nan
    harmonic_p: float = math.nan

    @property
    def significant(self) -> bool:
        return bool(self.p_value < ALPHA)

    @property
    def harmonic_significant(self) -> bool:
        return self.significant and bool(self.harmonic_p < ALPHA)

    def to_dict(self) -> dict[str, Any]:
        return {"motion": self.motion, "harmonic": self.harmonic, "share": self.share, "candidate": self.candidate,
                "chi2": self.chi2, "dof": self.dof, "p_value": self.p_value, "significant": self.significant,
                "harmonic_p_value": self.harmonic_p, "harmonic_significant": self.harmonic_significant}

    def sentence(self) -> str:
        """In words: within its noise, or its strongest harmonic and the candidate that carries it."""
        test = f"χ² {self.chi2:.3g} on {self.dof} dof, p {self.p_value:.2g}"
        if not self.significant:
            return f"{self.motion}: within its noise ({test}): no shape to name"
        if not self.harmonic_significant:
            return (f"{self.motion}: beyond its noise ({test}), but no single harmonic 2-4 stands out of it (the "
                    f"strongest, {self.harmonic}, holds {self.share:.0%}): only the map describes it")
        said = (f": the diagnosis' one-harmonic effect {_plain(self.candidate, self.harmonic)} describes that part"
                if self.candidate else ": no one-harmonic effect of the diagnosis describes it")
        return (f"{self.motion}: beyond its noise ({test}); its strongest single harmonic, {self.harmonic}, holds "
                f"{self.share:.0%} of the map{said}")


@dataclass
class MapGain:
    """Held-out RMS [σ] of the PIGE model and of the PIGE + map model, and what single harmonics explain."""

    heldout_pige: float
    heldout_map: float
    folds: int
    harmonics: list[HarmonicShare] = field(default_factory=list)

    @property
    def gain(self) -> float:
        return 1.0 - self.heldout_map / self.heldout_pige if self.heldout_pige > 0 else 0.0

    def explains(self) -> bool:
        """The map explains the residual: it lowers the held-out RMS by ≥ 10 % and to ≤ 1.5 σ."""
        return self.gain >= 0.10 and self.heldout_map <= 1.5

    def to_dict(self) -> dict[str, Any]:
        return {"heldout_rms_pige_sigma": self.heldout_pige, "heldout_rms_map_sigma": self.heldout_map,
                "gain": self.gain, "folds": self.folds, "map_explains_the_residual": self.explains(),
                "harmonics": [h.to_dict() for h in self.harmonics]}

    def sentences(self) -> list[str]:
        verdict = ("the error maps explain what the PIGE model misses" if self.explains() else
                   "the error maps do not explain the residual" if self.gain < 0.10 else
                   "the error maps explain part of the residual")
        change = f"{abs(self.gain):.0%} {'less' if self.gain >= 0 else 'more'}"
        out = [f"maps (held-out by pose, {self.folds} folds): {verdict}: held-out RMS {self.heldout_pige:.2f} σ with "
               f"the PIGEs alone, {self.heldout_map:.2f} σ with the maps ({change})"]
        if self.explains():
            out += [f"  {h.sentence()}" for h in self.harmonics]
        return out


def mapped_effects(spec: MapSpec | None) -> list[str]:
    """The catalogue's one-harmonic error motions of the mapped axes (and the backlash of an axis mapped per
    direction): a map holds every harmonic of them, so a diagnosis beside the maps does not search them again."""
    if spec is None:
        return []
    out = [f"{kind}_{ax}" for ax in spec.axes for kind in ("angular_error", "wobble", "radial_runout")]
    return out + [f"backlash_{ax}" for ax in spec.per_direction]


def map_gain(items: Sequence[tuple[str, Measurement | BallbarRun]], spec: MapSpec,
             result: MapResult | None = None) -> MapGain:
    """The held-out gain of the maps and the single harmonics' shares (module docstring)."""
    fitted = result if result is not None else identify_maps(items, spec)
    machine, names, layout, raw = map_blocks(items, spec)
    sigmas = [f.sigma_um for f in fitted.joint.files]
    fitted_zero = [j for j in range(len(names)) if j < n_location(machine) or np.isfinite(fitted.result.values[j])]
    blocks = design_maps(names, layout, raw, sigmas, fitted_zero).blocks
    a, y = whitened_system(blocks, sigmas)
    pose = np.concatenate([_pose_of_rows(b, k) for k, b in enumerate(blocks)])
    folds = np.full(pose.size, -1)
    for f, group in enumerate(np.array_split(np.unique(pose), FOLDS)):
        folds[np.isin(pose, group)] = f
    n_shared = blocks[0].design.shape[1]
    pige_cols = list(range(len(fitted_zero))) + list(range(n_shared, a.shape[1]))
    held = {"pige": _heldout(a[:, pige_cols], y, folds), "map": _heldout(a, y, folds)}
    return MapGain(held["pige"], held["map"], FOLDS, _harmonics(fitted))


def _pose_of_rows(block: Block, file_index: int) -> np.ndarray:
    """A pose key per row of a block: (file, pose) packed in one integer (3 rows per pose, 1 for a ballbar)."""
    per = 1 if block.instrument == "ballbar" else 3
    return file_index * 1_000_000 + np.arange(block.data.size) // per


def _heldout(a: np.ndarray, y: np.ndarray, folds: np.ndarray) -> float:
    """RMS of the rows of each fold predicted from a least-squares fit of the other folds."""
    resid = np.empty_like(y)
    for f in np.unique(folds):
        test = folds == f
        coef = np.linalg.lstsq(a[~test], y[~test], rcond=None)[0]
        resid[test] = y[test] - a[test] @ coef
    return float(np.sqrt(np.mean(resid**2)))


def _harmonics(result: MapResult) -> list[HarmonicShare]:
    out = []
    for ax, m in result.maps.items():
        for motion in m.motions:
            v = m.value[motion.name]
            ok = np.isfinite(v)
            total = float(np.sum(v[ok] ** 2))
            if motion.kind == "reversal" or ok.sum() - motion.left_out < 3 or total <= 0:
                continue  # fewer than 3 values beside the left-out functions: a harmonic's share says nothing
            t = np.radians(m.grid.angles_deg[ok])
            best = max(((h, _share(v[ok], t, h, total)) for h in (2, 3, 4)), key=lambda x: x[1])
            kind = CANDIDATE.get(motion.kind)
            cov = np.asarray(m.covariance.get(motion.name, np.full((v.size, v.size), np.nan)))[np.ix_(ok, ok)]
            chi2, dof, p = _against_zero(v[ok], cov)
            out.append(HarmonicShare(motion.name, best[0], best[1], f"{kind}_{ax}" if kind else None, chi2, dof, p,
                                     _harmonic_p(v[ok], cov, t, best[0])))
    return out


def _plain(effect: str, harmonic: int) -> str:
    """``a radial run-out of the C axis, 4 per revolution (radial_runout_C)``: the words first, the symbol after."""
    from pige_sym.diagnosis.results import effect_title

    title = effect_title(effect, {"harmonic": harmonic})
    words = title[len(effect) + 2:-1] if title.startswith(effect + " (") else ""
    return f"{words} ({effect})" if words else effect


def _against_zero(v: np.ndarray, cov: np.ndarray) -> tuple[float, int, float]:
    """χ², its degrees of freedom (the rank of ``cov``) and p of the values against 0 (module docstring)."""
    from scipy.stats import chi2

    if not np.isfinite(cov).all():
        return math.nan, 0, math.nan
    w, vecs = np.linalg.eigh(0.5 * (cov + cov.T))
    keep = w > 1e-9 * max(float(w.max(initial=0.0)), 1e-300)
    dof = int(keep.sum())
    if dof == 0:
        return math.nan, 0, math.nan
    proj = vecs[:, keep].T @ v
    stat = float(np.sum(proj**2 / w[keep]))
    return stat, dof, float(chi2.sf(stat, dof))


def _harmonic_p(v: np.ndarray, cov: np.ndarray, t: np.ndarray, h: int) -> float:
    """p of harmonic ``h``'s cos and sin coefficients (least squares over the angles) against 0."""
    basis = np.column_stack([np.cos(h * t), np.sin(h * t)])
    lift = np.linalg.pinv(basis)
    return _against_zero(lift @ v, lift @ cov @ lift.T)[2]


def _share(v: np.ndarray, t: np.ndarray, h: int, total: float) -> float:
    basis = np.column_stack([np.cos(h * t), np.sin(h * t)])
    fit = basis @ np.linalg.lstsq(basis, v, rcond=None)[0]
    return min(1.0, float(np.sum(fit**2)) / total) if math.isfinite(total) else 0.0
