"""Symbolic R-test error model of any ISO 10791 machine structure (SymPy).

This is the only place (with :mod:`pige_sym.codegen.emit`) that imports SymPy.  It builds,
for a parsed machine code, the ball-minus-nest deviation of CONVENTIONS §4 to first
order in the rotary-axis errors, its closed-form Jacobian, and the nominal
kinematics (rotations, RTCP linear commands, tool direction and its inverse).

Model
-----
Every angle enters only through ``c_k = cos θ_k`` and ``s_k = sin θ_k``, so all
expressions are polynomials in ``(c_k, s_k)``, the geometry and the errors.

* Rotary axis k (nominal direction u, nominal pivot p, ISO 841 sense σ = +1 tool
  side, −1 workpiece side) moves the body it carries as
  ``x ↦ q + R(u', σ(θ + e))(x − q)`` with ``q = p + δ``, ``u' = u + ε × u``
  (CONVENTIONS §3), δ the position errors [µm → mm], ε the orientation errors and
  e the zero-position error [µrad → rad].  R is Rodrigues' formula; ``|u'| = 1``
  to second order, and ``cos(θ+e), sin(θ+e)`` are expanded to first order in e.
* Linear axis with command L moves what it carries by ``+L`` (tool side) or
  ``−L`` (workpiece side, primed), so the tool moves by +L relative to the work.
* Workpiece side: a point x fixed in W is at ``F_m(…F_1(x))`` in M (axes from the
  workpiece outward).  Tool side: a point y fixed in the spindle frame is at
  ``G_1(…G_n(y))`` (axes from the bed towards the tool).
* The nest sits at ``ball_mm`` in W.  The ball sits at ``ball_mm`` in the spindle
  frame when there is no tool-side rotary axis, else at ``pivot_last + tool_mm``
  (``pivot_last`` of the tool-side rotary axis nearest the tool).
* RTCP: the linear commands L(θ) solve ``ball − nest = 0`` for the nominal
  kinematics (the first linear axis along each of X, Y, Z is commanded; any
  further parallel axis, U V W or a suffixed duplicate, stays at 0).
* Deviation (machine frame, µm): ``d(θ) = r(θ) − R_w(θ) r(0)`` with
  ``r = ball − nest`` at the commanded L and R_w the nominal rotation of W into M
  (zeroing in the nest frame).  ``d = J(θ) · params`` exactly to first order.

The deviation is therefore ``basis(θ) @ G(geometry) @ params`` where ``basis``
holds the trigonometric monomials and G is a small coefficient tensor; the
emitter renders exactly that.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import sympy as sp

from pige_sym.codegen.machine_code import Axis, MachineStructure, parse_machine_code
from pige_sym.errors import UnsupportedMachineError

# Location errors per rotary-axis letter: (position error names, orientation error names),
# each listed with the machine-axis index it refers to (CONVENTIONS §3 table order).
_LOCATION = {
    "A": (("Y", 1), ("Z", 2), ("B", 1), ("C", 2)),
    "B": (("X", 0), ("Z", 2), ("A", 0), ("C", 2)),
    "C": (("X", 0), ("Y", 1), ("A", 0), ("B", 1)),
}


_ROTARY_FOR_INDEX = "ABC"


UM_TO_MM = sp.Rational(1, 1000)


#: Error-motion components of the body carried by a rotary axis, in the carrier frame:
#: translations [µm] and small rotations about the nominal pivot [µrad].
MOTION_COMPONENTS = ("dx", "dy", "dz", "rx", "ry", "rz")


URAD_TO_RAD = sp.Rational(1, 10**6)


MM_TO_UM = 1000


def location_parameter_names(axis_name: str) -> list[str]:
    """The four ISO 230-7 location-error names of a rotary axis, in CONVENTIONS order.

    Positions first (µm), then orientations (µrad), e.g. ``EX0C, EY0C, EA0C, EB0C``.
    """
    return [f"E{d}0{axis_name}" for d, _ in _LOCATION[axis_name[0]]]


def zero_parameter_name(axis_name: str) -> str:
    """Name of the zero-position error of a rotary axis, e.g. ``EC0C``."""
    return f"E{axis_name[0]}0{axis_name}"


def _cross_matrix(v: sp.Matrix) -> sp.Matrix:
    return sp.Matrix([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])


def _unit(index: int) -> sp.Matrix:
    e = sp.zeros(3, 1)
    e[index] = 1
    return e


def reduce_trig(expr: sp.Expr, pairs: list[tuple[sp.Symbol, sp.Symbol]]) -> sp.Expr:
    """Reduce a polynomial in ``(c_k, s_k)`` with ``s_k**2 -> 1 - c_k**2``."""
    expr = sp.expand(expr)
    for c, s in pairs:
        if not expr.has(s):
            continue
        reduced = []  # term by term (an expanded sum): cheaper than a Poly in s, the same polynomial
        for term in sp.Add.make_args(expr):
            coeff, deg = term.as_coeff_exponent(s)
            reduced.append(coeff * s ** (deg % 2) * (1 - c**2) ** (deg // 2) if deg >= 2 else term)
        expr = sp.expand(sp.Add(*reduced))
    return expr


@dataclass
class RotaryAxisSymbols:
    """SymPy symbols belonging to one rotary axis."""

    axis: Axis
    cos: sp.Symbol
    sin: sp.Symbol
    pivot: sp.Matrix
    location: list[sp.Symbol]
    zero: sp.Symbol
    motion: list[sp.Symbol]


@dataclass
class SymbolicModel:
    """First-order R-test model of one machine, in SymPy form.

    Attributes
    ----------
    structure : MachineStructure
    rotary_axes : tuple of str
        Rotary-axis names in column order.
    parameters : tuple of str
        All error parameters: the location errors of every rotary axis (column
        order), then the zero-position errors.
    n_location : int
        Number of location-error parameters (the first entries of ``parameters``).
    jacobian : sympy.Matrix, shape (3, P)
        ∂d/∂params [µm per µm or µrad], polynomial in the cos/sin symbols and geometry.
    workpiece_rotation, tool_rotation : sympy.Matrix, shape (3, 3)
        Nominal rotations of W and of the spindle frame into M.
    linear_commands : sympy.Matrix, shape (3, 1)
        Commanded X, Y, Z [mm] (RTCP, nominal kinematics), equal to ``ball_mm`` at
        the reference pose.
    tool_direction : sympy.Matrix, shape (3, 1)
        Spindle direction expressed in the workpiece frame W.
    reference_jacobian : sympy.Matrix, shape (3, P)
        Jacobian of the un-zeroed ball-minus-nest offset at the reference pose,
        ``J_raw(0)``; the un-zeroed Jacobian at any pose is
        ``jacobian + workpiece_rotation @ reference_jacobian``.
    orientation_jacobian : sympy.Matrix, shape (3, P)
        Small rotation ω [µrad per µm or µrad] of the spindle frame relative to the
        workpiece frame, expressed in W: ``R_rel_actual = (I + [ω]×) R_rel_nominal``
        with ``R_rel = workpiece_rotationᵀ · tool_rotation``.  Not zeroed (nothing
        measures orientation at the reference pose).
    motion_jacobian : sympy.Matrix, shape (3, 6k)
        Un-zeroed ball-minus-nest offset [µm] per unit error motion of the body carried
        by each rotary axis (column order; per axis ``dx, dy, dz`` [µm] translations and
        ``rx, ry, rz`` [µrad] small rotations about the nominal pivot, in the carrier's
        frame, applied after the axis' own motion).  Angle-dependent error motions
        (angular positioning, tilt/wobble, radial runout, backlash) are these columns
        times functions of the angles.
    motion_orientation_jacobian : sympy.Matrix, shape (3, 6k)
        The tool-orientation error ω [µrad] (as ``orientation_jacobian``) per unit error motion, same columns.
    """

    structure: MachineStructure
    rotary: list[RotaryAxisSymbols]
    ball: sp.Matrix
    tool: sp.Matrix
    parameters: tuple[str, ...]
    n_location: int
    jacobian: sp.Matrix
    workpiece_rotation: sp.Matrix
    tool_rotation: sp.Matrix
    linear_commands: sp.Matrix
    tool_direction: sp.Matrix
    reference_jacobian: sp.Matrix
    orientation_jacobian: sp.Matrix
    motion_jacobian: sp.Matrix
    motion_orientation_jacobian: sp.Matrix
    motion_parameters: tuple[str, ...]
    spindle_direction: int
    has_tool_rotary: bool
    units: dict[str, str] = field(default_factory=dict)

    @property
    def rotary_axes(self) -> tuple[str, ...]:
        return tuple(r.axis.name for r in self.rotary)

    @property
    def trig_pairs(self) -> list[tuple[sp.Symbol, sp.Symbol]]:
        return [(r.cos, r.sin) for r in self.rotary]

    @property
    def geometry_symbols(self) -> list[sp.Symbol]:
        syms: list[sp.Symbol] = list(self.ball)
        for r in self.rotary:
            syms.extend(r.pivot)
        syms.extend(self.tool)
        return syms


def _unit_if(sym: sp.Symbol, active: sp.Symbol | None) -> sp.Integer:
    """1 if ``sym`` is the active error symbol, else 0: its derivative (one derivative at a time)."""
    return sp.Integer(1 if sym == active else 0)


def _axis_symbols(ax: Axis) -> RotaryAxisSymbols:
    nm = ax.name
    return RotaryAxisSymbols(
        axis=ax,
        cos=sp.Symbol(f"c_{nm}", real=True),
        sin=sp.Symbol(f"s_{nm}", real=True),
        pivot=sp.Matrix(sp.symbols(f"p{nm}_x p{nm}_y p{nm}_z", real=True)),
        location=[sp.Symbol(n, real=True) for n in location_parameter_names(nm)],
        zero=sp.Symbol(zero_parameter_name(nm), real=True),
        motion=[sp.Symbol(f"{nm}_{c}", real=True) for c in MOTION_COMPONENTS],
    )


def _commanded_axes(structure: MachineStructure) -> dict[int, Axis]:
    """The commanded linear axis per direction: the first along each of X, Y, Z in chain order."""
    commanded: dict[int, Axis] = {}
    for ax in structure.linear_axes:
        commanded.setdefault(ax.direction, ax)
    missing = [d for d in range(3) if d not in commanded]
    if missing:
        raise UnsupportedMachineError(
            f"machine {structure.canonical!r} has no linear axis along {', '.join('XYZ'[d] for d in missing)}: "
            "RTCP needs one linear axis along each of X, Y and Z"
        )
    return commanded


class _Chain:
    """The kinematic chain of a machine with symbolic axes, perturbable by one error symbol at a time."""

    def __init__(self, structure: MachineStructure) -> None:
        if not structure.rotary_axes:
            raise UnsupportedMachineError(
                f"machine {structure.canonical!r} has no rotary axis: there are no rotary-axis PIGEs to model"
            )
        self.structure = structure
        self.rotary = {ax.name: _axis_symbols(ax) for ax in structure.rotary_axes}
        self.ordered = [self.rotary[a.name] for a in structure.rotary_axes]
        self.pairs = [(r.cos, r.sin) for r in self.ordered]
        self.commanded = _commanded_axes(structure)
        self.lin_syms = {d: sp.Symbol(f"L_{'XYZ'[d]}", real=True) for d in range(3)}
        self.lin_vec = sp.Matrix([self.lin_syms[d] for d in range(3)])
        self.ball = sp.Matrix(sp.symbols("ball_x ball_y ball_z", real=True))
        self.tool = sp.Matrix(sp.symbols("tool_x tool_y tool_z", real=True))

    def reduce(self, m: sp.Matrix) -> sp.Matrix:
        """Reduce every entry with cos² + sin² = 1."""
        return m.applyfunc(lambda e: reduce_trig(e, self.pairs))

    def _perturbation(self, r: RotaryAxisSymbols, active: sp.Symbol) -> tuple[sp.Matrix, sp.Matrix, sp.Expr]:
        """Per unit of the active symbol: offset of the axis line [mm], its tilt [rad] and the zero error [rad]."""
        names = _LOCATION[r.axis.letter]
        delta = sp.zeros(3, 1)
        eps = sp.zeros(3, 1)
        delta[names[0][1]] = _unit_if(r.location[0], active) * UM_TO_MM
        delta[names[1][1]] = _unit_if(r.location[1], active) * UM_TO_MM
        eps[names[2][1]] = _unit_if(r.location[2], active) * URAD_TO_RAD
        eps[names[3][1]] = _unit_if(r.location[3], active) * URAD_TO_RAD
        return delta, eps, _unit_if(r.zero, active) * URAD_TO_RAD

    def rotary_motion(self, r: RotaryAxisSymbols, x: sp.Matrix, dx: sp.Matrix,
                      active: sp.Symbol | None) -> tuple[sp.Matrix, sp.Matrix, sp.Matrix, sp.Matrix]:
        """Rotary axis ``r`` moving the point ``x``: (moved point, rotation, and their derivatives).

        ``dx`` is the derivative of ``x`` with respect to the active error symbol at 0; the derivatives returned are
        the same, at every symbol 0 (first order: the chain is differentiated pose-wise, forward, instead of building
        it with the symbol and differentiating the whole expression).
        """
        u = _unit(r.axis.direction)
        sigma = r.axis.sign
        c, s = r.cos, r.sin
        k_mat = _cross_matrix(u)
        rot = sp.eye(3) + sigma * s * k_mat + (1 - c) * k_mat * k_mat
        moved = r.pivot + rot * (x - r.pivot)
        if active is None or not (active in r.location or active == r.zero or active in r.motion):
            return moved, rot, rot * dx, sp.zeros(3, 3)
        # the axis line moved by delta, tilted by eps (u' = u + eps x u), the angle by e, all per unit of the symbol
        delta, eps, e = self._perturbation(r, active)
        dk = _cross_matrix(eps.cross(u))
        drot = sigma * e * c * k_mat + sigma * s * dk + e * s * k_mat * k_mat + (1 - c) * (dk * k_mat + k_mat * dk)
        dmoved = delta + drot * (x - r.pivot) + rot * (dx - delta)
        # error motion of the carried body, applied after the axis' own motion
        d = sp.Matrix([_unit_if(m, active) for m in r.motion[:3]]) * UM_TO_MM
        w = sp.Matrix([_unit_if(m, active) for m in r.motion[3:]]) * URAD_TO_RAD
        return moved, rot, dmoved + d + w.cross(moved - r.pivot), drot + _cross_matrix(w) * rot

    def linear_motion(self, ax: Axis, x: sp.Matrix) -> sp.Matrix:
        if self.commanded[ax.direction] is not ax:
            return x  # parallel secondary axis held at its reference position
        return x + ax.sign * self.lin_syms[ax.direction] * _unit(ax.direction)

    def _side(self, axes: Sequence[Axis], x: sp.Matrix, active: sp.Symbol | None) -> tuple[sp.Matrix, ...]:
        """(point, rotation, their derivatives) after moving ``x`` through ``axes`` in that order."""
        dx, rot_all, drot_all = sp.zeros(3, 1), sp.eye(3), sp.zeros(3, 3)
        for ax in axes:
            if ax.kind == "rotary":
                x, rot, dx, drot = self.rotary_motion(self.rotary[ax.name], x, dx, active)
                rot_all, drot_all = rot * rot_all, drot * rot_all + rot * drot_all
            else:
                x = self.linear_motion(ax, x)
        return x, rot_all, dx, drot_all

    def evaluate(self, active: sp.Symbol | None) -> tuple[sp.Matrix, ...]:
        """(ball point, nest point, workpiece rotation, tool rotation) in the machine frame, then their derivatives
        with respect to the active error symbol at 0 (zeros without one)."""
        # workpiece side: the nest point, from the workpiece outward
        nest, rot_w, dnest, drot_w = self._side(self.structure.workpiece_axes, self.ball, active)
        tool_rot = [a for a in self.structure.tool_axes if a.kind == "rotary"]
        y = (self.rotary[tool_rot[-1].name].pivot + self.tool) if tool_rot else self.ball
        # tool side: the ball point, from the tool back to the bed
        ball, rot_t, dball, drot_t = self._side(list(reversed(self.structure.tool_axes)), y, active)
        return ball, nest, rot_w, rot_t, dball, dnest, drot_w, drot_t


def _solve_rtcp(chain: _Chain, r_nom: sp.Matrix) -> sp.Matrix:
    """Linear-axis commands that keep the ball on the nest (nominal RTCP), shape (3, 1) [mm]."""
    a_mat = chain.reduce(r_nom.jacobian(chain.lin_vec))
    r0 = chain.reduce(r_nom.subs({s: 0 for s in chain.lin_vec}))
    det = reduce_trig(a_mat.det(), chain.pairs)
    if det.free_symbols or det == 0:
        raise UnsupportedMachineError(
            f"machine {chain.structure.canonical!r}: a linear axis is carried by a rotary axis in a way that makes "
            f"RTCP singular (det of the linear-axis map = {det}); this structure is not supported"
        )
    return chain.reduce(-(a_mat.adjugate() / det) * r0)


@dataclass
class _Derivatives:
    """First-order columns: deviation per PIGE, per error motion, and orientation per PIGE (raw, un-zeroed)."""

    jacobian_raw: sp.Matrix
    motion: sp.Matrix
    orientation: sp.Matrix
    motion_orientation: sp.Matrix


def _derivatives(chain: _Chain, params: list[sp.Symbol], motions: list[sp.Symbol], lin_subs: dict,
                 rel_nom: sp.Matrix) -> _Derivatives:
    """Differentiate the chain one error symbol at a time (the others are 0, so expressions stay small).

    Forward: each axis passes on its motion's derivative (:meth:`_Chain.rotary_motion`), so no expression
    is built with the symbol in it and differentiated whole (the same polynomials, reduced, in half the time).
    """
    jac_cols: list[sp.Matrix] = []
    ori_cols: list[sp.Matrix] = []
    motion_cols: list[sp.Matrix] = []
    motion_ori_cols: list[sp.Matrix] = []
    for sym in params + motions:
        _, _, rot_w, rot_t, dball, dnest, drot_w, drot_t = chain.evaluate(sym)
        col = (dball - dnest).subs(lin_subs)
        # orientation of the spindle frame relative to W: R_rel_act = (I + [ω]x) R_rel_nom
        dm = (drot_w.T * rot_t + rot_w.T * drot_t) * rel_nom.T
        ori = sp.Matrix([dm[2, 1], dm[0, 2], dm[1, 0]])
        (motion_cols if sym in motions else jac_cols).append(col)
        (motion_ori_cols if sym in motions else ori_cols).append(ori)
    return _Derivatives(
        jacobian_raw=sp.Matrix.hstack(*jac_cols) * MM_TO_UM,
        motion=chain.reduce(sp.Matrix.hstack(*motion_cols) * MM_TO_UM),
        orientation=chain.reduce(sp.Matrix.hstack(*ori_cols) * 10**6),
        motion_orientation=chain.reduce(sp.Matrix.hstack(*motion_ori_cols) * 10**6),
    )


def _units(ordered: list[RotaryAxisSymbols]) -> dict[str, str]:
    units = {s.name: "um" for r in ordered for s in r.location[:2]}
    units |= {s.name: "urad" for r in ordered for s in r.location[2:]}
    units |= {r.zero.name: "urad" for r in ordered}
    return units


def _spindle_direction(structure: MachineStructure) -> int:
    if structure.spindle is not None and structure.spindle[0] in "ABC":
        return "ABC".index(structure.spindle[0])
    return 2


def build_model(code: str | MachineStructure) -> SymbolicModel:
    """Build the symbolic first-order model of a machine.

    Parameters
    ----------
    code : str or MachineStructure
        ISO 10791 machine structure code, e.g. ``"wC'A'bXYZ(C1)t"``.

    Raises
    ------
    UnsupportedMachineError
        No rotary axis, no linear axis along one of X/Y/Z, or an RTCP that is
        singular because a linear axis is carried by a rotary axis.
    """
    structure = parse_machine_code(code) if isinstance(code, str) else code
    chain = _Chain(structure)
    ordered = chain.ordered
    param_syms = [s for r in ordered for s in r.location] + [r.zero for r in ordered]
    motion_syms = [m for r in ordered for m in r.motion]

    ball_nom, nest_nom, rot_w, rot_t = chain.evaluate(None)[:4]
    rot_w, rot_t = chain.reduce(rot_w), chain.reduce(rot_t)
    lin_solution = _solve_rtcp(chain, ball_nom - nest_nom)
    lin_subs = {chain.lin_vec[d]: lin_solution[d] for d in range(3)}
    der = _derivatives(chain, param_syms, motion_syms, lin_subs, rot_w.T * rot_t)

    at_reference = {r.cos: 1 for r in ordered} | {r.sin: 0 for r in ordered}
    jac_ref = der.jacobian_raw.subs(at_reference)
    spindle_dir = _spindle_direction(structure)
    return SymbolicModel(
        structure=structure,
        rotary=ordered,
        ball=chain.ball,
        tool=chain.tool,
        parameters=tuple(s.name for s in param_syms),
        n_location=4 * len(ordered),
        jacobian=chain.reduce(der.jacobian_raw - rot_w * jac_ref),
        workpiece_rotation=rot_w,
        tool_rotation=rot_t,
        # commanded X, Y, Z: equal to ball_mm at the reference pose
        linear_commands=chain.reduce(lin_solution - lin_solution.subs(at_reference) + chain.ball),
        tool_direction=chain.reduce(rot_w.T * rot_t * _unit(spindle_dir)),
        reference_jacobian=chain.reduce(jac_ref),
        orientation_jacobian=der.orientation,
        motion_jacobian=der.motion,
        motion_orientation_jacobian=der.motion_orientation,
        motion_parameters=tuple(m.name for m in motion_syms),
        spindle_direction=spindle_dir,
        has_tool_rotary=any(a.kind == "rotary" for a in structure.tool_axes),
        units=_units(ordered),
    )
