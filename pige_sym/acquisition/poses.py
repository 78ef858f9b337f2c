"""Pose state of an acquisition: trigger, averaging window and the row written for each pose.

:class:`PoseEngine` receives valid samples one by one (from :mod:`pige_sym.acquisition.session`), asks the
trigger when a pose's window starts and ends, averages it (:func:`point_statistics`) and writes the row; the
rules are in :mod:`pige_sym.acquisition.engine`.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path

import numpy as np

from pige_sym.acquisition.device import Sample, readings_array
from pige_sym.acquisition.nest import NestGeometry
from pige_sym.acquisition.options import EXTRA_COLUMNS, AcquisitionOptions, AcquisitionSummary
from pige_sym.acquisition.resume import ResumeState
from pige_sym.acquisition.triggers import _ScheduleTrigger, _Stop, _Trigger
from pige_sym.errors import AcquisitionError
from pige_sym.kernels import load_kernels
from pige_sym.measurements.measurement import Measurement
from pige_sym.measurements.rtest_writer import MeasurementWriter
from pige_sym.nc.rtest_program import TestProgram


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


def row_template(program: TestProgram, nest: NestGeometry, opts: AcquisitionOptions, zero: np.ndarray) -> Measurement:
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
        axis_sense=dict(program.axis_sense),
    )


class PoseEngine:
    """Pose state: triggers, windows, rows."""

    def __init__(self, program: TestProgram, out: Path, nest: NestGeometry, opts: AcquisitionOptions,
                 summary: AcquisitionSummary, resume: ResumeState | None, trigger: _Trigger,
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
            self.writer = MeasurementWriter(out, row_template(program, nest, opts, resume.zero), append=True)
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
            self.writer = MeasurementWriter(self.out, row_template(self.program, self.nest, self.o, mean_raw))
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
