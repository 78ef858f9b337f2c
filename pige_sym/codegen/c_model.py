"""Pure C99 kinematics of a machine with every PIGE: the NumPy kernels' model, emitted from the same SymPy model.

:func:`render_model_c` returns the C source (``math.h`` only, no LinuxCNC header) of a header-only
model; :mod:`pige_sym.codegen.targets.linuxcnc` inlines it into a LinuxCNC kinematics component,
and anyone may ``#include`` it into a harness or a realtime component of their own.

Model
-----
``world`` is the controlled tool point in work coordinates: the table frame W at the reference pose
(where W coincides with the machine frame M, CONVENTIONS §2), plus ``tool_offset`` along the spindle
axis, which is what LinuxCNC's world holds with a tool length (G43) active. ``joints`` are the
machine's linear axes X, Y, Z in the kernels' ``linear_commands`` coordinates (at the reference pose
``joints = world``) and the commanded rotary angles ``θ_cmd`` [deg]. With θ = σ·θ_cmd
(CONVENTIONS §9), ``b = world − t·e_s`` (the tool point, t = tool offset, e_s the spindle axis) and
``tool_eff = tool − t·e_s`` (head machines: the tool tip relative to the last tool-side pivot)::

    joints = linear_commands(θ, b, pivots, tool_eff)
             − 0.001 · [basis(θ) @ coefficients(b, pivots, tool_eff) + workpiece_rotation(θ) @
                        reference_jacobian(b, pivots, tool_eff)] @ errors  +  t·e_s

that is the nominal exact rotation plus the kernels' first-order un-zeroed ball-minus-nest offset
(µm → mm): the linear axes move the tool point onto the workpiece point ``b`` of the machine with
``errors``. The errors are the kernels' ``PARAMETERS`` (location errors [µm, µrad], then
zero-position errors [µrad]); the zero-position term is not zeroed at the reference pose, since a
zero-position error moves the table there too. Only machines whose linear axes sit between the bed
and the rotary axes are accepted: then ``∂(ball − nest)/∂L = I`` and the equation above is the exact
correction of the first-order model.

Forward and inverse
-------------------
``P_inverse`` (world → joints, LinuxCNC's ``kinematicsInverse``) evaluates the equation above in
closed form. ``P_forward`` (joints → world) starts from the nominal closed form
``b = Aᵀ(joints − t·e_s − c)`` (``A`` = ∂linear_commands/∂b, a rotation, checked symbolically) and
refines it by Newton steps with the generated Jacobian ``P_jacobian`` = ∂joints/∂world. The
equation is affine in ``b`` for fixed angles (linear_commands and the coefficients are linear in
``b``), so the Jacobian does not depend on ``world`` and one Newton step from any start lands on the
solution up to rounding; a second step only runs if the first left more than ``P_NEWTON_TOL_MM``.

C API (``P`` is the prefix given to :func:`render_model_c`)
-----------------------------------------------------------
``P_params`` (``pivot[k][3]`` [mm], ``tool[3]`` [mm], ``sense[k]`` (σ: negative means −1, else +1),
``errors[P_N_ERRORS]`` [µm, µrad] in ``P_<NAME>`` index order, ``tool_offset`` [mm]);
``P_params_init``; ``P_inverse(p, world[3], angles_cmd_deg[k], joints[3])``;
``P_jacobian(p, angles_cmd_deg, m[3][3])``; ``P_forward_nominal``;
``P_forward_steps(p, joints, angles_cmd_deg, max_steps, world, &residual_mm)`` (returns the steps
taken, −1 if the Jacobian is singular); ``P_forward`` (0 or −1). Rotary arrays are in ``ROTARY_AXES``
order. No globals: every function reads only its arguments. ``P_API`` (default ``static``) sets the
linkage.
"""

from __future__ import annotations

import functools
import hashlib
import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import sympy as sp
from sympy.printing.c import C99CodePrinter

