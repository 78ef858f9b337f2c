"""Diagnosis candidates: the super design of PIGEs plus every catalogue effect, and reduction.

Layout
------
The *super design* has one column per PIGE (the machine's location errors, in the
order of the kernels) followed by the columns of every candidate effect
(:mod:`pige_sym.model.effects`), evaluated row by row in the machine frame.  A row's block is
``(3, C)``: the zeroed deviation [µm] per unit parameter [µm or µrad].  Thermal drift
enters once per time constant of a log-spaced grid (so τ can later be interpolated
between grid columns, which are exact linear combinations of the accumulated sums).

Candidates
----------
A :class:`Candidate` is one effect with fixed shape options (harmonic or τ) and the
slice of its columns in the super design.  Harmonics 1–4 of the angular error, wobble
and radial runout of every rotary axis that moves, backlash of every axis approached
from both sides, the three squareness pairs, setup offset, thermal drift; for a probed sphere
(``table_drift=True``) also the sphere creeping on its stand (``table_drift``, on the same τ grid) and,
from the import's columns, a direction-dependent trigger radius (``probe_trigger``).

Reduction to the identifiable part
----------------------------------
Jointly with the current model (PIGEs + accepted effects) a candidate's parameter
space splits into a part the data determine and *null directions* ``c₀`` whose
deviation ``C·c₀`` the current model reproduces exactly (or which leave no trace at
all).  With ``G`` the normal matrix, the Schur complement
``S = C'C − C'M (M'M)⁺ M'C`` scaled to unit diagonal has eigenvalues ``λ = 1/VIF``
along its eigenvectors; directions with ``λ ≤ NULL_LAMBDA`` are removed, named with
the model combination that absorbs them, and the rest is fitted: the reduced columns
are ``C·T`` (``T`` = kept eigenvectors, unscaled), reported back in the catalogue's
parameters as ``c = T·θ``.  Example: a first-harmonic wobble of a table axis whose
tilt turns with the table is a location error of that axis (its co-rotating half);
the counter-rotating half stays and is fitted.
"""

from __future__ import annotations

from collections.abc import Collection
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any

import numpy as np

from pige_sym.identification.canonical import canonical_basis, combination, rounded, separation
from pige_sym.model.effects import DRIFT_KINDS, EffectContext, EffectSpec

HARMONICS = (1, 2, 3, 4)
TAU_GRID_FRACTIONS = tuple(float(x) for x in np.geomspace(0.03, 5.0, 10))
NULL_LAMBDA = 1e-7  # 1/VIF below which a direction counts as undetermined (std inflated > ~3000x)
ZERO_COLUMN = 1e-10  # relative column norm below which a candidate column leaves no trace
TRACELESS_RTOL = 1e-10  # |C·c₀|² over trace(CᵀC), c₀ of unit scaled norm, at or below which c₀ leaves no trace


@dataclass(frozen=True)
class Candidate:
    """One candidate extension with fixed shape options.

    Attributes
    ----------
    spec : EffectSpec
    key : str
        Identity for selection: effects with the same key are alternatives (e.g. τ grid).
    cols : tuple of int
        Column indices of its raw parameters in the super design.
    extra_params : int
        Non-linear parameters chosen from data (τ: 1), counted in the BIC.
    """

    spec: EffectSpec
    key: str
    cols: tuple[int, ...]
    extra_params: int = 0
    mix: np.ndarray | None = field(default=None, compare=False, repr=False)

    def embedding(self, n_columns: int) -> np.ndarray:
        """Its columns as combinations of super-design columns, shape=(C, q).

        ``mix`` (C, q), when given, replaces the unit columns of ``cols`` (e.g. a thermal
        drift at a τ between grid points, interpolated from the grid's columns).
        """
        if self.mix is not None:
            return self.mix
        e = np.zeros((n_columns, len(self.cols)))
        e[list(self.cols), np.arange(len(self.cols))] = 1.0
        return e

    @property
    def label(self) -> str:
        """Id with options, e.g. ``wobble_C harmonic=2``."""
        opts = "".join(f" {k}={v:g}" for k, v in self.spec.options.items())
        return f"{self.spec.id}{opts}"


