"""Writing files safely, and JSON out: the one helper for each.

Rules every command follows (docs/formats.md, "What it refuses and why"):

- an existing output is never replaced without ``force``;
- an output is never one of the command's inputs (same file, also through links);
- only regular files are ever replaced: a symlink, FIFO, socket or device node at the output
  path is refused even with ``force``;
- the output's folder must exist (or be creatable) and be writable, checked *before* long work
  by :func:`check_output`;
- the text is written to a temporary file in the same folder, flushed to disk and renamed over
  the target, so a reader sees the old file or the new one, never half of one.

JSON: :func:`to_json` turns dataclass dicts with NumPy values into strict JSON (non-finite
floats become ``null``, never ``NaN``).
"""

from __future__ import annotations

import json
import math
import os
import stat
import tempfile
from collections.abc import Iterable
from pathlib import Path
from typing import IO, Any

from pige_sym.errors import FileFormatError, InputError

PathLike = str | os.PathLike[str]


def _same_file(a: Path, b: Path) -> bool:
    try:
        return a.exists() and b.exists() and os.path.samefile(a, b)
    except OSError:
        return False


def check_output(path: PathLike, *, force: bool = False, inputs: Iterable[PathLike] = (), what: str = "output") -> Path:
    """Refuse an output path that would clobber something; returns it as a Path.

    Parameters
    ----------
    path : path
        The file to be written.
    force : bool
        Allow replacing an existing *regular* file.
    inputs : iterable of paths
        The command's inputs; the output may be none of them.
    what : str
        Name of the option in messages (``--out``, ``--raw-log``, …).

    Raises
    ------
    InputError
        With one line that says what to change.
    """
    p = Path(path)
    for source in inputs:
        src = Path(source)
        if _same_file(p, src) or p.resolve() == src.resolve():
            raise InputError(f"{what} {p} is also an input of this command: choose another file")
    if p.is_symlink():
        raise InputError(f"{what} {p} is a symbolic link: pige never replaces one; write to the real path")
    if p.exists():
        mode = p.stat().st_mode
        if stat.S_ISDIR(mode):
            raise InputError(f"{what} {p} is a directory: give a file name")
        if not stat.S_ISREG(mode):
            raise InputError(f"{what} {p} is not a regular file (FIFO, socket or device): pige never replaces one")
        if not force:
            raise InputError(f"{what} {p} exists: pass --force to replace it, or choose another name")
    parent = p.parent if str(p.parent) else Path(".")
    existing = parent
    while not existing.exists() and existing != existing.parent:
        existing = existing.parent
    if not existing.is_dir():
        raise InputError(f"{what} {p}: {existing} is not a directory")
    if not os.access(existing, os.W_OK | os.X_OK):
        raise InputError(f"{what} {p}: the folder {existing} is not writable")
    return p


def new_file_mode() -> int:
    """Mode of a newly created file under the process's umask (``0o666 & ~umask``).

    Read from ``/proc/self/status`` where it exists (setting the umask to read it would race with
    other threads creating files); elsewhere by setting it and putting it back.
    """
    try:
        with open("/proc/self/status", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("Umask:"):
                    return 0o666 & ~int(line.split()[1], 8)
    except (OSError, ValueError):
        pass
    mask = os.umask(0o022)
    os.umask(mask)
    return 0o666 & ~mask


def atomic_write_text(path: PathLike, text: str, *, encoding: str = "utf-8", newline: str | None = None) -> Path:
    """Write ``text`` to ``path`` through a temporary file and a rename (same folder).

    The caller decides whether replacing is allowed (:func:`check_output`); this function only
    refuses to replace anything that is not a regular file.  Missing parent folders are created.
    The file gets the mode a plain ``open`` would give it (``0666`` less the umask: ``0644`` under
    ``022``, so a DNC account or a web server can read a compensated program), and a replaced file
    keeps its own mode.
    """
    p = Path(path)
    if p.is_symlink() or (p.exists() and not p.is_file()):
        raise InputError(f"{p} is not a regular file: pige never replaces one")
    p.parent.mkdir(parents=True, exist_ok=True)
    mode = new_file_mode() if not p.exists() else p.stat().st_mode & 0o7777
    fd, tmp_name = tempfile.mkstemp(prefix=f".{p.name}.", suffix=".tmp", dir=p.parent)
    try:
        os.fchmod(fd, mode)
        with os.fdopen(fd, "w", encoding=encoding, newline=newline) as fh:
            fh.write(text)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp_name, p)
    except OSError as exc:
        Path(tmp_name).unlink(missing_ok=True)
        raise InputError(f"cannot write {p}: {exc.strerror or exc}") from exc
    except BaseException:
        Path(tmp_name).unlink(missing_ok=True)
        raise
    return p


def open_regular_file(path: PathLike) -> IO[bytes]:
    """Open a regular file for binary reading; a FIFO, socket, device or folder is refused.

    The file is opened without blocking (a FIFO would otherwise wait for a writer), checked
    with ``fstat`` on the open descriptor (no race with a rename), then switched to blocking.

    Raises
    ------
    FileFormatError
        Naming the file and the problem.
    """
    p = str(path)
    try:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
    except FileNotFoundError:
        raise FileFormatError(p, None, "file not found") from None
    except OSError as exc:
        raise FileFormatError(p, None, f"cannot read: {exc.strerror or exc}") from None
    mode = os.fstat(fd).st_mode
    if not stat.S_ISREG(mode):
        os.close(fd)
        what = "a directory" if stat.S_ISDIR(mode) else "not a regular file (FIFO, socket or device)"
        raise FileFormatError(p, None, f"{what}: pige reads regular files only")
    if hasattr(os, "set_blocking"):
        os.set_blocking(fd, True)
    return os.fdopen(fd, "rb")


def json_ready(x: Any) -> Any:
    """Python values for JSON: NumPy scalars/arrays converted, non-finite floats → None, recursively."""
    import numpy as np

    if isinstance(x, dict):
        return {str(k): json_ready(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [json_ready(v) for v in x]
    if isinstance(x, np.ndarray):
        return json_ready(x.tolist())
    if isinstance(x, (np.floating, float)):
        return float(x) if math.isfinite(float(x)) else None
    if isinstance(x, (np.integer,)):
        return int(x)
    if isinstance(x, np.bool_):
        return bool(x)
    if isinstance(x, Path):
        return str(x)
    return x


def to_json(x: Any, *, indent: int | None = 1) -> str:
    """Strict JSON text of ``x`` (see :func:`json_ready`); never contains NaN or Infinity."""
    return json.dumps(json_ready(x), indent=indent, allow_nan=False, ensure_ascii=False)
