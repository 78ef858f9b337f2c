"""ISG kernel (Beckhoff TwinCAT CNC): the positioning map of a rotary axis as leadscrew error compensation ``kw.ssfk``.

What the public pages settle (Beckhoff Information System, TF5200 TwinCAT 3 CNC Axis compensation, and the ISG
kernel's HTML manual, read in 2026):

- **Format** (``Leadscrew error compensation (kw.ssfk.*)``, "Overview of parameters" 308687883, "Example -
  Non-equidistant bilateral SSFK" 308695435): an axis' compensation value list holds ``kw.ssfk.unit``
  (P-COMP-00017), ``interval`` (P-COMP-00018: the distance of equidistant interpolation points, 0 = each point
  given), ``kw_startpos`` (P-COMP-00019), ``kw_nr_max`` (P-COMP-00020, at most P-COMP-00059 ``max_points``,
  default 1500), ``bilateral`` (P-COMP-00021: one table per direction of motion), ``modulo`` (P-COMP-00022)
  and the table ``kw.ssfk.table[i].pos`` / ``.neg`` (P-COMP-00023/24: the values moving in the positive / negative
  direction), SGN32 integers in the list's unit, one ``name value`` per line.  The list header ``kopf.*`` is
  written by the TwinCAT System Manager when it configures the list (113371531); pige writes the body.
- **Sign** (308695435): a value is the measured position error, ``Δs_i = s_ist,i − s_soll,i`` (the actual
  position minus the programmed one), "absolute position errors" (15274025355); the CNC changes the position
  setpoint by it and takes it out of the actual values it shows (15327297547).  So a value is the axis' error e
  (:mod:`.positioning`).
- **Interpolation** (15327297547): linear between interpolation points; both tables on the same points; outside
  the table the value at its end holds.
- Activation: P-AXIS-00175 ``lr_param.ssfk`` = 1 in the axis parameters (308687883).

**Not settled, so stated by the user or refused:** the unit of a rotary axis' entries.  P-COMP-00017 offers
encoder increments or "metric (in 0.1 µm)", listed for translatory axes (TwinCAT CNC 15274009995); the ISG
kernel handles angles at 0.0001° by default (its "Measuring systems" page), but the pages read do not say that
a rotary axis' ``kw.ssfk`` entries use it.  ``--isg-unit-deg U`` states the angle of one unit of the list
(``kw.ssfk.unit = 1``); without it no table is written.

**Limits of the format**, checked before anything is weighed (:func:`check_format`): U a positive finite angle no
larger than ``--max-change``'s degrees (a coarser unit cannot hold one correction); the grid step a whole number of
units, at least one (P-COMP-00018: ``interval`` 0 means the points are given one by one, another list); at most
``max_points`` points (P-COMP-00059, default 1500); every position (``kw_startpos``, P-COMP-00019, and the last
point) and every value (P-COMP-00023/24) an SGN32 integer, −2³¹ … 2³¹ − 1.  Every value is held to ``--max-change``
(:mod:`..entry_checks`).  The modulo mode (P-COMP-00022) is not described in the
pages read: a full-turn axis' table is written over ±10 turns without it (its map repeats every 360°; an axis
whose positions wrap stays inside).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from pige_sym.compensation.controllers.entry_checks import ChangeLimits, check_entries, check_integer
from pige_sym.compensation.controllers.tables.positioning import PositioningMap, entered_map_values, positioning_maps
from pige_sym.compensation.parameters import CompensationParameters
from pige_sym.errors import InputError

SOURCE = ("Beckhoff TF5200 Axis compensation: kw.ssfk (113419147), parameters 308687883, example 308695435, "
          "interpolation 15327297547")
#: Default of P-COMP-00059 (kw.ssfk.max_points).
MAX_POINTS = 1500
TURNS = 10
#: SGN32 (P-COMP-00019, P-COMP-00023/24): the range of a position and of a value in the list's unit.
SGN32 = (-(2**31), 2**31 - 1)


def check_unit(unit_deg: float | None, limits: ChangeLimits | None = None) -> None:
    """``--isg-unit-deg``: a positive finite angle no coarser than ``--max-change`` (module docstring); None: not given.

    Raises
    ------
    InputError
    """
    if unit_deg is None:
        return
    bound = (limits or ChangeLimits()).deg
    if not (math.isfinite(unit_deg) and 0 < unit_deg <= bound):
        raise InputError(f"--isg-unit-deg {unit_deg:g}: give the angle [deg] of one unit of the axis' kw.ssfk list, a "
                         f"positive number no larger than --max-change's {bound:g} deg (read it from your axis' list, "
                         "e.g. 0.0001)")


def check_format(params: CompensationParameters, unit_deg: float | None, limits: ChangeLimits | None = None) -> None:
    """The unit and every map's list layout (module docstring) before any value is weighed; nothing without a unit."""
    check_unit(unit_deg, limits)
    if unit_deg is None:
        return
    for pm in positioning_maps(params).values():
        list_layout(pm, unit_deg)