from pige_sym.codegen.fingerprint import current_hash
from pige_sym.codegen.machine_code import MachineStructure, parse_machine_code
from pige_sym.codegen.symbolic import SymbolicModel, build_model, reduce_trig
from pige_sym.errors import InputError, UnsupportedMachineError

#: Newton steps at most in ``P_forward`` (one is exact for this affine model; see the module docstring).
NEWTON_MAX_STEPS = 3
#: Residual |inverse(world) − joints| [mm] below which ``P_forward`` stops.
NEWTON_TOL_MM = 1e-10
#: Map slots per rotary axis: the six error motions of CONVENTIONS §10, then the reversal of φ.
MAP_SLOTS = 7


class _Printer(C99CodePrinter):
    """C99 with plain double literals and integer powers as products (no ``pow``)."""

    def _print_Float(self, expr: sp.Float) -> str:
        return repr(float(expr))

    def _print_Rational(self, expr: sp.Rational) -> str:
        return repr(float(expr.p) / float(expr.q))

    def _print_Pow(self, expr: sp.Pow) -> str:
        base, exp = expr.as_base_exp()
        if exp.is_Integer and 0 < int(exp) <= 4:
            return "(" + "*".join([self.parenthesize(base, 100)] * int(exp)) + ")"
        return str(super()._print_Pow(expr))


def c_expr(expr: sp.Expr) -> str:
    """C source of an expression; non-integer rationals become double literals, integers stay exact."""
    floats = {r: sp.Float(r) for r in expr.atoms(sp.Rational) if not r.is_Integer}
    return str(_Printer().doprint(expr.xreplace(floats)))


@dataclass
class KinematicsExpressions:
    """The symbolic kinematics of one machine, ready to print.

    Attributes
    ----------
    model : SymbolicModel
    joints : sympy.Matrix, shape (3, 1)
        Linear joints [mm] of the tool point ``model.ball`` (tool offset 0), errors included.
    jacobian : sympy.Matrix, shape (3, 3)
        ∂joints/∂ball [1]; free of ball (the joints are affine in it).
    nominal_rotation : sympy.Matrix, shape (3, 3)
        ``A`` = ∂linear_commands/∂ball, a rotation (``AᵀA = I`` checked).
    nominal_offset : sympy.Matrix, shape (3, 1)
        ``c`` = linear_commands at ball = 0 [mm].
    errors : list of sympy.Symbol
        One symbol per kernel parameter, ``PARAMETERS`` order.
    motions : list of sympy.Symbol
        One symbol per error motion of a carried body, ``MOTION_PARAMETERS`` order.
    """

    model: SymbolicModel
    joints: sp.Matrix
    jacobian: sp.Matrix
    nominal_rotation: sp.Matrix
    nominal_offset: sp.Matrix
    errors: list[sp.Symbol]
    motions: list[sp.Symbol]


def check_supported(structure: MachineStructure) -> None:
    """Refuse machines whose linear axes are carried by a rotary axis (one line, what is wrong).

    Raises
    ------
    UnsupportedMachineError
    """
    wp = [a.kind for a in structure.workpiece_axes]
    tl = [a.kind for a in structure.tool_axes]
    inner_linear = "linear" in wp and "rotary" in wp[wp.index("linear"):]
    outer_linear = "rotary" in tl and "linear" in tl[tl.index("rotary"):]
    if inner_linear or outer_linear:
        raise UnsupportedMachineError(
            f"machine {structure.canonical!r}: a linear axis is carried by a rotary axis, so the linear joints do "
            "not move the tool point by their own amount; the kinematics need every linear axis between the bed "
            "and the rotary axes")


def kinematics_expressions(code: str | MachineStructure) -> KinematicsExpressions:
    """Build the symbolic kinematics (module docstring) of a machine (cached per machine: SymPy takes seconds).

    Raises
    ------
    UnsupportedMachineError
        A linear axis carried by a rotary axis, or a nominal map that is not a rotation.
    """
    structure = parse_machine_code(code) if isinstance(code, str) else code
    check_supported(structure)
    return _expressions(structure)


