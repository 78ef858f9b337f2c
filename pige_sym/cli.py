"""The ``pige`` command line (also ``python -m pige_sym``).

Exit status: 0 success, 1 the command ran but failed (e.g. a check found a
difference), 2 bad input (one line on stderr, no traceback).
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable, Sequence
from pathlib import Path

from .errors import PigeError

Handler = Callable[[argparse.Namespace], int]


class _Parser(argparse.ArgumentParser):
    """ArgumentParser whose usage errors exit with status 2 and one line."""

    def error(self, message: str) -> None:  # type: ignore[override]
        self.exit(2, f"pige {self.prog.split(' ', 1)[-1]}: {message}\n")


def _cmd_gen(args: argparse.Namespace) -> int:
    from .emit import render_module, write_module
    from .kernels import generated_dir, kernel_path
    from .machine_code import parse_machine_code

    out_dir = Path(args.out) if args.out else generated_dir()
    structures = [parse_machine_code(c) for c in args.codes]
    status = 0
    for st in structures:
        if args.check:
            path = kernel_path(st) if not args.out else out_dir / f"{st.module_name}.py"
            fresh = render_module(st)
            if not path.exists():
                print(f"MISSING {path} (machine {st.canonical}): run make gen MACHINE=\"{st.canonical}\"")
                status = 1
            elif path.read_text(encoding="utf-8") != fresh:
                print(f"DIFFERS {path} (machine {st.canonical}): run make gen-all and commit the result")
                status = 1
            else:
                print(f"ok      {path}")
        else:
            path = write_module(st, out_dir)
            print(f"wrote {path}")
    return status


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``pige`` with every subcommand."""
    parser = _Parser(
        prog="pige",
        description="Identify and compensate the rotary-axis PIGEs of five-axis machines from R-test data.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    sub.required = True

    p = sub.add_parser(
        "gen",
        help="generate NumPy kernels for machine codes",
        description="Derive the error model with SymPy and write a NumPy kernel module per machine code.",
        epilog="example:\n  pige gen \"wC'B'bXYZ(C1)t\"\n  pige gen --check \"wC'A'bXYZ(C1)t\"",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("codes", nargs="+", metavar="CODE", help="ISO 10791 machine structure code")
    p.add_argument("--out", help="output directory (default: generated/)")
    p.add_argument("--check", action="store_true", help="regenerate in memory and fail on any difference")
    p.set_defaults(handler=_cmd_gen)

    from .commands import register_all

    register_all(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``pige``; returns the exit status."""
    parser = build_parser()
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
