"""Emitter: render a :class:`~pige_sym.codegen.symbolic.SymbolicModel` as a plain NumPy module.

The module is rendered to a string first (:func:`render_module`), then written
(:func:`write_module`).  The generated module imports only NumPy and exposes

* ``MACHINE_CODE``, ``ROTARY_AXES``, ``PARAMETERS``, ``LOCATION_PARAMETERS``,
  ``ZERO_PARAMETERS``, ``UNITS``, ``BASIS`` (names of the basis columns),
  ``WORKPIECE_ROTARY``, ``TOOL_ROTARY``, ``HAS_DIRECTION_SOLVER``;
* ``basis(angles_deg) -> (n, K)`` and ``coefficients(ball_mm, pivots_mm, tool_mm)
  -> (K, 3, P)``, so that ``jacobian = basis @ coefficients`` (one BLAS call);
* ``deviation``, ``jacobian``, ``workpiece_rotation``, ``tool_rotation``,
  ``linear_commands``, ``tool_direction`` and ``angles_for_direction``.

The header records the machine code, parameter order and units, the SymPy
version and a hash of the inputs (code + generator sources), so
``make check-generated`` can detect any drift.
"""

from __future__ import annotations

from pathlib import Path

import sympy as sp
from sympy.printing.pycode import PythonCodePrinter

from pige_sym.codegen.fingerprint import current_hash
from pige_sym.codegen.machine_code import MachineStructure, parse_machine_code
from pige_sym.codegen.symbolic import SymbolicModel, build_model, direction_solver, trig_basis
from pige_sym.files import atomic_write_text


class _Printer(PythonCodePrinter):
    """Prints polynomials with plain float literals for rationals."""

    def _print_Rational(self, expr: sp.Rational) -> str:
        return repr(float(expr.p) / float(expr.q))

    def _print_Half(self, expr: sp.Rational) -> str:
        return "0.5"


def _code(expr: sp.Expr) -> str:
    return str(_Printer({"standard": "python3"}).doprint(expr))


input_hash = current_hash


def _symbol_locals(model: SymbolicModel, indent: str) -> list[str]:
    lines = [f"{indent}ball_x, ball_y, ball_z = _vec3(ball_mm, 'ball_mm')"]
    lines.append(f"{indent}pivots = _pivots(pivots_mm)")
    for r in model.rotary:
        nm = r.axis.name
        lines.append(f"{indent}p{nm}_x, p{nm}_y, p{nm}_z = pivots[{nm!r}]")
    lines.append(f"{indent}tool_x, tool_y, tool_z = _tool(tool_mm)")
    return lines


def _trig_locals(model: SymbolicModel, indent: str) -> list[str]:
    lines = [f"{indent}th = np.radians(_angles(angles_deg))"]
    for i, r in enumerate(model.rotary):
        nm = r.axis.name
        lines.append(f"{indent}c_{nm} = np.cos(th[:, {i}])")
        lines.append(f"{indent}s_{nm} = np.sin(th[:, {i}])")
    return lines


def _matrix_function(model: SymbolicModel, matrix: sp.Matrix, name: str, doc: str, geometry: bool) -> str:
    """Render a function returning matrix(θ) evaluated per point, shape (n, rows[, cols])."""
    args = "angles_deg" + (", ball_mm, pivots_mm=None, tool_mm=None" if geometry else "")
    out = [f"def {name}({args}):", f'    """{doc}"""']
    out += _trig_locals(model, "    ")
    if geometry:
        out += _symbol_locals(model, "    ")
    out.append("    n = th.shape[0]")
    vector = matrix.cols == 1
    shape = f"(n, {matrix.rows})" if vector else f"(n, {matrix.rows}, {matrix.cols})"
    out.append(f"    out = np.zeros({shape})")
    for i in range(matrix.rows):
        for j in range(matrix.cols):
            e = matrix[i, j]
            if e == 0:
                continue
            idx = f"[:, {i}]" if vector else f"[:, {i}, {j}]"
            out.append(f"    out{idx} = {_code(e)}")
    out.append("    return out")
    return "\n".join(out)


