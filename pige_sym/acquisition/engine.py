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
(:class:`~pige_sym.io.MeasurementWriter`).

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

import contextlib
import math
import os
import sys
import time
from collections import deque
from collections.abc import Callable, Iterable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from pige_sym.acquisition.device import DeviceAdapter, Info, RecordError, RTestProtocolAdapter, Sample, readings_array
from pige_sym.acquisition.nest import NestGeometry, default_nest
from pige_sym.acquisition.outputs import (
    _raw_log_path,
    _remove_partial_line,
    _write_summary,
    check_acquisition_files,
)
from pige_sym.acquisition.transport import PortSettings, RawLog, open_port, read_available
from pige_sym.acquisition.triggers import StdinKeys, _KeyTrigger, _ScheduleTrigger, _StableTrigger, _Stop, _Trigger
from pige_sym.codegen.machine_code import parse_machine_code
from pige_sym.constants import TRIGGERS as TRIGGERS
from pige_sym.errors import AcquisitionError, FileFormatError, InputError
from pige_sym.io import Measurement, MeasurementWriter, read_measurement
from pige_sym.kernels import load_kernels
from pige_sym.nc.rtest_program import TestProgram

#: A sequence number seen among the last this many samples and received again is a duplicate, not a restart.
RECENT_SEQS = 4096
EXTRA_COLUMNS = ("pose", "seq_first", "seq_last", "r1_um", "r2_um", "r3_um")


@dataclass(frozen=True)
class AcquisitionOptions:
    """How points are triggered and averaged (module docstring).

    Attributes
    ----------
    trigger : {"stable", "schedule", "key"}
    window_s : float [s]
        Averaging window per pose (device time).
    settle_s : float [s]
        Length of the stability test (``stable``).
    tolerance_um : float [µm]
        Peak-to-peak band of a settled reading, and the excursion that means motion.
    delay_s : float [s]
        Wait after the scheduled arrival before averaging (``schedule``).
    min_samples : int
        Fewer valid samples flag the pose (no row).
    max_gap_s : float [s]
        A longer gap in device time ends a window.
    reconnect_timeout_s : float [s]
        Give up when the port cannot be reopened (or stays silent) this long.
    retry_s : float [s]
        Pause between reopening attempts.
    frame : {"machine", "table"}
        Frame of the written deviations.
    replay_tol_um : float [µm]
        Largest difference between a replayed pose and its row (resume).
    spike_samples : int
        Longest run of out-of-band readings treated as a spike (left out) rather than motion.
    timing_check : bool
        Cross-check each settle with the program's schedule (``stable``); off for operator-paced programs.
    timing_tol : float
        Allowed timing difference, as a fraction of the shortest pose cycle (move + dwell).
    max_reconnects : int
        Reconnections in a row without a valid record before the run stops.
    max_window_samples : int
        Most samples kept for one window or settle test (memory bound); a full window ends.
    max_bytes : int or None [bytes]
        Most bytes read (and logged) in one session; None: sized for the run
        (:func:`default_max_bytes`).
    """

    trigger: str = "stable"
    window_s: float = 5.0
    settle_s: float = 0.5
    tolerance_um: float = 2.0
    delay_s: float = 1.0
    min_samples: int = 20
    max_gap_s: float = 1.0
    reconnect_timeout_s: float = 30.0
    retry_s: float = 0.1
    frame: str = "machine"
    replay_tol_um: float = 1.0
    spike_samples: int = 2
    timing_check: bool = True
    timing_tol: float = 0.3
    max_reconnects: int = 20
    max_window_samples: int = 100_000
    max_bytes: int | None = None

    def __post_init__(self) -> None:
        if self.trigger not in TRIGGERS:
            raise InputError(f"trigger must be one of {', '.join(TRIGGERS)}, got {self.trigger!r}")
        if self.frame not in ("machine", "table"):
            raise InputError(f"frame must be 'machine' or 'table', got {self.frame!r}")
        for name in ("window_s", "settle_s", "tolerance_um", "max_gap_s", "reconnect_timeout_s", "retry_s",
                     "replay_tol_um"):
            if not getattr(self, name) > 0:
                raise InputError(f"{name} must be > 0, got {getattr(self, name)!r}")
        if self.delay_s < 0:
            raise InputError("delay_s must be >= 0")
        if self.min_samples < 2:
            raise InputError(f"min_samples must be >= 2, got {self.min_samples}")
        if not 0 <= self.spike_samples <= 10:
            raise InputError(f"spike_samples must be 0 to 10, got {self.spike_samples}")
        if not 0 < self.timing_tol < 0.5:
            raise InputError(f"timing_tol must be in (0, 0.5) of a pose cycle, got {self.timing_tol!r}")
        if self.max_reconnects < 1 or self.max_window_samples < self.min_samples:
            raise InputError("max_reconnects must be >= 1 and max_window_samples >= min_samples")
        if self.max_bytes is not None and self.max_bytes < 4096:
            raise InputError(f"max raw log must be >= 4096 bytes, got {self.max_bytes}")
        for name in ("window_s", "settle_s", "tolerance_um", "max_gap_s", "reconnect_timeout_s", "retry_s",
                     "replay_tol_um", "delay_s"):
            if not math.isfinite(getattr(self, name)):
                raise InputError(f"{name} must be finite, got {getattr(self, name)!r}")


