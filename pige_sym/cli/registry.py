"""Discovery of the command modules of :mod:`pige_sym.cli`.

Every module of the package except ``main``, ``registry`` and ``_``-prefixed helpers defines
``register(subparsers)``, which adds its subparser and sets ``handler`` (a function
``args -> exit status``).  Modules are registered in alphabetical order.
"""

from __future__ import annotations

import argparse
import importlib
import pkgutil
from pathlib import Path

_NOT_COMMANDS = {"main", "registry"}


def register_all(subparsers: argparse._SubParsersAction) -> None:
    """Import every command module of :mod:`pige_sym.cli` and let it register itself."""
    for info in sorted(pkgutil.iter_modules([str(Path(__file__).parent)]), key=lambda i: i.name):
        if info.name.startswith("_") or info.name in _NOT_COMMANDS:
            continue
        module = importlib.import_module(f"{__package__}.{info.name}")
        module.register(subparsers)
