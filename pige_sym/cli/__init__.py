"""The ``pige`` command line: :mod:`~pige_sym.cli.main` builds the parser, one module per command.

Every command module defines ``register(subparsers)`` and imports what it needs inside its
handler, so ``pige --help`` costs little more than starting Python.
"""

from pige_sym.cli.main import main

__all__ = ["main"]