@functools.lru_cache(maxsize=16)
def _expressions(structure: MachineStructure) -> KinematicsExpressions:
    model = build_model(structure)
    errors = [sp.Symbol(name, real=True) for name in model.parameters]
    motions = [sp.Symbol(f"mo_{name}", real=True) for name in model.motion_parameters]
    offset = ((model.jacobian + model.workpiece_rotation * model.reference_jacobian) * sp.Matrix(errors)
              + model.motion_jacobian * sp.Matrix(motions))
    joints = (model.linear_commands - offset / 1000).applyfunc(sp.expand)
    ball = list(model.ball)
    jacobian = joints.jacobian(ball).applyfunc(sp.expand)
    rotation = model.linear_commands.jacobian(ball).applyfunc(sp.expand)
    pairs = model.trig_pairs
    if jacobian.free_symbols & set(ball) or any(
            reduce_trig(e, pairs) != 0 for e in (rotation.T * rotation - sp.eye(3))):
        raise UnsupportedMachineError(f"machine {structure.canonical!r}: the nominal kinematics are not a rigid "
                                      "motion of the tool point; no closed-form inverse")
    nominal_offset = model.linear_commands.subs({b: 0 for b in ball}).applyfunc(sp.expand)
    return KinematicsExpressions(model, joints, jacobian, rotation, nominal_offset, errors, motions)


def generator_hash(structure: MachineStructure, *modules: str) -> str:
    """The kernels' input hash extended by the source of this module and of ``modules`` (file paths)."""
    h = hashlib.sha256(current_hash(structure).encode())
    for path in (__file__, *modules):
        h.update(Path(path).read_bytes().replace(b"\r\n", b"\n"))
    return h.hexdigest()[:16]


def _locals(kin: KinematicsExpressions, prefix: str, used: set[str],
            extra: Sequence[tuple[str, str]] = ()) -> list[str]:
    """Declarations of what a body uses (and what those need), read from the arguments; declarations only."""
    model = kin.model
    spindle = model.spindle_direction
    candidates: list[tuple[str, str]] = [("dt", "p->tool_offset"), *extra]
    for i, r in enumerate(model.rotary):
        th = f"th_{r.axis.name}"
        candidates += [(th, f"{prefix}_theta(p, angles_cmd_deg, {i})"), (r.cos.name, f"cos({th})"),
                       (r.sin.name, f"sin({th})")]
        candidates += [(sym.name, f"p->pivot[{i}][{j}]") for j, sym in enumerate(r.pivot)]
    for j, sym in enumerate(model.ball):
        candidates.append((sym.name, f"world[{j}] - dt" if j == spindle else f"world[{j}]"))
    for j, sym in enumerate(model.tool):
        candidates.append((sym.name, f"p->tool[{j}] - dt" if j == spindle else f"p->tool[{j}]"))
    candidates += [(e.name, f"p->errors[{k}]") for k, e in enumerate(kin.errors)]
    candidates += [(m.name, f"p->motion[{k}]") for k, m in enumerate(kin.motions)]
    names = {name for name, _ in candidates}
    needed = set(used) & names
    for name, code in reversed(candidates):
        if name in needed:
            needed |= set(re.findall(r"[A-Za-z_][A-Za-z0-9_]*", code)) & names
    return [f"    const double {name} = {code};" for name, code in candidates if name in needed]


def _block(exprs: list[sp.Expr], targets: list[str]) -> tuple[list[str], set[str]]:
    """Assignments ``target = expr`` with common subexpressions as ``const double`` temporaries."""
    temps, reduced = sp.cse(exprs, symbols=sp.numbered_symbols("t"))
    lines = [f"    const double {t} = {c_expr(e)};" for t, e in temps]
    lines += [f"    {target} = {c_expr(e)};" for target, e in zip(targets, reduced, strict=True)]
    used = {s.name for e in exprs for s in e.free_symbols}
    return lines, used


