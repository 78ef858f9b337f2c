"""The files of an acquisition: ``--out``, its raw log and its summary, checked before any work.

``<stem>.raw.log`` and ``<stem>.acq.json`` sit beside the measurement file.  An existing raw
log is appended to (earlier attempts stay in it) unless ``--force`` replaces the run.  The checks
(:func:`check_acquisition_files`) follow :mod:`pige_sym.files`: no output replaced without
``--resume``/``--force``, none equal to an input or to another output, only regular files,
and a folder that takes a new file (probed) before the reference pose is measured.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from collections.abc import Iterable
from pathlib import Path
from typing import TYPE_CHECKING, Any

from pige_sym.errors import InputError
from pige_sym.files import atomic_write_text, check_output, to_json
from pige_sym.measurements.measurement import FORMAT_LINE

if TYPE_CHECKING:
    from pige_sym.acquisition.options import AcquisitionSummary


def summary_path(out: str | os.PathLike[str]) -> Path:
    """Sidecar JSON of an acquisition: ``<stem>.acq.json`` beside the measurement file."""
    p = Path(out)
    return p.with_name(p.stem + ".acq.json")


def default_raw_log(out: str | os.PathLike[str]) -> Path:
    """Default raw byte log: ``<stem>.raw.log`` beside the measurement file."""
    p = Path(out)
    return p.with_name(p.stem + ".raw.log")


def _remove_partial_line(path: Path) -> bool:
    """Cut an unterminated last line (a row cut by a crash); True if something was removed."""
    data = path.read_bytes()
    if not data or data.endswith(b"\n"):
        return False
    cut = data.rfind(b"\n") + 1
    with open(path, "r+b") as fh:
        fh.truncate(cut)
    return True


def _raw_log_path(out: Path, raw_log: str | os.PathLike[str] | None | bool) -> Path | None:
    if raw_log is True:
        return default_raw_log(out)
    if raw_log is None or raw_log is False:
        return None
    return Path(raw_log)


def check_acquisition_files(out: Path, raw_log: Path | None, *, resume: bool, force: bool,
                            inputs: Iterable[str | os.PathLike[str]] = ()) -> None:
    """Refuse outputs that would clobber a file, collide with each other, or cannot be written.

    ``out`` exists: needs ``resume`` (continue it) or ``force`` (replace it).  The raw log and the
    summary beside ``out`` follow ``out``.  No output may be an input or another output; the folder
    must take a new file (a probe file is created and removed), so a read-only or full disk is
    refused before the reference pose is measured.

    Raises
    ------
    InputError
        One line naming the option and what to change.
    """
    ins = [Path(x) for x in inputs]
    outputs = [("--out", out), ("summary", summary_path(out))] + ([("--raw-log", raw_log)] if raw_log else [])
    for i, (what, path) in enumerate(outputs):
        for other_what, other in outputs[:i]:
            if path.resolve() == other.resolve():
                raise InputError(f"{what} {path} is the same file as {other_what}: choose another name")
    if resume and out.exists():
        check_output(out, force=True, inputs=ins, what="--out")
    else:
        check_output(out, force=force, inputs=ins, what="--out")
        if out.exists() and force:
            _require_measurement_or_empty(out)
    for what, path in outputs[1:]:
        # an existing raw log is appended to (it loses nothing) unless --force starts it afresh
        check_output(path, force=force or resume or what == "--raw-log", inputs=ins, what=what)
    _probe_folder(out)


def _require_measurement_or_empty(path: Path) -> None:
    """``--force`` replaces an earlier acquisition only, never an unrelated file."""
    with open(path, "rb") as fh:
        head = fh.read(64)
    if head and not head.startswith(FORMAT_LINE.encode()):
        raise InputError(f"--out {path} exists and is not a pige-rtest file: pige acquire does not replace it "
                         "even with --force; choose another name")


def _probe_folder(out: Path) -> None:
    folder = out.parent if str(out.parent) else Path(".")
    try:
        folder.mkdir(parents=True, exist_ok=True)
        fd, name = tempfile.mkstemp(prefix=f".{out.name}.", suffix=".probe", dir=folder)
        try:
            os.write(fd, b"\n" * 4096)
            os.fsync(fd)
        finally:
            os.close(fd)
            os.unlink(name)
    except OSError as exc:
        raise InputError(f"--out {out}: cannot write in {folder}: {exc.strerror or exc}") from None
    if shutil.disk_usage(folder).free < 2**20:
        raise InputError(f"--out {out}: less than 1 MiB free in {folder}: free some space first")


def _write_summary(summary: AcquisitionSummary, out: Path) -> None:
    """Append this session to ``<stem>.acq.json`` (a list of sessions).

    An earlier summary that cannot be read is kept under ``<stem>.acq.json.unreadable[-N]``, never dropped.
    """
    from pige_sym.errors import PigeError
    from pige_sym.measurements.schema import load_json

    path = summary_path(out)
    sessions: list[Any] = []
    if summary.resumed and path.exists():
        try:
            old = load_json(path, "acquisition summary")
            if not isinstance(old, dict) or not isinstance(old.get("sessions"), list):
                raise ValueError("no sessions list")
            sessions = list(old["sessions"])
        except (PigeError, ValueError):
            keep = path.with_name(path.name + ".unreadable")
            n = 1
            while keep.exists():
                n += 1
                keep = path.with_name(f"{path.name}.unreadable-{n}")
            os.replace(path, keep)
    sessions.append(summary.to_dict())
    atomic_write_text(path, to_json({"sessions": sessions}) + "\n")
