"""Controller corrections, one module per controller, found by name (like pyserial's URL handlers).

``pige compensate --controller NAME`` imports ``pige_sym.compensation.controllers.<NAME>``; each such
module holds one controller's kinematic chain, its entries and the manuals it follows, and defines::

    TITLE: str                                       one line: controller and kinematic description
    representable(params) -> list[str]               the parameters its entries carry (CONVENTIONS §3 names)
    render(params, options) -> str                   the entries as text (ControllerOptions below)

A controller that reads today's configuration (LinuxCNC's ``--current``) also defines::

    check_current(params, current) -> None            refuses a configuration that contradicts the parameters

A controller whose printed lines carry more than its kinematic entries (the error maps' tables), or that can be
entered in more than one way, defines::

    entries(params, options) -> list[(label, values)]  each way of entering, fewest values first: exactly the
                                                       values its printed lines carry (as printed), in the
                                                       weighing's names (EX0C, C:ECC+@30)

and one whose lines go into several files (LinuxCNC: HAL, INI, compensation files)::

    sections(params, options) -> list[Section]         the same lines by target file (pasted whole, or written by
                                                       pige compensate --out-dir)

and one that writes compensation tables (error maps, CONVENTIONS §10) checks their format before any value is
weighed or computed (the table modules of :mod:`.tables`, each citing the source of its limits), and builds them
once from the entered values::

    check_tables(params, options) -> None             refuses what the tables cannot hold
    tables(params, options) -> list                   the tables, built once by the compensation stage and passed
                                                       as ``options.tables`` to entries, render and sections: what
                                                       is printed and what the prediction counts are one object

``OPTIONS`` names the ``pige compensate`` options a controller reads beyond the parameters (``--carrier``,
``--machine-axis``, …); another controller refuses them (:func:`check_options`).

The modules that are not controllers (:data:`NOT_CONTROLLERS`) hold what they share: the corrected axis
lines (:mod:`.axis_lines`), what a controller leaves at the tool (:mod:`.scope`), the checks made before
anything is written (:mod:`.entry_checks`) and the reader of a LinuxCNC configuration (:mod:`.hal_config`).
Units, signs and sources of every controller: docs/controller-corrections.md.
"""

from __future__ import annotations

import importlib
import pkgutil
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType
from typing import Any

from pige_sym.errors import InputError

#: Modules of this package that are not controllers.
NOT_CONTROLLERS = frozenset({"axis_lines", "entry_checks", "hal_config", "scope", "tables"})


@dataclass(frozen=True)
class ControllerOptions:
    """What a controller's rendering may need besides the parameters.

    Attributes
    ----------
    carrier : int
        Siemens swivel data record number (``$TC_CARR…[carrier]``).
    current : dict of str to float or HalConfig, optional
        Today's values of the controller's entries (LinuxCNC HAL pins [mm], or the configuration read by
        :func:`.hal_config.read_current`), for absolute lines.
    heidenhain_trans : str, optional
        What a HEIDENHAIN ``Trans`` row holds: ``position`` or ``shift`` (:mod:`.heidenhain`).
    machine_axes : dict of str to str, optional
        The controller's name of each rotary axis where its tables need it (SINUMERIK machine axis names).
    isg_unit_deg : float, optional
        The angle [deg] of one unit of an ISG ``kw.ssfk`` list of a rotary axis (:mod:`.tables.isg_ssfk`).
    scope : ControllerScope, optional
        What the entries carry and leave, as the compensation stage computed it (:mod:`.scope`); rendered, not
        computed again.
    tables : list, optional
        The controller's compensation tables as the compensation stage built them (the module's ``tables``):
        printed and counted, not built again (:func:`built_tables`).
    limits : ChangeLimits, optional
        ``--max-change`` (:class:`.entry_checks.ChangeLimits`) every entry is held to; None: its default.
    """

    carrier: int = 1
    current: Any = None
    heidenhain_trans: str | None = None
    machine_axes: dict[str, str] | None = None
    isg_unit_deg: float | None = None
    scope: Any = None
    limits: Any = None
    tables: Any = None

    def change_limits(self) -> Any:
        """``limits``, or the default ``--max-change``."""
        from pige_sym.compensation.controllers.entry_checks import ChangeLimits

        return self.limits if self.limits is not None else ChangeLimits()


