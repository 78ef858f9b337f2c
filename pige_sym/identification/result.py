"""The result of an identification: values, uncertainty, identifiability, stages; as JSON and as text.

Units are those of the kernels' ``UNITS`` (µm for positions, µrad for angles); an undetermined
parameter has no value (``None`` in JSON, never a number).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from pige_sym.constants import LOSSES as LOSSES
from pige_sym.constants import METHODS as METHODS
from pige_sym.errors import IdentificationError as IdentificationError
from pige_sym.identification.canonical import CanonicalBasis, Combination


def _t_central(t: float, dof: int) -> float:
    """``P(|T| <= t)`` of Student's t with integer ``dof`` (Abramowitz & Stegun 26.7.3-26.7.4, exact)."""
    theta = math.atan(t / math.sqrt(dof))
    c2, s = math.cos(theta) ** 2, math.sin(theta)
    if dof % 2:  # odd: (2/π)[θ + sinθ cosθ (1 + 2/3 cos²θ + 2·4/(3·5) cos⁴θ + …)]
        term, total = 1.0, 1.0
        for k in range(1, (dof - 1) // 2):
            term *= c2 * (2 * k) / (2 * k + 1)
            total += term
        return 2 / math.pi * (theta + (s * math.cos(theta) * total if dof > 1 else 0.0))
    term, total = 1.0, 1.0  # even: sinθ (1 + 1/2 cos²θ + 1·3/(2·4) cos⁴θ + …)
    for k in range(1, dof // 2):
        term *= c2 * (2 * k - 1) / (2 * k)
        total += term
    return s * total


def student_t_975(dof: int) -> float:
    """The 0.975 quantile of Student's t [1]: exact series and bisection up to 1000 degrees of freedom,
    Cornish–Fisher beyond (error < 1e-12 there).  Written out (checked against ``scipy.special.stdtrit`` in
    ``tests/test_identification.py``) so that ``pige identify`` does not pay SciPy's special-function import."""
    from statistics import NormalDist

    if dof > 1000:
        z = NormalDist().inv_cdf(0.975)
        return (z + (z**3 + z) / (4 * dof) + (5 * z**5 + 16 * z**3 + 3 * z) / (96 * dof**2)
                + (3 * z**7 + 19 * z**5 + 17 * z**3 - 15 * z) / (384 * dof**3))
    lo, hi = 0.0, 12.8  # t(1) = 12.706 is the largest
    while _t_central(hi, dof) < 0.95:
        hi *= 2
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if _t_central(mid, dof) < 0.95:
            lo = mid
        else:
            hi = mid
        if hi - lo < 1e-13 * hi:
            break
    return 0.5 * (lo + hi)


@dataclass
class Stage:
    """One differential of the double-differential scheme."""

    index: int
    solved: list[str]
    fixed: list[str]
    values: dict[str, float]
    std: dict[str, float | None]
    vif: dict[str, float]
    rank: int
    condition: float

    def to_dict(self) -> dict[str, Any]:
        return {"stage": self.index, "solved": self.solved, "fixed": self.fixed, "values": self.values,
                "std": self.std, "vif": {k: json_float(v) for k, v in self.vif.items()}, "rank": self.rank,
                "condition": json_float(self.condition)}


@dataclass
class IdentificationResult:
    """Estimated parameters with their uncertainty and identifiability.

    Attributes
    ----------
    parameters : list of str
        Names in order (PIGEs, optional zero-position errors, extra columns).
    values : ndarray, shape=(P,)
        Estimates [µm or µrad]; NaN where the data cannot determine the parameter.
    std : ndarray, shape=(P,)
        Standard errors (NaN where undetermined).
    covariance : ndarray, shape=(P, P)
    residuals_um : ndarray, shape=(n, m)
        Observed minus model for every row (reference row included), projected.
    axis_sense : dict of str to int
        Axes the measurement's controller commands in the reverse of CONVENTIONS' sense (CONVENTIONS §9);
        the values keep CONVENTIONS' meaning, the sense says how a later command turns them into commanded angles.
    null_space : list of Combination
        The canonical basis of the combinations the data do not determine (:mod:`pige_sym.identification.canonical`,
        coefficients in parameter units, each vector's pivot 1 and first); ``unidentifiable`` says them in words.
    """

    machine: str
    method: str
    projection: str
    loss: str
    parameters: list[str]
    units: dict[str, str]
    values: np.ndarray
    std: np.ndarray
    covariance: np.ndarray
    identifiable: np.ndarray
    rms_um: float
    sigma_um: float
    dof: int
    n_rows: int
    n_obs: int
    rank: int
    condition: float
    singular_values: np.ndarray
    observability: dict[str, float]
    unidentifiable: list[str]
    outlier_rows: list[int]
    residuals_um: np.ndarray
    stages: list[Stage] = field(default_factory=list)
    ball_mm: list[float] = field(default_factory=list)
    pivots_mm: dict[str, list[float]] = field(default_factory=dict)
    tool_mm: list[float] | None = None
    vif: np.ndarray | None = None
    unobserved: list[str] = field(default_factory=list)
    axis_sense: dict[str, int] = field(default_factory=dict)
    null_space: list[Combination] = field(default_factory=list)

    def value(self, name: str) -> float:
        return float(self.values[self.parameters.index(name)])

    def ci95(self) -> np.ndarray:
        """95 % confidence intervals, shape=(P, 2)."""
        t = student_t_975(max(self.dof, 1))
        return np.column_stack([self.values - t * self.std, self.values + t * self.std])

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict (values ``None`` where undetermined)."""
        ci = self.ci95()
        out: dict[str, Any] = {
            "machine": self.machine,
            "method": self.method,
            "projection": self.projection,
            "loss": self.loss,
            "pige": {p: json_float(v) for p, v in zip(self.parameters, self.values, strict=True)},
            "std": {p: json_float(v) for p, v in zip(self.parameters, self.std, strict=True)},
            "ci95": {p: [json_float(a), json_float(b)] for p, (a, b) in zip(self.parameters, ci, strict=True)},
            "units": self.units,
            "rank": self.rank,
            "n_parameters": len(self.parameters),
            "condition": json_float(self.condition),
            "rms_um": self.rms_um,
            "sigma_um": self.sigma_um,
            "dof": self.dof,
            "n_rows": self.n_rows,
            "n_obs": self.n_obs,
            "observability": {k: json_float(v) for k, v in self.observability.items()},
            "unidentifiable": self.unidentifiable,
            "null_space": [c.as_dict() for c in self.null_space],
            "unobserved": self.unobserved,
            "outlier_rows": self.outlier_rows,
            "ball_mm": self.ball_mm,
            "pivots_mm": self.pivots_mm,
            "tool_mm": self.tool_mm,
        }
        if self.axis_sense:
            out["axis_sense"] = dict(self.axis_sense)
        out["covariance"] = self.covariance_dict()
        if self.vif is not None:
            out["vif"] = {p: json_float(v) for p, v in zip(self.parameters, self.vif, strict=True)}
        if self.method == "double-differential":
            out["stages"] = [s.to_dict() for s in self.stages]
        return out

    def covariance_dict(self) -> dict[str, Any] | None:
        """``{"parameters": [...], "matrix": [[...]]}`` over the determined parameters [µm², µm·µrad, µrad²]
        (the parameter file's ``covariance``, :class:`~pige_sym.measurements.schema.CovarianceDocument`)."""
        cov = np.asarray(self.covariance, dtype=float)
        if cov.shape != (len(self.parameters),) * 2:
            return None
        keep = [i for i in range(len(self.parameters)) if np.isfinite(self.values[i]) and np.isfinite(self.std[i])
                and self.std[i] > 0 and np.isfinite(cov[i, i])]
        keep = [i for i in keep if all(np.isfinite(cov[i, j]) for j in keep)]  # the undetermined rows are NaN
        if not keep:
            return None
        sub = cov[np.ix_(keep, keep)]
        root = np.sqrt(np.clip(np.diag(sub), 1e-300, None))
        corr = np.clip(0.5 * (sub + sub.T) / np.outer(root, root), -1.0, 1.0)
        sub = corr * np.outer(self.std[keep], self.std[keep])  # its diagonal: the std printed beside it, exactly
        return {"parameters": [self.parameters[i] for i in keep], "matrix": sub.tolist()}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> IdentificationResult:
        """Rebuild a result (without residuals or covariance) from :meth:`to_dict` output."""
        params = list(d["pige"])
        vals = np.array([np.nan if d["pige"][p] is None else d["pige"][p] for p in params], dtype=float)
        std = np.array([np.nan if d["std"].get(p) is None else d["std"][p] for p in params], dtype=float)
        return cls(
            machine=d["machine"], method=d.get("method", "gauss-newton"), projection=d.get("projection", "xyz"),
            loss=d.get("loss", "linear"), parameters=params, units=d.get("units", {}), values=vals, std=std,
            covariance=np.diag(np.nan_to_num(std) ** 2), identifiable=np.isfinite(vals),
            rms_um=float(d.get("rms_um", np.nan)), sigma_um=float(d.get("sigma_um", np.nan)),
            dof=int(d.get("dof", 0)), n_rows=int(d.get("n_rows", 0)), n_obs=int(d.get("n_obs", 0)),
            rank=int(d.get("rank", 0)), condition=float(d["condition"]) if d.get("condition") is not None else np.inf,
            singular_values=np.array([]), observability={}, unidentifiable=list(d.get("unidentifiable", [])),
            outlier_rows=list(d.get("outlier_rows", [])), residuals_um=np.zeros((0, 0)),
            ball_mm=list(d.get("ball_mm", [])), pivots_mm=dict(d.get("pivots_mm", {})), tool_mm=d.get("tool_mm"),
            axis_sense=dict(d.get("axis_sense", {})),
            null_space=[Combination(tuple((str(k), float(v)) for k, v in c.items())) for c in d.get("null_space", [])],
        )


def not_identifiable(basis: CanonicalBasis, names: list[str], units: dict[str, str]) -> tuple[list[Combination],
                                                                                         list[str]]:
    """A null space as a result holds it: its canonical combinations and one ``… is not identifiable`` line
    each (the one printer, :meth:`~pige_sym.identification.canonical.Combination.text`)."""
    combos = basis.combinations(names)
    return combos, [f"{c.text(units)} is not identifiable" for c in combos]


def value_std(value: float, std: float, sep: str = " ± ") -> str:
    """``value ± std`` for a reader: the std to two significant digits, the value to the same decimal place
    (``11.95 ± 0.42``, never ``12 ± 0.42``); without a usable std the value to four significant digits."""
    if not math.isfinite(value):
        return "—"
    if not (math.isfinite(std) and std > 0):
        return f"{value:.4g}"
    decimals = max(0, 1 - int(math.floor(math.log10(std))))
    return f"{value:.{decimals}f}{sep}{std:.{decimals}f}"


def per_pose(lo: int, hi: int) -> str:
    """A count per pose for a reader: ``5 per pose`` when every pose has the same, else ``4–9 per pose``."""
    return f"{lo} per pose" if lo == hi else f"{lo}–{hi} per pose"


def json_float(x: float) -> float | None:
    x = float(x)
    return None if not math.isfinite(x) else x


def format_result(result: IdentificationResult) -> str:
    """Human-readable table of an identification result."""
    lines = [f"machine {result.machine}   method {result.method}   projection {result.projection}   loss {result.loss}",
             f"rows {result.n_rows}  observations {result.n_obs}  rank {result.rank}/{len(result.parameters)}  "
             f"condition {result.condition:.3g}  residual RMS {result.rms_um:.3f} um  sigma {result.sigma_um:.3f} um",
             "", f"{'parameter':<12}{'value':>11}{'std':>10}   {'95% interval':<24}unit"]
    ci = result.ci95()
    for j, name in enumerate(result.parameters):
        u = result.units.get(name, "")
        if not np.isfinite(result.values[j]):
            lines.append(f"{name:<12}{'—':>11}{'—':>10}   {'not identifiable':<24}{u}")
            continue
        lines.append(f"{name:<12}{result.values[j]:>11.3f}{result.std[j]:>10.3f}   "
                     f"[{ci[j, 0]:8.3f}, {ci[j, 1]:8.3f}]      {u}")
    if result.unobserved:
        lines += ["", f"unobserved (no trace in these data): {', '.join(result.unobserved)}"]
    if result.unidentifiable:
        lines += ["", "not identifiable from these data:"] + [f"  {c}" for c in result.unidentifiable]
    if result.outlier_rows:
        lines += ["", f"outlier rows (0-based, reference = 0): {result.outlier_rows}"]
    if result.stages:
        lines += ["", "differentials:"]
        for s in result.stages:
            lines.append(f"  stage {s.index}: solved {len(s.solved)}, fixed {', '.join(s.fixed) or 'none'}")
    obs = ", ".join(f"{k}={v:.3g}" for k, v in result.observability.items())
    lines += ["", f"observability: {obs}"]
    return "\n".join(lines)
