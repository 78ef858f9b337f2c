"""Joint identification from several files of one machine: R-test runs, probe imports, ballbar setups.

Each file contributes a block of observations ``y_f = A_f p + N_f c_f + ε_f``:

- R-test: the three components of every row but the reference (:mod:`~pige_sym.identification.problem`);
- sphere probe: the same rows whitened with the file's full covariance (the reference pose's coupling,
  :mod:`~pige_sym.identification.instruments`);
- ballbar (CONVENTIONS §8): one row per pose, ``ΔL_i = n_iᵀ J_i p`` with ``n_i = R_w(θ_i)·offset/L0`` and ``J_i``
  the Jacobian at the tool-ball point ``table_ball + offset``; ``zero: absolute`` adds the reference pose's own
  offset ``ôᵀ J_ref p`` (the bar's length is known), ``zero: relative`` a free constant ``c_f`` instead
  (``N_f`` a column of ones): a constant added to such a file changes nothing.

Weights: each file's noise σ_f is estimated from its own fit (``RSS_f / (n_f − rank_f)``, with its constant),
its rows divided by it; the joint solve is the scaled least squares of
:mod:`~pige_sym.identification.spectrum` over the PIGEs and the constants, its variance factor estimated
from the joint residual (≈ 1 when the files agree), so the standard errors follow the data.  What the set
of files cannot determine is named, constants included, and gets no value.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from pige_sym.errors import IdentificationError, InputError
from pige_sym.identification.instruments import instrument, whitened_rows
from pige_sym.identification.problem import ExtraColumns, design_rows
from pige_sym.identification.result import IdentificationResult, json_float, not_identifiable
from pige_sym.identification.spectrum import observability, solve_scaled
from pige_sym.kernels import load_kernels
from pige_sym.measurements.axis_sense import describe_axis_sense
from pige_sym.measurements.ballbar import BallbarRun, bar_directions
from pige_sym.measurements.measurement import Measurement
from pige_sym.measurements.schema import refuse_unphysical


@dataclass
class Block:
    """One file's observations: design (r, P) [µm per µm or µrad], data (r,) [µm], constants (r, q)."""

    label: str
    instrument: str
    design: np.ndarray
    data: np.ndarray
    nuisance: np.ndarray
    nuisance_names: list[str]


@dataclass
class FileSummary:
    """A file's part in the joint fit: rows, σ from its own fit, RMS of its joint residual, its constant."""

    label: str
    instrument: str
    rows: int
    sigma_um: float
    rms_um: float
    constant_um: float | None = None
    constant_std_um: float | None = None
    fitted_um: np.ndarray | None = field(default=None, repr=False, compare=False)  # (r,) its joint model [µm]

    def to_dict(self) -> dict[str, Any]:
        return {"file": self.label, "instrument": self.instrument, "rows": self.rows,
                "sigma_um": json_float(self.sigma_um), "rms_um": json_float(self.rms_um),
                "constant_um": None if self.constant_um is None else json_float(self.constant_um),
                "constant_std_um": None if self.constant_std_um is None else json_float(self.constant_std_um)}


@dataclass
class JointResult:
    """The joint estimate (PIGEs) and each file's part; ``variance_factor`` the fit's RSS/(N − rank) of the rows
    divided by each file's σ (the covariance is the unit one times it)."""

    result: IdentificationResult
    files: list[FileSummary] = field(default_factory=list)
    variance_factor: float = 1.0

    def to_dict(self) -> dict[str, Any]:
        return self.result.to_dict() | {"files": [f.to_dict() for f in self.files]}


def _pige_names(machine: str, with_zero: bool) -> tuple[list[str], list[int]]:
    kern = load_kernels(machine)
    names = list(kern.LOCATION_PARAMETERS) + (list(kern.ZERO_PARAMETERS) if with_zero else [])
    return names, [kern.PARAMETERS.index(n) for n in names]


