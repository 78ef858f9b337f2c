"""What the diagnosis does differently for instruments other than the R-test.

- :func:`screen_scale`: probe rows differ in precision (the contact pattern, the stand hiding contacts);
  the outlier screen compares residuals after bringing every row to one scale with its covariance.
- :func:`instrument_notes`: what the search does not model about the instrument (the rows' correlation
  through the reference pose; a direction-dependent trigger radius that one contact pattern hides).
"""

from __future__ import annotations

import numpy as np

from pige_sym.diagnosis.results import Finding
from pige_sym.identification.instruments import instrument
from pige_sym.kernels import load_kernels
from pige_sym.measurements.measurement import Measurement


def screen_scale(m: Measurement) -> np.ndarray:
    """Per probe row, ``s̄·Σ_i^{-1/2}`` with ``Σ_i`` the covariance of its deviation (its centre's and the
    reference centre's turned with the table) and ``s̄`` the median of their RMS σ: rows of unequal
    precision (different contact patterns) brought to one scale, so the outlier screen's robust noise
    level fits every row.  Shape (n, 3, 3); row 0 (the reference, zero by definition) is the identity."""
    from pige_sym.measurements.probe_import import row_covariances

    cov = row_covariances(m)
    rot = load_kernels(m.machine).workpiece_rotation(m.angles_deg)
    total = cov + rot @ cov[0] @ np.transpose(rot, (0, 2, 1))
    vals, vecs = np.linalg.eigh(total[1:])
    scale = float(np.median(np.sqrt(vals.mean(axis=1))))
    out = np.tile(np.eye(3), (m.n_rows, 1, 1))
    out[1:] = scale * (vecs / np.sqrt(vals)[:, None, :]) @ np.transpose(vecs, (0, 2, 1))
    return out


def instrument_notes(m: Measurement, findings: list[Finding]) -> list[str]:
    """What the search did not model about an instrument other than the R-test (its rows are correlated)."""
    kind = instrument(m)
    if kind == "rtest":
        return []
    blind = (" A probe whose trigger radius depends on the direction biases the axis-line offsets; with one contact "
             "pattern at every pose nothing in the residuals shows it (docs/probe.md): calibrate the probe per "
             "direction, or probe with pige program --pattern alternate so the diagnosis can fit it."
             if kind == "sphere-probe" and not any(f.effect == "probe_trigger" for f in findings) else "")
    if not findings:
        return [f"{kind}: the search treats the poses as independent; the final estimate is the identification "
                "with the reference pose's correlation (standard errors from it)." + blind]
    return [f"{kind}: the search and the final fit treat the poses as independent; the reference pose's "
            "correlation is not in them, so the standard errors of the location errors are understated "
            "(pige identify gives them honestly for the PIGE model)." + blind]
