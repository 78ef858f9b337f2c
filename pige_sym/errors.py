"""Exception hierarchy of pige_sym.

Every error the tool raises on purpose derives from :class:`PigeError`.  The CLI
turns a :class:`PigeError` into one line on stderr and exit status 2 (bad input);
anything else is a bug and keeps its traceback.  Messages say what to fix.
"""

from __future__ import annotations


class PigeError(Exception):
    """Base class of every error pige_sym raises deliberately."""


class MachineCodeError(PigeError, ValueError):
    """A machine structure code does not follow the grammar (CONVENTIONS §1).

    Attributes
    ----------
    code : str
        The code as given.
    position : int
        0-based index of the offending character in ``code`` (``len(code)``
        when the code ends too early).
    """

    def __init__(self, code: str, position: int, problem: str) -> None:
        self.code = code
        self.position = position
        self.problem = problem
        if position < len(code):
            where = f"character {code[position]!r} at position {position}"
        else:
            where = f"end of code at position {position}"
        super().__init__(f"machine code {code!r}: {where}: {problem}")


class UnsupportedMachineError(PigeError):
    """A well-formed machine code the model cannot handle (e.g. no rotary axis)."""


class KernelError(PigeError):
    """Generated kernels are missing, stale or called with inconsistent inputs."""


class InputError(PigeError, ValueError):
    """A value given by the user (option, array shape, parameter name) is invalid."""


class FileFormatError(PigeError):
    """A data file breaks its format; the message names file, line and problem."""

    def __init__(self, path: str, line: int | None, problem: str) -> None:
        self.path = str(path)
        self.line = line
        self.problem = problem
        loc = f"{self.path}:{line}" if line is not None else self.path
        super().__init__(f"{loc}: {problem}")


class AcquisitionError(PigeError):
    """Acquisition from a measuring device cannot go on (port, device, resume mismatch).

    Rows written before the error stay in a valid ``pige-rtest 1`` file that
    ``pige acquire --resume`` continues.
    """


class NCProgramError(FileFormatError):
    """An NC program block the tool cannot read or compensate safely; names the file and line."""


class IdentificationError(PigeError):
    """The identification cannot be carried out with the given data or options."""


class CompensationError(PigeError):
    """The parameters cannot be used for compensation as they are."""


class GuardStopped(PigeError):
    """A guard of the LinuxCNC cycle stopped a run before it identified (the sphere radius found): nothing is stored
    or proposed; the message says what to check."""


class HistoryError(PigeError):
    """The history database cannot be used as it is: damaged (a page, a table, a stored value), or an estimate no
    machine has; the message names the database, what is wrong (the run and field when known) and how to recover.
    pige changes nothing in a database it refuses."""


# ---- internal signals: raised and caught inside pige_sym, never shown to a user as such


class RecordError(Exception):
    """A device frame that is not a valid record; ``reason`` is one of ``pige_sym.acquisition.device.REASONS``."""

    def __init__(self, reason: str, detail: str = "") -> None:
        super().__init__(f"{reason}: {detail}" if detail else reason)
        self.reason = reason


class SchemaRefusal(Exception):
    """A JSON value that breaks the schema (:mod:`~pige_sym.measurements.schema` makes it a FileFormatError)."""

    def __init__(self, where: str, problem: str) -> None:
        super().__init__(f"{where}: {problem}" if where else problem)


class LexError(ValueError):
    """A malformed NC token; ``column`` is its 0-based offset in the line."""

    def __init__(self, column: int, problem: str) -> None:
        super().__init__(problem)
        self.column = column
        self.problem = problem


class AcquisitionStop(Exception):
    """Ends the acquisition loop cleanly (reason in the message)."""