def measurement_block(m: Measurement, label: str, with_zero: bool, extra: ExtraColumns | None = None) -> Block:
    """The block of an R-test or probe measurement (full 3-D projection, every row but the reference); ``extra``
    columns (all rows, zeroed) follow the PIGEs'."""
    design, data, rows = design_rows(m, with_zero=with_zero, extra=extra)  # no (P + q)² normal matrix
    if instrument(m) == "rtest":
        a = design[rows].reshape(-1, design.shape[2])
        y = data[rows].reshape(-1)
    else:
        rot = load_kernels(m.machine).workpiece_rotation(m.angles_deg)
        a, y = whitened_rows(m, design, data, rot, rows)
    return Block(label, instrument(m), a, y, np.zeros((y.size, 0)), [])


def ballbar_block(run: BallbarRun, label: str, with_zero: bool) -> Block:
    """The block of a ballbar setup (module docstring)."""
    kern = load_kernels(run.machine)
    names, idx = _pige_names(run.machine, with_zero)
    unit = run.offset_mm / run.length_mm
    point = run.table_ball_mm + run.offset_mm
    jac = kern.jacobian(run.angles_deg, None, point)[:, :, idx]
    a = np.einsum("ni,nip->np", bar_directions(kern.workpiece_rotation(run.angles_deg), run.offset_mm), jac)
    if run.zero == "absolute":
        a = a + unit @ kern.reference_jacobian(point)[:, idx]
        return Block(label, "ballbar", a, run.dl_um.copy(), np.zeros((run.n_rows, 0)), [])
    return Block(label, "ballbar", a, run.dl_um.copy(), np.ones((run.n_rows, 1)), [f"zero[{label}]"])


def own_sigma(b: Block) -> float:
    """The file's noise σ [µm] from its own fit (its PIGEs and constants), floored at 0.1 nm."""
    full = np.hstack([b.design, b.nuisance])
    sol = solve_scaled(full.T @ full, full.T @ b.data, float(b.data @ b.data))
    dof = b.data.size - sol.rank
    if dof <= 0:
        raise InputError(f"{b.label}: {b.data.size} observations, {sol.rank} determined: too few rows to estimate "
                         "the file's noise for the joint weighting")
    return math.sqrt(max(sol.rss / dof, 1e-8))  # noise-free data: 0.1 nm, not a weight of 1e12


def identify_joint(items: Sequence[tuple[str, Measurement | BallbarRun]], *, with_zero: bool = False) -> JointResult:
    """Identify the PIGEs jointly from several files of one machine (module docstring).

    Parameters
    ----------
    items : sequence of (label, Measurement or BallbarRun)
    with_zero : bool
        Also estimate the zero-position errors.

    Returns
    -------
    JointResult
    """
    machine = common_machine(items)
    names, _ = _pige_names(machine, with_zero)
    blocks = file_blocks(items, with_zero)
    sigmas = [own_sigma(b) for b in blocks]
    a, y = whitened_system(blocks, sigmas)
    all_names = names + [n for b in blocks for n in b.nuisance_names]
    return _assemble(machine, names, all_names, blocks, sigmas, a, y, items)


def identify_blocks(machine: str, names: list[str], blocks: list[Block], sigmas: list[float],
                    items: Sequence[tuple[str, Any]]) -> JointResult:
    """The joint fit of prepared blocks whose first ``len(names)`` design columns are shared (``names``):
    each block whitened by its σ, a constant per relative file (as :func:`identify_joint`)."""
    a, y = whitened_system(blocks, sigmas)
    all_names = names + [n for b in blocks for n in b.nuisance_names]
    return _assemble(machine, names, all_names, blocks, sigmas, a, y, items)


def common_machine(items: Sequence[tuple[str, Measurement | BallbarRun]], *,
                   apart: str = "identify them apart") -> str:
    """The canonical code of the one machine every file measures; refused when they differ (``apart`` says what to
    do instead: the check is the same for every command that fits files jointly)."""
    machines = {load_kernels(x.machine).MACHINE_CODE for _, x in items}
    if len(machines) != 1:
        raise InputError(f"the files measure different machines ({', '.join(sorted(machines))}): {apart}")
    common_axis_sense(items)
    return machines.pop()