@dataclass
class AcquisitionSummary:
    """What one acquisition session read, rejected, wrote and why it stopped.

    Counts are for this session.  ``missing`` counts sequence numbers skipped
    between accepted samples (records lost in transit or rejected).
    """

    port: str
    out: str
    raw_log: str | None
    program: str
    n_poses: int
    first_pose: int = 0
    rows_written: int = 0
    poses_replayed: int = 0
    flagged: list[dict[str, Any]] = field(default_factory=list)
    bytes_read: int = 0
    frames: int = 0
    accepted: int = 0
    info_records: int = 0
    rejected: dict[str, int] = field(default_factory=dict)
    noise_bytes: int = 0
    noise_runs: int = 0
    missing: int = 0
    gaps: int = 0
    timeouts: int = 0
    stalls: int = 0
    disconnects: int = 0
    reconnects: int = 0
    spikes: int = 0
    spurious_settles: int = 0
    resumed: bool = False
    removed_partial_line: bool = False
    completed: bool = False
    stop_reason: str | None = None
    device_info: list[str] = field(default_factory=list)
    wall_s: float = 0.0

    @property
    def rejected_total(self) -> int:
        return sum(self.rejected.values())

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["rejected_total"] = self.rejected_total
        return d

    def format(self) -> str:
        """A few lines for the terminal."""
        done = self.first_pose + self.rows_written + len([f for f in self.flagged if f["pose"] >= self.first_pose])
        head = "acquisition complete" if self.completed else f"acquisition stopped: {self.stop_reason}"
        lines = [
            head,
            f"poses: {done}/{self.n_poses} done, {self.rows_written} rows written to {self.out}"
            + (f", {self.poses_replayed} replayed (resume from pose {self.first_pose})" if self.resumed else "")
            + (f", flagged (no row): {', '.join(str(f['pose']) for f in self.flagged)}" if self.flagged else ""),
            f"records: {self.accepted} samples accepted of {self.frames} frames, {self.bytes_read} bytes read",
        ]
        why = ", ".join(f"{k} {v}" for k, v in sorted(self.rejected.items()) if v)
        lines.append(f"rejected: {self.rejected_total}" + (f" ({why})" if why else ""))
        lines.append(f"missing by sequence gaps: {self.missing}; noise: {self.noise_bytes} bytes in "
                     f"{self.noise_runs} runs; device-time gaps > max gap: {self.gaps}")
        lines.append(f"link: {self.timeouts} timeouts in {self.stalls} stalls, {self.disconnects} disconnects, "
                     f"{self.reconnects} reconnects")
        if self.spikes or self.spurious_settles:
            lines.append(f"spikes left out: {self.spikes} readings; spurious settles dropped: {self.spurious_settles}")
        if self.raw_log:
            lines.append(f"raw log: {self.raw_log}")
        for f in self.flagged:
            lines.append(f"flagged pose {f['pose']}: {f['n_samples']} valid samples ({f['reason']})")
        return "\n".join(lines)


# --------------------------------------------------------------------------------------------- points


def point_statistics(readings_um: np.ndarray, zero_um: np.ndarray, nest: NestGeometry,
                     rotation: np.ndarray | None) -> tuple[np.ndarray, float]:
    """Mean ball-centre deviation and its per-sample spread from raw readings.

    Parameters
    ----------
    readings_um : ndarray, shape=(m, 3) [µm]
        Raw readings of the window's samples.
    zero_um : ndarray, shape=(3,) [µm]
        Readings at the reference pose.
    nest : NestGeometry
    rotation : ndarray, shape=(3, 3) or None
        Nominal workpiece rotation of the pose (nest frame → machine frame), None to stay in the nest frame.

    Returns
    -------
    mean_um : ndarray, shape=(3,) [µm]
    sd_um : float [µm]
        Root mean square of the three per-axis sample standard deviations (ddof=1).
    """
    d = nest.displacement(readings_um - zero_um)
    if rotation is not None:
        d = d @ rotation.T
    sd = float(np.sqrt(np.mean(np.var(d, axis=0, ddof=1)))) if d.shape[0] > 1 else 0.0
    return d.mean(axis=0), sd