def list_layout(pm: PositioningMap, unit_deg: float) -> tuple[np.ndarray, np.ndarray]:
    """(nodes [deg, commanded], positions [units]) of one axis' list, every field of the layout checked.

    Raises
    ------
    InputError
        A grid that is not equidistant, a step that is not a whole number of units (at least one), too many points,
        or a position beyond SGN32.
    """
    step = pm.uniform_step_deg()
    if step is None:
        raise InputError(f"{pm.axis}: the map's grid angles are not equidistant (kw.ssfk.interval takes one step)")
    units = step / unit_deg
    if abs(units - round(units)) > 1e-6 or round(units) < 1:
        raise InputError(f"{pm.axis}: the grid step {step:g} deg is not a whole number of --isg-unit-deg {unit_deg:g} "
                         "(kw.ssfk.interval, P-COMP-00018: at least 1 unit)")
    nodes = pm.nodes_cmd((-360.0 * TURNS, 360.0 * TURNS)) if pm.full_turn else pm.nodes_cmd()
    if nodes.size > MAX_POINTS:
        raise InputError(f"{pm.axis}: {nodes.size} points; kw.ssfk holds {MAX_POINTS} by default (P-COMP-00059)")
    check_integer(f"ISG kw.ssfk list of {pm.axis}", "kw_startpos (or the last position)",
                  np.round(np.array([nodes[0], nodes[-1]]) / unit_deg), *SGN32, "P-COMP-00019: SGN32",
                  f"--isg-unit-deg {unit_deg:g} puts commanded {nodes[0]:g}..{nodes[-1]:g} deg out of range: check the "
                  "unit of your axis' list")
    return nodes, np.round(nodes / unit_deg).astype(np.int64)


