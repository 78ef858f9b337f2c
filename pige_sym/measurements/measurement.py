"""A measurement in memory: what an R-test file holds, with units and physical limits.

The file format is in :mod:`pige_sym.measurements.rtest` (reader) and
:mod:`pige_sym.measurements.rtest_writer` (writer); CONVENTIONS §6 defines it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from pige_sym.codegen.machine_code import MachineStructure, parse_machine_code
from pige_sym.errors import FileFormatError, InputError
from pige_sym.options import strict_float

if TYPE_CHECKING:
    pass



FORMAT_LINE = "# pige-rtest 1"
#: The measurement formats this pige reads (the first line of the file, after ``# ``).
MEASUREMENT_FORMATS = ("pige-rtest 1", "pige-ballbar 1")


DEVIATION_COLUMNS = ("dx_um", "dy_um", "dz_um")


LINEAR_COLUMNS = ("X_mm", "Y_mm", "Z_mm")


#: A probe import's numbers per pose (:mod:`~pige_sym.measurements.probe_import`): the fitted centre, its covariance
#: and its response to a direction-dependent trigger radius (:mod:`~pige_sym.measurements.probe_trigger`).
PROBE_COLUMNS = ("cx_mm", "cy_mm", "cz_mm",
                 "cov_xx_um2", "cov_xy_um2", "cov_xz_um2", "cov_yy_um2", "cov_yz_um2", "cov_zz_um2",
                 *(f"trig_{p}_{a}" for p in ("cos3", "sin3", "vert") for a in "xyz"))


#: Known numeric columns besides the required ones, read as numbers (strictly, vectorised) into ``optional``.
OPTIONAL_COLUMNS = ("temp_C", "n_samples", "sd_um", *PROBE_COLUMNS)


FRAMES = ("machine", "table")


REFERENCE_TOLERANCE = 1e-9


#: Largest magnitude accepted per column or metadata kind (non-physical values are refused), in its unit.
LIMITS: dict[str, float] = {"t_s": 1e9, "deg": 1e5, "um": 1e5, "mm": 1e5, "temp_C": 1e3, "n_samples": 1e9,
                            "sd_um": 1e5}


def unphysical(names: list[str], values: Any, std: Any, bound: float) -> tuple[str, float] | None:
    """The first (name, value) of an estimate beyond ±``bound`` by more than 3 standard errors, or None: the rule
    identify (:func:`~pige_sym.measurements.schema.refuse_unphysical`) and the history's reader apply (NaN,
    undetermined, is none)."""
    for name, v, s in zip(names, values, std, strict=True):
        v, s = float(v), float(s)
        if math.isfinite(v) and abs(v) - 3 * (s if math.isfinite(s) else 0.0) > bound:
            return name, v
    return None


@dataclass
class Measurement:
    """One R-test measurement: metadata and per-point data.

    Attributes
    ----------
    machine : str
        Machine structure code as written in the file.
    ball_mm : ndarray, shape=(3,) [mm]
        Ball centre at the reference pose, machine frame.
    t_s : ndarray, shape=(n,) [s]
        Time since the reference.
    angles_deg : ndarray, shape=(n, k) [deg]
        Rotary angles θ in CONVENTIONS' sense, columns in ``rotary_axes`` order.  A file holds the
        commanded angles θ_cmd = σ·θ (``axis_sense``): the reader and the writer convert
        (:mod:`~pige_sym.measurements.axis_sense`).
    deviation_um : ndarray, shape=(n, 3) [µm]
        Ball minus nest in ``frame``.
    rotary_axes : tuple of str
        Rotary-axis names in column order.
    frame : {"machine", "table"}
    tool_mm : ndarray, shape=(3,) [mm] or None
    pivots_mm : dict of str to ndarray, shape=(3,) [mm]
    trajectory : str or None
    linear_mm : ndarray, shape=(n, 3) [mm] or None
        Commanded X, Y, Z when present.
    optional : dict of str to ndarray, shape=(n,)
        Known optional numeric columns present (``temp_C``, ``n_samples``, ``sd_um``).
    extra_columns : dict of str to list of str
        Unknown columns, verbatim, in file order.
    metadata : dict of str to str
        Every metadata entry as text, in file order (known and unknown keys).
    path : str or None
    axis_sense : dict of str to int
        The axes the controller commands in the reverse of CONVENTIONS' sense (axis → −1; CONVENTIONS §9).
    """

    machine: str
    ball_mm: np.ndarray
    t_s: np.ndarray
    angles_deg: np.ndarray
    deviation_um: np.ndarray
    rotary_axes: tuple[str, ...]
    frame: str = "machine"
    tool_mm: np.ndarray | None = None
    pivots_mm: dict[str, np.ndarray] = field(default_factory=dict)
    trajectory: str | None = None
    linear_mm: np.ndarray | None = None
    optional: dict[str, np.ndarray] = field(default_factory=dict)
    extra_columns: dict[str, list[str]] = field(default_factory=dict)
    metadata: dict[str, str] = field(default_factory=dict)
    path: str | None = None
    axis_sense: dict[str, int] = field(default_factory=dict)

    @property
    def n_rows(self) -> int:
        """Number of data rows (the reference row included)."""
        return int(self.t_s.shape[0])

    @property
    def commanded_deg(self) -> np.ndarray:
        """The commanded angles θ_cmd = σ·θ, as the file and the controller hold them, shape=(n, k) [deg]."""
        from pige_sym.measurements.axis_sense import to_commanded

        return to_commanded(self.angles_deg, self.axis_sense, self.rotary_axes)

    @property
    def structure(self) -> MachineStructure:
        """Parsed machine structure."""
        return parse_machine_code(self.machine)

    def columns(self) -> list[str]:
        """Column names in the order they are written."""
        cols = ["t_s", *(f"{a}_deg" for a in self.rotary_axes), *DEVIATION_COLUMNS]
        if self.linear_mm is not None:
            cols += list(LINEAR_COLUMNS)
        cols += [c for c in OPTIONAL_COLUMNS if c in self.optional]
        cols += list(self.extra_columns)
        return cols

    def deviation_machine_um(self, kernels: object | None = None) -> np.ndarray:
        """Deviation in the machine frame, shape=(n, 3) [µm].

        ``frame: table`` data are rotated with the nominal workpiece rotation of the
        commanded angles (CONVENTIONS §4); ``kernels`` defaults to the machine's.
        """
        if self.frame == "machine":
            return self.deviation_um
        from pige_sym.kernels import load_kernels

        kern: Any = kernels if kernels is not None else load_kernels(self.machine)
        rot = kern.workpiece_rotation(self.angles_deg)
        return np.einsum("nij,nj->ni", rot, self.deviation_um)


def format_line_problem(first: str | None, expected: str) -> str:
    """Why ``first`` is not the format line ``expected``: naming the format and version found and those this pige
    reads (a newer ``# pige-ballbar 2`` is not an R-test file with a bad first line)."""
    import re

    got = "an empty file" if first is None else repr(first.strip()[:80])
    found = re.fullmatch(r"#\s*(pige-[A-Za-z]+)\s+(\S+)", (first or "").strip().removeprefix("\ufeff"))
    if found:
        name, version = found.groups()
        same = [f.split()[1] for f in MEASUREMENT_FORMATS if f.split()[0] == name]
        reads = f"{name} version {' or '.join(same)} only" if same else f"no {name} files"
        return (f"format {name} version {version}: this pige reads {reads} (supported: "
                f"{', '.join(MEASUREMENT_FORMATS)}); write the file in a supported version or update pige")
    return f"first line must be {expected!r}, got {got}"


def numeric_column(m: Measurement, name: str) -> np.ndarray | None:
    """A known numeric column, shape=(n,): from ``optional`` (as the reader gives it) or, for a measurement
    built in memory with text columns, parsed strictly from ``extra_columns``; None when absent.

    Raises
    ------
    FileFormatError
        A value that is not a finite ASCII decimal number (names the row and the column).
    """
    if name in m.optional:
        return np.asarray(m.optional[name], dtype=float)
    if name not in m.extra_columns:
        return None
    out = np.empty(m.n_rows)
    for r, text in enumerate(m.extra_columns[name]):
        v = strict_float(str(text))
        if v is None:
            raise FileFormatError(m.path or "<measurement>", None, f"row {r + 1}, column {name}: {text!r} is not a "
                                  "finite number")
        out[r] = v
    return out


def parse_vec3(text: str, path: str, line: int, key: str) -> np.ndarray:
    parts = [p.strip() for p in text.split(",")]
    if len(parts) != 3:
        raise FileFormatError(path, line, f"{key}: expected 3 comma-separated numbers, got {text!r}")
    out = []
    for p in parts:
        v = strict_float(p)
        if v is None:
            raise FileFormatError(path, line, f"{key}: {p!r} is not a number (ASCII decimal, e.g. 120.5 or -1e-3)")
        if abs(v) > LIMITS["mm"]:
            raise FileFormatError(path, line, f"{key}: {p} mm is not physical (|value| <= {LIMITS['mm']:g} mm)")
        out.append(v)
    return np.array(out)


def column_limit(name: str) -> tuple[float, str]:
    """Largest magnitude [unit] accepted in a known column, and the unit."""
    if name in LIMITS:
        return LIMITS[name], name.rsplit("_", 1)[-1]
    unit = name.rsplit("_", 1)[-1]
    return LIMITS.get(unit, math.inf), unit


def missing_tool(machine: str, tool_mm: object, how: str = "--tool x,y,z") -> str | None:
    """Why ``machine`` cannot be used without ``tool_mm`` (None when it can); ``how`` says how to give it.

    A tool-side rotary axis turns the ball (or stylus) about its pivot: the lever ``tool_mm`` (CONVENTIONS §4,
    §7) is part of the data, like ``ball_mm``.
    """
    if tool_mm is not None:
        return None
    heads = [a.name for a in parse_machine_code(machine).tool_axes if a.kind == "rotary"]
    if not heads:
        return None
    return (f"{machine} has tool-side rotary axes ({', '.join(heads)}): give the ball (stylus) centre from the "
            f"last tool-side pivot at the reference pose, {how}")


def validate_measurement(m: Measurement) -> None:
    """Check shapes and the reference row of an in-memory measurement (raises InputError)."""
    why = missing_tool(m.machine, m.tool_mm, "tool_mm=(x, y, z)")
    if why:
        raise InputError(why)
    n = m.t_s.shape[0]
    k = len(m.rotary_axes)
    if n == 0:
        raise InputError("measurement has no rows")
    if m.angles_deg.shape != (n, k) or m.deviation_um.shape != (n, 3):
        raise InputError(f"shapes: t_s {m.t_s.shape}, angles_deg {m.angles_deg.shape}, deviation_um "
                         f"{m.deviation_um.shape}; expected (n,), (n, {k}), (n, 3)")
    if m.linear_mm is not None and m.linear_mm.shape != (n, 3):
        raise InputError(f"linear_mm has shape {m.linear_mm.shape}, expected ({n}, 3)")
    if m.frame not in FRAMES:
        raise InputError(f"frame must be 'machine' or 'table', got {m.frame!r}")
    arrays = {"t_s": m.t_s, "angles_deg": m.angles_deg, "deviation_um": m.deviation_um, "ball_mm": m.ball_mm,
              **({} if m.linear_mm is None else {"linear_mm": m.linear_mm}), **m.optional}
    for name, arr in arrays.items():
        if not np.isfinite(np.asarray(arr, dtype=float)).all():
            raise InputError(f"{name} holds NaN or infinite values: pige never writes them")
