"""Discovery of the command modules of :mod:`pige_sym.cli`.

Every module of the package except ``main``, ``registry`` and ``_``-prefixed helpers defines
``register(subparsers)``, which adds its subparser and sets ``handler`` (a function
``args -> exit status``).  Modules are registered in alphabetical order.

A command's description is often its module docstring, written in reStructuredText for the API docs;
:func:`plain_text` turns it into what a terminal shows (``--pivot`` → --pivot, a role such as
:mod:`pige_sym.nc` → pige_sym.nc), and :func:`register_all` applies it to every parser it registers.
"""

from __future__ import annotations

import argparse
import importlib
import pkgutil
import re
from pathlib import Path

_NOT_COMMANDS = {"main", "registry"}
_ROLE = re.compile(r":(?:mod|func|class|data|meth|attr|obj|exc):`~?([^`]+)`")


def plain_text(text: str | None) -> str | None:
    """reStructuredText literals and roles as plain text (``x`` → x, :func:`~a.b` → b, :mod:`a.b` → a.b)."""
    if text is None:
        return None
    text = _ROLE.sub(lambda m: m.group(1), re.sub(r":(func|class|meth|attr|obj|exc):`~[\w.]*\.(\w+)`",
                                                  r"\2", text))
    return text.replace("``", "")


def _plain_parsers(parser: argparse.ArgumentParser) -> None:
    """Apply :func:`plain_text` to a parser's description, epilog and help strings, and its subparsers'."""
    parser.description = plain_text(parser.description)
    parser.epilog = plain_text(parser.epilog)
    for action in parser._actions:
        action.help = plain_text(action.help)
        if isinstance(action, argparse._SubParsersAction):
            for choice in action._choices_actions:
                choice.help = plain_text(choice.help)
            for sub in action.choices.values():
                _plain_parsers(sub)


def command_modules() -> list[str]:
    """The command modules of :mod:`pige_sym.cli`, in alphabetical order; module ``a_b`` registers command
    ``a-b`` (tests/test_docs_cli.py holds every module to it)."""
    return sorted(info.name for info in pkgutil.iter_modules([str(Path(__file__).parent)])
                  if not info.name.startswith("_") and info.name not in _NOT_COMMANDS)


def module_of(command: str) -> str | None:
    """The module that registers ``command`` (a word of the command line), or None when no module does."""
    name = command.replace("-", "_")
    return name if name.replace("_", "-") == command and name in command_modules() else None


def register_all(subparsers: argparse._SubParsersAction, only: str | None = None) -> None:
    """Import every command module of :mod:`pige_sym.cli` (or only the module ``only``) and let it register
    itself."""
    for name in command_modules():
        if only is not None and name != only:
            continue
        module = importlib.import_module(f"{__package__}.{name}")
        module.register(subparsers)
    for choice in subparsers._choices_actions:
        choice.help = plain_text(choice.help)
    for parser in subparsers.choices.values():
        _plain_parsers(parser)