def _fmt(x: float) -> str:
    return repr(float(x))


def _template(program: TestProgram, nest: NestGeometry, opts: AcquisitionOptions, zero: np.ndarray) -> Measurement:
    k = len(program.rotary_axes)
    meta: dict[str, str] = {"machine": "", "ball_mm": "", "frame": opts.frame}
    if program.tool_mm is not None:
        meta["tool_mm"] = ""
    for ax in program.pivots_mm:
        meta[f"pivot_{ax}_mm"] = ""
    meta["trajectory"] = ""
    meta["source"] = "pige acquire"
    meta["nest"] = nest.description
    meta["zero_um"] = ", ".join(_fmt(z) for z in zero)
    meta["acquisition"] = (f"trigger={opts.trigger} window_s={opts.window_s:g} settle_s={opts.settle_s:g} "
                           f"tolerance_um={opts.tolerance_um:g} min_samples={opts.min_samples}")
    empty = np.zeros(0)
    return Measurement(
        machine=program.machine, ball_mm=program.ball_mm, t_s=empty, angles_deg=np.zeros((0, k)),
        deviation_um=np.zeros((0, 3)), rotary_axes=program.rotary_axes, frame=opts.frame, tool_mm=program.tool_mm,
        pivots_mm=dict(program.pivots_mm), trajectory=program.description, linear_mm=np.zeros((0, 3)),
        optional={"n_samples": empty, "sd_um": empty}, extra_columns={c: [] for c in EXTRA_COLUMNS}, metadata=meta,
    )


@dataclass
class _ResumeState:
    start_pose: int
    zero: np.ndarray
    rows: dict[int, np.ndarray]
    last_t: float


def _read_resume(path: Path, program: TestProgram, nest: NestGeometry, opts: AcquisitionOptions) -> _ResumeState | None:
    """State to continue a partial file, None when it holds no data row yet."""
    lines = path.read_text(encoding="utf-8").splitlines()
    if sum(1 for ln in lines if ln.strip() and not ln.startswith("#")) < 2:
        return None  # no data row (at most the column header): nothing measured yet
    m = read_measurement(path)
    problems = []
    if parse_machine_code(m.machine).canonical != program.machine:
        problems.append(f"machine {m.machine} (now {program.machine})")
    if not np.array_equal(m.ball_mm, program.ball_mm):
        problems.append(f"ball_mm {m.ball_mm.tolist()} (now {program.ball_mm.tolist()})")
    if m.frame != opts.frame:
        problems.append(f"frame {m.frame} (now {opts.frame})")
    if (m.tool_mm is None) != (program.tool_mm is None) or (
            m.tool_mm is not None and program.tool_mm is not None and not np.array_equal(m.tool_mm, program.tool_mm)):
        problems.append("tool_mm")
    if set(m.pivots_mm) != set(program.pivots_mm) or any(
            not np.array_equal(m.pivots_mm[a], program.pivots_mm[a]) for a in m.pivots_mm):
        problems.append("pivots")
    if m.trajectory != program.description:
        problems.append(f"program {m.trajectory!r} (now {program.description!r})")
    if m.metadata.get("nest") != nest.description:
        problems.append(f"nest {m.metadata.get('nest')!r} (now {nest.description!r})")
    if problems:
        raise AcquisitionError(f"{path}: cannot resume, the file was recorded with a different set-up: "
                               + "; ".join(problems) + ". Use the same options, or write to a new --out file")
    if "pose" not in m.extra_columns or "zero_um" not in m.metadata:
        raise AcquisitionError(f"{path}: not written by pige acquire (no pose column or zero_um): cannot resume")
    try:
        poses = [int(p) for p in m.extra_columns["pose"]]
        zero = np.array([float(x) for x in m.metadata["zero_um"].split(",")])
    except ValueError:
        raise FileFormatError(str(path), None, "bad pose column or zero_um metadata") from None
    if zero.shape != (3,) or poses[0] != 0 or any(b <= a for a, b in zip(poses, poses[1:], strict=False)):
        raise FileFormatError(str(path), None, "pose column must start at 0 and increase; zero_um needs 3 numbers")
    if poses[-1] >= program.n_poses:
        raise AcquisitionError(f"{path}: pose {poses[-1]} is beyond the program's {program.n_poses} poses")
    rows = {p: m.deviation_um[i] for i, p in enumerate(poses)}
    return _ResumeState(poses[-1] + 1, zero, rows, float(m.t_s[-1]))