@dataclass
class Layout:
    """Column layout of the super design.

    Attributes
    ----------
    pige : list of str
        PIGE names (first columns).
    units : dict of str to str
    candidates : list of Candidate
    n_columns : int
    tau_grid_s : ndarray, shape=(g,) [s]
        Thermal time constants of the drift candidates (empty when the file has no duration).
    drift_cols : dict of str to list of tuple of int
        Per drift kind (``thermal_drift``, ``table_drift``), the column triples (vx, vy, vz) of each τ grid
        point.
    probe_sensitivity : ndarray, shape=(n, 3, 3), or None
    nuisance : tuple of str
        Columns right after the PIGEs that every model holds and no result reports: a probe file's reference
        centre error ``u`` (``d_i`` gains ``R_w,i·u``, :data:`REFERENCE_NUISANCE`).
    """

    pige: list[str]
    units: dict[str, str]
    candidates: list[Candidate]
    n_columns: int
    tau_grid_s: np.ndarray
    drift_cols: dict[str, list[tuple[int, ...]]] = field(default_factory=dict)
    probe_sensitivity: np.ndarray | None = None  # (n, 3, 3) of a probe import: the probe_trigger columns
    nuisance: tuple[str, ...] = ()

    @property
    def base(self) -> int:
        """Columns every model holds: the PIGEs and the nuisance."""
        return len(self.pige) + len(self.nuisance)


#: The reference centre's error of a probe file (CONVENTIONS §7): ``c_nom`` is built from the measured ``c(0)``,
#: so its error ``u`` enters every row turned by the table, ``R_w,i·u`` [µm].
REFERENCE_NUISANCE = ("reference_x_um", "reference_y_um", "reference_z_um")


def _moves(angles: np.ndarray, k: int) -> bool:
    return bool(np.ptp(angles[:, k]) > 1e-9)


def build_layout(kern: Any, angles_deg: np.ndarray, t_s: np.ndarray, approach: np.ndarray,
                 restrict: list[str] | None = None, table_drift: bool = False,
                 probe_sensitivity: np.ndarray | None = None, reference_centre: bool = False,
                 exclude: Collection[str] = ()) -> Layout:
    """Every applicable candidate of a measurement, in super-design column order.

    Parameters
    ----------
    kern : KernelModule
    angles_deg : ndarray, shape=(n, k) [deg]
    t_s : ndarray, shape=(n,) [s]
    approach : ndarray, shape=(n, k)
        Direction of approach per axis (−1, 0, +1).
    restrict : list of str, optional
        Keep only these catalogue ids.
    exclude : collection of str
        Leave out these catalogue ids (e.g. the one-harmonic error motions of an axis whose maps are fitted).
    table_drift : bool
        Also the nest/sphere drifting on the table (probe files: a sphere on a stand).
    probe_sensitivity : ndarray, shape=(n, 3, 3), optional
        A probe import's trigger sensitivities: adds the ``probe_trigger`` candidate.
    reference_centre : bool
        A probe file: the reference centre's error is a nuisance of every model (:data:`REFERENCE_NUISANCE`).
    """
    pige = list(kern.LOCATION_PARAMETERS)
    nuisance = REFERENCE_NUISANCE if reference_centre else ()
    units = {p: kern.UNITS[p] for p in pige} | {q: "um" for q in nuisance}
    specs: list[tuple[EffectSpec, str, int]] = []
    duration = float(t_s[-1] - t_s[0]) if len(t_s) > 1 else 0.0
    taus = np.array([f * duration for f in TAU_GRID_FRACTIONS]) if duration > 0 else np.zeros(0)
    for tau in taus:
        specs.append((EffectSpec("thermal_drift", {"tau_s": float(tau)}), "thermal_drift", 1))
    for tau in taus if table_drift else ():
        specs.append((EffectSpec("table_drift", {"tau_s": float(tau)}), "table_drift", 1))
    for k, ax in enumerate(kern.ROTARY_AXES):
        if not _moves(angles_deg, k):
            continue
        for kind in ("angular_error", "wobble", "radial_runout"):
            for h in HARMONICS:
                specs.append((EffectSpec(f"{kind}_{ax}", {"harmonic": h}), f"{kind}_{ax} h{h}", 0))
        if np.unique(approach[1:, k]).size >= 2:  # approached from both sides, or from one side after rest
            specs.append((EffectSpec(f"backlash_{ax}"), f"backlash_{ax}", 0))
    for pair in ("XY", "YZ", "ZX"):
        specs.append((EffectSpec(f"squareness_{pair}"), f"squareness_{pair}", 0))
    specs.append((EffectSpec("setup_offset"), "setup_offset", 0))
    if probe_sensitivity is not None:
        specs.append((EffectSpec("probe_trigger"), "probe_trigger", 0))
    col = len(pige) + len(nuisance)
    cands: list[Candidate] = []
    drift_cols: dict[str, list[tuple[int, ...]]] = {}
    for spec, key, extra in specs:
        q = len(spec.param_names)
        cols = tuple(range(col, col + q))
        col += q
        if spec.kind in DRIFT_KINDS:
            drift_cols.setdefault(spec.kind, []).append(cols)
        if (restrict is None or spec.id in restrict) and spec.id not in exclude:
            cands.append(Candidate(spec, key, cols, extra))
    return Layout(pige, units, cands, col, taus, drift_cols, probe_sensitivity, nuisance)


