"""SINUMERIK 840D sl: the positioning map of a rotary axis as leadscrew error compensation (``$AA_ENC_COMP``).

What the pages read settle (Function Manual Extended Functions, K3 Compensations, 03/2013, 6FC5397-1BP40-3BA1):

- **Format** (pp. 240, 242): per machine axis AXi and measuring system e, ``$AA_ENC_COMP[e,N,AXi]`` the value of
  interpolation point N, ``$AA_ENC_COMP_STEP[e,AXi]`` their distance, ``$AA_ENC_COMP_MIN[e,AXi]`` the position of
  point 0, ``$AA_ENC_COMP_MAX[e,AXi]`` that of the last point, ``$AA_ENC_COMP_IS_MODULO[e,AXi]``; the example is
  a program ``%_N_AX_EEC_INI`` … ``CHANDATA(1)`` … ``M17``.  MD38000 ``$MA_MM_ENC_COMP_MAX_POINTS[e,AXi]``
  reserves the points (p. 239); the tables load only while MD32700 ``$MA_ENC_COMP_ENABLE[e]`` is 0, and the
  compensation acts with it 1 once the axis is referenced (pp. 237, 239).
- **Sign** (p. 238): the compensation value modifies the axis' position actual value, and "a positive
  compensation value causes the corresponding machine axis to move in the negative direction".  So the value is
  the axis' error e (the axis stands at θ_cmd + e: :mod:`.positioning`), in the axis' own unit (degrees for a
  rotary axis: the position it modifies; 808D Function Manual 01/2017, p. 109, spindle table 0° to 360°).
- **Interpolation** (p. 237): linear between equidistant points; below point 0 its value holds, above the last
  point the last value (p. 240), except with the modulo function: the table repeats, the value at MAX followed
  by the value at MIN, so a full turn is written MIN 0°, MAX 360° with both values entered (808D p. 109; K3
  p. 249 for the sag tables: "these two values should be identical").

**E once, in the offset angle.** The table carries the map φ alone (its mean left out, CONVENTIONS §10); a
zero-position error E the file gives the axis is entered by the swivel data record's offset angle
(:mod:`..siemens`: −σE), not by the table too.  Both act on the same machine axis position: the LEC modifies the
axis' actual value so that it stands where commanded (p. 238), and TRAORI turns the chain by "the axis position minus
the offset angle" (W1, "Rotary axis offset"), so an E in both would be corrected twice.  The offset angle is the
documented place of an axis' zero ("the initial state of the associated rotary axis is the position specified by the
parameter"), while the LEC table "should be structured such that the compensation value at the reference point is
zero … this prevents position jumps occurring when the LEC is activated (after reference point approach)" (K3
p. 238; 808D p. 106): a constant E in the table would be such a jump.  So E stays in the offset angle, which the
swivel data record alone already enters, and the table adds the shape.  (Its value at the reference point is φ
there, small but not zero: pige does not know the reference point; subtracting that value [deg] from every table
value and from the offset angle keeps what the two enter together.)

One table serves both directions of motion: a map per direction enters its mean, and the reversal φ⁺ − φ⁻ is
named as not entered (the direction-dependent tables of p. 249, ``$AN_CEC_DIRECTION``, are sag compensation
tables; the pages read do not state the sign of their values).  The machine axis name AXi is the NC's
(MD10000 ``$MN_AXCONF_MACHAX_NAME_TAB``): given with ``--machine-axis C=<name>``, never assumed; one name per
machine axis (two rotary axes given one name would write one table mixing both).

**Limits of the format**, checked before anything is weighed (:func:`check_format`): the points are equidistant
(one ``$AA_ENC_COMP_STEP``), the point index N runs from 0 to MD38000 − 1 (K3 09/2009, 6FC5397-1BP20-0BA0, p. 361:
"0 ≤ N ≤ MD38000 − 1"; the number printed as required), and "the size of the compensation value is not limited"
(p. 361; 808D Function Manual 01/2017 p. 106: "not monitored … small compensation values must be selected"), so
every value is held to ``--max-change`` (:mod:`..entry_checks`).  No fixed upper bound of the points is checked:
the pages read bound N by the machine's own MD38000 (03/2013 p. 240), configured per axis (its change reformats the
static user memory, p. 237; 8 bytes a value, 09/2009 p. 364), which pige cannot know and prints as required; the
largest value MD38000 accepts is stated in the Detailed Machine Data Description, not read here (the 808D's 200
points, 808D p. 106, are that control's).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from pige_sym.compensation.controllers.entry_checks import check_entries
from pige_sym.compensation.controllers.tables.positioning import PositioningMap, entered_map_values, positioning_maps
from pige_sym.compensation.parameters import CompensationParameters
from pige_sym.errors import InputError

SOURCE = "SINUMERIK K3 Compensations 6FC5397-1BP40-3BA1 pp. 237-242; 808D Function Manual 01/2017 p. 109"
#: Decimals of a compensation value [deg]: 1e-9 deg.
VALUE_DECIMALS = 9
#: The entry that carries a mapped axis' zero-position error E instead of its table (module docstring).
ZERO_ENTERED_BY = "the swivel data record's offset angle ($TC_CARR64/65)"


def lec_table(pm: PositioningMap, values: bool = True) -> tuple[np.ndarray, np.ndarray, bool]:
    """(positions [deg], values [deg], modulo) of one axis' table: a full turn 0…360° with the modulo function, a
    tilt axis its grid (module docstring); the values hold the map without E (the offset angle enters E, module
    docstring); without ``values`` the values are not computed (an empty array).

    Raises
    ------
    InputError
        The grid is not equidistant.
    """
    step = pm.uniform_step_deg()
    if step is None:
        raise InputError(f"{pm.axis}: the map's grid angles are not equidistant; $AA_ENC_COMP takes one step "
                         "($AA_ENC_COMP_STEP)")
    if pm.full_turn:
        nodes = pm.nodes_cmd((0.0, 360.0))
        first = float(nodes[np.searchsorted(nodes, -1e-9)])
        positions = first + step * np.arange(int(round(360.0 / step)) + 1)
    else:
        positions = pm.nodes_cmd()
    values_deg = pm.commanded_error_deg(positions, 0, with_zero=False) if values else np.zeros(0)
    return positions, values_deg, pm.full_turn


def check_format(params: CompensationParameters, machine_axes: dict[str, str] | None) -> None:
    """The machine axis names (rotary axes of the machine, one name each) and every map's grid (equidistant),
    before any value is weighed (module docstring).

    Raises
    ------
    InputError
    """
    from pige_sym.kernels import load_kernels

    axes = tuple(load_kernels(params.machine).ROTARY_AXES)
    named: dict[str, str] = {}
    for axis, name in (machine_axes or {}).items():
        if axis not in axes:
            raise InputError(f"--machine-axis {axis}={name}: {axis} is not a rotary axis of {params.machine} (axes: "
                             f"{', '.join(axes)})")
        if name.upper() in named:
            raise InputError(f"--machine-axis {named[name.upper()]}={name} and {axis}={name}: one machine axis name "
                             "for two rotary axes would write one $AA_ENC_COMP table mixing both; give each axis its "
                             "own name (MD10000 $MN_AXCONF_MACHAX_NAME_TAB)")
        named[name.upper()] = axis
    for pm in positioning_maps(params).values():
        lec_table(pm, values=False)


@dataclass(frozen=True)
class LecTable:
    """One machine axis' ``$AA_ENC_COMP`` table as printed (module docstring).

    Attributes
    ----------
    pm : PositioningMap
    name : str
        The NC's machine axis name (``--machine-axis``).
    positions, values : (n,) [deg]
        The interpolation points (commanded) and the values there (the map without E, :func:`lec_table`).
    modulo : bool
    """

    pm: PositioningMap
    name: str
    positions: np.ndarray
    values: np.ndarray
    modulo: bool

    @property
    def axis(self) -> str:
        return self.pm.axis

    def printed(self, theta_cmd_deg: np.ndarray, _direction: int) -> np.ndarray:
        """The printed value [deg] (rounded to :data:`VALUE_DECIMALS`) at commanded grid angles, for both directions."""
        at = np.asarray(theta_cmd_deg, dtype=float)
        if self.modulo:
            at = np.mod(at - self.positions[0], 360.0) + self.positions[0]
        idx = np.argmin(np.abs(self.positions[None, :] - at[:, None]), axis=1)
        return np.asarray(np.round(self.values, VALUE_DECIMALS)[idx], dtype=float)


def lec_tables(params: CompensationParameters, machine_axes: dict[str, str] | None,
               limits: Any = None) -> list[LecTable]:
    """The table of every axis whose map holds φ, every value held to ``limits``
    (:class:`~pige_sym.compensation.controllers.entry_checks.ChangeLimits`); none when an axis' machine name is not
    known (no table is printed).

    Raises
    ------
    InputError
        A machine axis name or a grid the format refuses (:func:`check_format`), or a value beyond ``limits``.
    """
    check_format(params, machine_axes)
    maps = positioning_maps(params)
    if not maps or any(not (machine_axes or {}).get(a) for a in maps):
        return []
    out = []
    for axis, pm in maps.items():
        name = (machine_axes or {})[axis]
        positions, values, modulo = lec_table(pm)
        check_entries(f"SINUMERIK $AA_ENC_COMP of {name}", "compensation value", values, "deg", limits, positions,
                      f"commanded {axis}")
        out.append(LecTable(pm, name, positions, values, modulo))
    return out


def render_lines(params: CompensationParameters, machine_axes: dict[str, str] | None,
                 limits: Any = None, tables: list[LecTable] | None = None) -> list[str]:
    """The ``;`` notes and the ``$AA_ENC_COMP`` program of every positioning map (empty without maps); every value
    held to ``limits`` (:class:`~pige_sym.compensation.controllers.entry_checks.ChangeLimits`).  ``tables``: the
    tables as built (:func:`lec_tables`; None: built here)."""
    check_format(params, machine_axes)
    maps = positioning_maps(params)
    if not maps:
        return []
    out = [f"; positioning maps (CONVENTIONS §10) as leadscrew error compensation $AA_ENC_COMP ({SOURCE}): the "
           "value [deg] is the axis' error in its commanded sense; a positive value moves the axis negative (p. 238)"]
    missing = [a for a in maps if not (machine_axes or {}).get(a)]
    if missing:
        return out + [f"; not printed: the machine axis name of {', '.join(missing)} (MD10000 "
                      f"$MN_AXCONF_MACHAX_NAME_TAB) is not known: give --machine-axis {missing[0]}=<name>"]
    body = ["%_N_AX_EEC_INI", "CHANDATA(1)"]
    for t in (tables if tables is not None else lec_tables(params, machine_axes, limits)):
        axis, name, positions, pm = t.axis, t.name, t.positions, t.pm
        out += [f"; {n}" for n in pm.notes(ZERO_ENTERED_BY)]
        if pm.per_direction:
            out.append(f"; {axis}: one table for both directions: the mean of {axis}'s positioning maps per direction "
                       "is entered, the reversal is NOT (module docstring)")
        span = (" with the modulo function (0 and 360 hold the same value)" if t.modulo
                else "; outside, the end values hold (p. 240)")
        out.append(f"; {axis} = machine axis {name}: {positions.size} points, commanded {positions[0]:g}.."
                   f"{positions[-1]:g} deg{span}"
                   + f"; requires MD38000 $MA_MM_ENC_COMP_MAX_POINTS[0,{name}] >= {positions.size}, the table loaded "
                   f"with MD32700 $MA_ENC_COMP_ENABLE[0] = 0, then 1")
        body += [f"$AA_ENC_COMP[0,{k},{name}]={v + 0.0:.{VALUE_DECIMALS}f}" for k, v in enumerate(t.values)]
        body += [f"$AA_ENC_COMP_STEP[0,{name}]={positions[1] - positions[0]:.10g}",
                 f"$AA_ENC_COMP_MIN[0,{name}]={positions[0]:.10g}", f"$AA_ENC_COMP_MAX[0,{name}]={positions[-1]:.10g}",
                 f"$AA_ENC_COMP_IS_MODULO[0,{name}]={int(t.modulo)}"]
    return out + [*body, "M17"]


def map_motions(params: CompensationParameters) -> list[str]:
    """The maps the table carries whole: φ of an axis mapped for both directions at once."""
    maps = params.error_maps
    if maps is None:
        return []
    return [f"{ax}:{phi}" for ax, pm in positioning_maps(params).items() if not pm.per_direction
            for phi in maps.axes[ax].values if phi[1] == phi[2]]


def entered_values(params: CompensationParameters, tables: list[LecTable]) -> dict[str, float]:
    """What the printed tables ``tables`` (:func:`lec_tables`) enter (:func:`~.positioning.entered_map_values`): each
    axis' one table for both directions (a map per direction enters its mean as φ⁺ and φ⁻), as printed; the table
    holds φ alone, E is the offset angle's (module docstring); nothing without tables."""
    out: dict[str, float] = {}
    for t in tables:
        out |= entered_map_values(params, t.pm, t.printed, zero_elsewhere=True)  # the offset angle enters E
    return out
