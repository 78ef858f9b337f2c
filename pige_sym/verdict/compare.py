"""Measured before/after: two R-test measurements of the same program (``pige compare``).

Both files must describe the same test: same machine structure, same rotary axes, same number
of points, and commanded angles that agree within :data:`ANGLE_TOLERANCE_DEG` at every point
(a compensated program changes the angles by a few µrad only).  Deviations are compared in the
machine frame, point by point: ``|d|`` per pose [µm], its RMS over the measured points (the
reference row, zero by definition, left out) and its maximum, before and after, and the
improvement ``1 − RMS_after / RMS_before``.  Everything here is *measured*: no model enters
these numbers.

What is left, and why: each measurement is diagnosed (:func:`~pige_sym.diagnosis.diagnose.diagnose`)
and its deviation split into the PIGE part (the model of the final fit's PIGEs), one part per
accepted effect (its fitted contribution) and the unexplained rest (noise and anything not in
the catalogue).  The RMS of each part is reported; the parts are not orthogonal, so the RMS do
not add up, but ``explained`` (1 − mean square of the rest / mean square of the deviation)
says how much of the deviation the model accounts for.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from pige_sym.errors import InputError
from pige_sym.measurements.measurement import Measurement
from pige_sym.measurements.rtest import read_measurement

ANGLE_TOLERANCE_DEG = 0.05


@dataclass
class Part:
    """One part of a measured deviation.

    Attributes
    ----------
    name : str
        ``PIGEs``, an effect id, or ``unexplained``.
    rms_um, max_um : float or None
        RMS and max of ``|part|`` over the measured points [µm]; None when it cannot be computed
        (a PIGE without a value).
    values_um : ndarray, shape=(n, 3) [µm] or None
    """

    name: str
    rms_um: float | None
    max_um: float | None
    values_um: np.ndarray | None = None

    def to_dict(self) -> dict[str, Any]:
        return {"part": self.name, "rms_um": self.rms_um, "max_um": self.max_um}


@dataclass
class Decomposition:
    """A measured deviation split into PIGE part, effect parts and the unexplained rest."""

    parts: list[Part]
    explained: float | None
    sigma_um: float
    notes: list[str] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        return {"parts": [p.to_dict() for p in self.parts], "explained_fraction": self.explained,
                "noise_sigma_um": self.sigma_um, "notes": self.notes}


@dataclass
class CompareResult:
    """Before/after of two measurements of the same program.

    Attributes
    ----------
    before_um, after_um : ndarray, shape=(n,) [µm]
        ``|d|`` per pose (machine frame).
    angles_deg : ndarray, shape=(n, k) [deg]
        Commanded angles of the *before* file.
    max_angle_difference_deg : float
    """

    before: str
    after: str
    machine: str
    rotary_axes: tuple[str, ...]
    angles_deg: np.ndarray
    before_um: np.ndarray
    after_um: np.ndarray
    rms_before_um: float
    rms_after_um: float
    max_before_um: float
    max_after_um: float
    improvement: float
    max_angle_difference_deg: float
    before_parts: Decomposition | None = None
    after_parts: Decomposition | None = None

    def to_dict(self) -> dict[str, Any]:
        from pige_sym.files import json_ready

        poses = [{"pose": i, "angles_deg": dict(zip(self.rotary_axes, a, strict=True)), "before_um": b,
                  "after_um": c} for i, (a, b, c) in enumerate(zip(self.angles_deg, self.before_um, self.after_um,
                                                                   strict=True))]
        return json_ready({
            "basis": "measured", "before": self.before, "after": self.after, "machine": self.machine,
            "rms_before_um": self.rms_before_um, "rms_after_um": self.rms_after_um,
            "max_before_um": self.max_before_um, "max_after_um": self.max_after_um, "improvement": self.improvement,
            "max_angle_difference_deg": self.max_angle_difference_deg, "poses": poses,
            "before_parts": None if self.before_parts is None else self.before_parts.to_dict(),
            "after_parts": None if self.after_parts is None else self.after_parts.to_dict(),
        })

    def format(self) -> str:
        """Summary, what is left, and the per-pose table (plain text)."""
        lines = [f"measured before/after on {self.machine} ({len(self.before_um)} poses; angles agree within "
                 f"{self.max_angle_difference_deg:.4f} deg)",
                 f"  before {self.before}: RMS {self.rms_before_um:.3f} um, max {self.max_before_um:.3f} um",
                 f"  after  {self.after}: RMS {self.rms_after_um:.3f} um, max {self.max_after_um:.3f} um",
                 f"  improvement (RMS): {self.improvement:.1%}"]
        for label, dec in (("before", self.before_parts), ("after", self.after_parts)):
            if dec is None:
                continue
            parts = ", ".join(f"{p.name} {_n(p.rms_um)}" for p in dec.parts)
            expl = "—" if dec.explained is None else f"{dec.explained:.0%}"
            lines.append(f"  {label}: RMS by part [um]: {parts}; the model explains {expl} (noise σ "
                         f"{dec.sigma_um:.3f} um per component, |noise| RMS ≈ {math.sqrt(3) * dec.sigma_um:.3f} um)")
            lines += [f"    {n}" for n in dec.notes]
        lines.append(f"{'pose':>5s} " + " ".join(f"{a + ' [deg]':>10s}" for a in self.rotary_axes)
                     + f" {'|d| before':>11s} {'|d| after':>10s}  [um]")
        for i, (a, b, c) in enumerate(zip(self.angles_deg, self.before_um, self.after_um, strict=True)):
            lines.append(f"{i:5d} " + " ".join(f"{x:10.3f}" for x in a) + f" {b:11.3f} {c:10.3f}")
        return "\n".join(lines)


def _n(x: float | None) -> str:
    return "—" if x is None or not math.isfinite(x) else f"{x:.3f}"


def _stats(norms: np.ndarray) -> tuple[float, float]:
    pts = norms[1:] if norms.shape[0] > 1 else norms
    return float(np.sqrt((pts**2).mean())), float(pts.max())


def check_same_program(before: Measurement, after: Measurement, names: tuple[str, str]) -> float:
    """Largest commanded-angle difference [deg]; refuses two measurements of different tests.

    Raises
    ------
    InputError
        Different machine, axes, number of points, or angles beyond the tolerance (first row named).
    """
    from pige_sym.kernels import load_kernels

    a, b = names
    code_a, code_b = load_kernels(before.machine).MACHINE_CODE, load_kernels(after.machine).MACHINE_CODE
    if code_a != code_b:
        raise InputError(f"{a} is a {code_a}, {b} a {code_b}: compare two measurements of the same machine")
    if tuple(before.rotary_axes) != tuple(after.rotary_axes):
        raise InputError(f"{a} and {b} list the rotary axes differently ({before.rotary_axes} vs {after.rotary_axes})")
    if before.n_rows != after.n_rows:
        raise InputError(f"{a} has {before.n_rows} points, {b} {after.n_rows}: compare two runs of the same program")
    diff = np.abs(before.angles_deg - after.angles_deg)
    bad = np.flatnonzero((diff > ANGLE_TOLERANCE_DEG).any(axis=1))
    if bad.size:
        i = int(bad[0])
        raise InputError(f"{a} and {b} differ at data row {i + 1}: angles {before.angles_deg[i].tolist()} vs "
                         f"{after.angles_deg[i].tolist()} deg (tolerance {ANGLE_TOLERANCE_DEG} deg): not the same "
                         "program")
    return float(diff.max()) if diff.size else 0.0


def _rms_max(values: np.ndarray) -> tuple[float, float]:
    return _stats(np.linalg.norm(values, axis=1))


def decompose(m: Measurement, diagnosis: Any = None) -> Decomposition:
    """Split the machine-frame deviation of ``m`` into PIGE part, effect parts and the rest (module docstring)."""
    from pige_sym.diagnosis.diagnose import diagnose
    from pige_sym.kernels import load_kernels
    from pige_sym.model.effects import EffectContext, EffectSpec

    kern = load_kernels(m.machine)
    diag = diagnosis if diagnosis is not None else diagnose(m)
    dev = m.deviation_machine_um(kern)
    final = diag.final
    notes: list[str] = []
    values = {p: final.value(p) for p in final.parameters if p in kern.PARAMETERS}
    parts: list[Part] = []
    rest: np.ndarray | None = dev.copy()
    if all(math.isfinite(v) for v in values.values()):
        vec = np.array([values.get(p, 0.0) for p in kern.PARAMETERS])
        pige = kern.deviation(m.angles_deg, vec, m.ball_mm, m.pivots_mm or None, m.tool_mm)
        parts.append(Part("PIGEs", *_rms_max(pige), values_um=pige))
        rest = dev - pige
    else:
        missing = [p for p, v in values.items() if not math.isfinite(v)]
        parts.append(Part("PIGEs", None, None))
        notes.append(f"PIGE part not computed: {', '.join(missing)} not identifiable")
        rest = None
    ctx = EffectContext(kern, m.angles_deg, m.t_s, m.ball_mm, m.pivots_mm or None, m.tool_mm)
    for f in diag.findings:
        if f.effect == "outliers":
            notes.append(f"outlier rows {diag.outlier_rows} (left in the unexplained part)")
            continue
        contrib = EffectSpec(f.effect, dict(f.options)).contribution(ctx, f.params)
        parts.append(Part(f.effect, *_rms_max(contrib), values_um=contrib))
        if rest is not None:
            rest = rest - contrib
    explained = None
    if rest is not None:
        parts.append(Part("unexplained", *_rms_max(rest), values_um=rest))
        total = float((dev[1:] ** 2).sum())
        explained = 1.0 - float((rest[1:] ** 2).sum()) / total if total > 0 else None
    return Decomposition(parts, explained, float(final.sigma_um), notes)


def compare_measurements(before: str | os.PathLike[str], after: str | os.PathLike[str], *,
                         explain: bool = True) -> CompareResult:
    """Measured before/after of two files of the same program (module docstring).

    Parameters
    ----------
    before, after : path-like
        ``pige-rtest 1`` files.
    explain : bool
        Also diagnose both and split the deviations into parts.
    """
    from pige_sym.kernels import load_kernels

    mb, ma = read_measurement(before), read_measurement(after)
    names = (str(before), str(after))
    max_diff = check_same_program(mb, ma, names)
    kern = load_kernels(mb.machine)
    nb = np.linalg.norm(mb.deviation_machine_um(kern), axis=1)
    na = np.linalg.norm(ma.deviation_machine_um(kern), axis=1)
    rb, xb = _stats(nb)
    ra, xa = _stats(na)
    out = CompareResult(names[0], names[1], kern.MACHINE_CODE, tuple(mb.rotary_axes), mb.angles_deg.copy(), nb, na,
                        rb, ra, xb, xa, 1.0 - ra / rb if rb > 0 else 0.0, max_diff)
    if explain:
        out.before_parts = decompose(mb)
        out.after_parts = decompose(ma)
    return out