def ssfk_table(pm: PositioningMap, unit_deg: float, limits: ChangeLimits | None = None
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(positions, pos, neg) of one axis in list units (integers): equidistant, a full turn over ±10 turns; every
    value held to ``limits`` (``--max-change``) and SGN32.

    Raises
    ------
    InputError
        A layout :func:`list_layout` refuses, or a value beyond ``limits`` or SGN32.
    """
    nodes, positions = list_layout(pm, unit_deg)
    where = f"ISG kw.ssfk list of {pm.axis}"
    out = []
    for field, direction in (("table[i].pos", +1), ("table[i].neg", -1)):
        error = pm.commanded_error_deg(nodes, direction)
        check_entries(where, field, error, "deg", limits, nodes, f"commanded {pm.axis}")
        check_integer(where, field, np.round(error / unit_deg), *SGN32, "P-COMP-00023/24: SGN32",
                      "check --isg-unit-deg")
        out.append(np.round(error / unit_deg).astype(np.int64))
    return positions, out[0], out[1]


@dataclass(frozen=True)
class SsfkList:
    """One axis' ``kw.ssfk`` list as printed (module docstring).

    Attributes
    ----------
    pm : PositioningMap
        The map it holds.
    unit_deg : float
        The angle of one unit [deg] (``--isg-unit-deg``).
    positions, pos, neg : (n,) int
        The points and the values moving in the positive / negative direction [units] (:func:`ssfk_table`).
    """

    pm: PositioningMap
    unit_deg: float
    positions: np.ndarray
    pos: np.ndarray
    neg: np.ndarray

    @property
    def axis(self) -> str:
        return self.pm.axis

    def body(self) -> list[str]:
        """The ``kw.ssfk`` lines of the list (module docstring)."""
        positions = self.positions
        body = ["kw.ssfk.unit 1", f"kw.ssfk.interval {positions[1] - positions[0]}",
                f"kw.ssfk.kw_startpos {positions[0]}", f"kw.ssfk.kw_nr_max {positions.size}", "kw.ssfk.bilateral 1",
                "kw.ssfk.modulo 0"]
        body += [f"kw.ssfk.table[{i}].pos {v}" for i, v in enumerate(self.pos)]
        return body + [f"kw.ssfk.table[{i}].neg {v}" for i, v in enumerate(self.neg)]

    def printed(self, theta_cmd_deg: np.ndarray, direction_cmd: int) -> np.ndarray:
        """The list's value [deg] at commanded angles (its nodes) for a commanded direction (pos for +1 and 0, neg for
        −1)."""
        at = np.round(np.asarray(theta_cmd_deg, dtype=float) / self.unit_deg).astype(np.int64)
        idx = np.searchsorted(self.positions, at)
        if (idx >= self.positions.size).any() or (self.positions[np.minimum(idx, self.positions.size - 1)] != at).any():
            raise AssertionError(f"{self.axis}: a grid angle is not a node of its kw.ssfk list")  # pragma: no cover
        return np.asarray((self.neg if direction_cmd < 0 else self.pos)[idx] * self.unit_deg, dtype=float)


def ssfk_lists(params: CompensationParameters, unit_deg: float | None, limits: Any = None) -> list[SsfkList]:
    """The list of every axis whose map holds φ, every value held to ``limits`` and SGN32 (:func:`ssfk_table`); none
    without ``unit_deg`` (no list is written).

    Raises
    ------
    InputError
        A unit, a layout or a value the list cannot hold (module docstring).
    """
    check_format(params, unit_deg, limits)
    if unit_deg is None:
        return []
    return [SsfkList(pm, unit_deg, *ssfk_table(pm, unit_deg, limits)) for pm in positioning_maps(params).values()]


def render_lines(params: CompensationParameters, unit_deg: float | None, limits: Any = None,
                 lists: list[SsfkList] | None = None) -> list[str]:
    """Per axis: the notes (``#``, outside the list) and the list body; the refusal when the unit is not given.
    ``lists``: the lists as built (:func:`ssfk_lists`; None: built here).

    Raises
    ------
    InputError
        A unit that is not a positive finite angle within ``--max-change``, a layout or a value the list cannot hold
        (module docstring).
    """
    check_format(params, unit_deg, limits)
    if not positioning_maps(params):
        return []
    out = [f"# positioning maps (CONVENTIONS §10) as kw.ssfk lists ({SOURCE}): a value is the axis' error (actual "
           "minus programmed) in its commanded sense, pos/neg by the direction of motion"]
    if unit_deg is None:
        return out + ["# not written: the unit of a rotary axis' kw.ssfk entries is not settled by the pages read "
                      "(P-COMP-00017: encoder increments or 0.1 um): give --isg-unit-deg U, the angle [deg] of one "
                      "unit of your axis' list (kw.ssfk.unit 1)"]
    for lst in (lists if lists is not None else ssfk_lists(params, unit_deg, limits)):
        body = lst.body()
        out += [f"# {n}" for n in lst.pm.notes()]
        out += [f"# {lst.axis}: list body ({len(body)} lines, no comment inside; values rounded to 1 unit = "
                f"{unit_deg:g} deg, {unit_deg * math.pi / 180 * 1e6:.3g} urad; outside the table the end values hold)",
                *body]
    return out


def entered_values(params: CompensationParameters, lists: list[SsfkList]) -> dict[str, float]:
    """What the printed lists ``lists`` (:func:`ssfk_lists`) enter (:func:`~.positioning.entered_map_values`): every
    positioning map as its table's integers times the unit, per direction; nothing without lists."""
    out: dict[str, float] = {}
    for lst in lists:
        out |= entered_map_values(params, lst.pm, lst.printed)
    return out