class _Engine:
    """Pose state: triggers, windows, rows."""

    def __init__(self, program: TestProgram, out: Path, nest: NestGeometry, opts: AcquisitionOptions,
                 summary: AcquisitionSummary, resume: _ResumeState | None, trigger: _Trigger,
                 on_pose: Callable[[int], None]) -> None:
        self.program = program
        self.out = out
        self.nest = nest
        self.o = opts
        self.summary = summary
        self.resume = resume
        self.trigger = trigger
        self.on_pose = on_pose
        kern = load_kernels(program.machine)
        self.rot = np.asarray(kern.workpiece_rotation(program.angles_deg))
        self.linear = program.linear_mm()
        self.start_pose = resume.start_pose if resume else 0
        self.pose = 0
        self.window: list[Sample] = []
        self.zero: np.ndarray | None = None
        self.t0: float | None = None
        self.last_t: float | None = None
        self.last_row_t = resume.last_t if resume else -math.inf
        self.writer: MeasurementWriter | None = None
        if resume is not None:
            self.writer = MeasurementWriter(out, _template(program, nest, opts, resume.zero), append=True)
        cycle = program.move_s + program.dwell_s
        self.lost_pose_s = float(cycle.min()) if opts.trigger == "stable" else math.inf
        self.trigger.begin(0, None)

    @property
    def done(self) -> bool:
        return self.pose >= self.program.n_poses

    def close(self) -> None:
        if self.writer is not None:
            self.writer.close()
            self.summary.rows_written = self.writer.rows_written()  # the file decides, not the counter

    def on_sample(self, s: Sample) -> None:
        gap = False
        if self.last_t is not None:
            dt = s.t_s - self.last_t
            if dt <= 0:
                raise _Stop(f"device time went back from {self.last_t:g} s to {s.t_s:g} s (device restarted?) at "
                            f"pose {self.pose}: restart the program and run again with --resume")
            if dt > self.o.max_gap_s:
                gap = True
                self.summary.gaps += 1
                if dt > self.lost_pose_s:
                    raise _Stop(f"no data for {dt:g} s of device time at pose {self.pose}, longer than a pose cycle: "
                                "the machine may have passed a pose unseen; restart the program and use --resume")
        self.last_t = s.t_s
        r = np.asarray(s.readings_um, dtype=float)
        while not self.done:
            verdict = self.trigger.step(s, r, gap)
            if verdict == "take":
                self.window.append(s)
                if len(self.window) < self.o.max_window_samples:
                    return
                self.trigger.reason = f"window full ({self.o.max_window_samples} samples)"
            elif verdict == "skip":
                return
            self._finish_pose(self.trigger.reason)
            gap = False
            if not self.done:
                self.trigger.begin(self.pose, self.trigger.level)
            if verdict == "take":
                return

    def _flag(self, pose: int, n: int, reason: str) -> None:
        """No row for ``pose`` (nothing is invented); the summary lists it."""
        if pose >= self.start_pose:
            self.summary.flagged.append({"pose": pose, "n_samples": n, "reason": reason})
        self.pose = pose + 1
        self.on_pose(pose)

    def _finish_pose(self, reason: str) -> None:
        samples = self.window
        self.window = []
        n = len(samples)
        for unseen in range(self.pose, min(self.trigger.assigned, self.program.n_poses)):
            self._flag(unseen, 0, "passed unseen: no motion seen before it; the program timing places the next "
                       "window later")
        pose = self.pose
        if self.trigger.doubtful is not None:
            self._flag(pose, n, f"doubtful pose assignment: {self.trigger.doubtful}")
            return
        if n < self.o.min_samples:
            if pose == 0:
                raise _Stop(f"reference pose: only {n} valid samples ({reason}); the nest cannot be zeroed. Check the "
                            f"dwell (it must exceed settling + {self.o.window_s:g} s) and the link")
            self._flag(pose, n, reason)
            return
        if isinstance(self.trigger, _ScheduleTrigger):
            samples, why = self._scheduled_window(samples)
            if why:
                self._flag(pose, len(samples), why)
                return
        raw = readings_array(samples)
        mean_raw = raw.mean(axis=0)
        t_mean = float(np.mean([x.t_s for x in samples]))
        if pose == 0:
            self._zero(mean_raw, t_mean)
        assert self.zero is not None
        rot = self.rot[pose] if self.o.frame == "machine" else None
        mean, sd = point_statistics(raw, self.zero, self.nest, rot)
        if pose == 0:
            mean = np.zeros(3)
        if pose < self.start_pose:
            self._check_replay(pose, mean)
        else:
            self._write_row(pose, samples, mean, sd, mean_raw, t_mean)
        self.trigger.confirm(pose)
        self.pose += 1
        self.on_pose(pose)

    def _scheduled_window(self, samples: list[Sample]) -> tuple[list[Sample], str | None]:
        """A window placed by the schedule: spikes (readings beyond ``tolerance_um`` from the window's median)
        are left out; a window where more than a tenth of the readings are off is not a pose (flagged)."""
        raw = readings_array(samples)
        off = (np.abs(raw - np.median(raw, axis=0)) > self.o.tolerance_um).any(axis=1)
        n_off = int(off.sum())
        if n_off > 0.1 * len(samples):
            return samples, (f"doubtful pose: {n_off} of {len(samples)} readings farther than "
                             f"{self.o.tolerance_um:g} um from the window's median (the machine was not still)")
        self.summary.spikes += n_off
        kept = [x for x, bad in zip(samples, off, strict=True) if not bad]
        if len(kept) < self.o.min_samples:
            return kept, f"only {len(kept)} valid samples after leaving out {n_off} spikes"
        return kept, None

    def _zero(self, mean_raw: np.ndarray, t_mean: float) -> None:
        """The reference window zeroes the nest (or must match the zero of the file being resumed)."""
        self.t0 = t_mean
        if self.resume is None:
            self.zero = mean_raw
            self.writer = MeasurementWriter(self.out, _template(self.program, self.nest, self.o, mean_raw))
            return
        if np.abs(mean_raw - self.resume.zero).max() > self.o.replay_tol_um:
            raise AcquisitionError(
                f"resume: the reference readings {np.round(mean_raw, 3).tolist()} um differ from the file's "
                f"zero {np.round(self.resume.zero, 3).tolist()} um by more than {self.o.replay_tol_um:g} um: "
                "the nest moved or was re-zeroed; start a new file")
        self.zero = self.resume.zero

    def _check_replay(self, pose: int, mean: np.ndarray) -> None:
        """A pose already in the resumed file, measured again: it must agree with its row."""
        self.summary.poses_replayed += 1
        row = self.resume.rows.get(pose) if self.resume else None
        if row is not None and np.abs(mean - row).max() > self.o.replay_tol_um:
            raise AcquisitionError(
                f"resume: pose {pose} measured again differs from its row by {np.abs(mean - row).max():.3g} um "
                f"(> {self.o.replay_tol_um:g} um): the machine must run the program again from its start with the "
                "same set-up")

    def _write_row(self, pose: int, samples: list[Sample], mean: np.ndarray, sd: float, mean_raw: np.ndarray,
                   t_mean: float) -> None:
        assert self.t0 is not None and self.writer is not None
        t_row = 0.0 if pose == 0 else max(t_mean - self.t0, self.last_row_t)
        seqs = [x.seq for x in samples]
        extra = {"pose": str(pose), "seq_first": "" if seqs[0] is None else str(seqs[0]),
                 "seq_last": "" if seqs[-1] is None else str(seqs[-1]),
                 "r1_um": _fmt(mean_raw[0]), "r2_um": _fmt(mean_raw[1]), "r3_um": _fmt(mean_raw[2])}
        self.writer.write_row(t_row, self.program.angles_deg[pose], mean, self.linear[pose],
                              {"n_samples": float(len(samples)), "sd_um": sd}, extra)
        self.last_row_t = t_row
        self.summary.rows_written += 1


