"""Point acquisition: read a measuring device, average each pose, write ``pige-rtest 1`` rows.

Data path
---------
``port bytes → raw log (appended, flushed) → framer → adapter (records) → sequence
check → pose trigger → window average → row``.  Every byte read is logged before it
is parsed.  Malformed records are counted per reason and skipped, never repaired
(:mod:`pige_sym.acquisition.device`).  Sequence numbers must increase: a number seen
among the last :data:`RECENT_SEQS` samples is a ``duplicate`` (rejected, also when it
comes out of order), a jump forward adds to ``missing``, a jump back to a number not
seen means the device restarted and stops the run (the pose count would no longer be
known).

Triggers (``--trigger``): when the window of a pose starts
------------------------------------------------------------
``stable`` (default)
    Pose 0 (the reference) starts when the readings settle: over the last
    ``settle_s`` of device time every sensor stays within a peak-to-peak band of
    ``tolerance_um``, apart from at most one *spike* (a run of at most
    ``spike_samples`` readings far from the median).  Every later pose needs motion
    first (more than ``spike_samples`` readings in a row farther than
    ``tolerance_um`` from the previous pose's level: a spike is not motion), then
    settling.  The window holds the samples after settling, up to ``window_s`` of
    device time; spikes are left out of it (``spikes`` in the summary); it ends early
    when the readings leave the settled level for longer than a spike (the machine
    moved on) or after a data gap longer than ``max_gap_s``.

    Each settle is cross-checked with the program's timing, from the settle of the
    last written pose (``timing_tol`` × the shortest pose cycle; ``timing_check``):
    too early is a spurious settle (dropped: ``spurious_settles``), matching a later
    pose flags the poses passed unseen, matching none flags the pose as doubtful.
    No row is ever written under a pose the timing does not support.
``schedule``
    Pose i is averaged over device times ``[T0 + arrive_i + delay_s,
    T0 + arrive_i + delay_s + window_s)`` where ``arrive_i`` is the program schedule
    (:mod:`pige_sym.nc.rtest_program`) and ``T0`` the time of the first sample.
    Readings farther than ``tolerance_um`` from the window's median are spikes (left
    out); more than a tenth of them flags the pose (the machine was not still).
``key``
    The window starts at the first sample after the operator presses Enter (or
    after ``key_source()`` returns True) and lasts ``window_s``.

A window with fewer than ``min_samples`` valid samples is *flagged*: no row is
written for that pose (nothing is invented) and the summary lists it.

Rows
----
Readings are zeroed with the mean of the reference window (metadata ``zero_um``),
converted per sample to the ball-centre displacement in the nest frame
(:class:`~pige_sym.acquisition.nest.NestGeometry`), turned into the measurement frame with the
nominal workpiece rotation of the commanded angles (``frame: machine``) or kept
(``frame: table``), then averaged.  Columns: ``t_s`` (mean device time of the window
minus that of the reference window), the commanded angles, ``dx_um, dy_um, dz_um``
(mean; exactly 0 on the reference row), ``X_mm, Y_mm, Z_mm`` (nominal RTCP
commands), ``n_samples``, ``sd_um`` (root mean square of the three per-axis sample
standard deviations of one sample), and the extra columns ``pose`` (index in the
program), ``seq_first``, ``seq_last`` (device sequence numbers of the first and last
sample averaged) and ``r1_um, r2_um, r3_um`` (mean raw readings, for re-processing
with another nest geometry).  Rows are fsynced one by one
(:class:`~pige_sym.measurements.rtest_writer.MeasurementWriter`).

Link faults
-----------
No byte for ``timeout_s`` is a timeout; consecutive timeouts form one *stall*.  A
timeout or an I/O error (disconnect) closes the port and reopens it (every
``retry_s``, for at most ``reconnect_timeout_s``); acquisition then goes on at the
current pose.  A gap in device time longer than one pose cycle (move + dwell) in
``stable`` mode, a device restart, an end-of-program record before the last pose,
or a port that stays away stops the run cleanly: the summary says why
(``completed`` False) and the file holds every row measured so far.

Bounds (a bad device ends the run, it never runs away): no valid record for
``reconnect_timeout_s`` (silence, noise, an endless line, a port that accepts and
closes), ``max_reconnects`` reconnections in a row without a valid record, more than
``max_bytes`` read in the session (default :func:`default_max_bytes`; what was read
up to the limit is logged), ``max_window_samples`` per window, frames of at most the
framer's ``max_len``, and device time running past the end of the program.

Resume
------
``resume=True`` continues a partial file: an incomplete last line (crash during a
write) is removed, the file's set-up (machine, ball, frame, pivots, tool, program,
nest) must match, and its ``zero_um`` is reused.  The machine runs the program again
from its start: poses already in the file are measured again but not written, each
checked against its row (within ``replay_tol_um``) so that a different set-up or a
program restarted elsewhere is refused; rows are appended from the first pose
after the file's last row.  With a deterministic device (the virtual R-test with the
same seed) the final file is byte-identical to an uninterrupted run.
"""

from __future__ import annotations

import os
import sys
import time
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

