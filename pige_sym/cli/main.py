"""The ``pige`` parser and entry point (also ``python -m pige_sym``).

Exit status: 0 success, 1 the command ran but failed (e.g. a check found a
difference), 2 bad input (one line on stderr, no traceback).
"""

from __future__ import annotations

import argparse
import re
import sys
from collections.abc import Callable, Sequence
from typing import Any

from pige_sym.errors import PigeError

Handler = Callable[[argparse.Namespace], int]


class _Parser(argparse.ArgumentParser):
    """ArgumentParser whose usage errors exit with status 2 and one line.

    A value that starts with a minus and a digit is a value, also a vector (``--pivot -12,3,4``,
    ``--ball -1.5e1,0,80``): argparse alone reads only plain negative numbers so, and takes the rest for an
    unknown option.  No option of pige looks like a number, so nothing else changes.
    """

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self._negative_number_matcher = re.compile(r"^-\.?\d")

    def error(self, message: str) -> None:  # type: ignore[override]
        self.exit(2, f"{self.prog}: {message}\n")


#: ``pige --help``'s examples: a first session (README.md), in the order a user runs them.
EXAMPLES = """\
examples (a first session; every command has --help with more):
  pige program --machine "wC'A'bXYZ(C1)t" --trajectory cone-frustum --ball 120,0,80 --out rtest.mpf
  pige simulate --machine "wC'A'bXYZ(C1)t" --pige random --seed 1 --effect angular_error_C --out run.csv
  pige identify run.csv                         # the PIGEs, and whether the model explains the file
  pige diagnose run.csv --json > diagnosis.json # what the PIGE model misses, fitted
  pige check run.csv --tolerances examples/tolerances.json
  pige compensate rtest.mpf --params diagnosis.json --out rtest_comp.mpf
  pige report run.csv --out report --program rtest.mpf --tolerances examples/tolerances.json
  pige demo --instrument sphere-probe --out probe-demo   # the whole story with a touch probe

exit status: 0 success, 1 the command ran but failed (not in tolerance, ...), 2 bad input (one line)."""


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The argument parser of ``pige`` with every subcommand, or with only ``command``'s.

    Parameters
    ----------
    command : str, optional
        A command word (``identify``, ``import-probe``): only its module is imported and only its parser built
        (the same parser as in the whole one; a command's parser is most of the 35 ms the whole one takes).  The
        top-level help and an unknown word need the whole parser (None).
    """
    parser = _Parser(
        prog="pige",
        description=("Identify and compensate the rotary-axis PIGEs of five-axis machines from an R-test, "
                     "a touch probe on a calibration sphere, or a double ballbar."),
        epilog=EXAMPLES,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    from pige_sym.constants import VERSION as __version__

    parser.add_argument("--version", action="version", version=f"pige {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    sub.required = True

    from pige_sym.cli.registry import module_of, register_all

    register_all(sub, None if command is None else module_of(command))
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


class _Interrupts:
    """While a command runs, SIGINT raises KeyboardInterrupt as usual and is remembered: a C extension
    (matplotlib's renderer, a module being imported) may turn the KeyboardInterrupt into another exception,
    which is then an interrupt too, and Python drops one raised in a finaliser (``__del__``: "Exception ignored
    ... KeyboardInterrupt") and goes on; the command then ends with status 130 all the same, and nothing is
    published after the interrupt (:func:`pige_sym.files.raise_if_interrupted`).  The previous handler is put
    back afterwards."""

    def __init__(self) -> None:
        self.seen = False
        self.old: object = None

    def __enter__(self) -> _Interrupts:
        import signal
        import threading

        from pige_sym.files import clear_interrupt

        clear_interrupt()
        if threading.current_thread() is threading.main_thread() and \
                signal.getsignal(signal.SIGINT) is signal.default_int_handler:
            self.old = signal.signal(signal.SIGINT, self._handle)
        return self

    def __exit__(self, *exc: object) -> None:
        from pige_sym.files import clear_interrupt

        clear_interrupt()
        if self.old is not None:
            import signal

            signal.signal(signal.SIGINT, self.old)  # type: ignore[arg-type]

    def _handle(self, signum: int, frame: object) -> None:
        from pige_sym.files import note_interrupt

        self.seen = True
        note_interrupt()
        raise KeyboardInterrupt


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``pige``; returns the exit status (an interrupt, also while the parser is built: 130)."""
    tolerant_console()
    argv = list(sys.argv[1:] if argv is None else argv)
    with _Interrupts() as interrupts:
        try:
            parser = build_parser(_command_word(argv))  # imports the command's module: seconds on a loaded machine
            if not argv:  # `pige` alone: what it can do
                parser.print_help()
                return 0
            args = parser.parse_args(argv)
        except KeyboardInterrupt:
            return _interrupted(argv[0] if argv else "")
        except Exception:
            if interrupts.seen:  # an import the interrupt broke (NumPy's C modules turn it into an ImportError)
                return _interrupted(argv[0] if argv else "")
            raise
        return _run(args, interrupts)


def _command_word(argv: Sequence[str]) -> str | None:
    """The command ``argv`` names, when its first word is one (then only its parser is built), else None."""
    from pige_sym.cli.registry import module_of

    return argv[0] if argv and module_of(argv[0]) is not None else None


def _run(args: argparse.Namespace, interrupts: _Interrupts) -> int:
    """The command's handler, its errors turned into exit statuses (module docstring)."""
    try:
        status = int(args.handler(args))
    except PigeError as exc:
        print(f"pige {args.command}: {exc}", file=sys.stderr)
        return 2
    except BrokenPipeError:  # output piped into head & co.
        sys.stderr.close()
        return 0
    except KeyboardInterrupt:
        return _interrupted(args.command)
    except Exception:
        if interrupts.seen:  # a KeyboardInterrupt that a C extension turned into another exception
            return _interrupted(args.command)
        raise
    if interrupts.seen:  # a KeyboardInterrupt dropped in a finaliser: the command went on, but was interrupted
        return _interrupted(args.command)
    return status


def _interrupted(command: str) -> int:
    print(f"pige {command}: interrupted" if command else "pige: interrupted", file=sys.stderr)
    return 130
