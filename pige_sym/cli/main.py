"""The ``pige`` parser and entry point (also ``python -m pige_sym``).

Exit status: 0 success, 1 the command ran but failed (e.g. a check found a
difference), 2 bad input (one line on stderr, no traceback).
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable, Sequence

from pige_sym.errors import PigeError

Handler = Callable[[argparse.Namespace], int]


class _Parser(argparse.ArgumentParser):
    """ArgumentParser whose usage errors exit with status 2 and one line."""

    def error(self, message: str) -> None:  # type: ignore[override]
        self.exit(2, f"{self.prog}: {message}\n")


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``pige`` with every subcommand."""
    parser = _Parser(
        prog="pige",
        description=("Identify and compensate the rotary-axis PIGEs of five-axis machines "
                     "(R-test, or touch probe and sphere)."),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    from pige_sym.constants import VERSION as __version__

    parser.add_argument("--version", action="version", version=f"pige {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    sub.required = True

    from pige_sym.cli.registry import register_all

    register_all(sub)
    return parser


def tolerant_console() -> None:
    """Let stdout/stderr replace what their encoding cannot show (``µ``, ``→`` on a cp1252 console).

    A command must not crash on its last line because the terminal cannot print a character.
    """
    for stream in (sys.stdout, sys.stderr):
        reconfigure = getattr(stream, "reconfigure", None)
        if reconfigure is not None and getattr(stream, "errors", "strict") == "strict":
            try:
                reconfigure(errors="replace")
            except (ValueError, OSError):  # a closed or detached stream: nothing to print to anyway
                pass


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``pige``; returns the exit status."""
    tolerant_console()
    parser = build_parser()
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv:  # `pige` alone: what it can do
        parser.print_help()
        return 0
    args = parser.parse_args(argv)
    try:
        return int(args.handler(args))
    except PigeError as exc:
        print(f"pige {args.command}: {exc}", file=sys.stderr)
        return 2
    except BrokenPipeError:  # output piped into head & co.
        sys.stderr.close()
        return 0
    except KeyboardInterrupt:
        print(f"pige {args.command}: interrupted", file=sys.stderr)
        return 130