def add_pose_clusters(layout: Layout, options: list[dict[str, float]]) -> list[Candidate]:
    """Append a ``pose_cluster`` candidate per pose (3 new columns each); returns the new candidates."""
    new = []
    for opt in options:
        spec = EffectSpec("pose_cluster", dict(opt))
        cols = tuple(range(layout.n_columns, layout.n_columns + 3))
        layout.n_columns += 3
        key = "pose_cluster " + " ".join(f"{k}={v:g}" for k, v in opt.items())
        new.append(Candidate(spec, key, cols))
    layout.candidates += new
    return new


def all_specs(layout: Layout) -> list[tuple[EffectSpec, tuple[int, ...]]]:
    """Every candidate's effect block of the super design, in column order."""
    return [(c.spec, c.cols) for c in layout.candidates]


def evaluate_rows(layout: Layout, blocks: list[tuple[EffectSpec, tuple[int, ...]]], kern: Any, m: Any,
                  approach: np.ndarray, rows: np.ndarray, compact: bool = False) -> np.ndarray:
    """Super-design rows, shape=(r, 3, C) [µm per parameter unit].

    With ``compact`` only the base columns (PIGEs and nuisance) and the given blocks, in that order, are
    returned, shape=(r, 3, P + Σq) (see :func:`compact_columns`).

    Parameters
    ----------
    blocks : list of (EffectSpec, column indices)
        The effect blocks to fill (others stay zero).
    m : Measurement
        In the machine frame.
    rows : ndarray of int, shape=(r,)
        Row indices (the reference row 0 is prepended internally for zeroing).
    """
    idx = np.concatenate([[0], np.asarray(rows, dtype=int)])
    angles = m.angles_deg[idx]
    pivots = m.pivots_mm or None
    jac = kern.jacobian(angles, None, m.ball_mm, pivots, m.tool_mm)
    loc = [kern.PARAMETERS.index(p) for p in layout.pige]
    width = len(compact_columns(layout, blocks)) if compact else layout.n_columns
    p, q = len(loc), len(layout.nuisance)
    if not blocks:
        out = np.zeros((len(rows), 3, width))
        out[:, :, :p] = jac[1:, :, loc]
        if q:
            out[:, :, p:p + q] = kern.workpiece_rotation(angles[1:])
        return out
    raw = np.zeros((len(idx), 3, width))
    sens = None if layout.probe_sensitivity is None else layout.probe_sensitivity[idx]
    ctx = EffectContext(kern, angles, m.t_s[idx], m.ball_mm, pivots, m.tool_mm, approach=approach[idx],
                        probe_sensitivity=sens)
    at = layout.base
    for spec, cols in blocks:
        start = at if compact else cols[0]
        raw[:, :, start: start + len(cols)] = spec.raw_columns(ctx)[0]
        at += len(cols)
    # zero all effect columns at once: raw − R_w · raw(reference row); the columns that need no
    # zeroing (squareness: travel from the reference; drift: t = 0) are zero at the reference anyway
    raw[:, :, p:] -= ctx.rot_w @ raw[0][:, p:]
    raw[:, :, :p] = jac[:, :, loc]
    if q:
        raw[:, :, p:p + q] = ctx.rot_w  # the reference centre's error, turned with the table (not zeroed)
    return raw[1:]