def common_axis_sense(items: Sequence[tuple[str, Measurement | BallbarRun]]) -> dict[str, int]:
    """The commanded axis sense every file records (CONVENTIONS §9); refused when they differ."""
    senses = {tuple(sorted(x.axis_sense.items())) for _, x in items}
    if len(senses) > 1:
        said = "; ".join(f"{lab}: {describe_axis_sense(x.axis_sense, x.rotary_axes)}" for lab, x in items)
        raise InputError(f"the files record different commanded axis senses ({said}): one machine's controller "
                         "commands its axes one way; re-make the files with the same --axis-sense")
    return dict(senses.pop()) if senses else {}


def common_geometry(items: Sequence[tuple[str, Measurement | BallbarRun]], key: str, differ: str | None = "refuse"
                    ) -> Any:
    """The nominal pivots (``pivots_mm``) or tool (``tool_mm``) every measurement file states, for the result: the
    PIGEs refer to the pivots, and a parameter file without them would put a controller's axes elsewhere.  None when
    no file states them; when two files state different ones: refused (``differ="refuse"``: one machine has one
    nominal geometry), or None (``differ=None``: the setups of a head differ by their tool, and none of them is
    the tool a program machines with)."""
    stated = [(lab, getattr(x, key)) for lab, x in items if isinstance(x, Measurement) and getattr(x, key) is not None
              and len(getattr(x, key)) > 0]
    if not stated:
        return None

    def norm(v: Any) -> Any:
        return {a: [float(c) for c in np.asarray(p, dtype=float)] for a, p in v.items()} if isinstance(v, dict) \
            else [float(c) for c in np.asarray(v, dtype=float)]

    first_label, first = stated[0][0], norm(stated[0][1])
    for lab, v in stated[1:]:
        if norm(v) != first:
            if differ is None:
                return None
            raise InputError(f"{lab} states {key} {norm(v)} but {first_label} {first}: the PIGEs refer to one "
                             "nominal geometry; identify files of different set-ups apart")
    return first


def file_blocks(items: Sequence[tuple[str, Measurement | BallbarRun]], with_zero: bool = False) -> list[Block]:
    """Each file's block, in order."""
    return [ballbar_block(x, lab, with_zero) if isinstance(x, BallbarRun) else measurement_block(x, lab, with_zero)
            for lab, x in items]


def whitened_system(blocks: Sequence[Block], sigmas: Sequence[float]) -> tuple[np.ndarray, np.ndarray]:
    """Rows of every block divided by its σ, shared PIGE columns then each block's constants, (n, P + q), (n,)."""
    q_total = sum(b.nuisance.shape[1] for b in blocks)
    rows, offset = [], 0
    for b, s in zip(blocks, sigmas, strict=True):
        nuis = np.zeros((b.data.size, q_total))
        nuis[:, offset:offset + b.nuisance.shape[1]] = b.nuisance
        offset += b.nuisance.shape[1]
        rows.append((np.hstack([b.design, nuis]) / s, b.data / s))
    return np.vstack([r[0] for r in rows]), np.concatenate([r[1] for r in rows])


