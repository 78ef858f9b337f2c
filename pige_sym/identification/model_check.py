"""Does the PIGE model explain a file down to its noise?  A chi-square test of the whitened residual.

Under the model (the PIGEs and nothing else) the residual sum of squares of the whitened rows, divided by the
noise variance σ₀², is chi-square distributed with ``dof = n_obs − rank`` degrees of freedom, so::

    F = (σ̂ / σ₀)²       (σ̂² = RSS / dof, the σ ``pige identify`` reports)

is ``χ²_dof / dof`` when σ₀ is known, and Fisher's ``F(dof, dof₀)`` when σ₀ is itself estimated from ``dof₀``
degrees of freedom (a probe import's pooled contact scatter: ``dof₀ = contacts − 3·poses − 1`` with a fitted
``R_eff``; its σ₀ is uncertain by about ``1/√(2 dof₀)``, 9 % for 61, which a chi-square test would ignore and
flag 2 of 20 noise-only probe files).  The model is flagged as missing something when ``F`` exceeds its
``1 − ALPHA`` = 99.9 % quantile: a residual that large has a chance of 1 in 1000 from noise alone.  The tail
is the regularized incomplete beta function (``F``) or gamma function (chi-square), evaluated by their
continued fractions and series (Numerical Recipes §6.2, §6.4) and checked against SciPy in the tests, so
``pige identify`` does not import SciPy (its special functions take 0.3–0.9 s to import here).

The noise σ₀, per observed component [µm], in this order:

- ``--noise`` (``noise_um``): what the user states for the instrument (taken as known);
- a probe import (``instrument: sphere-probe``): the file's centre covariances (the sphere fits, pooled contact
  scatter); the identification whitens the rows by them scaled to a mean variance of 1
  (:mod:`pige_sym.identification.instruments`), so σ₀ is the root of that mean variance;
- an R-test file: the instrument's nominal noise, :data:`~pige_sym.constants.RTEST_NOISE_UM` (the noise
  ``pige plan`` and ``pige simulate`` assume), taken as known.  The ``sd_um`` column ``pige acquire`` writes is
  not used: it is the scatter of the samples within one dwell, and their mean's noise is dominated by what
  varies from pose to pose (repeatability, the reference row): on the virtual device ``sd_um/√n_samples`` is
  0.025 µm where the residual of the full model is 0.2 µm.

A flagged file names the next step: ``pige diagnose FILE`` (which names and fits what the model misses; the
estimate it gives is the one ``pige check`` and ``pige compensate --params`` use).
"""

from __future__ import annotations

import math
import shlex
from collections.abc import Callable
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from pige_sym.constants import RTEST_NOISE_UM
from pige_sym.identification.result import IdentificationResult
from pige_sym.measurements.measurement import Measurement

#: False-alarm rate of the model check: 1 in 1000 files the model does explain is flagged.
ALPHA = 1e-3


def _continued_fraction(terms: Callable[[int], tuple[float, float]], start: float) -> float:
    """``start / (1 + a₁/(1 + a₂/…))``-type continued fractions by the modified Lentz method: ``terms(m)`` gives
    the m-th ``(a, b)`` of ``b₀ + a₁/(b₁ + a₂/(b₂ + …))`` with ``b₀ = start``."""
    tiny = 1e-300
    f = start if start != 0 else tiny
    c, d = f, 0.0
    for m in range(1, 100_000):
        a, b = terms(m)
        d = b + a * d
        d = 1.0 / (d if abs(d) > tiny else tiny)
        c = b + a / c
        c = c if abs(c) > tiny else tiny
        f *= c * d
        if abs(c * d - 1.0) < 1e-15:
            break
    return f


def _beta_tail(x: float, a: float, b: float) -> float:
    """The regularized incomplete beta ``I_x(a, b)`` (continued fraction, Numerical Recipes §6.4)."""
    if x <= 0.0 or x >= 1.0:
        return 0.0 if x <= 0.0 else 1.0
    if x > (a + 1.0) / (a + b + 2.0):
        return 1.0 - _beta_tail(1.0 - x, b, a)
    front = math.exp(math.lgamma(a + b) - math.lgamma(a) - math.lgamma(b) + a * math.log(x) + b * math.log1p(-x))

    def terms(m: int) -> tuple[float, float]:
        k = m // 2
        if m % 2:
            return -(a + k) * (a + b + k) * x / ((a + 2 * k) * (a + 2 * k + 1)), 1.0
        return k * (b - k) * x / ((a + 2 * k - 1) * (a + 2 * k)), 1.0

    return front / a / _continued_fraction(terms, 1.0)


def _gamma_upper(a: float, x: float) -> float:
    """The regularized upper incomplete gamma ``Q(a, x)`` (series or continued fraction, Numerical Recipes §6.2)."""
    if x <= 0.0:
        return 1.0
    front = math.exp(-x + a * math.log(x) - math.lgamma(a))
    if x < a + 1.0:  # series of P(a, x)
        term = total = 1.0 / a
        n = a
        while abs(term) > 1e-16 * abs(total):
            n += 1.0
            term *= x / n
            total += term
        return 1.0 - front * total
    return front / _continued_fraction(lambda m: (-m * (m - a), x + 2 * m + 1.0 - a), x + 1.0 - a)


def f_upper_tail(f: float, dof: int, dof0: float) -> float:
    """``P(X ≥ f)`` for ``X ~ F(dof, dof0)`` (``dof0 = inf``: ``χ²_dof / dof``)."""
    if f <= 0.0:
        return 1.0
    if math.isinf(dof0):
        return _gamma_upper(dof / 2.0, dof * f / 2.0)
    return _beta_tail(dof0 / (dof0 + dof * f), dof0 / 2.0, dof / 2.0)