def _function(kin: KinematicsExpressions, prefix: str, head: str, exprs: list[sp.Expr], targets: list[str],
              inputs: Sequence[tuple[str, str]] = (), after: Sequence[str] = ()) -> str:
    """One C function: signature ``head``, the locals it reads (``inputs`` too), the CSE body, ``after``.

    Only declarations precede the first statement, so the body is also valid where a compiler warns of
    declarations after statements.
    """
    body, used = _block(exprs, targets)
    used |= {t for ln in after for t in re.findall(r"[A-Za-z_][A-Za-z0-9_]*", ln)}
    declared = _locals(kin, prefix, used, inputs)
    text = "\n".join([*declared, *body, *after])
    unused = [f"    (void){arg};" for arg in ("p", "angles_cmd_deg") if not re.search(rf"\b{arg}\b", text)]
    return "\n".join([head, "{", *declared, *unused, *body, *after, "}"])


def _inverse(kin: KinematicsExpressions, prefix: str) -> str:
    s = kin.model.spindle_direction
    head = (f"/* world -> joints (closed form): the linear joints that put the tool point on world [mm]. */\n"
            f"{prefix}_API void {prefix}_inverse(const {prefix}_params *p, const double world[3], "
            f"const double angles_cmd_deg[], double joints[3])")
    return _function(kin, prefix, head, list(kin.joints), [f"joints[{j}]" for j in range(3)],
                     after=[f"    joints[{s}] += dt;"])


def _jacobian(kin: KinematicsExpressions, prefix: str) -> str:
    head = (f"/* d joints / d world [1] at the given angles (the model is affine in world). */\n"
            f"{prefix}_API void {prefix}_jacobian(const {prefix}_params *p, const double angles_cmd_deg[], "
            "double m[3][3])")
    exprs = [kin.jacobian[i, j] for i in range(3) for j in range(3)]
    return _function(kin, prefix, head, exprs, [f"m[{i}][{j}]" for i in range(3) for j in range(3)])


def _forward_nominal(kin: KinematicsExpressions, prefix: str) -> str:
    s = kin.model.spindle_direction
    q = sp.Matrix(sp.symbols("q0 q1 q2", real=True))
    ball = kin.nominal_rotation.T * (q - kin.nominal_offset)
    head = (f"/* joints -> world with the nominal geometry and no errors (closed form, start of the Newton steps). */\n"
            f"{prefix}_API void {prefix}_forward_nominal(const {prefix}_params *p, const double joints[3], "
            "const double angles_cmd_deg[], double world[3])")
    inputs = [(f"q{j}", f"joints[{j}]" + (" - dt" if j == s else "")) for j in range(3)]
    exprs = [reduce_trig(e, kin.model.trig_pairs) for e in ball]
    return _function(kin, prefix, head, exprs, [f"world[{j}]" for j in range(3)],
                     inputs, [f"    world[{s}] += dt;"])