def compact_columns(layout: Layout, blocks: list[tuple[EffectSpec, tuple[int, ...]]]) -> list[int]:
    """Super-design indices of the columns of a compact evaluation (PIGEs, then the blocks in order)."""
    return list(range(layout.base)) + [c for _, cols in blocks for c in cols]


@dataclass
class Reduction:
    """A candidate reduced to its identifiable part, jointly with a model.

    Attributes
    ----------
    basis : ndarray, shape=(q, q')
        Kept directions in the catalogue's parameter units (``c = basis @ θ``).
    null : ndarray, shape=(q, q − q')
        Removed directions in catalogue units: the canonical basis of those without trace, then of the absorbed
        ones (:func:`_removed_directions`; each 1 on its pivot).
    absorbed : ndarray, shape=(K, q − q')
        Model coefficients reproducing each removed direction (``M·absorbed ≈ C·null``).
    vif : ndarray, shape=(q',)
        Variance inflation of each kept direction.
    """

    basis: np.ndarray
    null: np.ndarray
    absorbed: np.ndarray
    vif: np.ndarray
    _describe: Any = field(default=None, repr=False, compare=False)

    @cached_property
    def removed(self) -> list[str]:
        """One sentence per removed direction, naming what absorbs it (built on first use)."""
        return [] if self._describe is None else list(self._describe())

    def absorbed_terms(self, names: list[str]) -> list[dict[str, float]]:
        """Per removed direction, the model coefficients that absorb it (``{name: value}``, the JSON form):
        rounded (:func:`~pige_sym.identification.canonical.rounded`), round-off below 1e-9 of the largest left out."""
        out = []
        for j in range(self.null.shape[1]):
            col = self.absorbed[:, j]
            floor = 1e-9 * float(np.abs(col).max(initial=0.0))
            out.append({n: rounded(float(v)) for n, v in zip(names, col, strict=False) if abs(v) > floor})
        return out


def reduce_candidate(gram: np.ndarray, model_w: np.ndarray, cand: Candidate, model_names: list[str],
                     model_units: dict[str, str], model_pinv: np.ndarray | None = None,
                     null_lambda: float = NULL_LAMBDA) -> Reduction:
    """Split a candidate into its identifiable part and named null directions (module docstring).

    Parameters
    ----------
    gram : ndarray, shape=(C, C)
        Super-design normal matrix.
    model_w : ndarray, shape=(C, K)
        Current model columns as combinations of super-design columns.
    cand : Candidate
    model_names : list of str
        Names of the K model columns.
    model_units : dict
    model_pinv : ndarray, shape=(K, K), optional
        ``(WᵀGW)⁺`` when already known (it is the same for every candidate against one model).
    null_lambda : float
        ``1/VIF`` at or below which a direction counts as undetermined.
    """
    emb = cand.embedding(gram.shape[0])
    gcc = emb.T @ gram @ emb
    gmc = model_w.T @ gram @ emb
    if model_pinv is None:
        model_pinv = np.linalg.pinv(model_w.T @ gram @ model_w, rcond=1e-12, hermitian=True)
    coef = model_pinv @ gmc  # (K, q) model fit of each candidate column
    schur = gcc - gmc.T @ coef
    d = np.sqrt(np.clip(np.diag(gcc), 0, None))
    dmax = float(d.max()) if d.size else 0.0
    dead = d <= ZERO_COLUMN * max(dmax, 1e-300)
    s = 1.0 / np.where(dead, 1.0, d)
    scaled = schur * np.outer(s, s)
    scaled[dead, :] = 0.0
    scaled[:, dead] = 0.0
    lam, vec = np.linalg.eigh((scaled + scaled.T) / 2)
    keep = lam > null_lambda
    basis = vec[:, keep] * s[:, None]
    null, traceless, half = _removed_directions(cand, vec[:, ~keep], s, gcc, separation(lam, ~keep))
    absorbed = coef @ null if null.size else np.zeros((model_w.shape[1], 0))
    absorbed[:, traceless] = 0.0  # a direction without trace in the data: nothing absorbs it (coef·null is round-off)

    def describe() -> list[str]:
        return [_removed_sentence(cand, null[:, j], absorbed[:, j], bool(traceless[j]), model_names, model_units,
                                  half) for j in range(null.shape[1])]

    return Reduction(basis, null, absorbed, 1.0 / np.clip(lam[keep], 1e-300, None), describe)


