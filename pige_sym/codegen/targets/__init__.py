"""Emitter targets, found by name like pyserial's URL handlers: ``pige gen --target NAME``.

A target is the module ``pige_sym.codegen.targets.<NAME>``; :data:`TARGETS` lists the shipped ones
and :func:`load_target` imports one by name. Every target module defines

* ``NAME`` (its name) and ``DESCRIPTION`` (one line for ``--help``);
* ``default_name(structure) -> str``: the base name of its files for a machine;
* ``render(structure, name) -> dict[str, str]``: file name → text, rendered in memory (nothing is
  written: :mod:`pige_sym.cli.gen` checks every output path, then writes).

``numpy`` renders the NumPy kernels (:mod:`pige_sym.codegen.emit`, unchanged); ``linuxcnc`` a LinuxCNC
kinematics component with every PIGE and the pure C99 model it inlines
(:mod:`pige_sym.codegen.c_model`).
"""

from __future__ import annotations

import importlib
from types import ModuleType

from pige_sym.errors import InputError

#: The shipped targets, in the order ``--help`` lists them (the first is the default).
TARGETS = ("numpy", "linuxcnc")


def load_target(name: str) -> ModuleType:
    """The target module called ``name``.

    Raises
    ------
    InputError
        No target of that name (the message lists the ones there are).
    """
    if name not in TARGETS:
        raise InputError(f"--target {name!r}: no such emitter target; use one of {', '.join(TARGETS)}")
    module = importlib.import_module(f"{__name__}.{name}")
    for attr in ("NAME", "DESCRIPTION", "default_name", "render"):
        if not hasattr(module, attr):
            raise InputError(f"--target {name!r}: the target module lacks {attr}")  # a broken plug-in
    return module