def built_tables(build: Callable[[Any, ControllerOptions], list[Any]], params: Any,
                 options: ControllerOptions | None) -> list[Any]:
    """A controller's tables: ``options.tables`` as the compensation stage built them, else ``build(params,
    options)`` (a caller outside the stage, which prints or counts once)."""
    if options is not None and options.tables is not None:
        return list(options.tables)
    return list(build(params, options if options is not None else ControllerOptions()))


def controller_names() -> tuple[str, ...]:
    """The controllers pige can print for, ``table`` first (the modules of this package)."""
    names = sorted(i.name for i in pkgutil.iter_modules([str(Path(__file__).parent)])
                   if not i.name.startswith("_") and i.name not in NOT_CONTROLLERS)
    return tuple(sorted(names, key=lambda n: n != "table"))


def get_controller(name: str) -> ModuleType:
    """The module of controller ``name`` (module docstring).

    Raises
    ------
    InputError
        No controller of that name.
    """
    if name not in controller_names():
        raise InputError(f"unknown controller style {name!r}: use {', '.join(controller_names())}")
    return importlib.import_module(f"{__name__}.{name}")


def check_options(style: str, given: list[str]) -> None:
    """Refuse an option ``given`` (``--machine-axis``, …) that controller ``style`` does not read (its ``OPTIONS``).

    Raises
    ------
    InputError
        Naming the option and the controllers that read it.
    """
    module = get_controller(style)
    for option in given:
        if option not in getattr(module, "OPTIONS", ()):
            readers = [n for n in controller_names() if option in getattr(get_controller(n), "OPTIONS", ())]
            raise InputError(f"{option} does not apply to --controller {style}: it is read by --controller "
                             f"{', '.join(readers)} only; leave it out")


def check_before_writing(params: Any, style: str, current: Any = None, options: ControllerOptions | None = None
                         ) -> None:
    """Check what controller ``style`` would enter before anything is written (module docstring).

    The parameters against physical bounds and ``--max-change`` (:func:`.entry_checks.check_parameters`), the
    format of the controller's tables (``check_tables``), and today's configuration ``current`` (or
    ``options.current``) against the parameters by the controller that reads one (``check_current``).  Cheap:
    called before the values are weighed, and again on the weighed values before they are rendered.

    Raises
    ------
    InputError
        A value beyond its bound, a table its format cannot hold, a configuration for a controller that reads
        none, or a contradiction (both values and their sources named).
    """
    from pige_sym.compensation.controllers.entry_checks import check_parameters

    module = get_controller(style)
    opts = options if options is not None else ControllerOptions(current=current)
    current = current if current is not None else opts.current
    check_parameters(params, opts.change_limits())
    check_tables = getattr(module, "check_tables", None)
    if check_tables is not None:
        check_tables(params, opts)
    if current is None:
        return
    check_current = getattr(module, "check_current", None)
    if check_current is None:
        readers = [n for n in controller_names() if hasattr(get_controller(n), "check_current")]
        raise InputError(f"--current: the {style} entries are changes to add; today's configuration is read for "
                         f"--controller {', '.join(readers)} only")
    check_current(params, current)


def entered_for_controller(params: Any, enter: str = "weighed", travel: Any = None) -> Any:
    """``params`` with the values to enter: weighed by their uncertainty over the axes' travel (``travel``: axis
    → (min, max) [deg], :func:`~pige_sym.compensation.weighing.travel_poses`), or every estimate (``all``)."""
    from pige_sym.compensation.weighing import every_estimate, travel_poses, weigh, with_entered

    if enter not in ("weighed", "all"):
        raise InputError(f"enter {enter!r}: use weighed or all")
    if params.weighing is not None:
        return params
    weighing = weigh(params, travel_poses(params, travel))
    return with_entered(params, every_estimate(weighing) if enter == "all" else weighing)