def _declarations(kin: KinematicsExpressions, prefix: str) -> str:
    model = kin.model
    k, n, spindle = len(model.rotary), len(kin.errors), "XYZ"[model.spindle_direction]
    m = len(kin.motions)
    index = "\n".join(f"#define {prefix}_{name} {i}  /* [{model.units[name]}]"
                      + (" zero-position error */" if i >= model.n_location else " */")
                      for i, name in enumerate(model.parameters))
    return f"""#ifndef {prefix}_API
#define {prefix}_API static
#endif

#define {prefix}_N_ROTARY {k}  /* rotary axes, in this order: {", ".join(model.rotary_axes)} */
#define {prefix}_N_ERRORS {n}
#define {prefix}_N_MOTIONS {m}  /* per rotary axis dx, dy, dz [um], rx, ry, rz [urad] of its carried body */
#define {prefix}_SPINDLE_AXIS {model.spindle_direction}  /* tool offset along machine {spindle} */
#define {prefix}_NEWTON_MAX_STEPS {NEWTON_MAX_STEPS}
#define {prefix}_NEWTON_TOL_MM {NEWTON_TOL_MM!r}
/* index of each error in {prefix}_params.errors */
{index}

typedef struct {prefix}_params {{
    double pivot[{k}][3];    /* nominal pivot of each rotary axis, machine frame at the reference pose [mm] */
    double tool[3];        /* tool tip relative to the last tool-side pivot, no tool offset [mm] (head axes) */
    double sense[{k}];       /* commanded sense: theta = sense * theta_cmd (negative: -1, else +1) */
    double errors[{n}];     /* location errors [um, urad], then zero-position errors [urad] */
    double tool_offset;    /* tool length along the spindle axis [mm], part of world (LinuxCNC G43) */
    double motion[{m}];    /* error motions of the carried bodies at this pose [um, urad] ({prefix}_map_add) */
}} {prefix}_params;

/* Geometry at the origin, senses +1, no errors, no tool offset. */
{prefix}_API void {prefix}_params_init({prefix}_params *p)
{{
    int i, j;
    for (i = 0; i < {k}; i++) {{
        for (j = 0; j < 3; j++) p->pivot[i][j] = 0.0;
        p->sense[i] = 1.0;
    }}
    for (j = 0; j < 3; j++) p->tool[j] = 0.0;
    for (i = 0; i < {n}; i++) p->errors[i] = 0.0;
    for (i = 0; i < {m}; i++) p->motion[i] = 0.0;
    p->tool_offset = 0.0;
}}

/* The CONVENTIONS angle theta = sense * theta_cmd of rotary axis i [rad]. */
{prefix}_API double {prefix}_theta(const {prefix}_params *p, const double angles_cmd_deg[], int i)
{{
    return (p->sense[i] < 0.0 ? -1.0 : 1.0) * angles_cmd_deg[i] * 0.017453292519943295;
}}"""


def _initializer(rows: list[str]) -> str:
    """A C initializer of a 2-D array: ``{{a, b}, {c, d}}``."""
    return "{" + ", ".join("{" + r + "}" for r in rows) + "}"


def _maps(kin: KinematicsExpressions, prefix: str) -> str:
    """Error maps (CONVENTIONS §10) to ``motion[]``: hat-function weights on a uniform grid and, per axis, where
    each of its map's slots goes (:func:`pige_sym.codegen.map_slots.map_slots`, φ times s)."""
    from pige_sym.codegen.map_slots import MOTION_COMPONENTS, map_slots

    model = kin.model
    workpiece = {a.name for a in model.structure.workpiece_axes}
    columns, signs, names = [], [], []
    for i, axis in enumerate(model.rotary_axes):
        slots = map_slots(axis)
        columns.append(", ".join(str(6 * i + MOTION_COMPONENTS.index(component)) for _, component, _ in slots))
        signs.append(", ".join("-1.0" if kind in ("positioning", "reversal") and axis in workpiece else "1.0"
                               for _, _, kind in slots))
        names.append(f"{axis}: " + ", ".join(name for name, _, _ in slots))
    k = len(model.rotary_axes)
    return f"""/* Error maps of the rotary axes (CONVENTIONS §10): per axis {MAP_SLOTS} slots, the six motions of its
   carried body in the order of CONVENTIONS' table, then the reversal map of phi (phi+ - phi-):
   {"; ".join(names)} [um, urad]. */
#define {prefix}_MAP_SLOTS {MAP_SLOTS}
/* index in motion[] of each slot */
static const int {prefix}_map_column[{k}][{MAP_SLOTS}] = {_initializer(columns)};
/* phi and its reversal turn the body about the axis by s * phi: s = -1 on the workpiece side (CONVENTIONS §3) */
static const double {prefix}_map_sign[{k}][{MAP_SLOTS}] = {_initializer(signs)};

/* Hat-function weights of theta [deg] on the nodes start + i * step, i < nodes: the map's value at theta is
   (1 - *w1) * v[*i0] + *w1 * v[*i1].  A full-turn grid (full_turn != 0, nodes * step = 360) wraps from its last
   node to its first; any other grid holds its end values outside.  0, or -1 (no map) when nodes < 1 or the step
   is not positive. */
{prefix}_API int {prefix}_map_weights(double start_deg, double step_deg, int nodes, int full_turn, double theta_deg,
                                   int *i0, int *i1, double *w1)
{{
    double u, k;
    *i0 = 0;
    *i1 = 0;
    *w1 = 0.0;
    if (nodes < 1 || !(step_deg > 0.0)) return -1;
    if (nodes == 1) return 0;
    if (full_turn) {{
        u = fmod(theta_deg - start_deg, 360.0);
        if (u < 0.0) u += 360.0;
        u /= step_deg;
        k = floor(u);
        if (k >= nodes) k = nodes - 1;  /* rounding at the wrap */
        *i0 = (int)k;
        *i1 = (*i0 + 1) % nodes;
        *w1 = u - k;
        return 0;
    }}
    u = (theta_deg - start_deg) / step_deg;
    if (u <= 0.0) return 0;
    if (u >= nodes - 1) {{
        *i0 = *i1 = nodes - 1;
        return 0;
    }}
    k = floor(u);
    *i0 = (int)k;
    *i1 = *i0 + 1;
    *w1 = u - k;
    return 0;
}}

/* Add to motion[] the error motions of rotary axis i's carried body from its map values at this pose: slot[0..5]
   the six motions [um, urad], slot[6] the reversal [urad], of which half acts with the direction of approach
   approach_theta (+1: theta increasing, -1: decreasing, 0: the mean). */
{prefix}_API void {prefix}_map_add(int i, const double slot[{prefix}_MAP_SLOTS], double approach_theta, double motion[])
{{
    int j;
    for (j = 0; j < {prefix}_MAP_SLOTS - 1; j++) motion[{prefix}_map_column[i][j]] += {prefix}_map_sign[i][j] * slot[j];
    j = {prefix}_MAP_SLOTS - 1;
    motion[{prefix}_map_column[i][j]] += {prefix}_map_sign[i][j] * 0.5 * approach_theta * slot[j];
}}"""