_HELPERS = '''
def _angles(angles_deg):
    a = np.asarray(angles_deg, dtype=float)
    if a.ndim == 1 and len(ROTARY_AXES) == 1:
        a = a[:, None]
    if a.ndim == 1 and a.shape[0] == len(ROTARY_AXES):
        a = a[None, :]
    if a.ndim != 2 or a.shape[1] != len(ROTARY_AXES):
        raise ValueError(
            f"angles_deg must have shape (n, {len(ROTARY_AXES)}) with columns {ROTARY_AXES}, got {a.shape}"
        )
    return a


def _vec3(v, name):
    a = np.asarray(v, dtype=float).reshape(-1)
    if a.shape != (3,):
        raise ValueError(f"{name} must be 3 numbers [mm], got shape {a.shape}")
    return a


def _pivots(pivots_mm):
    out = {ax: np.zeros(3) for ax in ROTARY_AXES}
    for key, value in (pivots_mm or {}).items():
        if key not in out:
            raise ValueError(f"pivots_mm: {key!r} is not a rotary axis of {MACHINE_CODE} (axes: {ROTARY_AXES})")
        out[key] = _vec3(value, f"pivots_mm[{key!r}]")
    return out


def _tool(tool_mm):
    if tool_mm is None:
        if TOOL_ROTARY:
            raise ValueError(f"{MACHINE_CODE} has tool-side rotary axes {TOOL_ROTARY}: give tool_mm")
        return np.zeros(3)
    return _vec3(tool_mm, "tool_mm")


def _params(params):
    p = np.asarray(params, dtype=float).reshape(-1)
    if p.shape[0] == len(LOCATION_PARAMETERS):
        p = np.concatenate([p, np.zeros(len(ZERO_PARAMETERS))])
    if p.shape[0] != len(PARAMETERS):
        raise ValueError(
            f"params must hold {len(LOCATION_PARAMETERS)} location errors or all {len(PARAMETERS)} "
            f"parameters in the order {PARAMETERS}, got {p.shape[0]}"
        )
    return p
'''


