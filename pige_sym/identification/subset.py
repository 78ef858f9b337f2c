"""The check-up fit: the PIGEs that change between runs estimated, the others held at known values.

A check-up re-measures only some PIGEs (the *free* set F: by default the axis-line positions, which thermal growth
moves) with a few poses, and holds the others (H) at the values the last full calibration found, less the
corrections entered since (:mod:`pige_sym.verdict.checkup`).  With the normal equations ``N x = r`` of the whole
problem (:func:`~pige_sym.identification.problem.build_problem`: ordinary least squares for an R-test, generalised
least squares with the reference-pose coupling for a probe file), the held values move to the right-hand side:

    ``N_FF x_F = r_F − N_FH x_H``,   ``RSS = yᵀy − 2 xᵀr + xᵀN x`` with ``x = (x_F, x_H)``.

Covariance ``Cov(x_F) = s² N_FF⁻¹``:

- **probe file**: the rows' covariances are the sphere fit's own (contact scatter pooled over every contact, each
  centre's ``σ²(GᵀWG)⁻¹``), so ``s²`` is the scale :mod:`~pige_sym.identification.instruments` divided them by:
  the standard errors do not rest on the few residual degrees of freedom of a three-pose check-up.  ``dof`` is the
  sphere fit's (contacts − 3 per pose − 1 for a fitted radius);
- **R-test**: the full calibration's noise per component when given (``noise_um`` on ``noise_dof`` degrees of
  freedom: a three-pose check-up leaves two degrees of freedom of its own), else ``s² = RSS/(N − |F|)`` as in
  :func:`~pige_sym.identification.least_squares.identify`.

**The held values' error.**  The held values are estimates (the full calibration's, with covariance ``Σ_H``): a
held value off by ``δ`` moves the free estimates by ``−K δ`` (``K = N_FF⁻¹N_FH``).  Given ``Σ_H``
(``held_covariance``), the check-up's covariance includes it, ``s² N_FF⁻¹ + K Σ_H Kᵀ`` (its standard errors hold
every source of its error), and :attr:`SubsetFit.fit_covariance` keeps the fit's own part.

**Consistency.**  ``χ² = RSS/s²_expected`` on ``N − |F|`` degrees of freedom (probe: the rows' own scale; R-test:
the full calibration's noise when given) tests whether the check-up's poses agree with the held values; its
p-value is reported, and below :data:`CONSISTENCY_ALPHA` the fit says so (an orientation error or the set-up
changed: the held values no longer describe the machine).  Given ``Σ_H``, the residual is the least one over the
held values too, each kept near its value by its uncertainty: ``min_x RSS(x) + s²_expected (x_H − h)ᵀ Σ_H⁻¹
(x_H − h)`` (on the same ``N − |F|`` degrees of freedom: the held values' prior adds as many rows as parameters), so
a disagreement the held values' own error explains is no reason to calibrate fully.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from pige_sym.errors import IdentificationError, InputError
from pige_sym.identification.distributions import chi2_sf
from pige_sym.identification.instruments import instrument
from pige_sym.identification.problem import build_problem
from pige_sym.identification.spectrum import solve_scaled
from pige_sym.kernels import load_kernels
from pige_sym.measurements.measurement import Measurement
from pige_sym.measurements.schema import refuse_unphysical

#: Below this p-value the check-up's residual says the held PIGEs no longer fit (a note, not a refusal).
CONSISTENCY_ALPHA = 1e-3


@dataclass
class SubsetFit:
    """Estimates of the free PIGEs with the others held.

    Attributes
    ----------
    parameters : list of str
        The free PIGEs, in the kernels' order.
    values, std : ndarray, shape=(F,) [µm, µrad]
    covariance : ndarray, shape=(F, F)
    held : dict of str to float
        The values the others were held at [µm, µrad].
    dof : int
        Degrees of freedom of the standard errors (module docstring).
    rms_um : float
        RMS of the residuals of the fitted rows [µm] (probe: of the deviations, unweighted).
    consistency_p : float or None
        p-value of the residual's χ² (module docstring); None when the noise is not known (R-test without it).
    notes : list of str
    sensitivity : ndarray, shape=(F, H)
        ``K = N_FF⁻¹ N_FH``: a held value off by ``δ`` moves the free estimates by ``−K δ`` (held in ``held``'s order).
    fit_covariance : ndarray, shape=(F, F)
        The fit's own covariance ``s² N_FF⁻¹`` (``covariance`` adds the held values' error when it is given).
    """

    machine: str
    parameters: list[str]
    units: dict[str, str]
    values: np.ndarray
    std: np.ndarray
    covariance: np.ndarray
    held: dict[str, float]
    dof: int
    rms_um: float
    n_obs: int
    consistency_p: float | None = None
    notes: list[str] = field(default_factory=list)
    sensitivity: np.ndarray | None = None
    fit_covariance: np.ndarray | None = None

    def value_dict(self) -> dict[str, float]:
        return {n: float(v) for n, v in zip(self.parameters, self.values, strict=True)}

    def to_dict(self) -> dict[str, Any]:
        from pige_sym.files import json_ready

        return json_ready({"machine": self.machine, "pige": self.value_dict(),
                           "std": dict(zip(self.parameters, self.std.tolist(), strict=True)), "units": self.units,
                           "covariance": {"parameters": self.parameters, "matrix": self.covariance},
                           "held": self.held, "dof": self.dof, "rms_um": self.rms_um, "n_obs": self.n_obs,
                           "consistency_p": self.consistency_p, "notes": self.notes})


def identify_subset(m: Measurement, free: list[str], held: dict[str, float], *,
                    noise_um: float | None = None, noise_dof: int | None = None,
                    held_covariance: np.ndarray | None = None) -> SubsetFit:
    """Fit the ``free`` PIGEs of a measurement with every other location PIGE at ``held`` (module docstring).

    Parameters
    ----------
    m : Measurement
        R-test or probe file.
    free : list of str
        PIGEs to estimate.
    held : dict of str to float
        Value of every other location PIGE [µm, µrad].
    noise_um, noise_dof : float, int, optional
        R-test: the noise per component the full calibration saw and its degrees of freedom (module docstring).
    held_covariance : ndarray, shape=(H, H), optional
        The held values' covariance, in ``held``'s order [µm², µrad²] (module docstring).

    Raises
    ------
    InputError
        A name that is not a location PIGE of the machine, or a location PIGE neither free nor held.
    IdentificationError
        The poses do not determine every free PIGE (names them).
    """
    kern = load_kernels(m.machine)
    names = list(kern.LOCATION_PARAMETERS)
    unknown = [n for n in [*free, *held] if n not in names]
    missing = [n for n in names if n not in free and n not in held]
    if unknown or missing or not free or set(free) & set(held):
        raise InputError(f"check-up of {kern.MACHINE_CODE}: give each location PIGE ({', '.join(names)}) once, free or "
                         f"held ({'unknown: ' + ', '.join(unknown) if unknown else 'missing: ' + ', '.join(missing)})"
                         if unknown or missing else f"check-up of {kern.MACHINE_CODE}: free and held PIGEs overlap "
                                                    "or none is free")
    problem = build_problem(m, "xyz")
    f = [names.index(n) for n in names if n in free]
    h = [names.index(n) for n in names if n in held]
    xh = np.array([float(held[names[i]]) for i in h])
    n_ff = problem.normal[np.ix_(f, f)]
    rhs = problem.rhs[f] - problem.normal[np.ix_(f, h)] @ xh
    sol = solve_scaled(n_ff, rhs, problem.yy)
    order = [names[i] for i in f]
    if sol.rank < len(f) or not np.isfinite(sol.vif).all():
        bad = [order[i] for i in np.flatnonzero(~np.isfinite(sol.vif))] or order
        raise IdentificationError(f"the check-up's poses do not determine {', '.join(bad)} (with the others held): "
                                  "probe the poses pige plan --checkup chose")
    x = np.zeros(len(names))
    x[f], x[h] = sol.values, xh
    rss = max(float(problem.yy - 2 * x @ problem.rhs + x @ problem.normal @ x), 0.0)
    resid_dof = problem.n_obs - len(f)
    scale, dof, expected = _scale(m, problem, rss, resid_dof, noise_um, noise_dof)
    own = sol.cov_unit * scale
    sens = sol.cov_unit @ problem.normal[np.ix_(f, h)]
    kept = {names[i]: float(held[names[i]]) for i in h}
    sigma_h = _held_covariance(held_covariance, len(h))
    cov = own if sigma_h is None else own + sens @ sigma_h @ sens.T
    std = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    units = {n: kern.UNITS[n] for n in order}
    refuse_unphysical(order, sol.values, std, units, m.path or "the measurement")
    if expected is not None and sigma_h is not None:
        rss = _rss_with_held(problem, f, h, xh, sigma_h, expected)
    p = None if expected is None or resid_dof <= 0 else chi2_sf(resid_dof, rss / expected)
    beyond = "their noise" if sigma_h is None else "their noise and the held values' uncertainty"
    notes = [] if p is None or p >= CONSISTENCY_ALPHA else [
        f"the check-up's poses disagree with the held PIGEs beyond {beyond} (chi-square p = {p:.2g}): an "
        "orientation error, the set-up or the probe changed since the last full calibration; calibrate the machine "
        "fully"]
    resid = _rms(problem, x)
    return SubsetFit(kern.MACHINE_CODE, order, units, sol.values, std, cov, kept, dof, resid, problem.n_obs, p, notes,
                     sens, own)


def _held_covariance(given: np.ndarray | None, size: int) -> np.ndarray | None:
    """The held values' covariance when given with finite values and the right shape (else None)."""
    if given is None or size == 0:
        return None
    sigma = np.asarray(given, dtype=float)
    if sigma.shape != (size, size):
        raise InputError(f"the held values' covariance is {sigma.shape}, expected ({size}, {size})")
    return sigma if np.isfinite(sigma).all() else None