# --------------------------------------------------------------------------------------------- the loop


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
    state = _prepare_resume(out_p, program, nest, opts, summary, say) if resume else None
    if summary.completed:
        _write_summary(summary, out_p)
        return summary
    trigger = _make_trigger(opts, program, key_source, say)
    link = _Link(port, settings or PortSettings(), opts, adapter or RTestProtocolAdapter(), opener, summary)
    session = _open_session(link, program, out_p, nest, state, trigger, (log_path, resume or not force), progress)
    _run_session(session, started, out_p, say)
    return summary


def _open_session(link: _Link, program: TestProgram, out: Path, nest: NestGeometry, state: Any,
                  trigger: _Trigger, raw_log: tuple[Path | None, bool], progress: bool) -> _Session:
    """Open the port, then assemble engine, raw log, record pipeline and progress bars.

    Nothing is written before the port is open: a failing port leaves an existing raw log as it was.
    ``raw_log`` is (path or None, append).
    """
    opts, summary = link.opts, link.summary
    bars = _ProgressBars(program.n_poses, opts.window_s, progress)
    try:
        link.open()
    except AcquisitionError:
        bars.close()
        raise
    engine = _Engine(program, out, nest, opts, summary, state, trigger, bars.on_pose)
    log = RawLog(raw_log[0], append=raw_log[1])
    return _Session(link, _Records(link.adapter, summary, engine), engine, log, summary, link.settings, opts,
                    opts.max_bytes or default_max_bytes(program), bars, progress)