def render_module(code: str | MachineStructure) -> str:
    """Render the kernel module of a machine as Python source text.

    Parameters
    ----------
    code : str or MachineStructure

    Returns
    -------
    str
        Source of a module that imports only NumPy.
    """
    structure = parse_machine_code(code) if isinstance(code, str) else code
    model = build_model(structure)
    basis = trig_basis(model.jacobian, model.trig_pairs)
    solver = direction_solver(model)
    names = model.rotary_axes
    n_par = len(model.parameters)

    def monomial_name(m: tuple[int, ...]) -> str:
        parts = []
        for i, nm in enumerate(names):
            for fn, deg in (("cos", m[2 * i]), ("sin", m[2 * i + 1])):
                if deg:
                    parts.append(f"{fn}({nm})" + (f"^{deg}" if deg > 1 else ""))
        return "*".join(parts) if parts else "1"

    def monomial_code(m: tuple[int, ...]) -> str:
        parts = []
        for i, nm in enumerate(names):
            for fn, deg in (("c", m[2 * i]), ("s", m[2 * i + 1])):
                parts += [f"{fn}_{nm}"] * deg
        return " * ".join(parts) if parts else "1.0"

    units_lines = "\n".join(
        f"#   {i:2d}  {p:<8s} [{model.units[p]}]" + ("  (zero-position error)" if i >= model.n_location else "")
        for i, p in enumerate(model.parameters)
    )
    wp_rot = tuple(a.name for a in structure.workpiece_axes if a.kind == "rotary")
    tl_rot = tuple(a.name for a in structure.tool_axes if a.kind == "rotary")
    header = f'''# Generated by pige_sym from the machine structure code {structure.canonical}
# DO NOT EDIT — regenerate with: make gen MACHINE="{structure.canonical}"
# machine code : {structure.canonical}
# rotary axes  : {", ".join(names)} (column order of angles_deg)
# parameters (order and units):
{units_lines}
# sympy version: {sp.__version__}
# input hash   : {input_hash(structure)}
"""R-test kernels for {structure.canonical} (generated; do not edit — make gen).

First-order ball-minus-nest deviation (CONVENTIONS §4) in the machine frame,
its Jacobian and the nominal kinematics.  ``jacobian = basis @ coefficients``:
the deviation is linear in the error parameters and in {len(basis.monomials)} trigonometric
basis functions of the rotary angles.
"""

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
BASIS = {tuple(monomial_name(m) for m in basis.monomials)!r}
SPINDLE_DIRECTION = {model.spindle_direction}
HAS_DIRECTION_SOLVER = {solver is not None}
GENERATOR_HASH = {input_hash(structure)!r}
'''
    parts = [header, _HELPERS]

    # basis
    lines = [
        "def basis(angles_deg):",
        '    """Trigonometric basis, shape=(n, K) [1]; columns named in BASIS."""',
    ]
    lines += _trig_locals(model, "    ")
    lines.append(f"    out = np.empty((th.shape[0], {len(basis.monomials)}))")
    for k, m in enumerate(basis.monomials):
        lines.append(f"    out[:, {k}] = {monomial_code(m)}")
    lines.append("    return out")
    parts.append("\n".join(lines))

    # coefficients
    lines = [
        "def coefficients(ball_mm, pivots_mm=None, tool_mm=None):",
        '    """Coefficient tensor G, shape=(K, 3, P) [µm per µm or µrad]: jacobian = basis @ G."""',
    ]
    lines += _symbol_locals(model, "    ")
    lines.append(f"    g = np.zeros(({len(basis.monomials)}, 3, {n_par}))")
    for k, cm in enumerate(basis.coefficients):
        for i in range(3):
            for j in range(n_par):
                if cm[i, j] != 0:
                    lines.append(f"    g[{k}, {i}, {j}] = {_code(cm[i, j])}")
    lines.append("    return g")
    parts.append("\n".join(lines))

    parts.append(
        '''def jacobian(angles_deg, params=None, ball_mm=None, pivots_mm=None, tool_mm=None):
    """Jacobian of the deviation, shape=(n, 3, P) [µm per µm or µrad].

    The first-order model is linear in the parameters, so ``params`` is accepted
    for a uniform signature but does not change the result.
    """
    if ball_mm is None:
        raise ValueError("jacobian needs ball_mm")
    b = basis(angles_deg)
    g = coefficients(ball_mm, pivots_mm, tool_mm)
    return (b @ g.reshape(g.shape[0], -1)).reshape(b.shape[0], 3, g.shape[2])


def deviation(angles_deg, params, ball_mm, pivots_mm=None, tool_mm=None):
    """Ball-minus-nest deviation in the machine frame, shape=(n, 3) [µm].

    Parameters
    ----------
    angles_deg : array, shape=(n, k) [deg]
        Commanded rotary angles, columns in ROTARY_AXES order.
    params : array, shape=(P,) or (8,)-like
        Error parameters in PARAMETERS order [µm, µrad]; the location errors alone
        are accepted (zero-position errors then 0).
    ball_mm : array, shape=(3,) [mm]
    pivots_mm : dict axis -> (3,) [mm], optional
    tool_mm : (3,) [mm], required with tool-side rotary axes
    """
    p = _params(params)
    g = coefficients(ball_mm, pivots_mm, tool_mm)
    return basis(angles_deg) @ (g @ p)'''
    )
    lines = [
        "def reference_jacobian(ball_mm, pivots_mm=None, tool_mm=None):",
        '    """Un-zeroed offset Jacobian at the reference pose J_raw(0), shape=(3, P) [µm per µm or µrad].',
        "",
        "    The ball-minus-nest offset before zeroing is, at any pose,",
        "    ``(jacobian + workpiece_rotation @ reference_jacobian) @ params``; effects whose",
        "    size changes with the pose (angle-dependent errors) need it.",
        '    """',
    ]
    lines += _symbol_locals(model, "    ")
    lines.append(f"    out = np.zeros((3, {n_par}))")
    for i in range(3):
        for j in range(n_par):
            if model.reference_jacobian[i, j] != 0:
                lines.append(f"    out[{i}, {j}] = {_code(model.reference_jacobian[i, j])}")
    lines.append("    return out")
    parts.append("\n".join(lines))
    mot = trig_basis(model.motion_jacobian, model.trig_pairs)
    n_mot = len(model.motion_parameters)
    lines = [
        "def motion_jacobian(angles_deg, ball_mm, pivots_mm=None, tool_mm=None):",
        '    """Un-zeroed offset per unit error motion, shape=(n, 3, 6k) [µm per µm or µrad].',
        "",
        "    Columns MOTION_PARAMETERS: per rotary axis dx, dy, dz [µm] and rx, ry, rz [µrad],",
        "    a small rigid motion of the body the axis carries (carrier frame, rotations about",
        "    the nominal pivot) applied after the axis' own motion.  Zeroing at the reference",
        "    pose is the caller's business (subtract workpiece_rotation @ value at the reference).",
        '    """',
    ]
    lines += _trig_locals(model, "    ")
    lines += _symbol_locals(model, "    ")
    lines.append(f"    b = np.empty((th.shape[0], {len(mot.monomials)}))")
    for k, m in enumerate(mot.monomials):
        lines.append(f"    b[:, {k}] = {monomial_code(m)}")
    lines.append(f"    g = np.zeros(({len(mot.monomials)}, 3, {n_mot}))")
    for k, cm in enumerate(mot.coefficients):
        for i in range(3):
            for j in range(n_mot):
                if cm[i, j] != 0:
                    lines.append(f"    g[{k}, {i}, {j}] = {_code(cm[i, j])}")
    lines.append(f"    return (b @ g.reshape({len(mot.monomials)}, -1)).reshape(th.shape[0], 3, {n_mot})")
    parts.append("\n".join(lines))
    ori = trig_basis(model.orientation_jacobian, model.trig_pairs)
    lines = [
        "def orientation_jacobian(angles_deg):",
        '    """Tool-orientation error Jacobian, shape=(n, 3, P) [µrad per µm or µrad].',
        "",
        "    ω = orientation_jacobian @ params is the small rotation of the spindle frame",
        "    relative to the workpiece, expressed in W: R_rel_actual = (I + [ω]x) R_rel_nominal.",
        '    """',
    ]
    lines += _trig_locals(model, "    ")
    lines.append(f"    out = np.zeros((th.shape[0], 3, {n_par}))")
    for m, cm in zip(ori.monomials, ori.coefficients, strict=True):
        for i in range(3):
            for j in range(n_par):
                if cm[i, j] != 0:
                    term = monomial_code(m)
                    lines.append(f"    out[:, {i}, {j}] += {_code(cm[i, j])} * {term}")
    lines.append("    return out")
    parts.append("\n".join(lines))
    parts.append(
        _matrix_function(
            model, model.workpiece_rotation, "workpiece_rotation",
            "Nominal rotation of the workpiece frame W into M, shape=(n, 3, 3).", geometry=False,
        )
    )
    parts.append(
        _matrix_function(
            model, model.tool_rotation, "tool_rotation",
            "Nominal rotation of the spindle frame into M, shape=(n, 3, 3).", geometry=False,
        )
    )
    parts.append(
        _matrix_function(
            model, model.linear_commands, "linear_commands",
            "Commanded X, Y, Z (RTCP, nominal kinematics), shape=(n, 3) [mm]; ball_mm at the reference pose.",
            geometry=True,
        )
    )
    parts.append(
        _matrix_function(
            model, model.tool_direction, "tool_direction",
            "Spindle direction in the workpiece frame W, shape=(n, 3) [unit vectors].", geometry=False,
        )
    )
    parts.append(_render_direction_solver(model, solver))
    return "\n\n\n".join(p.strip("\n") for p in parts) + "\n"