def _rss_with_held(problem: Any, f: list[int], h: list[int], xh: np.ndarray, sigma_h: np.ndarray,
                   expected: float) -> float:
    """``min_x RSS(x) + s²_expected (x_H − h)ᵀ Σ_H⁻¹ (x_H − h)`` (module docstring), from the normal equations."""
    idx = f + h
    normal = problem.normal[np.ix_(idx, idx)].copy()
    rhs = problem.rhs[idx].copy()
    prior = expected * np.linalg.pinv(sigma_h, hermitian=True)
    k = len(f)
    normal[k:, k:] += prior
    rhs[k:] += prior @ xh
    yy = problem.yy + float(xh @ prior @ xh)
    x = np.linalg.lstsq(normal, rhs, rcond=None)[0]
    return max(float(yy - rhs @ x), 0.0)


def _scale(m: Measurement, problem: Any, rss: float, resid_dof: int, noise_um: float | None,
           noise_dof: int | None) -> tuple[float, int, float | None]:
    """(covariance scale s², degrees of freedom, expected RSS per degree of freedom or None) (module docstring)."""
    if instrument(m) == "sphere-probe":
        from pige_sym.measurements.probe_import import row_covariances

        cov = row_covariances(m)
        rows = problem.rows
        scale = float(np.mean(np.trace(cov[rows], axis1=1, axis2=2)) + np.trace(cov[0])) / 3.0
        contacts = m.optional.get("n_samples")
        fitted = "given" not in m.metadata.get("r_eff_mm", "")
        dof = int(contacts.sum()) - 3 * m.n_rows - int(fitted) if contacts is not None else resid_dof
        return scale, max(dof, 1), scale
    expected = None if noise_um is None or not (math.isfinite(noise_um) and noise_um > 0) else noise_um**2
    if expected is not None:
        return expected, max(int(noise_dof or resid_dof), 1), expected
    if resid_dof <= 0:
        raise IdentificationError(f"{problem.n_obs} observations leave no degree of freedom for the noise of the "
                                  f"check-up's {problem.normal.shape[0]} PIGEs: measure more poses")
    return rss / resid_dof, resid_dof, expected


def _rms(problem: Any, x: np.ndarray) -> float:
    """RMS of the fitted rows' residuals [µm] (from the explicit design when it is kept)."""
    if problem.design is None or problem.data is None:
        return float("nan")
    rows = problem.rows
    resid = problem.data[rows] - np.einsum("nmp,p->nm", problem.design[rows][:, :, :x.size], x)
    return float(np.sqrt(np.mean(resid**2)))