def _run_session(session: _Session, started: float, out: Path, say: Callable[[str], None]) -> None:
    """Run the loop; whatever ends it, the file is closed and the summary written (re-raising interrupts)."""
    summary = session.summary
    try:
        session.run()
        summary.completed = True
    except _Stop as stop:
        summary.stop_reason = str(stop)
    except (KeyboardInterrupt, AcquisitionError) as exc:
        interrupted = isinstance(exc, KeyboardInterrupt)
        summary.stop_reason = "interrupted (Ctrl-C or SIGTERM)" if interrupted else str(exc)
        _finish(session, started, out)
        if interrupted:
            say(summary.format())
        raise
    _finish(session, started, out)


def default_max_bytes(program: TestProgram) -> int:
    """Default byte budget of one session: 16 MiB plus 128 kB per second of program [bytes].

    A fast nest (1 kHz, 64-byte records) sends 64 kB/s, so the budget holds a run twice over;
    a runaway stream is stopped after a few seconds instead of filling the disk.
    """
    return int(16 * 2**20 + 128_000 * program.duration_s)


def _prepare_resume(out: Path, program: TestProgram, nest: NestGeometry, opts: AcquisitionOptions,
                    summary: AcquisitionSummary, say: Callable[[str], None]) -> _ResumeState | None:
    """Resume state of ``out`` (None: start a new file); ``summary.completed`` when nothing is left."""
    if not out.exists():
        say(f"resume: {out} does not exist yet, starting a new file")
        return None
    summary.resumed = True
    summary.removed_partial_line = _remove_partial_line(out)
    if summary.removed_partial_line:
        say(f"resume: removed an incomplete last line from {out}")
    state = _read_resume(out, program, nest, opts)
    if state is None:
        return None
    summary.first_pose = state.start_pose
    if state.start_pose >= program.n_poses:
        summary.completed = True
        say(f"resume: {out} already holds every pose of the program")
        return state
    say(f"resume: {out} holds poses up to {state.start_pose - 1}; the program is measured again from "
        f"its start and rows are appended from pose {state.start_pose}")
    return state


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


class _ProgressBars:
    """Overall and per-point tqdm bars on stderr (disabled unless ``progress``)."""

    def __init__(self, n_poses: int, window_s: float, progress: bool) -> None:
        from tqdm import tqdm

        self.window_s = window_s
        self.overall = tqdm(total=n_poses, unit="pose", desc="poses", disable=not progress, position=0,
                            dynamic_ncols=True, file=sys.stderr)
        self.point = tqdm(total=window_s, unit="s", desc="point", disable=not progress, position=1, leave=False,
                          dynamic_ncols=True, file=sys.stderr,
                          bar_format="{desc}: {percentage:3.0f}%|{bar}| {n:.1f}/{total:g} s{postfix}")

    def on_pose(self, pose: int) -> None:
        self.overall.update(1)
        self.point.reset(total=self.window_s)

    def show(self, engine: _Engine, summary: AcquisitionSummary) -> None:
        win = engine.window
        self.point.n = min((win[-1].t_s - win[0].t_s) if len(win) > 1 else 0.0, self.window_s)
        self.point.set_description_str(f"pose {engine.pose}")
        self.point.set_postfix_str(f"{engine.trigger.status()}, {len(win)} samples, "
                                   f"{summary.rejected_total} rejected", refresh=True)

    def close(self) -> None:
        self.overall.close()
        self.point.close()


