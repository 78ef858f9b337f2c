"""The positioning tables pige does not write, with what their pages settle and why no value is written.

**FANUC pitch error compensation of a rotary axis** (Parameter Manual B-63980EN/01, p. 100; the parameters
in the 16i/18i technical report A-77810E, "Setting data"): per axis No. 3620 the number of the compensation point
of the reference position, Nos. 3621/3622 the most distant points on the − and + sides, No. 3623 the
magnification, No. 3624 the interval of the points, No. 3625 the travel per rotation of a rotary axis; a
compensation value is output for the section between two points (an increment, not an absolute value); on a
rotary axis the most distant − point is the reference's, the most distant + point is reference + 3625/3624, the
sum of the values over a turn must be 0, and the reference point takes the same value as the last.  **Not
settled**: whether a value is the measured error or its correction (the pages read plot "pitch error
compensation amount" without saying which), the detection unit it counts in (a machine's setting), and where
inside a section the increment is output (so the interpolation between points).  pige prints the layout, no value.

**HEIDENHAIN nonlinear axis error compensation** (Technical Manual MANUALplus 620, pp. 713–718; TNC 407
Technical Manual pp. 4-28…4-31): compensation value tables ``*.COM`` with the compensation points in the
``AXISPOS`` column (from the machine datum), the values of the dependent axis in that axis' column, the values
measured in the negative direction in ``BACKLASH``, assigned to the axes in a ``*.CMA`` table, at most 256 entries
per table (module 9095's error 3), a rotary axis' entries from 0 to 360°.  **Not settled**: the sign of an
entry (the pages say "enter the compensation values" beside a plot of the error; only the linear compensation
MP720 states its sign), and the table file's own format (the pages refer to the chapter "Tables").  No value.

**ISG volumetric compensation** (Beckhoff TF5280 / ISG kernel: "List of parameters supported" 296423819, "Units
of measure" 296426379, "ISG CSV format" 296429067): the component errors of a rotary axis are named as ISO 230
(``EXA`` … ``ECA``, ``EXC`` … ``ECC``), in mm and rad, as functions of the axis angle in degrees; the CSV has a
header of argument and parameter names and one row per argument, ``//`` comments.  **Not settled**: how a
component error of an axis that moves the workpiece acts in ISG's kinematic model (its frame and sign: the
configuration's ``Chain``, ``workpiece_axes``, ``negate`` and ``alternative_model`` change it, and the pages read
do not define them), nor the interpolation of a table.  CONVENTIONS §10's motions are defined on the carried
body in its carrier's frame; writing them as ISG's would be a guess.  No table.
"""

from __future__ import annotations

from pige_sym.compensation.controllers.tables.positioning import positioning_maps
from pige_sym.compensation.parameters import CompensationParameters

FANUC_SOURCE = "FANUC Parameter Manual B-63980EN/01 p. 100; technical report A-77810E"
HEIDENHAIN_SOURCE = "HEIDENHAIN Technical Manual MANUALplus 620 pp. 713-718; TNC 407 Technical Manual pp. 4-28..4-31"
ISG_VOLUMETRIC_SOURCE = "Beckhoff TF5280 volumetric compensation: 296423819, 296426379, 296429067"


def fanuc_lines(params: CompensationParameters) -> list[str]:
    """The layout of a rotary axis' pitch error compensation per positioning map, and the refusal."""
    out = []
    for axis, pm in positioning_maps(params).items():
        step = pm.uniform_step_deg()
        layout = (f"No. 3624 = {step:g} deg, No. 3625 = 360 deg, points reference .. reference + {round(360 / step)} "
                  "(No. 3620, 3621 = 3620, 3622)" if pm.full_turn and step else "a tilt axis: points over its travel")
        out.append(f"(pitch error compensation of {axis} [{FANUC_SOURCE}]: {layout}; NO VALUE printed: the pages read "
                   "do not settle whether a value is the error or its correction, its detection unit, or where "
                   "inside a section it is output)")
    return out


def heidenhain_lines(params: CompensationParameters) -> list[str]:
    """The refusal of the nonlinear axis error compensation tables, one line per positioning map."""
    return [f"; nonlinear axis error compensation of {axis} (*.COM / *.CMA) [{HEIDENHAIN_SOURCE}]: NO TABLE "
            "printed: the pages read do not settle the sign of an entry nor the table file's format"
            for axis in positioning_maps(params)]


def isg_volumetric_lines(params: CompensationParameters) -> list[str]:
    """The refusal of the volumetric compensation's rotary-axis tables."""
    if params.error_maps is None:
        return []
    return [f"# volumetric compensation (EXA..ECC tables) [{ISG_VOLUMETRIC_SOURCE}]: NOT written: the pages read do "
            "not define how a component error of an axis that moves the workpiece acts in ISG's model (frame and "
            "sign depend on Chain, workpiece_axes, negate, alternative_model)"]
