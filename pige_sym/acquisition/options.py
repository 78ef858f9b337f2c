"""What an acquisition is asked (:class:`AcquisitionOptions`) and what it reports (:class:`AcquisitionSummary`).

The meaning of every option is in :mod:`pige_sym.acquisition.engine`; the summary is written to
``<stem>.acq.json`` beside the measurement file.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from typing import Any

from pige_sym.constants import TRIGGERS
from pige_sym.errors import InputError
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


def default_max_bytes(program: TestProgram) -> int:
    """Default byte budget of one session: 16 MiB plus 128 kB per second of program [bytes].

    A fast nest (1 kHz, 64-byte records) sends 64 kB/s, so the budget holds a run twice over;
    a runaway stream is stopped after a few seconds instead of filling the disk.
    """
    return int(16 * 2**20 + 128_000 * program.duration_s)