def _removed_directions(cand: Candidate, null_scaled: np.ndarray, s: np.ndarray, gcc: np.ndarray,
                        gap: float) -> tuple[np.ndarray, np.ndarray, str | None]:
    """The removed directions in catalogue units, canonical, and which of them leave no trace in the data.

    The null span (``null_scaled``, (q, r) in the unit-diagonal scale ``s``) splits into the directions without
    trace (``C·c₀ = 0``: the zeroing removes them) and, orthogonal to them in that scale, the ones the model absorbs;
    each part is given by its canonical basis (:mod:`pige_sym.identification.canonical`), the traceless part
    first.  A first-harmonic wobble or runout whose null span is a rotating half gets that half's own basis
    (:func:`_rotating_half`).  Returns the directions (q, r), a (r,) bool of the traceless ones and the half.
    """
    q, r = null_scaled.shape
    if r == 0:
        return np.zeros((q, 0)), np.zeros(0, dtype=bool), None
    half = _rotating_half(cand, null_scaled * s[:, None]) if r == 2 else None
    if half is not None:  # a rotating half: its canonical directions, fixed in the body (1, 0, 0, ±1), (0, 1, ∓1, 0)
        sign = 1.0 if half == "+" else -1.0
        null = np.array([[1.0, 0, 0, sign], [0, 1.0, -sign, 0]]).T
        return null, np.array([_trace(null[:, j], gcc) for j in range(2)]) <= TRACELESS_RTOL, half
    scaled_gram = gcc * np.outer(s, s)
    lam0, rot = np.linalg.eigh(null_scaled.T @ scaled_gram @ null_scaled)
    size = max(float(np.trace(scaled_gram)), 1e-300)
    none = lam0 <= TRACELESS_RTOL * size
    inner = (float(lam0[~none].min() - lam0[none].max()) / size) if none.any() and not none.all() else 1.0
    parts = [(canonical_basis(null_scaled @ rot[:, part], s, separation=min(gap, inner)).coefficients, flag)
             for part, flag in ((none, True), (~none, False)) if part.any()]
    return (np.hstack([c for c, _ in parts]), np.concatenate([np.full(c.shape[1], f) for c, f in parts]), None)


def _trace(vec: np.ndarray, gcc: np.ndarray) -> float:
    """``|C·vec|² / trace(CᵀC)``: how much of the data a direction moves, relative to the candidate's columns."""
    return float(vec @ gcc @ vec) / max(float(np.trace(gcc)), 1e-300)


def _rotating_half(cand: Candidate, null: np.ndarray) -> str | None:
    """Whether the null space of a first-harmonic wobble/runout contains a whole rotating half.

    A 1×-per-revolution tilt/offset vector of constant length turning with (or against)
    θ is ``(a_cos, a_sin, b_cos, b_sin) ∝ (1, 0, 0, ±1)`` and ``(0, 1, ∓1, 0)``.  The
    half that the PIGEs (or the zeroing) absorb is the one fixed in the rotating body.
    """
    if cand.spec.kind not in ("wobble", "radial_runout") or cand.spec.harmonic != 1:
        return None
    q, _ = np.linalg.qr(null)
    halves = {"+": np.array([[1.0, 0, 0, 1], [0, 1, -1, 0]]) / np.sqrt(2),
              "-": np.array([[1.0, 0, 0, -1], [0, 1, 1, 0]]) / np.sqrt(2)}
    for which, basis in halves.items():
        if np.linalg.norm(q.T @ basis.T) > np.sqrt(2) * (1 - 1e-3):
            return which
    return None


def _removed_sentence(cand: Candidate, vec: np.ndarray, absorbed: np.ndarray, traceless: bool,
                      model_names: list[str], model_units: dict[str, str], half: str | None) -> str:
    combo = combination(vec, cand.spec.param_names).text()
    prefix = ""
    if half is not None:
        kind = "a tilt" if cand.spec.kind == "wobble" else "an offset"
        prefix = (f"co-rotating half ({kind} that turns with axis {cand.spec.axis}, i.e. fixed in its body: "
                  f"a location or setup error): ")
    if traceless:
        return f"{prefix}{combo} leaves no trace in the zeroed data"
    what = combination(absorbed, model_names).text(model_units)
    return f"{prefix}{combo} is indistinguishable from {what}"