class _Session:
    """The read loop of one acquisition, with every resource bounded.

    Bounds: bytes read per session (``max_bytes``, logged up to the limit), time without a
    valid record (``reconnect_timeout_s``: a silent port, noise, an endless line or a port
    that accepts and closes), reconnections in a row without a valid record
    (``max_reconnects``), samples per window (``max_window_samples``) and frame length (the
    framer's ``max_len``).  Each ends the run through :class:`_Stop` with a reason.
    """

    def __init__(self, link: _Link, records: _Records, engine: _Engine, log: RawLog, summary: AcquisitionSummary,
                 settings: PortSettings, opts: AcquisitionOptions, max_bytes: int, bars: _ProgressBars,
                 progress: bool) -> None:
        self.link, self.records, self.engine, self.log = link, records, engine, log
        self.summary, self.settings, self.o = summary, settings, opts
        self.max_bytes = max_bytes
        self.bars = bars
        self.progress = progress
        now = time.monotonic()
        self.timer = self.last_valid = now
        self.last_reconnect = -math.inf
        self.reconnects_in_a_row = 0
        self.accepted_seen = 0
        self.in_stall = False
        self.last_status = 0.0

    def run(self) -> None:
        import serial  # pyserial: imported when a port is used, not when the command line is built

        while not self.engine.done:
            self._check_valid_records()
            try:
                data = self.link.read()
            except (serial.SerialException, OSError):
                self.summary.disconnects += 1
                self._reconnect()
                continue
            if not data:
                self._on_silence()
                continue
            self.in_stall = False
            self.timer = time.monotonic()
            self._log(data)
            self.records.feed(data)
            if self.progress and self.timer - self.last_status > 0.1:
                self.last_status = self.timer
                self.bars.show(self.engine, self.summary)

    def _check_valid_records(self) -> None:
        now = time.monotonic()
        if self.summary.accepted != self.accepted_seen:
            self.accepted_seen = self.summary.accepted
            self.last_valid = now
            self.reconnects_in_a_row = 0
        elif now - self.last_valid >= self.o.reconnect_timeout_s:
            s = self.summary
            raise _Stop(f"no valid record from the device for {now - self.last_valid:.0f} s at pose "
                        f"{self.engine.pose} ({s.bytes_read} bytes read, {s.rejected_total} records rejected, "
                        f"{self.records.framer.noise_bytes} noise bytes, {s.reconnects} reconnects): check the port, "
                        "its settings and the device, then run again with --resume")

    def _on_silence(self) -> None:
        now = time.monotonic()
        if now - self.timer < self.settings.timeout_s:
            return
        self.summary.timeouts += 1
        if not self.in_stall:
            self.summary.stalls += 1
            self.in_stall = True
        self._reconnect()

    def _reconnect(self) -> None:
        self.reconnects_in_a_row += 1
        if self.reconnects_in_a_row > self.o.max_reconnects:
            raise _Stop(f"reconnected {self.o.max_reconnects} times in a row without a valid record at pose "
                        f"{self.engine.pose}: the port accepts and drops the link; check the device, then run "
                        "again with --resume")
        pause = self.last_reconnect + self.o.retry_s - time.monotonic()
        if pause > 0:
            time.sleep(pause)  # a port that fails at once is not hammered
        self.records.reset()
        self.link.reopen(self.engine.pose)
        self.last_reconnect = self.timer = time.monotonic()

    def _log(self, data: bytes) -> None:
        """Log (and flush) the bytes before anything is parsed; stop at the byte budget."""
        room = self.max_bytes - self.summary.bytes_read
        if len(data) > room:
            self.log.write(data[:max(room, 0)])
            self.summary.bytes_read += max(room, 0)
            raise _Stop(f"read {self.max_bytes} bytes at pose {self.engine.pose}, the byte budget of this run "
                        "(--max-raw-log): the device sends far more than the program needs; check its rate, "
                        "or raise --max-raw-log")
        self.log.write(data)
        self.summary.bytes_read += len(data)


