"""Results of a diagnosis: findings, rejected candidates and the outcome (JSON derives from them).

Units: parameters in µm or µrad as named by ``units``; RMS values in µm; ΔBIC
dimensionless.  ``Finding.removed`` names the directions of a candidate that the data
cannot separate from the PIGEs (see :mod:`pige_sym.diagnosis.candidates`); ``basis`` (q × q'),
``null`` (one list of q values per removed direction) and ``absorbed`` (the PIGE
combination per removed direction) let a caller split known values into the part the
finding estimates and the part the PIGEs absorb (:meth:`Finding.identifiable_part`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from pige_sym.identification.result import IdentificationResult, value_std

EVIDENCE = {
    "thermal_drift": "a smooth trend of the residual with time (warm-up), not with the angles",
    "table_drift": "a smooth trend with time that turns with the table: the sphere (nest) creeps on its stand",
    "angular_error": "a tangential residual about {axis} that repeats {h}x per revolution",
    "wobble": "a residual from a tilt of the {axis} axis that repeats {h}x per revolution",
    "radial_runout": "a radial residual of the {axis} axis that repeats {h}x per revolution",
    "backlash": "a residual that changes sign with the direction of approach of {axis}",
    "squareness": "a residual proportional to the commanded linear travel",
    "setup_offset": "a residual that turns with the table",
    "probe_trigger": "centres moved by the probe's direction-dependent trigger radius (lobing, vertical "
                     "pre-travel), seen because the contact pattern changes from pose to pose",
    "pose_cluster": "rows at one pose deviate together: an effect of that pose outside the catalogue, not outliers",
}


#: What each catalogue effect is, in words: the name ``pige diagnose`` and the report both give it.
EFFECT_NAMES = {
    "thermal_drift": "thermal drift of the tool against the table",
    "table_drift": "the sphere or nest creeping on its stand",
    "angular_error": "an angular positioning error of {axis}",
    "wobble": "a wobble of the {axis} axis",
    "radial_runout": "a radial run-out of the {axis} axis",
    "backlash": "backlash of {axis}",
    "squareness": "a squareness error of the linear axes {axis}",
    "setup_offset": "the instrument set up off its nominal place",
    "probe_trigger": "the probe's direction-dependent trigger radius",
    "pose_cluster": "the rows of one pose deviating together",
    "outliers": "isolated rows far beyond the noise",
}


def effect_title(effect: str, options: dict[str, float]) -> str:
    """An effect as both ``pige diagnose`` and the report name it: its catalogue id, then what it is, e.g.
    ``angular_error_C (an angular positioning error of C, 2 per revolution)``."""
    head, _, axis = effect.rpartition("_")  # angular_error_C: the kind and its axis (or axis pair)
    kind, axis = (head, axis) if head in EFFECT_NAMES else (effect, "")
    words = EFFECT_NAMES.get(kind, "").format(axis=axis)
    if "harmonic" in options:
        words += f", {int(options['harmonic'])} per revolution"
    rest = ", ".join(f"{k} {v:.3g}" for k, v in options.items() if k not in ("harmonic", "tau_s"))
    words = ", ".join(w for w in (words, rest) if w)
    return f"{effect} ({words})" if words else effect


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
    vif: dict[str, float] = field(default_factory=dict)
    removed: list[str] = field(default_factory=list)
    basis: list[list[float]] = field(default_factory=list)
    null: list[list[float]] = field(default_factory=list)
    absorbed: list[dict[str, float]] = field(default_factory=list)
    alternatives: list[str] = field(default_factory=list)

    def identifiable_part(self, params: dict[str, float]) -> tuple[dict[str, float], dict[str, float]]:
        """Split catalogue values into the part this finding estimates and the part the PIGEs absorb.

        Parameters
        ----------
        params : dict of str to float
            Catalogue parameter values (e.g. a simulation's truth).

        Returns
        -------
        dict
            The estimable part ``basis·θ`` in catalogue parameters (compare with ``params``).
        dict
            The PIGE shift ``Σ φ_j · absorbed_j`` caused by the removed part ``Σ φ_j · null_j``.
        """
        names = [p for p in self.params if p != "tau_s"]
        c = np.array([params[p] for p in names])
        if not self.null:
            return dict(zip(names, c.tolist(), strict=True)), {}
        basis = np.array(self.basis).reshape(len(names), -1)
        null = np.array(self.null).T
        coef = np.linalg.lstsq(np.concatenate([basis, null], axis=1), c, rcond=None)[0]
        kept = basis @ coef[: basis.shape[1]]
        phi = coef[basis.shape[1]:]
        shift: dict[str, float] = {}
        for f, absorbed in zip(phi, self.absorbed, strict=True):
            for k, v in absorbed.items():
                shift[k] = shift.get(k, 0.0) + float(f * v)
        return dict(zip(names, kept.tolist(), strict=True)), shift

    def to_dict(self) -> dict[str, Any]:
        vif = {k: (v if math.isfinite(v) else None) for k, v in self.vif.items()}
        return {"vif": vif, "removed": self.removed, "null_directions": self.null, "absorbed": self.absorbed,
                "alternatives": self.alternatives,
            "effect": self.effect, "options": self.options, "params": self.params, "std": self.std,
            "units": self.units, "delta_bic": self.delta_bic, "f_statistic": self.f_statistic,
            "p_value": self.p_value, "rms_um_before": self.rms_um_before, "rms_um_after": self.rms_um_after,
            "heldout_rms_um_before": self.heldout_rms_um_before, "heldout_rms_um_after": self.heldout_rms_um_after,
            "pige_shift": self.pige_shift, "evidence": self.evidence, "explained_fraction": self.explained,
        }

    def title(self) -> str:
        """What was found, as ``pige diagnose`` and the report both name it (:func:`effect_title`)."""
        return effect_title(self.effect, self.options)

    def sentence(self) -> str:
        """One-line verdict."""
        vals = ", ".join(f"{'τ' if k == 'tau_s' else k}={value_std(v, self.std[k], '±')} {self.units[k]}"
                         for k, v in self.params.items())
        big = max(self.pige_shift.items(), key=lambda kv: abs(kv[1]), default=None)
        # E<direction>0<axis>: a linear direction (X, Y, Z) is a position error in µm, else µrad
        unit = "um" if big and big[0][1:2] in ("X", "Y", "Z") else "urad"
        moved = f"; moves {big[0]} by {big[1]:+.3g} {unit}" if big and abs(big[1]) > 0 else ""
        reduced = f"; identifiable part only, removed: {'; '.join(self.removed)}" if self.removed else ""
        if self.alternatives:
            reduced += f"; ambiguous: {'; '.join(self.alternatives)}"
        worst = max(self.vif.values(), default=1.0)
        if worst > 10:
            reduced += f"; VIF up to {worst:.3g} (its standard errors are inflated up to {math.sqrt(worst):.3g}x)"
        if math.isfinite(self.heldout_rms_um_before) and math.isfinite(self.heldout_rms_um_after):
            gain = f"held-out RMS {self.heldout_rms_um_before:.3g} → {self.heldout_rms_um_after:.3g} um"
        else:  # no cross-validation (the joint search of ballbar setups): the fitted residual
            gain = (f"residual RMS {self.rms_um_before:.3g} → {self.rms_um_after:.3g} in units of each file's noise "
                    "σ")
        return f"{self.title()}: {self.evidence}; {vals}; {gain} (ΔBIC {self.delta_bic:.1f}){moved}{reduced}"


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
    clusters: list[str] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        final = self.final.to_dict()
        return {
            "machine": self.machine,
            "baseline": {"rms_um": self.baseline_rms_um, "bic": self.baseline_bic,
                         "heldout_rms_um": self.baseline_heldout_rms_um},
            "findings": [f.to_dict() for f in self.findings],
            "rejected": [r.to_dict() for r in self.rejected],
            "pige": final["pige"], "std": final["std"], "covariance": final["covariance"], "units": final["units"],
            "unidentifiable": final["unidentifiable"], "null_space": final["null_space"],
            "rank": final["rank"], "condition": final["condition"],
            "rms_um": final["rms_um"], "outlier_rows": self.outlier_rows, "method": "diagnosis",
            "ball_mm": final["ball_mm"], "pivots_mm": final["pivots_mm"], "tool_mm": final["tool_mm"],
            "plots": self.plots, "clusters": self.clusters, **({"axis_sense": final["axis_sense"]}
                                                               if "axis_sense" in final else {}),
        }

    def verdict(self) -> str:
        if not self.findings:
            return (f"No effect beyond the PIGEs is supported by the data (residual RMS {self.baseline_rms_um:.3g} um, "
                    f"{len(self.rejected)} candidates tried).")
        return "\n".join(f"- {f.sentence()}" for f in self.findings)