_NEWTON = """/* Solve m d = r (Cramer: d = adj(m) r / det); 0, or -1 when m is singular. */
{P}_API int {P}_solve3(double m[3][3], const double r[3], double d[3])
{{
    const double a00 = m[1][1] * m[2][2] - m[1][2] * m[2][1], a01 = m[0][2] * m[2][1] - m[0][1] * m[2][2];
    const double a02 = m[0][1] * m[1][2] - m[0][2] * m[1][1], a10 = m[1][2] * m[2][0] - m[1][0] * m[2][2];
    const double a11 = m[0][0] * m[2][2] - m[0][2] * m[2][0], a12 = m[0][2] * m[1][0] - m[0][0] * m[1][2];
    const double a20 = m[1][0] * m[2][1] - m[1][1] * m[2][0], a21 = m[0][1] * m[2][0] - m[0][0] * m[2][1];
    const double a22 = m[0][0] * m[1][1] - m[0][1] * m[1][0];
    const double det = m[0][0] * a00 + m[0][1] * a10 + m[0][2] * a20;
    if (!(fabs(det) > 1e-12)) return -1;
    d[0] = (a00 * r[0] + a01 * r[1] + a02 * r[2]) / det;
    d[1] = (a10 * r[0] + a11 * r[1] + a12 * r[2]) / det;
    d[2] = (a20 * r[0] + a21 * r[1] + a22 * r[2]) / det;
    return 0;
}}

/* joints -> world: nominal closed form, then Newton steps with {P}_jacobian until
   |inverse(world) - joints| <= {P}_NEWTON_TOL_MM or max_steps. Returns the steps taken, -1 if singular;
   the final residual [mm] goes to *residual_mm when it is not NULL. */
{P}_API int {P}_forward_steps(const {P}_params *p, const double joints[3], const double angles_cmd_deg[],
                             int max_steps, double world[3], double *residual_mm)
{{
    double m[3][3], r[3], d[3], norm = 0.0;
    int k, j;
    {P}_forward_nominal(p, joints, angles_cmd_deg, world);
    {P}_jacobian(p, angles_cmd_deg, m);
    for (k = 0; ; k++) {{
        {P}_inverse(p, world, angles_cmd_deg, r);
        norm = 0.0;
        for (j = 0; j < 3; j++) {{
            r[j] -= joints[j];
            norm = fmax(norm, fabs(r[j]));
        }}
        if (norm <= {P}_NEWTON_TOL_MM || k >= max_steps) break;
        if ({P}_solve3(m, r, d)) return -1;
        for (j = 0; j < 3; j++) world[j] -= d[j];
    }}
    if (residual_mm) *residual_mm = norm;
    return k;
}}

/* joints -> world (LinuxCNC kinematicsForward): 0, or -1 when the Jacobian is singular. */
{P}_API int {P}_forward(const {P}_params *p, const double joints[3], const double angles_cmd_deg[], double world[3])
{{
    return {P}_forward_steps(p, joints, angles_cmd_deg, {P}_NEWTON_MAX_STEPS, world, 0) < 0 ? -1 : 0;
}}"""