class _Link:
    """The port of one acquisition: opened, reopened after a failure, read without losing bytes."""

    def __init__(self, port: str, settings: PortSettings, opts: AcquisitionOptions, adapter: DeviceAdapter,
                 opener: Callable[[], Any] | None, summary: AcquisitionSummary) -> None:
        self.port = port
        self.settings = settings
        self.opts = opts
        self.adapter = adapter
        self.opener = opener
        self.summary = summary
        self.conn: Any = None

    def _open(self) -> Any:
        conn = self.opener() if self.opener is not None else open_port(self.port, self.settings)
        self.adapter.on_connect(conn)
        return conn

    def open(self) -> None:
        import serial  # pyserial: imported when a port is used, not when the command line is built

        """First opening: a failure is the user's to fix (AcquisitionError)."""
        try:
            self.conn = self._open()
        except (AcquisitionError, serial.SerialException, OSError) as exc:
            raise AcquisitionError(str(exc)) from None

    def reopen(self, pose: int) -> None:
        import serial  # pyserial: imported when a port is used, not when the command line is built

        """Close and reopen every ``retry_s`` until it works or ``reconnect_timeout_s`` has passed."""
        self.close()
        deadline = time.monotonic() + self.opts.reconnect_timeout_s
        while True:
            try:
                self.conn = self._open()
                self.summary.reconnects += 1
                return
            except (AcquisitionError, serial.SerialException, OSError) as exc:
                if time.monotonic() >= deadline:
                    raise _Stop(f"lost the device at pose {pose}: could not reopen {self.port} for "
                                f"{self.opts.reconnect_timeout_s:g} s ({exc}); run again with --resume") from None
                time.sleep(self.opts.retry_s)

    def read(self) -> bytes:
        self.adapter.poll(self.conn)
        return read_available(self.conn, self.settings.poll_s)

    def close(self) -> None:
        if self.conn is not None:
            with contextlib.suppress(Exception):  # the port may already be broken
                self.conn.close()
            self.conn = None


class _Records:
    """Bytes → frames → records → sequence check → engine."""

    def __init__(self, adapter: DeviceAdapter, summary: AcquisitionSummary, engine: _Engine) -> None:
        self.adapter = adapter
        self.summary = summary
        self.engine = engine
        self.framer = adapter.new_framer()
        self.last_seq: int | None = None
        self.recent: set[int] = set()  # sequence numbers of the last RECENT_SEQS accepted samples
        self._recent_order: deque[int] = deque()

    def reset(self) -> None:
        """A new connection: a partial frame is dropped (counted as truncated)."""
        self.framer.reset()

    def _remember(self, seq: int) -> None:
        self.recent.add(seq)
        self._recent_order.append(seq)
        if len(self._recent_order) > RECENT_SEQS:
            self.recent.discard(self._recent_order.popleft())

    def _reject(self, reason: str) -> None:
        self.summary.rejected[reason] = self.summary.rejected.get(reason, 0) + 1

    def feed(self, data: bytes) -> None:
        s, engine = self.summary, self.engine
        for frame in self.framer.feed(data):
            try:
                rec = self.adapter.parse(frame)
            except RecordError as exc:
                self._reject(exc.reason)
                continue
            if isinstance(rec, Info):
                s.info_records += 1
                if len(s.device_info) < 20:
                    s.device_info.append(rec.text)
                if rec.is_end and not engine.done:
                    raise _Stop(f"the device reported the end of its program before pose {engine.pose} "
                                f"of {engine.program.n_poses} was measured")
                continue
            if rec.seq is not None and self.last_seq is not None:
                if rec.seq == self.last_seq or (rec.seq < self.last_seq and rec.seq in self.recent):
                    self._reject("duplicate")  # sent again (also out of order, e.g. a gateway replaying its buffer)
                    continue
                if rec.seq < self.last_seq:
                    raise _Stop(f"the device restarted (sequence {self.last_seq} then {rec.seq}) at pose "
                                f"{engine.pose}: run again with --resume")
                s.missing += rec.seq - self.last_seq - 1
            if rec.seq is not None:
                self.last_seq = rec.seq
                self._remember(rec.seq)
            s.accepted += 1
            engine.on_sample(rec)
            if engine.done:
                return


def _finish(session: _Session, started: float, out: Path) -> None:
    summary, records = session.summary, session.records
    session.bars.close()
    session.link.close()
    session.engine.close()
    session.log.close()
    fr = records.framer
    summary.frames = fr.frames
    summary.noise_bytes = fr.noise_bytes
    summary.noise_runs = fr.noise_runs
    for reason, count in (("truncated", fr.truncated), ("overlong", fr.overlong)):
        if count:
            summary.rejected[reason] = summary.rejected.get(reason, 0) + count
    trig = session.engine.trigger
    if isinstance(trig, _StableTrigger):
        summary.spikes += trig.spikes
        summary.spurious_settles = trig.spurious
    summary.wall_s = time.monotonic() - started
    if session.engine.writer is not None or out.exists():
        _write_summary(summary, out)