from pige_sym.acquisition.device import DeviceAdapter, RTestProtocolAdapter
from pige_sym.acquisition.nest import NestGeometry, default_nest
from pige_sym.acquisition.options import AcquisitionOptions, AcquisitionSummary
from pige_sym.acquisition.outputs import (
    _raw_log_path,
    _write_summary,
    check_acquisition_files,
)
from pige_sym.acquisition.resume import prepare_resume
from pige_sym.acquisition.session import Link, open_session, run_session
from pige_sym.acquisition.transport import PortSettings
from pige_sym.acquisition.triggers import StdinKeys, _KeyTrigger, _ScheduleTrigger, _StableTrigger, _Trigger
from pige_sym.nc.rtest_program import TestProgram


def acquire(port: str, program: TestProgram, out: str | os.PathLike[str], *,
            options: AcquisitionOptions | None = None, settings: PortSettings | None = None,
            nest: NestGeometry | None = None, adapter: DeviceAdapter | None = None, resume: bool = False,
            force: bool = False, raw_log: str | os.PathLike[str] | None | bool = True, progress: bool = False,
            key_source: Callable[[], bool] | None = None, echo: Callable[[str], None] | None = None,
            opener: Callable[[], Any] | None = None,
            inputs: Iterable[str | os.PathLike[str]] = ()) -> AcquisitionSummary:
    """Acquire every pose of a test program from a device and write a ``pige-rtest 1`` file.

    Parameters
    ----------
    port : str
        URL or device path for :func:`serial.serial_for_url` (``/dev/ttyUSB0``, ``/dev/pts/3``,
        ``socket://127.0.0.1:5555``, ``rfc2217://host:port``, ``loop://``).
    program : TestProgram
        Poses, schedule and set-up (:func:`pige_sym.nc.rtest_program.load_test_program`).
    out : path-like
        Measurement file, written row by row.
    options : AcquisitionOptions
    settings : PortSettings
    nest : NestGeometry
        Default: cube-corner nest with flat probes.
    adapter : DeviceAdapter
        Default: the ``rtest`` streaming protocol.
    resume : bool
        Continue a partial ``out`` (module docstring).
    force : bool
        Replace an existing ``out`` (and its raw log and summary) with a new run.  Without
        ``resume`` or ``force`` an existing ``out`` is refused; an existing raw log alone is
        appended to.
    raw_log : path-like, True or None/False
        Raw byte log; True means ``<stem>.raw.log`` beside ``out``; None/False disables it.
    progress : bool
        Show tqdm progress bars (overall and per point) on stderr.
    key_source : callable () -> bool
        For ``trigger="key"``: True when the operator confirms the pose (default: Enter on stdin).
    echo : callable (str) -> None
        Receives messages (prompts, resume notes); default: stderr.
    opener : callable () -> port object
        Opens the port instead of :func:`~pige_sym.acquisition.transport.open_port` (tests, special links);
        the port must be non-blocking (pyserial ``timeout=0``).
    inputs : iterable of path-like
        Files the run reads (program, nest): no output may be one of them.

    Returns
    -------
    AcquisitionSummary
        Also written to ``<stem>.acq.json``.  ``completed`` is False when the run stopped
        early (``stop_reason`` says why); the file is valid either way.

    Raises
    ------
    InputError
        An output would clobber a file or cannot be written (checked before the port is opened).
    AcquisitionError
        The port cannot be opened at the start, or ``resume`` does not match the file.
    KeyboardInterrupt
        After writing the summary (``pige acquire`` turns SIGTERM into this too); rows already
        written stay.
    """
    opts = options or AcquisitionOptions()
    nest = nest or default_nest()
    say = echo or (lambda msg: print(msg, file=sys.stderr))
    out_p = Path(out)
    log_path = _raw_log_path(out_p, raw_log)
    check_acquisition_files(out_p, log_path, resume=resume, force=force, inputs=inputs)
    summary = AcquisitionSummary(port=port, out=str(out_p), raw_log=None if log_path is None else str(log_path),
                                 program=program.description, n_poses=program.n_poses)
    started = time.monotonic()
    state = prepare_resume(out_p, program, nest, opts, summary, say) if resume else None
    if summary.completed:
        _write_summary(summary, out_p)
        return summary
    trigger = _make_trigger(opts, program, key_source, say)
    link = Link(port, settings or PortSettings(), opts, adapter or RTestProtocolAdapter(), opener, summary)
    session = open_session(link, program, out_p, nest, state, trigger, (log_path, resume or not force), progress)
    run_session(session, started, out_p, say)
    return summary


def _make_trigger(opts: AcquisitionOptions, program: TestProgram, key_source: Callable[[], bool] | None,
                  say: Callable[[str], None]) -> _Trigger:
    if opts.trigger == "stable":
        return _StableTrigger(opts, program)
    if opts.trigger == "schedule":
        return _ScheduleTrigger(opts, program)
    axes = program.rotary_axes

    def prompt(pose: int) -> None:
        ang = ", ".join(f"{a}={v:g}" for a, v in zip(axes, program.angles_deg[pose], strict=True))
        say(f"pose {pose}/{program.n_poses - 1} ({ang} deg): press Enter when the machine is in position")

    return _KeyTrigger(opts, key_source or StdinKeys(), prompt)
