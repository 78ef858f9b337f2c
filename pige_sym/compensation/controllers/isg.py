"""``isg``: ISG kernel / Beckhoff TwinCAT CNC, the error maps of the rotary axes in its axis compensation lists.

The positioning map of each rotary axis as the leadscrew error compensation list ``kw.ssfk`` (bilateral: one
table per direction of motion; :mod:`.tables.isg_ssfk`, with the pages it follows and the unit the user states
with ``--isg-unit-deg``), and the volumetric compensation's ``EXA`` … ``ECC`` tables refused with the reason
(:mod:`.tables.refused`).  The kinematic transformation's own parameters (the PIGEs) are not written here: no
page of its parameters was read; the scope lines name every PIGE as not represented.
"""

from __future__ import annotations

from pige_sym.compensation.controllers import ControllerOptions, built_tables
from pige_sym.compensation.controllers.scope import scope_lines
from pige_sym.compensation.controllers.tables.isg_ssfk import SsfkList, ssfk_lists
from pige_sym.compensation.controllers.tables.isg_ssfk import check_format as ssfk_format
from pige_sym.compensation.controllers.tables.isg_ssfk import entered_values as ssfk_values
from pige_sym.compensation.controllers.tables.isg_ssfk import render_lines as ssfk_lines
from pige_sym.compensation.controllers.tables.positioning import positioning_names
from pige_sym.compensation.controllers.tables.refused import isg_volumetric_lines
from pige_sym.compensation.parameters import CompensationParameters

TITLE = "ISG kernel / Beckhoff TwinCAT CNC: leadscrew error compensation lists (kw.ssfk) of the rotary axes"
#: The options of ``pige compensate`` this controller reads (:func:`~pige_sym.compensation.controllers.check_options`).
OPTIONS = ("--isg-unit-deg",)


def check_tables(params: CompensationParameters, options: ControllerOptions) -> None:
    """``--isg-unit-deg`` and the lists' layout (SGN32 fields, points, interval), before any value is weighed
    (:mod:`.tables.isg_ssfk`)."""
    ssfk_format(params, options.isg_unit_deg, options.change_limits())


def representable(params: CompensationParameters) -> list[str]:
    """No PIGE: the lists hold positioning errors only."""
    return []


def map_motions(params: CompensationParameters) -> list[str]:
    """φ of every axis, per direction too (bilateral lists)."""
    return positioning_names(params)


def tables(params: CompensationParameters, options: ControllerOptions) -> list[SsfkList]:
    """The ``kw.ssfk`` lists, built once (:func:`.tables.isg_ssfk.ssfk_lists`; none without ``--isg-unit-deg``)."""
    return ssfk_lists(params, options.isg_unit_deg, options.change_limits())


def entries(params: CompensationParameters, options: ControllerOptions | None) -> list[tuple[str, dict[str, float]]]:
    """The lists enter the positioning maps as printed (rounded to the list's unit), nothing else."""
    return [("the kw.ssfk lists", ssfk_values(params, built_tables(tables, params, options)))]


def render(params: CompensationParameters, options: ControllerOptions) -> str:
    """The lists' notes and bodies, the volumetric refusal and what the lists leave at the tool."""
    out = [f"# ISG kernel / TwinCAT CNC compensation lists of {params.machine}; parameters from {params.source}",
           *scope_lines(params, "isg", "# ", options)]
    body = ssfk_lines(params, options.isg_unit_deg, options.change_limits(), built_tables(tables, params, options))
    if not body:
        out.append("# the parameter file holds no positioning map (identify with --map): no kw.ssfk list")
    return "\n".join(out + body + isg_volumetric_lines(params))
