"""``pige_cycle/values.hal``: the values the kinematics hold, one HAL command per value.

The INI sources it (``HALCMD = source ./pige_cycle/values.hal``), so the values hold again at every start of
LinuxCNC.  ``pige cycle install`` writes it with the values the configuration set; ``M451 P2`` rewrites it with the
entered values (:func:`write_values`): the new text goes to a temporary file beside it, the file as it was is kept
as ``values.hal.previous``, then the new one replaces it by a rename (a power failure leaves the old file or the
new one, never half of one).  The lines::

    # comments
    setp <pin> <value>        a pin set directly
    sets <signal> <value>     a pin netted to a signal (HAL refuses setp on it)

With a map test (:mod:`~pige_sym.cycle.map_pins`) the map pins follow the PIGE pins in the safe order: each mapped
axis' ``map-<a>-nodes`` set to 0 first, then the grids and the values, the node counts last (a node-count pin is the
one pin set twice; its last line is its value).
"""

from __future__ import annotations

from pathlib import Path

from pige_sym.cycle.kinematics import KinematicsSetup
from pige_sym.errors import FileFormatError


def values_text(setup: KinematicsSetup, values: dict[str, float]) -> str:
    """The values file for ``values`` (pin -> value; the setup's own where missing)."""
    unit = ", ".join(sorted({p.unit for p in setup.pins}))
    out = [f"# pige cycle: the values {setup.module} holds [{unit}], sourced by the INI (HALCMD = source "
           "./pige_cycle/values.hal)",
           "# M451 P2 rewrites this file (the one before is kept as values.hal.previous); edit it only with LinuxCNC "
           "stopped"]
    from pige_sym.cycle.map_pins import is_map_pin, nodes_first

    maps = False
    for p in setup.pins:
        if is_map_pin(p) and not maps:
            out += nodes_first(setup)
            maps = True
        out.append(f"{p.command(values.get(p.pin, p.value))}    # {p.holds}")
    return "\n".join(out) + "\n"


def read_values(path: Path, setup: KinematicsSetup) -> dict[str, float]:
    """The values the file sets, by pin.

    Raises
    ------
    FileFormatError
        A line that is not one of the setup's pins or signals with a number, or a value missing.
    """
    from pige_sym.cycle.map_pins import is_nodes_pin
    from pige_sym.files import read_input_text
    from pige_sym.options import strict_float

    by_target = {p.target: p for p in setup.pins}
    out: dict[str, float] = {}
    for number, raw in enumerate(read_input_text(path, what="values file").splitlines(), start=1):
        words = raw.split("#", 1)[0].split()
        if not words:
            continue
        p = by_target.get(words[1]) if len(words) == 3 else None
        value = strict_float(words[2]) if p is not None else None
        if p is None or value is None or words[0] != ("sets" if p.signal else "setp"):
            raise FileFormatError(str(path), number, f"{raw.strip()[:60]!r}: expected setp/sets of one of "
                                  f"{', '.join(by_target)} with a number")
        if p.pin in out and not is_nodes_pin(p):
            raise FileFormatError(str(path), number, f"{p.target} is set twice: the file sets each value once")
        out[p.pin] = value
    missing = [p.target for p in setup.pins if p.pin not in out]
    if missing:
        raise FileFormatError(str(path), None, f"{', '.join(missing)} not set: the file holds every value of "
                              f"{setup.module}; restore it from values.hal.previous or install again")
    return out


def write_values(path: Path, previous: Path, text: str) -> None:
    """Replace the values file by ``text`` (module docstring), keeping the file as it was in ``previous``."""
    from pige_sym.files import atomic_write_text

    atomic_write_text(previous, path.read_bytes().decode("utf-8"), newline="")
    atomic_write_text(path, text, newline="")
