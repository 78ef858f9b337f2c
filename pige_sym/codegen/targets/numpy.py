"""Target ``numpy``: the NumPy kernel module of a machine (:mod:`pige_sym.codegen.emit`, output unchanged).

One file, ``kin_<machine>.py``; ``pige gen`` writes it into ``generated/`` (a checkout) or the user
cache, and ``pige gen --check`` compares it with the tracked one.
"""

from __future__ import annotations

from pige_sym.codegen.emit import render_module
from pige_sym.codegen.machine_code import MachineStructure

NAME = "numpy"
DESCRIPTION = "NumPy kernels (deviation, Jacobian, nominal kinematics) in generated/ or the user cache"


def default_name(structure: MachineStructure) -> str:
    """``kin_<machine>`` (e.g. ``kin_wCpApbXYZ_C1_t``): the module name pige loads."""
    return structure.module_name


def render(structure: MachineStructure, name: str | None = None) -> dict[str, str]:
    """``{"kin_<machine>.py": source}``; the module name is fixed (pige loads it by that name)."""
    return {f"{default_name(structure)}.py": render_module(structure)}
