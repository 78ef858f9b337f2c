"""Which values to enter, and how much: every estimate weighed by its uncertainty.

An identification gives estimates x̂ with a covariance Σ (``pige identify/diagnose --json`` write it as
``covariance``).  Entering x̂ as it is corrects the machine by x̂, so it leaves ``x − x̂`` behind: for a
weakly determined parameter (EB0A 45 ± 35 µrad where the truth is 15) that can be more than it removes.

**The rule** (docs/algorithms.md, "Corrections weighed by their uncertainty"): the entered values are the
posterior mean of the parameters under a zero-mean normal prior whose variance per parameter is estimated
from the data itself (empirical Bayes, "automatic relevance determination"),

    T = diag(τ²) maximising N(x̂; 0, Σ + T) (:func:`prior_variances`),   c = T (T + Σ)⁻¹ x̂.

With uncorrelated estimates ``τᵢ² = max(x̂ᵢ² − σᵢ², 0)``: E[x̂ᵢ²] = xᵢ² + σᵢ², so τᵢ² is the size of the
parameter without its noise.  A parameter the data do not show (τᵢ = 0) is **not entered**, and the
parameters correlated with it take their estimate conditional on it being 0 (what an identification
without it would give); a parameter many standard errors from 0 is entered as estimated; in between it is
entered in part.  The full covariance is used, so a combination the data determine well keeps its value
even when each parameter alone is weak.  Without a covariance in the file the standard errors stand for
it (correlations unknown); without standard errors nothing is weighed (said so).

**The prediction.** The tool-point error after entering c on a machine whose parameters are x is, to
first order, ``D(θ, point)·(x − c)`` (:func:`~pige_sym.compensation.kinematics.raw_offset`, the same
kernels as the identification).  Its RMS over a set of poses is drawn for ``x ~ N(x̂, Σ)`` (``DRAWS``
draws, a fixed seed): the expected value is the draws' mean, the 95 % bound their 95th percentile.
Nothing is predicted as 0.000 when it is known to ±2 µm.

The poses are the compensated program's poses (the NC rewrite) or, for controller entries, the axes'
travel (:func:`travel_poses`): a poorly determined PIGE hurts most where the measured poses did not go.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from pige_sym.compensation.covariance import BlockCovariance, as_blocks
from pige_sym.compensation.covariance import correlated_groups as _correlated_groups  # noqa: F401 (its tests)
from pige_sym.compensation.draws import DRAWS, Draws, ErrorPrediction  # noqa: F401 (DRAWS: the rule's constant)
from pige_sym.compensation.entry_words import why_entered
from pige_sym.compensation.kinematics import raw_offset
from pige_sym.compensation.parameters import AngleExtension, CompensationParameters, extension_prefixes
from pige_sym.constants import DEFAULT_BALL_MM, DEFAULT_TILT_TRAVEL_DEG
from pige_sym.kernels import load_kernels
from pige_sym.model.trajectories import approach_directions

#: Poses at most: a longer program is judged on this many, evenly spaced along it.
MAX_POSES = 20000
#: Grid step of the travel poses [deg].
TRAVEL_STEP_DEG = 5.0
#: What a singular covariance gets added to its diagonal, per unit of each variance (:func:`regular`).
SINGULAR_RIDGE = 1e-9
#: A weighing row's start for a value the controller does not hold (:func:`weighing_rows`).
NOT_HERE = "not representable in this controller (below); weighed for the NC rewrite: "
#: The rule, as reports and ``--json`` state it.
RULE = ("posterior mean under a prior N(0, diag(tau^2)) whose variances the estimates and their covariance "
        "determine (tau^2 = max(x^2 - std^2, 0) for an uncorrelated value): what the data do not show is not "
        "entered, a well-determined value is entered as estimated")


@dataclass(frozen=True)
class JudgedPoses:
    """The poses a correction is judged on.

    Attributes
    ----------
    angles_deg : (n, k) [deg]
        CONVENTIONS angles (§9 θ) of the machine's rotary axes, in kernel order.
    points_mm : (n, 3) [mm]
        Intended workpiece point of each pose.
    approach : (n, k) of {−1, 0, +1}
        Direction of approach of each axis (a reversal error depends on it).
    description : str
        Which poses, for the reader.
    """

    angles_deg: np.ndarray
    points_mm: np.ndarray
    approach: np.ndarray
    description: str


@dataclass
class Weighing:
    """What is entered and what it is predicted to leave.

    Attributes
    ----------
    estimate, std : dict of str to float
        The file's values and standard errors [µm, µrad] (PIGEs, zero-position errors, effect parameters).
    entered : dict of str to float or None
        The value to enter per parameter; ``None`` where nothing is entered (not determined).
    why : dict of str to str
        Per parameter, in words: entered as estimated, in part, or not (and why).
    predicted : dict of str to ErrorPrediction
        ``none`` (no correction), ``all_estimates`` (every estimate entered) and ``entered`` (this
        recommendation); empty without an uncertainty.
    judged_on : str
    rule : str
    covariance_from : str
        ``covariance``, ``std`` (correlations unknown) or ``none`` (nothing weighed).
    """

    estimate: dict[str, float]
    std: dict[str, float]
    entered: dict[str, float | None]
    why: dict[str, str]
    predicted: dict[str, ErrorPrediction]
    judged_on: str
    rule: str = RULE
    covariance_from: str = "covariance"
    notes: list[str] = field(default_factory=list)
    covariance: BlockCovariance | None = field(default=None, repr=False)
    moments: Any = field(default=None, repr=False)
    draws: Draws | None = field(default=None, repr=False)

    def predicted_for(self, values: dict[str, float]) -> ErrorPrediction | None:
        """The RMS tool-point error left by entering ``values`` (others not entered) on the judged poses."""
        if self.draws is None:
            return None
        names = list(self.estimate)
        est = np.array([self.estimate[n] for n in names])
        return self.draws.left(est - np.array([values.get(n, 0.0) for n in names]))

    def rows(self) -> list[str]:
        """What is entered other than as estimated, one line per value or map (:func:`weighing_rows`)."""
        return weighing_rows(self, {})

    def to_dict(self) -> dict[str, Any]:
        pred = {k: v.to_dict() for k, v in self.predicted.items()}
        return {"entered": dict(self.entered), "why": dict(self.why), "rule": self.rule,
                "covariance_from": self.covariance_from, "judged_on": self.judged_on,
                "predicted_after_um": pred.get("entered"), "predicted_before_um": pred.get("none"),
                "predicted_all_estimates_um": pred.get("all_estimates"), "notes": list(self.notes)}


def entered_values(estimate: np.ndarray, covariance: np.ndarray | BlockCovariance) -> np.ndarray:
    """The values to enter, shape=(q,) [µm, µrad]: ``c = T (T + Σ)⁻¹ x̂`` with T of :func:`prior_variances`.

    Parameters
    ----------
    estimate : (q,) [µm, µrad]
    covariance : (q, q) or BlockCovariance
        Positive semi-definite, its diagonal positive (a singular one as :func:`regular` makes it); solved group by
        group of correlated values.
    """
    x = np.asarray(estimate, dtype=float)
    blocks = regular(covariance)
    tau2 = prior_variances(x, blocks)
    return np.where(tau2 > 0, tau2 * blocks.solve_shifted(tau2, x), 0.0)


def regular(covariance: np.ndarray | BlockCovariance) -> BlockCovariance:
    """``covariance`` if positive definite, else with :data:`SINGULAR_RIDGE` of each variance added to its diagonal:
    a combination stated as known exactly is taken as known to 3e-5 of its values' standard errors (the whole
    matrix is positive definite when each of its groups is: each group is checked, the ridge goes to every one)."""
    blocks = as_blocks(covariance)
    return blocks if blocks.positive_definite() else blocks.ridged(SINGULAR_RIDGE)


def prior_variances(estimate: np.ndarray, covariance: np.ndarray | BlockCovariance, *, sweeps: int = 500,
                    ) -> np.ndarray:
    """τ² that maximise the evidence ``N(x̂; 0, Σ + diag τ²)`` one at a time (type-II maximum likelihood), shape=(q,).

    Coordinate ascent with each coordinate's exact maximum (Tipping & Faul 2003, "Fast marginal likelihood
    maximisation for sparse Bayesian models"): with ``C₋ᵢ = Σ + T`` without τᵢ², ``s = C₋ᵢ⁻¹ᵢᵢ`` and
    ``q = (C₋ᵢ⁻¹x̂)ᵢ``, the evidence is largest at ``τᵢ² = (q² − s)/s²`` when ``q² > s``, else at 0.  It starts
    from ``max(x̂ᵢ² − σᵢ², 0)`` (the exact answer for uncorrelated estimates, used as it is for a value that no
    other is correlated with) and sweeps until no τᵢ² moves by more than 1e-12 of ``x̂ᵢ² + σᵢ²``, or the
    evidence's slope in each τᵢ² (upwards only where τᵢ² = 0) is below 1e-9 per ``x̂ᵢ² + σᵢ²``: a maximum of the
    evidence in every coordinate.  After each sweep the step it made is taken again, doubled while the evidence
    grows (two correlated values make a ridge that coordinate steps crawl along: without it, 3 of 20,000 drawn
    estimates stopped after 500 sweeps with τ² = 8.3 where the maximum is at 0).  Groups of values not correlated
    with each other are solved apart.
    """
    x = np.asarray(estimate, dtype=float)
    blocks = as_blocks(covariance)
    tau2 = np.clip(x**2 - blocks.diagonal(), 0.0, None)
    for group, block in blocks.groups:
        tau2[group] = _coordinate_ascent(x[group], block, tau2[group], sweeps)
    return tau2


def _log_evidence(x: np.ndarray, cov: np.ndarray, tau2: np.ndarray) -> float:
    """``log N(x̂; 0, Σ + diag τ²)`` without its constant."""
    c = cov + np.diag(tau2)
    return float(-0.5 * (np.linalg.slogdet(c)[1] + x @ np.linalg.solve(c, x)))


def _extrapolated(x: np.ndarray, cov: np.ndarray, start: np.ndarray, end: np.ndarray) -> np.ndarray:
    """``start + f (end − start)`` for f = 2, 4, 8, … (clipped at 0) while the evidence grows; ``end`` if it does
    not at f = 2."""
    best, best_ev, f = end, _log_evidence(x, cov, end), 2.0
    while f <= 2.0**40:
        trial = np.clip(start + f * (end - start), 0.0, None)
        ev = _log_evidence(x, cov, trial)
        if not ev > best_ev:
            break
        best, best_ev, f = trial, ev, 2 * f
    return best


def _coordinate_ascent(x: np.ndarray, cov: np.ndarray, tau2: np.ndarray, sweeps: int) -> np.ndarray:
    """:func:`prior_variances` for one group of correlated values."""
    tau2 = tau2.copy()
    scale = x**2 + np.diag(cov)
    rhs = np.column_stack([np.eye(x.size), x])
    for _ in range(sweeps):
        start = tau2.copy()
        moved = 0.0
        for i in range(x.size):
            without = tau2.copy()
            without[i] = 0.0
            sol = np.linalg.solve(cov + np.diag(without), rhs[:, [i, x.size]])  # C₋ᵢ⁻¹ [eᵢ, x̂]
            s, q = sol[i, 0], sol[i, 1]
            new = (q * q - s) / (s * s) if q * q > s else 0.0
            moved = max(moved, abs(new - tau2[i]) / scale[i])
            tau2[i] = new
        if moved <= 1e-12 or _slope_left(x, cov, tau2, scale) <= 1e-9:
            break
        tau2 = _extrapolated(x, cov, start, tau2)
    return tau2


def _slope_left(x: np.ndarray, cov: np.ndarray, tau2: np.ndarray, scale: np.ndarray) -> float:
    """How far τ² is from a maximum of the evidence: its largest slope ``∂ log N / ∂τᵢ² = ½ (αᵢ² − (C⁻¹)ᵢᵢ)``
    (α = C⁻¹ x̂, C = Σ + diag τ²) times ``x̂ᵢ² + σᵢ²``, where τᵢ² > 0 and, upwards only, where τᵢ² = 0."""
    inv = np.linalg.inv(cov + np.diag(tau2))
    slope = 0.5 * ((inv @ x) ** 2 - np.diag(inv)) * scale
    return float(np.max(np.where(tau2 > 0, np.abs(slope), slope)))


def error_moments(params: CompensationParameters, names: list[str], poses: JudgedPoses) -> Any:
    """``M = Dᵀ D / n`` of the tool-point error per unit parameter over the poses, shape=(q, q): an array, or with
    maps a ``scipy.sparse.csr_array`` (a map value acts only near its grid angle: :mod:`~pige_sym.compensation.
    map_moments`).

    ``(x − c)ᵀ M (x − c)`` is the mean square tool-point error [µm²] left by entering ``c``.
    """
    kern = load_kernels(params.machine)
    pivots = {a: np.asarray(v, dtype=float) for a, v in params.pivots_mm.items()} or None
    a, pts = poses.angles_deg, poses.points_mm
    by_name = dict(_effect_columns(params.extensions))
    maps = params.error_maps.values() if params.error_maps is not None else {}
    plain = [name for name in names if name not in maps]
    cols = []
    for name in plain:
        p = np.zeros((a.shape[0], len(kern.PARAMETERS)))
        if name in by_name:
            ext, key = by_name[name]
            unit = AngleExtension(ext.spec, {k: float(k == key) for k in ext.params})
            axis = ext.spec.axis
            p[:, kern.PARAMETERS.index(f"E{axis[0]}0{axis}")] = unit.zero_error_urad(a, tuple(kern.ROTARY_AXES),
                                                                                     poses.approach)
        else:
            p[:, kern.PARAMETERS.index(name)] = 1.0
        cols.append(raw_offset(kern, a, pts, p, pivots, params.tool_mm).reshape(-1))
    d = np.stack(cols, axis=1) if cols else np.zeros((3 * a.shape[0], 0))
    if len(plain) == len(names):
        return np.asarray(d.T @ d / max(a.shape[0], 1))
    from pige_sym.compensation.map_moments import map_design, sparse_moments

    map_names, map_part = map_design(params, kern, poses, pivots)
    return sparse_moments(d, plain, map_part, map_names, names, a.shape[0])


def _effect_columns(extensions: list[AngleExtension]) -> list[tuple[str, tuple[AngleExtension, str]]]:
    """``(<id>.<param>, (extension, param))`` of every effect parameter (the names the diagnosis writes)."""
    return [(f"{pre}.{k}", (e, k)) for pre, e in zip(extension_prefixes(extensions), extensions, strict=True)
            for k in e.params]


def predict(estimate: np.ndarray, covariance: np.ndarray | BlockCovariance, moments: Any, entered: np.ndarray,
            seed: int = 0) -> ErrorPrediction:
    """RMS tool-point error left by ``entered`` for parameters drawn from N(estimate, covariance) [µm]
    (:class:`~pige_sym.compensation.draws.Draws`: to predict several corrections, keep one)."""
    return Draws(covariance, moments, seed).left(np.asarray(estimate, dtype=float) - np.asarray(entered, dtype=float))


def weigh(params: CompensationParameters, poses: JudgedPoses) -> Weighing:
    """Decide what to enter from ``params`` and predict what it leaves on ``poses`` (module docstring).

    A head machine's file without ``tool_mm`` is weighed all the same; what it leaves is then not predicted
    (the tool point is not known).
    """
    from pige_sym.measurements.measurement import missing_tool

    est = estimate_of(params)
    names = list(est)
    values = np.array([est[n] for n in names])
    cov, source = _covariance(params, names)
    no_tool = missing_tool(params.machine, params.tool_mm, "tool_mm")
    moments = None if no_tool else error_moments(params, names, poses)
    undetermined: dict[str, float | None] = {n: None for n in params.set_to_zero}
    notes = [f"the error left is not predicted: {no_tool}"] if no_tool else []
    if cov is None:
        cov = BlockCovariance(len(names), (), np.arange(len(names)), np.zeros(len(names)))
        entered, std, source = values, {}, "none"
        why = {n: "entered as given: the file states no uncertainty" for n in names}
        notes.append("the parameter file states no standard errors: nothing is weighed, and the errors are "
                     "predicted as if its values were exact (pige identify --json writes them)")
    else:
        variance = cov.diagonal()
        std = {n: float(np.sqrt(variance[i])) for i, n in enumerate(names)}
        entered = entered_values(values, cov)
        why = {n: why_entered(i, names, values, cov, entered, params.units.get(n, "")) for i, n in enumerate(names)}
        if source != "covariance":
            notes.append("the parameter file has standard errors but no covariance: the parameters are weighed as if "
                         "uncorrelated")
        elif any("@" in n for n in names):
            notes.append("the PIGEs are weighed with their covariance, each map value by its own standard error (the "
                         "maps' covariance is singular: the §10 projection leaves their left-out functions no "
                         "variance)")
    draws = None if moments is None else Draws(cov, moments)
    predicted = {} if draws is None else {"none": draws.left(values), "entered": draws.left(values - entered)}
    if draws is not None and source != "none":
        predicted["all_estimates"] = draws.left(np.zeros_like(values))
    chosen: dict[str, float | None] = {n: float(v) for n, v in zip(names, entered, strict=True)}
    return Weighing(est, std, chosen | undetermined,
                    why | {n: "not determined by the data: not entered" for n in undetermined}, predicted,
                    poses.description, covariance_from=source, notes=notes, covariance=cov, moments=moments,
                    draws=draws)


def _covariance(params: CompensationParameters, names: list[str]) -> tuple[BlockCovariance | None, str]:
    """The estimates' covariance as blocks: the file's for the PIGEs and effects (``pige identify --map --json`` writes
    it with the maps), the map values' standard errors as uncorrelated ones (their covariance is singular: the §10
    projection leaves the left-out functions no variance, and a singular Σ + T has no evidence to maximise); None
    when any value has no uncertainty."""
    maps = set(params.error_maps.values()) if params.error_maps is not None else set()
    plain = [n for n in names if n not in maps]
    cov, source = params.covariance_of(plain)
    if cov is None:
        return None, source
    blocks = BlockCovariance.from_dense(cov)
    if len(plain) == len(names):
        return blocks, source
    stds = _map_std(params)
    index = {n: k for k, n in enumerate(names)}
    mapped = [n for n in names if n in maps]
    std = np.array([stds.get(n, np.nan) for n in mapped])
    if not (np.isfinite(std) & (std > 0)).all():
        return None, "none"
    return BlockCovariance.with_singles(blocks, np.array([index[n] for n in plain], dtype=int),
                                        np.array([index[n] for n in mapped], dtype=int), np.square(std),
                                        len(names)), source


def _map_std(params: CompensationParameters) -> dict[str, float]:
    """Each map value's standard error, by its name (:meth:`~pige_sym.model.error_motions.ErrorMaps.values`); NaN
    where the file gives none."""
    out = {}
    for axis, m in params.error_maps.axes.items():
        for motion in m.values:
            s = params.error_map_std.get(axis, {}).get(motion, ())
            for g, angle in enumerate(m.grid.angles_deg):
                out[f"{axis}:{motion}@{angle:g}"] = float(s[g]) if g < len(s) and s[g] is not None else np.nan
    return out


def every_estimate(weighing: Weighing) -> Weighing:
    """The weighing overruled: every estimate entered as it is (``--enter all``), predicted as such."""
    entered = {n: (weighing.estimate[n] if v is not None else None) for n, v in weighing.entered.items()}
    why = {n: ("entered as estimated (--enter all)" if v is not None else weighing.why[n]) for n, v in entered.items()}
    predicted = dict(weighing.predicted)
    if "all_estimates" in predicted:
        predicted["entered"] = predicted["all_estimates"]
    return replace(weighing, entered=entered, why=why, predicted=predicted, notes=weighing.notes + [
        "--enter all: every estimate is entered as it is, whatever its uncertainty"])


def weighing_rows(weighing: Weighing, units: dict[str, str], carried: set[str] | None = None) -> list[str]:
    """One line per value not entered as estimated: ``EB0A: entered in part (73 % of the estimate): the data show it
    only weakly (+45.35 ± 35 urad): enter +32.9``; the map values (``C:EXC@30``) in one line per axis and motion; with
    ``carried`` (what a controller holds: PIGEs, ``<axis>:<motion>`` maps) a value it does not hold is said to be
    weighed for the NC rewrite only."""
    rows = []
    maps: dict[str, list[str]] = {}
    for n, v in weighing.entered.items():
        if "@" in n:
            maps.setdefault(n.split("@")[0], []).append(weighing.why[n])
            continue
        if weighing.why[n].startswith("entered as estimated"):
            continue
        value = f": enter {v:+.4g}" if v is not None and weighing.why[n].startswith("entered in part") else ""
        rows.append(f"{n}: {'' if carried is None or n in carried else NOT_HERE}{weighing.why[n]}{value}")
    for motion, whys in maps.items():
        whole = sum(w.startswith("entered as estimated") for w in whys)
        none = sum(w.startswith("not entered") for w in whys)
        if whole < len(whys):
            rows.append(f"map {motion}: {'' if carried is None or motion in carried else NOT_HERE}{whole} of "
                        f"{len(whys)} values entered as estimated, {none} not entered (within their uncertainty), "
                        f"{len(whys) - whole - none} in part (weakly determined)")
    return rows


def estimate_of(params: CompensationParameters) -> dict[str, float]:
    """Every determined value of ``params``: PIGEs and zero-position errors, then effect parameters."""
    out = {n: v for n, v in params.values.items() if n not in params.set_to_zero}
    for name, (ext, key) in _effect_columns(params.extensions):
        out[name] = ext.params[key]
    if params.error_maps is not None:
        out |= params.error_maps.values()
    return out


def with_entered(params: CompensationParameters, weighing: Weighing) -> CompensationParameters:
    """``params`` holding the entered values (a parameter not entered at 0, effects with their entered part)."""
    entered = {n: v for n, v in weighing.entered.items() if v is not None}
    values = {n: entered.get(n, 0.0) for n in params.values}
    maps = params.error_maps.with_values(entered) if params.error_maps is not None else None
    exts = [AngleExtension(e.spec, {k: entered.get(f"{pre}.{k}", 0.0) for k in e.params})
            for pre, e in zip(extension_prefixes(params.extensions), params.extensions, strict=True)]
    return replace(params, values=values, extensions=exts, weighing=weighing, error_maps=maps)


def travel_poses(params: CompensationParameters, travel_deg: dict[str, tuple[float, float]] | None = None,
                 ) -> JudgedPoses:
    """A grid over the rotary axes' travel at the measured point and at the default R-test ball.

    A full-turn axis (C, and any axis not in ``travel_deg`` whose letter is C) runs 0…360°; every other axis
    ``DEFAULT_TILT_TRAVEL_DEG`` unless ``travel_deg`` gives its range [deg] (CONVENTIONS angles).
    """
    kern = load_kernels(params.machine)
    axes = tuple(kern.ROTARY_AXES)
    travel = dict(travel_deg or {})
    grids = []
    for ax in axes:
        lo, hi = travel.get(ax, (0.0, 360.0 - TRAVEL_STEP_DEG) if ax[0] == "C" else DEFAULT_TILT_TRAVEL_DEG)
        grids.append(np.linspace(lo, hi, int(round((hi - lo) / TRAVEL_STEP_DEG)) + 1))
    angles = np.stack([g.ravel() for g in np.meshgrid(*grids, indexing="ij")], axis=1)
    points = [tuple(params.ball_mm)] if params.ball_mm is not None else []
    points += [DEFAULT_BALL_MM] if tuple(DEFAULT_BALL_MM) not in points else []
    ang = np.vstack([angles] * len(points))
    pts = np.repeat(np.asarray(points, dtype=float), angles.shape[0], axis=0)
    ranges = ", ".join(f"{ax} {g[0]:g}…{g[-1]:g}°" for ax, g in zip(axes, grids, strict=True))
    where = " and ".join("(" + ", ".join(f"{x:g}" for x in p) + ") mm" for p in points)
    return JudgedPoses(ang, pts, np.zeros_like(ang),
                       f"the axes' travel ({ranges}, every {TRAVEL_STEP_DEG:g}°) at {where}")


def program_poses(angles_deg: np.ndarray, points_mm: np.ndarray, approach: np.ndarray | None = None,
                  ) -> JudgedPoses:
    """The compensated program's poses (at most ``MAX_POSES``, evenly spaced along the program)."""
    a = np.atleast_2d(np.asarray(angles_deg, dtype=float))
    n = a.shape[0]
    appr = approach_directions(a) if approach is None else np.atleast_2d(approach)
    take = np.unique(np.linspace(0, n - 1, MAX_POSES).round().astype(int)) if n > MAX_POSES else np.arange(n)
    said = f"the compensated program's {n} poses" + (f" ({take.size} of them, evenly spaced)" if n > MAX_POSES
                                                     else "")
    return JudgedPoses(a[take], np.atleast_2d(points_mm)[take], appr[take], said)
