"""Emitter: render a :class:`~pige_sym.codegen.symbolic.SymbolicModel` as a plain NumPy module.

The module is rendered to a string first (:func:`render_module`), then written
(:func:`write_module`).  The generated module imports only NumPy and exposes

* ``MACHINE_CODE``, ``ROTARY_AXES``, ``PARAMETERS``, ``LOCATION_PARAMETERS``,
  ``ZERO_PARAMETERS``, ``UNITS``, ``BASIS`` (names of the basis columns),
  ``WORKPIECE_ROTARY``, ``TOOL_ROTARY``, ``HAS_DIRECTION_SOLVER``;
* ``basis(angles_deg) -> (n, K)`` and ``coefficients(ball_mm, pivots_mm, tool_mm)
  -> (K, 3, P)``, so that ``jacobian = basis @ coefficients`` (one BLAS call);
* ``deviation``, ``jacobian`` (optionally into a preallocated ``out``),
  ``workpiece_rotation``, ``tool_rotation``, ``linear_commands``, ``tool_direction``
  and ``angles_for_direction`` (see :class:`pige_sym.kernels.protocol.KernelModule`).

How a function is rendered: the fixed parts (signatures and docstrings) are templates
in :data:`SPECS`; the body is the symbolic expressions printed with plain float
literals; the locals a body needs are chosen from the candidates of
:func:`_trig_locals` and :func:`_geometry_locals` (each angle's cos/sin evaluated once,
lever arms ``d_P_Q = 0.001 * (P - Q)`` [mm → µm per µrad] as named locals) and nothing
else is defined.  The input checks shared by all modules are real code in
:mod:`pige_sym.codegen.kernel_helpers`, copied in verbatim.

The header records the machine code, parameter order and units, the SymPy version
(information only: ``make check-generated`` compares the code, not that line) and the
generator fingerprint.
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Sequence
from pathlib import Path

import sympy as sp
from sympy.printing.pycode import PythonCodePrinter

from pige_sym.codegen.decompose import DirectionSolver, direction_solver, trig_basis
from pige_sym.codegen.fingerprint import current_hash
from pige_sym.codegen.machine_code import MachineStructure, parse_machine_code
from pige_sym.codegen.symbolic import SymbolicModel, build_model
from pige_sym.codegen.templates import LINEAR_FUNCTIONS, SPECS
from pige_sym.files import atomic_write_text

_HELPERS_FILE = Path(__file__).with_name("kernel_helpers.py")


_MARKER = "# --- copied into every kernel module ---"


_TOKEN = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")


class _Printer(PythonCodePrinter):
    """Prints numbers as plain float literals (no ``(0.001)*``)."""

    def _print_Float(self, expr: sp.Float) -> str:
        return repr(float(expr))

    def _print_Rational(self, expr: sp.Rational) -> str:
        return repr(float(expr.p) / float(expr.q))

    def _print_Half(self, expr: sp.Rational) -> str:
        return "0.5"


def _code(expr: sp.Expr) -> str:
    """Python source of an expression; non-integer rationals become float literals."""
    floats = {r: sp.Float(r) for r in expr.atoms(sp.Rational) if not r.is_Integer}
    return str(_Printer({"standard": "python3"}).doprint(expr.xreplace(floats)))


def _tokens(lines: Iterable[str]) -> set[str]:
    return {t for line in lines for t in _TOKEN.findall(line)}


def _select_locals(candidates: Sequence[tuple[str, str]], body: Sequence[str]) -> list[str]:
    """Assignments among ``candidates`` (name, code) that the body needs, with their dependencies, in order."""
    names = {name for name, _ in candidates}
    needed = _tokens(body) & names
    for name, code in reversed(candidates):
        if name in needed:
            needed |= _tokens([code]) & names
    lines = [f"    {name} = {code}" for name, code in candidates if name in needed]
    if "cos_th" in needed and "sin_th" in needed:  # one evaluation of the angles' cos and sin
        lines = [ln for ln in lines if not ln.startswith(("    cos_th =", "    sin_th ="))]
        lines.insert(0, "    cos_th, sin_th = _cos_sin(angles_deg)")
    return lines


def _trig_locals(model: SymbolicModel) -> list[tuple[str, str]]:
    out = [("cos_th", "_cos_sin(angles_deg)[0]"), ("sin_th", "_cos_sin(angles_deg)[1]"),
           ("n", "cos_th.shape[1]")]
    for i, r in enumerate(model.rotary):
        out += [(f"c_{r.axis.name}", f"cos_th[{i}]"), (f"s_{r.axis.name}", f"sin_th[{i}]")]
    return out


def _geometry_locals(model: SymbolicModel, levers: Sequence[tuple[str, str]] = ()) -> list[tuple[str, str]]:
    out = [("ball", "_vec3(ball_mm, 'ball_mm')")]
    out += [(f"ball_{c}", f"ball[{i}]") for i, c in enumerate("xyz")]
    out.append(("pivots", "_pivots(pivots_mm)"))
    for r in model.rotary:
        nm = r.axis.name
        out += [(f"p{nm}_{c}", f"pivots[{nm!r}][{i}]") for i, c in enumerate("xyz")]
    out.append(("tool", "_tool(tool_mm)"))
    out += [(f"tool_{c}", f"tool[{i}]") for i, c in enumerate("xyz")]
    return out + list(levers)


def _geometry_checks(selected: Sequence[str]) -> list[str]:
    """Validate geometry arguments that the body does not otherwise read."""
    names = {ln.split("=", 1)[0].strip() for ln in selected}
    checks = [
        ("ball", "    _vec3(ball_mm, 'ball_mm')"),
        ("pivots", "    _pivots(pivots_mm)"),
        ("tool", "    _tool(tool_mm)"),
    ]
    return [code for name, code in checks if name not in names]


def _function(spec: str, body: list[str], candidates: Sequence[tuple[str, str]], geometry: bool) -> str:
    selected = _select_locals(candidates, body)
    checks = _geometry_checks(selected) if geometry else []
    return "\n".join([spec, *checks, *selected, *body])


class _Levers:
    """Lever arms ``d_P_Q = 0.001 * (P - Q)``: first-order coefficients of a rotation error [µm/µrad]."""

    def __init__(self, model: SymbolicModel) -> None:
        self.order = [str(s) for s in model.geometry_symbols]
        self.used: dict[str, str] = {}

    def code(self, expr: sp.Expr) -> str:
        """Source of a coefficient, using a lever-arm local where the entry is ±0.001·(P − Q)."""
        terms = sp.expand(expr).as_coefficients_dict()
        if len(terms) == 2 and all(isinstance(s, sp.Symbol) and str(s) in self.order for s in terms):
            (a, ka), (b, kb) = sorted(terms.items(), key=lambda t: self.order.index(str(t[0])))
            if ka == -kb and abs(ka) == sp.Rational(1, 1000):
                name = f"d_{a}_{b}"
                self.used[name] = f"0.001 * ({a} - {b})"
                return name if ka > 0 else f"-{name}"
        return _code(expr)

    def locals(self) -> list[tuple[str, str]]:
        return sorted(self.used.items())


def _monomial_name(names: Sequence[str], m: tuple[int, ...]) -> str:
    parts = []
    for i, nm in enumerate(names):
        for fn, deg in (("cos", m[2 * i]), ("sin", m[2 * i + 1])):
            if deg:
                parts.append(f"{fn}({nm})" + (f"^{deg}" if deg > 1 else ""))
    return "*".join(parts) if parts else "1"


def _monomial_factors(names: Sequence[str], m: tuple[int, ...]) -> list[str]:
    parts: list[str] = []
    for i, nm in enumerate(names):
        for fn, deg in (("c", m[2 * i]), ("s", m[2 * i + 1])):
            parts += [f"{fn}_{nm}"] * deg
    return parts


def _basis_columns(names: Sequence[str], monomials: Sequence[tuple[int, ...]], target: str) -> list[str]:
    """Fill ``target`` (n, K), Fortran order, column by column with products built in place."""
    lines = []
    for k, m in enumerate(monomials):
        f = _monomial_factors(names, m)
        col = f"{target}[:, {k}]"
        if not f:
            lines.append(f"    {col} = 1.0")
        elif len(f) == 1:
            lines.append(f"    {col} = {f[0]}")
        else:
            lines.append(f"    np.multiply({f[0]}, {f[1]}, out={col})")
            lines += [f"    {col} *= {x}" for x in f[2:]]
    return lines


def _render_basis(model: SymbolicModel, monomials: Sequence[tuple[int, ...]]) -> str:
    body = [f"    out = np.empty((n, {len(monomials)}), order='F')"]
    body += _basis_columns(model.rotary_axes, monomials, "out")
    body.append("    return out")
    spec = SPECS["basis"].format(K=len(monomials), P=len(model.parameters))
    return _function(spec, body, _trig_locals(model), geometry=False)


def _wrapped(items: Sequence[str], indent: str, width: int = 116) -> list[str]:
    """``items`` joined by commas, as lines of at most ``width`` characters (inside brackets)."""
    lines, line = [], indent
    for item in items:
        piece = f"{item},"
        if len(line) + len(piece) + 1 > width and line.strip():
            lines.append(line.rstrip())
            line = indent
        line += piece + " "
    lines.append(line.rstrip())
    return lines


def _sparse_fill(target: str, entries: Sequence[tuple[tuple[int, ...], str]], index_name: str) -> tuple[str, list[str]]:
    """Fill the non-zero entries of ``target`` in one indexed assignment.

    Returns the module-level constant holding the indices (one tuple per dimension) and the body
    lines assigning the values in the same order.
    """
    if not entries:
        return "", []
    dims = len(entries[0][0])
    const = [f"#: Indices (one tuple per dimension) of the non-zero entries that ``{target}`` receives.",
             f"{index_name} = ("]
    for d in range(dims):
        const += ["    (", *_wrapped([str(idx[d]) for idx, _ in entries], "        "), "    ),"]
    const.append(")")
    body = [f"    {target}[{index_name}] = (", *_wrapped([code for _, code in entries], "        "), "    )"]
    return "\n".join(const), body


def _tensor_entries(coefficients: Sequence[sp.Matrix], levers: _Levers) -> list[tuple[tuple[int, ...], str]]:
    """(k, i, j) and source of every non-zero coefficient, in order."""
    return [((k, i, j), levers.code(cm[i, j])) for k, cm in enumerate(coefficients)
            for i in range(cm.rows) for j in range(cm.cols) if cm[i, j] != 0]


def _with_constant(constant: str, function: str) -> str:
    return f"{constant}\n\n\n{function}" if constant else function


def _render_coefficients(model: SymbolicModel, coefficients: Sequence[sp.Matrix]) -> str:
    levers = _Levers(model)
    k, p = len(coefficients), len(model.parameters)
    const, fill = _sparse_fill("g", _tensor_entries(coefficients, levers), "_COEFFICIENTS_NONZERO")
    body = [f"    g = np.zeros(({k}, 3, {p}))", *fill, "    return g"]
    spec = SPECS["coefficients"].format(K=k, P=p)
    return _with_constant(const, _function(spec, body, _geometry_locals(model, levers.locals()), geometry=True))


def _render_reference_jacobian(model: SymbolicModel) -> str:
    levers = _Levers(model)
    p = len(model.parameters)
    entries = [(idx[1:], code) for idx, code in _tensor_entries([model.reference_jacobian], levers)]
    const, fill = _sparse_fill("out", entries, "_REFERENCE_NONZERO")
    body = [f"    out = np.zeros((3, {p}))", *fill, "    return out"]
    function = _function(SPECS["reference_jacobian"].format(P=p), body, _geometry_locals(model, levers.locals()), True)
    return _with_constant(const, function)


def _render_motion_jacobian(model: SymbolicModel) -> str:
    mot = trig_basis(model.motion_jacobian, model.trig_pairs)
    levers = _Levers(model)
    k, m = len(mot.monomials), len(model.motion_parameters)
    const, fill = _sparse_fill("g", _tensor_entries(mot.coefficients, levers), "_MOTION_NONZERO")
    body = [f"    b = np.empty((n, {k}), order='F')", *_basis_columns(model.rotary_axes, mot.monomials, "b")]
    body += [f"    g = np.zeros(({k}, 3, {m}))", *fill]
    body.append(f"    return (b @ g.reshape({k}, -1)).reshape(n, 3, {m})")
    candidates = _trig_locals(model) + _geometry_locals(model, levers.locals())
    return _with_constant(const, _function(SPECS["motion_jacobian"], body, candidates, geometry=True))


def _render_orientation_jacobian(model: SymbolicModel, motions: bool = False) -> str:
    matrix = model.motion_orientation_jacobian if motions else model.orientation_jacobian
    ori = trig_basis(matrix, model.trig_pairs)
    p = matrix.shape[1]
    body = [f"    out = np.zeros((n, 3, {p}))"]
    for m, cm in zip(ori.monomials, ori.coefficients, strict=True):
        term = " * ".join(_monomial_factors(model.rotary_axes, m)) or "1.0"
        for i in range(3):
            for j in range(p):
                if cm[i, j] != 0:
                    body.append(f"    out[:, {i}, {j}] += {_code(cm[i, j])} * {term}")
    body.append("    return out")
    spec = SPECS["motion_orientation_jacobian" if motions else "orientation_jacobian"].format(P=p)
    return _function(spec, body, _trig_locals(model), geometry=False)


def _render_matrix(model: SymbolicModel, matrix: sp.Matrix, name: str, geometry: bool) -> str:
    """A function returning ``matrix(θ)`` per point, shape (n, rows[, cols])."""
    vector = matrix.cols == 1
    shape = f"(n, {matrix.rows})" if vector else f"(n, {matrix.rows}, {matrix.cols})"
    body = [f"    out = np.zeros({shape})"]
    for i in range(matrix.rows):
        for j in range(matrix.cols):
            if matrix[i, j] != 0:
                idx = f"[:, {i}]" if vector else f"[:, {i}, {j}]"
                body.append(f"    out{idx} = {_code(matrix[i, j])}")
    body.append("    return out")
    candidates = _trig_locals(model) + (_geometry_locals(model) if geometry else [])
    return _function(SPECS[name], body, candidates, geometry)


def _render_direction_solver(model: SymbolicModel, solver: DirectionSolver | None) -> str:
    spec = SPECS["angles_for_direction"].format()
    if solver is None:
        return spec + (
            "\n    raise NotImplementedError(f'{MACHINE_CODE}: no closed-form tool-direction inverse "
            "(needs exactly two rotary axes)')"
        )
    pc, ps = model.trig_pairs[solver.primary]
    sc, ss = model.trig_pairs[solver.secondary]
    (a1, b1, g1), (a2, b2, g2) = solver.rows
    c1, c2 = solver.other_components
    body = [
        "    v = np.asarray(direction, dtype=float).reshape(-1, 3)",
        "    v = v / np.linalg.norm(v, axis=1, keepdims=True)",
        f"    a, b, g = {_code(solver.a)}, {_code(solver.b)}, {_code(solver.g)}",
        "    r = np.hypot(a, b)",
        f"    cosarg = np.clip((v[:, {solver.primary_component}] - g) / r, -1.0, 1.0)",
        "    theta_p = np.arctan2(b, a) + branch * np.arccos(cosarg)",
        "    theta_p = (theta_p + np.pi) % (2 * np.pi) - np.pi",
        "    zeros = np.zeros_like(theta_p)",
        f"    a1 = {_code(a1)} + zeros",
        f"    b1 = {_code(b1)} + zeros",
        f"    r1 = v[:, {c1}] - ({_code(g1)} + zeros)",
        f"    a2 = {_code(a2)} + zeros",
        f"    b2 = {_code(b2)} + zeros",
        f"    r2 = v[:, {c2}] - ({_code(g2)} + zeros)",
        "    det = a1 * b2 - a2 * b1",
        "    ok = np.abs(det) > 1e-12",
        "    safe = np.where(ok, det, 1.0)",
        f"    {sc.name} = (r1 * b2 - r2 * b1) / safe",
        f"    {ss.name} = (a1 * r2 - a2 * r1) / safe",
        f"    theta_s = np.arctan2({ss.name}, {sc.name})",
        "    prev = 0.0 if previous_deg is None else np.radians(np.asarray(previous_deg, dtype=float)"
        f"[{solver.secondary}])",
        "    for i in range(theta_s.shape[0]):",
        "        if not ok[i]:",
        "            theta_s[i] = prev if i == 0 else theta_s[i - 1]",
        "    theta_s = np.unwrap(theta_s)",
        f"    out = np.zeros((v.shape[0], {len(model.rotary)}))",
        f"    out[:, {solver.primary}] = np.degrees(theta_p)",
        f"    out[:, {solver.secondary}] = np.degrees(theta_s)",
        "    return out",
    ]
    used = _tokens(body)
    primary = [f"    {sym.name} = np.{fn}(theta_p)" for sym, fn in ((pc, "cos"), (ps, "sin")) if sym.name in used]
    return "\n".join([spec, *body[:7], *primary, *body[7:]])


def _copied_helpers() -> str:
    return _HELPERS_FILE.read_text(encoding="utf-8").split("\n" + _MARKER + "\n", 1)[1].strip("\n")


def _render_header(structure: MachineStructure, model: SymbolicModel, monomials: Sequence[tuple[int, ...]],
                   has_solver: bool) -> str:
    names = model.rotary_axes
    units_lines = "\n".join(
        f"#   {i:2d}  {p:<8s} [{model.units[p]}]" + ("  (zero-position error)" if i >= model.n_location else "")
        for i, p in enumerate(model.parameters)
    )
    wp_rot = tuple(a.name for a in structure.workpiece_axes if a.kind == "rotary")
    tl_rot = tuple(a.name for a in structure.tool_axes if a.kind == "rotary")
    fingerprint = current_hash(structure)
    return f'''# Generated by pige_sym from the machine structure code {structure.canonical}
# DO NOT EDIT — regenerate with: pige gen "{structure.canonical}" (shipped kernels: make gen-all)
# machine code : {structure.canonical}
# rotary axes  : {", ".join(names)} (column order of angles_deg)
# parameters (order and units):
{units_lines}
# sympy version: {sp.__version__}
# input hash   : {fingerprint}
"""R-test kernels for {structure.canonical} (generated; do not edit — pige gen).