def f_quantile(q: float, dof: int, dof0: float) -> float:
    """The ``q`` quantile of ``F(dof, dof0)`` (``dof0 = inf``: of ``χ²_dof / dof``), by bisection on
    :func:`f_upper_tail`."""
    lo, hi = 0.0, 2.0
    while f_upper_tail(hi, dof, dof0) > 1.0 - q:
        lo, hi = hi, hi * 2.0
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if f_upper_tail(mid, dof, dof0) > 1.0 - q else (lo, mid)
    return 0.5 * (lo + hi)


@dataclass
class ModelCheck:
    """The chi-square test of one identification (module docstring).

    Attributes
    ----------
    file : str
        The file, as the next step names it.
    sigma_um : float
        Residual σ̂ of the fit [µm].
    noise_um : float
        Noise σ₀ the test assumes, per component [µm].
    noise_source : str
        Where σ₀ comes from, in words.
    ratio : float
        ``F = (σ̂/σ₀)²``.
    dof, noise_dof : int, float
        Degrees of freedom of the residual and of σ₀ (``inf``: σ₀ taken as known).
    quantile : float
        The 99.9 % quantile of ``F`` (the threshold).
    p_value : float
    flagged : bool
        True when ``ratio > quantile``: the PIGE model misses something.
    """

    file: str
    sigma_um: float
    noise_um: float
    noise_source: str
    ratio: float
    dof: int
    noise_dof: float
    quantile: float
    p_value: float
    flagged: bool

    @property
    def test_name(self) -> str:
        """``chi-square`` (σ₀ known or assumed) or ``F`` (σ₀ estimated from ``noise_dof``)."""
        return "chi-square" if math.isinf(self.noise_dof) else "F"

    @property
    def next_step(self) -> str:
        """The command to run next."""
        if self.flagged:
            return f"pige diagnose {shlex.quote(self.file)}"
        return "none needed: pige check and pige compensate can use this fit"

    def to_dict(self) -> dict[str, Any]:
        out = asdict(self)
        out["noise_dof"] = None if math.isinf(self.noise_dof) else int(self.noise_dof)  # JSON has no infinity
        out["test"] = self.test_name
        out["alpha"] = ALPHA
        out["explained"] = not self.flagged
        out["next_step"] = self.next_step
        return out

    def text(self) -> str:
        """The lines ``pige identify`` prints."""
        test = (f"chi2/dof = {self.ratio:.3g} on {self.dof} dof" if math.isinf(self.noise_dof) else
                f"F = {self.ratio:.3g} on ({self.dof}, {self.noise_dof:.0f}) dof")
        stat = (f"residual sigma {self.sigma_um:.3g} um = {math.sqrt(self.ratio):.2g} x the noise "
                f"{self.noise_um:.3g} um ({self.noise_source}): {test}, "
                f"p {'< 1e-15' if self.p_value < 1e-15 else f'= {self.p_value:.2g}'}; flagged above its 99.9 % "
                f"quantile {self.quantile:.3g}")
        if not self.flagged:
            return f"model check: the PIGEs explain these data down to the noise ({stat})."
        return (f"model check: the residual is well above the noise: the PIGE model misses something in these data "
                f"({stat}).\n"
                f"  The estimates above can be biased by it. Next step: {self.next_step} names and fits what is "
                "missing; its estimate is the one pige check and pige compensate --params then use.")


def check_model(m: Measurement, result: IdentificationResult, *, noise_um: float | None = None) -> ModelCheck | None:
    """The model check of ``result``, identified from ``m`` (None when the fit has no residual dof).

    Parameters
    ----------
    m : Measurement
    result : IdentificationResult
        A fit of ``m`` (any projection; probe files: ``xyz``).
    noise_um : float, optional
        The instrument's noise per component [µm] (``pige identify --noise``); default: the file's or the
        instrument's (module docstring).
    """
    if result.dof <= 0 or not math.isfinite(result.sigma_um):
        return None
    noise_dof = math.inf
    if noise_um is not None:
        sigma0, source = float(noise_um), "stated with --noise"
    elif m.metadata.get("instrument") == "sphere-probe":
        sigma0, noise_dof = _probe_noise(m)
        source = f"the file's centre covariances, from the contacts' scatter on {noise_dof:.0f} dof"
    else:
        sigma0, source = RTEST_NOISE_UM, "the R-test's nominal noise; state yours with --noise"
    ratio = (result.sigma_um / sigma0) ** 2
    quantile = f_quantile(1.0 - ALPHA, result.dof, noise_dof)
    return ModelCheck(m.path or "FILE", result.sigma_um, sigma0, source, ratio, result.dof, noise_dof, quantile,
                      f_upper_tail(ratio, result.dof, noise_dof), ratio > quantile)


def _probe_noise(m: Measurement) -> tuple[float, float]:
    """σ₀ [µm] of a probe import (the whitening's scale: each row's own variance plus the reference centre's) and
    its degrees of freedom: contacts − 3 per pose − 1 for a fitted ``R_eff`` (the pooled sphere fit)."""
    from pige_sym.measurements.probe_import import row_covariances

    cov = row_covariances(m)
    sigma0 = math.sqrt((float(np.trace(cov[1:], axis1=1, axis2=2).mean()) + float(np.trace(cov[0]))) / 3.0)
    contacts = m.optional.get("n_samples")
    if contacts is None:
        return sigma0, math.inf
    fitted = str(m.metadata.get("r_eff_mm", "")).endswith("(fitted)")
    return sigma0, max(float(contacts.sum()) - 3.0 * m.n_rows - (1.0 if fitted else 0.0), 1.0)