def _assemble(machine: str, names: list[str], all_names: list[str], blocks: list[Block], sigmas: list[float],
              a: np.ndarray, y: np.ndarray, items: Sequence[tuple[str, Any]]) -> JointResult:
    kern = load_kernels(machine)
    p, n_obs = len(names), y.size
    sol = solve_scaled(a.T @ a, a.T @ y, float(y @ y))
    if n_obs <= sol.rank:
        raise IdentificationError(f"{n_obs} observations cannot determine {sol.rank} parameters: measure more")
    vf = sol.rss / (n_obs - sol.rank)
    cov = sol.cov_unit * vf
    ident = np.isfinite(sol.vif)
    values = np.where(ident, sol.values, np.nan)
    std = np.where(ident, np.sqrt(np.clip(np.diag(cov), 0, None)), np.nan)
    units = {n: kern.UNITS.get(n, "um") for n in all_names}
    null_space, combos = not_identifiable(sol.null_space, all_names, units)
    smax = sol.svals[0] if sol.svals.size and sol.svals[0] > 0 else 1.0
    cond = float(smax / sol.svals[sol.rank - 1]) if sol.rank == len(all_names) else float("inf")
    first = next((x for _, x in items if isinstance(x, Measurement)), None)
    ball = list(first.ball_mm) if first is not None else list(next(x for _, x in items).table_ball_mm)
    resid = np.concatenate([b.data - np.hstack([b.design, _spread(b, blocks)]) @ np.nan_to_num(sol.values)
                            for b in blocks])
    pooled = math.sqrt(vf * sum(s**2 * b.data.size for b, s in zip(blocks, sigmas, strict=True)) / n_obs)
    constants_determined = int(np.isfinite(sol.vif[p:]).sum())
    result = IdentificationResult(
        machine=machine, method="joint", projection="per file", loss="linear", parameters=list(names),
        units={n: units[n] for n in names}, values=values[:p], std=std[:p], covariance=cov[:p, :p],
        identifiable=ident[:p], rms_um=float(np.sqrt(np.mean(resid**2))), sigma_um=pooled, dof=n_obs - sol.rank,
        n_rows=sum(b.data.size for b in blocks), n_obs=n_obs, rank=sol.rank - constants_determined, condition=cond,
        singular_values=sol.svals, observability=observability(sol.svals, n_obs), unidentifiable=combos,
        outlier_rows=[], residuals_um=np.zeros((0, 1)), stages=[], ball_mm=[float(x) for x in ball],
        pivots_mm=common_geometry(items, "pivots_mm") or {}, tool_mm=common_geometry(items, "tool_mm", differ=None),
        vif=sol.vif[:p], unobserved=[all_names[j] for j in sol.unobserved if j < p],
        axis_sense=common_axis_sense(items), null_space=null_space,
    )
    refuse_unphysical(list(names), values[:p], std[:p], units, "the joint fit")
    files, offset = [], p
    for b, s in zip(blocks, sigmas, strict=True):
        q = b.nuisance.shape[1]
        fitted = b.design @ np.nan_to_num(sol.values[:p]) + b.nuisance @ np.nan_to_num(sol.values[offset:offset + q])
        rms = float(np.sqrt(np.mean((b.data - fitted) ** 2)))
        summary = FileSummary(b.label, b.instrument, b.data.size, s, rms, fitted_um=fitted)
        if q:
            summary.constant_um, summary.constant_std_um = float(values[offset]), float(std[offset])
        files.append(summary)
        offset += q
    return JointResult(result, files, vf)


def _spread(b: Block, blocks: list[Block]) -> np.ndarray:
    """``b``'s constant columns placed among every file's constants, shape=(r_b, q_total)."""
    q_total = sum(x.nuisance.shape[1] for x in blocks)
    out = np.zeros((b.data.size, q_total))
    start = sum(x.nuisance.shape[1] for x in blocks[:blocks.index(b)])
    out[:, start:start + b.nuisance.shape[1]] = b.nuisance
    return out


def format_files(files: list[FileSummary]) -> str:
    """The per-file table printed under a joint result."""
    lines = ["", f"{'file':<28}{'instrument':<14}{'rows':>6}{'own sigma [um]':>16}{'joint RMS [um]':>16}   constant"]
    for f in files:
        const = "-" if f.constant_um is None else (
            "not identifiable" if not math.isfinite(f.constant_um)
            else f"{f.constant_um:+.3f} ± {f.constant_std_um:.3f} um")
        lines.append(f"{f.label[-28:]:<28}{f.instrument:<14}{f.rows:>6}{f.sigma_um:>16.3f}{f.rms_um:>16.3f}   {const}")
    return "\n".join(lines)