def _render_direction_solver(model: SymbolicModel, solver: object) -> str:
    from pige_sym.codegen.symbolic import DirectionSolver

    head = [
        "def angles_for_direction(direction, branch=1, previous_deg=None):",
        '    """Rotary angles that put a workpiece-frame tool direction on the spindle axis.',
        "",
        "    Parameters",
        "    ----------",
        "    direction : array, shape=(n, 3)",
        "        Tool direction in the workpiece frame W (normalised here).",
        "    branch : {+1, -1}",
        "        Which of the two solutions of the primary (tilting) axis to take.",
        "    previous_deg : array, shape=(k,), optional",
        "        Angles used where the secondary axis is undetermined (singular pose).",
        "",
        "    Returns",
        "    -------",
        "    angles_deg : array, shape=(n, k) [deg], secondary axis unwrapped to be continuous.",
        '    """',
    ]
    if not isinstance(solver, DirectionSolver):
        head.append(
            "    raise NotImplementedError(f'{MACHINE_CODE}: no closed-form tool-direction inverse "
            "(needs exactly two rotary axes)')"
        )
        return "\n".join(head)
    pc, ps = model.trig_pairs[solver.primary]
    sc, ss = model.trig_pairs[solver.secondary]
    k = len(model.rotary)
    body = [
        "    v = np.asarray(direction, dtype=float).reshape(-1, 3)",
        "    v = v / np.linalg.norm(v, axis=1, keepdims=True)",
        f"    a, b, g = {_code(solver.a)}, {_code(solver.b)}, {_code(solver.g)}",
        "    r = np.hypot(a, b)",
        f"    cosarg = np.clip((v[:, {solver.primary_component}] - g) / r, -1.0, 1.0)",
        "    theta_p = np.arctan2(b, a) + branch * np.arccos(cosarg)",
        "    theta_p = (theta_p + np.pi) % (2 * np.pi) - np.pi",
        f"    {pc.name} = np.cos(theta_p)",
        f"    {ps.name} = np.sin(theta_p)",
        "    zeros = np.zeros_like(theta_p)",
    ]
    (a1, b1, g1), (a2, b2, g2) = solver.rows
    c1, c2 = solver.other_components
    body += [
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
        f"    out = np.zeros((v.shape[0], {k}))",
        f"    out[:, {solver.primary}] = np.degrees(theta_p)",
        f"    out[:, {solver.secondary}] = np.degrees(theta_s)",
        "    return out",
    ]
    return "\n".join(head + body)


def same_code(a: str, b: str) -> bool:
    """Whether two rendered modules hold the same code (the informative SymPy version line is ignored)."""

    def strip(text: str) -> list[str]:
        return [line for line in text.splitlines() if not line.startswith("# sympy version")]

    return strip(a) == strip(b)


def write_module(code: str | MachineStructure, directory: str | Path) -> Path:
    """Render and write the kernel module; returns its path."""
    structure = parse_machine_code(code) if isinstance(code, str) else code
    text = render_module(structure)
    return atomic_write_text(Path(directory) / f"{structure.module_name}.py", text)
