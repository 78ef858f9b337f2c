"""Subcommands of ``pige``, one module each.

Every module in this package defines ``register(subparsers)``, which adds its
subparser and sets ``handler`` (a function ``args -> exit status``).  Modules are
discovered automatically and registered in alphabetical order; ``pige gen`` lives
in :mod:`pige_sym.cli` itself.
"""

from __future__ import annotations

import argparse
import importlib
import pkgutil


def register_all(subparsers: argparse._SubParsersAction) -> None:
    """Import every command module of this package and let it register itself."""
    for info in sorted(pkgutil.iter_modules(__path__), key=lambda i: i.name):
        if info.name.startswith("_"):
            continue
        module = importlib.import_module(f"{__name__}.{info.name}")
        module.register(subparsers)