First-order ball-minus-nest deviation (CONVENTIONS §4) in the machine frame,
its Jacobian and the nominal kinematics.  ``jacobian = basis @ coefficients``:
the deviation is linear in the error parameters and in {len(monomials)} trigonometric
basis functions of the rotary angles.
"""

from typing import Any

import numpy as np

MACHINE_CODE = {structure.canonical!r}
ROTARY_AXES = {names!r}
WORKPIECE_ROTARY = {wp_rot!r}
TOOL_ROTARY = {tl_rot!r}
PARAMETERS = {model.parameters!r}
LOCATION_PARAMETERS = {model.parameters[: model.n_location]!r}
ZERO_PARAMETERS = {model.parameters[model.n_location:]!r}
MOTION_PARAMETERS = {model.motion_parameters!r}
UNITS = {dict(model.units)!r}
BASIS = {tuple(_monomial_name(names, m) for m in monomials)!r}
SPINDLE_DIRECTION = {model.spindle_direction}
HAS_DIRECTION_SOLVER = {has_solver}
GENERATOR_HASH = {fingerprint!r}'''


def render_module(code: str | MachineStructure) -> str:
    """Render the kernel module of a machine as Python source text.

    Parameters
    ----------
    code : str or MachineStructure

    Returns
    -------
    str
        Source of a module that imports only NumPy (and ``typing``).
    """
    structure = parse_machine_code(code) if isinstance(code, str) else code
    model = build_model(structure)
    basis = trig_basis(model.jacobian, model.trig_pairs)
    solver = direction_solver(model)
    parts = [
        _render_header(structure, model, basis.monomials, solver is not None),
        _copied_helpers(),
        _render_basis(model, basis.monomials),
        _render_coefficients(model, basis.coefficients),
        LINEAR_FUNCTIONS,
        _render_reference_jacobian(model),
        _render_motion_jacobian(model),
        _render_orientation_jacobian(model),
        _render_orientation_jacobian(model, motions=True),
        _render_matrix(model, model.workpiece_rotation, "workpiece_rotation", geometry=False),
        _render_matrix(model, model.tool_rotation, "tool_rotation", geometry=False),
        _render_matrix(model, model.linear_commands, "linear_commands", geometry=True),
        _render_matrix(model, model.tool_direction, "tool_direction", geometry=False),
        _render_direction_solver(model, solver),
    ]
    return "\n\n\n".join(p.strip("\n") for p in parts) + "\n"


def same_code(a: str, b: str) -> bool:
    """Whether two rendered modules hold the same code (the informative SymPy version line is ignored)."""

    def strip(text: str) -> list[str]:
        return [line for line in text.splitlines() if not line.startswith("# sympy version")]

    return strip(a) == strip(b)


def write_module(code: str | MachineStructure, directory: str | Path) -> Path:
    """Render and write the kernel module; returns its path."""
    structure = parse_machine_code(code) if isinstance(code, str) else code
    return atomic_write_text(Path(directory) / f"{structure.module_name}.py", render_module(structure))