def header_lines(structure: MachineStructure, model: SymbolicModel, regenerate: str, digest: str) -> list[str]:
    """The header every generated C file carries (machine, order and units, SymPy version, input hash)."""
    params = [f"   {i:2d}  {p:<8s} [{model.units[p]}]" + ("  (zero-position error)" if i >= model.n_location else "")
              for i, p in enumerate(model.parameters)]
    return [f"Generated by pige_sym from the machine structure code {structure.canonical}",
            f"DO NOT EDIT - regenerate with: {regenerate}",
            f"machine code : {structure.canonical}",
            f"rotary axes  : {', '.join(model.rotary_axes)} (order of angles, pivots and senses)",
            "units        : lengths mm, angles deg (commanded), errors um / urad",
            "parameters (order of errors[] and units):", *params,
            f"sympy version: {sp.__version__}",
            f"input hash   : {digest}"]


def render_model_c(code: str | MachineStructure, prefix: str, *, include_math: bool = True,
                   regenerate: str | None = None, header: bool = True) -> str:
    """C99 source of the kinematics model (module docstring), every name prefixed with ``prefix``.

    Parameters
    ----------
    code : str or MachineStructure
    prefix : str
        C identifier prefix of every function, type and macro (e.g. ``"pige_xyzac_trt"``).
    include_math : bool
        Include ``<math.h>`` (off where the including file provides ``sin``/``cos``/``fabs``/``fmax``,
        e.g. ``rtapi_math.h`` in a LinuxCNC component).
    regenerate : str, optional
        The command that regenerates the file, for the header.
    header : bool
        Start with the header comment (machine, parameter order and units, SymPy version, input hash);
        off where the including file carries it.

    Returns
    -------
    str
        A header-only C99 model, guarded by ``<PREFIX>_MODEL_H``.

    Raises
    ------
    InputError
        ``prefix`` is not a C identifier.
    UnsupportedMachineError
        :func:`check_supported`.
    """
    if not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]{0,63}", prefix):
        raise InputError(f"C prefix {prefix!r}: use a C identifier (letters, digits, '_'; not starting with a digit)")
    kin = kinematics_expressions(code)
    structure = kin.model.structure
    guard = f"{prefix.upper()}_MODEL_H"
    command = regenerate or f'pige gen --target linuxcnc "{structure.canonical}"'
    head = "\n".join(["/*", *[f" * {ln}" for ln in header_lines(structure, kin.model, command,
                                                                generator_hash(structure))], " */"])
    parts = [head] if header else []
    parts += [f"#ifndef {guard}\n#define {guard}" + ("\n\n#include <math.h>" if include_math else ""),
             _declarations(kin, prefix), _maps(kin, prefix), _inverse(kin, prefix), _jacobian(kin, prefix),
             _forward_nominal(kin, prefix), _NEWTON.format(P=prefix), f"#endif /* {guard} */"]
    return "\n\n".join(parts) + "\n"
