"""The least-squares problem of a measurement: observations and design, formed from basis sums.

``y`` stacks the projected deviations of every row but the reference (N values, µm); the design ``A``
(N × P, µm per µm or µrad) is ``basis(θ) @ G`` per row, plus any extra model columns
(:class:`ExtraColumns`, the diagnosis' extensions).  See :mod:`pige_sym.identification.least_squares`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pige_sym.constants import LOSSES as LOSSES
from pige_sym.constants import METHODS as METHODS
from pige_sym.errors import IdentificationError as IdentificationError
from pige_sym.errors import InputError
from pige_sym.identification.instruments import instrument, whitened_normal
from pige_sym.kernels import load_kernels
from pige_sym.measurements.measurement import Measurement, missing_tool
from pige_sym.model.projection import Projection, parse_projection


@dataclass
class ExtraColumns:
    """Additional model columns (e.g. a diagnosis extension), evaluated on the data rows.

    Attributes
    ----------
    names : list of str
    units : dict of str to str
    columns : ndarray, shape=(n, 3, q)
        Deviation per unit parameter (machine frame), one slice per parameter, all rows
        including the reference row.
    """

    names: list[str]
    units: dict[str, str]
    columns: np.ndarray


@dataclass
class Problem:
    """A linear least-squares identification problem, ready to solve.

    Built once per measurement/projection; holds the normal equations in
    parameter units and, when small enough, the explicit design for per-row work.
    """

    names: list[str]
    units: dict[str, str]
    normal: np.ndarray  # (P, P)  AᵀA
    rhs: np.ndarray  # (P,)  Aᵀy
    yy: float
    n_obs: int
    n_rows: int
    m: int
    design: np.ndarray | None  # (n, m, P) all rows (reference row included) or None
    data: np.ndarray | None  # (n, m)
    rows: np.ndarray  # indices of rows used in the fit


def build_problem(measurement: Measurement, projection: str | Projection = "xyz", *, with_zero: bool = False,
                  extra: ExtraColumns | None = None, rows: np.ndarray | None = None,
                  explicit: bool | None = None) -> Problem:
    """Assemble the least-squares problem of a measurement.

    Parameters
    ----------
    measurement : Measurement
    projection : str or Projection
        ``xyz``, ``x``, ``y``, ``z``, a vector … (CONVENTIONS §5), in the measurement frame.
    with_zero : bool
        Also estimate the zero-position errors.
    extra : ExtraColumns, optional
        Additional columns appended after the PIGEs.
    rows : array of int, optional
        Rows to fit (default: all but the reference row 0).
    explicit : bool, optional
        Keep the explicit design (needed for robust fits and diagnosis); default when
        the problem is small (n·m·P ≤ 5e6).
    """
    kern = load_kernels(measurement.machine)
    why = missing_tool(kern.MACHINE_CODE, measurement.tool_mm, "tool_mm=(x, y, z) in the measurement")
    if why:
        raise InputError(why)
    proj = parse_projection(projection)
    names = list(kern.LOCATION_PARAMETERS) + (list(kern.ZERO_PARAMETERS) if with_zero else [])
    p_idx = [kern.PARAMETERS.index(n) for n in names]
    units = {n: kern.UNITS[n] for n in names}
    n = measurement.n_rows
    if rows is None:
        rows = np.arange(1, n)
    rows = np.asarray(rows, dtype=int)
    if rows.size == 0:
        raise IdentificationError("no data rows to fit (only the reference row)")
    dirs = proj.directions
    if measurement.frame == "table":
        # observations n·d_W = (R_w n)·d_M: per-row directions in the machine frame
        rot = kern.workpiece_rotation(measurement.angles_deg)
        dirs_rows = np.einsum("nij,mj->nmi", rot, dirs)
    else:
        dirs_rows = None
    y_all = proj.apply_data(measurement.deviation_um)  # (n, m): projection in the measurement frame
    m = dirs.shape[0]
    q = 0 if extra is None else len(extra.names)
    probe = instrument(measurement) != "rtest"
    if probe and (proj.name != "xyz" or measurement.frame != "machine"):
        raise InputError(f"a {instrument(measurement)} measurement is identified with the full 3-D projection "
                         f"(xyz) in the machine frame, not {proj.name!r}")
    if explicit is None:
        explicit = probe or extra is not None or n * m * (len(names) + q) <= 5_000_000
    g = kern.coefficients(measurement.ball_mm, measurement.pivots_mm or None, measurement.tool_mm)[:, :, p_idx]
    if explicit or dirs_rows is not None:
        design = _explicit_design(kern, measurement, g, dirs, dirs_rows, extra)
        if extra is not None:
            names = names + list(extra.names)
            units = units | dict(extra.units)
        if probe:
            rot = kern.workpiece_rotation(measurement.angles_deg)
            normal, rhs, yy = whitened_normal(measurement, design, y_all, rot, rows)
            return Problem(names, units, normal, rhs, yy, rows.size * m, n, m, design, y_all, rows)
        a = design[rows].reshape(-1, design.shape[2])
        y = y_all[rows].reshape(-1)
        return Problem(names, units, a.T @ a, a.T @ y, float(y @ y), a.shape[0], n, m, design, y_all, rows)
    # basis sums: AᵀA = Σ_m G_mᵀ (BᵀB) G_m
    b = kern.basis(measurement.angles_deg[rows])
    gram = b.T @ b
    g_d = np.einsum("mi,kip->mkp", dirs, g)  # (m, K, P)
    by = b.T @ y_all[rows]  # (K, m)
    normal = np.einsum("mkp,kl,mlq->pq", g_d, gram, g_d)
    rhs = np.einsum("mkp,km->p", g_d, by)
    yy = float((y_all[rows] ** 2).sum())
    return Problem(names, units, normal, rhs, yy, rows.size * m, n, m, None, y_all, rows)


def _explicit_design(kern: object, measurement: Measurement, g: np.ndarray, dirs: np.ndarray,
                     dirs_rows: np.ndarray | None, extra: ExtraColumns | None) -> np.ndarray:
    """The design of every row (reference included), shape=(n, m, P + q): the PIGE columns ``basis(θ) @ G``, then
    the extra columns, projected on ``dirs`` (m, 3) or per row on ``dirs_rows`` (n, m, 3)."""
    n = measurement.n_rows
    jac = kern.basis(measurement.angles_deg) @ g.reshape(g.shape[0], -1)  # type: ignore[attr-defined]
    jac = jac.reshape(n, 3, g.shape[2])
    if dirs_rows is None:
        design = np.einsum("mi,nip->nmp", dirs, jac)
    else:
        design = np.einsum("nmi,nip->nmp", dirs_rows, jac)
    if extra is not None:
        ex = extra.columns
        ex_p = np.einsum("mi,niq->nmq", dirs, ex) if dirs_rows is None else np.einsum("nmi,niq->nmq", dirs_rows, ex)
        design = np.concatenate([design, ex_p], axis=2)
    return np.asarray(design)


def design_rows(measurement: Measurement, *, with_zero: bool = False, extra: ExtraColumns | None = None,
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The full 3-D (xyz) design of every row (reference included), shape=(n, 3, P + q), the deviations (n, 3) [µm]
    and the rows fitted (every row but the reference): what :func:`build_problem` forms its normal equations from,
    without them (a joint fit with thousands of map columns stacks the rows; their (P + q)² normal matrix is not
    needed).  The same checks and refusals as :func:`build_problem`."""
    kern = load_kernels(measurement.machine)
    why = missing_tool(kern.MACHINE_CODE, measurement.tool_mm, "tool_mm=(x, y, z) in the measurement")
    if why:
        raise InputError(why)
    rows = np.arange(1, measurement.n_rows)
    if rows.size == 0:
        raise IdentificationError("no data rows to fit (only the reference row)")
    proj = parse_projection("xyz")
    dirs_rows = None
    if measurement.frame == "table":
        rot = kern.workpiece_rotation(measurement.angles_deg)
        dirs_rows = np.einsum("nij,mj->nmi", rot, proj.directions)
    if instrument(measurement) != "rtest" and measurement.frame != "machine":
        raise InputError(f"a {instrument(measurement)} measurement is identified with the full 3-D projection "
                         f"(xyz) in the machine frame, not {proj.name!r}")
    names = list(kern.LOCATION_PARAMETERS) + (list(kern.ZERO_PARAMETERS) if with_zero else [])
    p_idx = [kern.PARAMETERS.index(n) for n in names]
    g = kern.coefficients(measurement.ball_mm, measurement.pivots_mm or None, measurement.tool_mm)[:, :, p_idx]
    design = _explicit_design(kern, measurement, g, proj.directions, dirs_rows, extra)
    return design, proj.apply_data(measurement.deviation_um), rows
