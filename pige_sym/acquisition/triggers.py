"""Triggers: which samples of the stream belong to the averaging window of the current pose.

``stable`` (settle detection that ignores spikes, cross-checked with the program's timing),
``schedule`` (the program's times) and ``key`` (the operator).  The behaviour of each is
described in :mod:`pige_sym.acquisition.engine`.
"""

from __future__ import annotations

import queue
import sys
import threading
from collections import deque
from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np

from pige_sym.acquisition.device import Sample
from pige_sym.errors import AcquisitionStop as Stop
from pige_sym.nc.rtest_program import TestProgram

if TYPE_CHECKING:
    from pige_sym.acquisition.options import AcquisitionOptions


_Stop = Stop


class StdinKeys:
    """Key source for ``trigger="key"``: True once per line typed on stdin (Enter)."""

    def __init__(self) -> None:
        self._q: queue.Queue[str] = queue.Queue()
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        for line in sys.stdin:
            self._q.put(line)

    def __call__(self) -> bool:
        try:
            self._q.get_nowait()
        except queue.Empty:
            return False
        return True


# --------------------------------------------------------------------------------------------- triggers


class _Trigger:
    """Decides, sample by sample, whether a sample belongs to the current pose's window.

    ``step`` returns ``"skip"`` (not averaged), ``"take"`` (averaged) or ``"done"`` (the
    window is over; the sample is then offered to the next pose).  After ``"done"``,
    ``assigned`` is the pose the window belongs to (greater than the current pose when
    poses were passed unseen) and ``doubtful`` a reason not to write it, or None.
    """

    reason = "complete"

    def __init__(self) -> None:
        self.assigned = 0
        self.doubtful: str | None = None

    def begin(self, pose: int, level: np.ndarray | None) -> None:
        self.reason = "complete"
        self.assigned = pose
        self.doubtful = None

    def step(self, s: Sample, r: np.ndarray, gap: bool) -> str:
        raise NotImplementedError

    def confirm(self, pose: int) -> None:  # noqa: B027 - optional hook
        """The window of ``pose`` was written: it anchors the timing of the next ones."""

    @property
    def level(self) -> np.ndarray | None:
        return None

    def status(self) -> str:
        return ""


def _runs(flags: np.ndarray) -> list[int]:
    """Lengths of the runs of True in a 1-D boolean array."""
    out: list[int] = []
    n = 0
    for f in flags:
        if f:
            n += 1
        elif n:
            out.append(n)
            n = 0
    if n:
        out.append(n)
    return out


class _StableTrigger(_Trigger):
    """Settle detection that ignores isolated spikes, cross-checked with the program's timing.

    A *spike* is a run of at most ``spike_samples`` consecutive readings outside the band
    (``tolerance_um`` from the level); a longer run is motion.  Spikes are left out of
    the averages (counted in ``spikes``).  A settle is checked against the program: its
    time after the last written pose (the *anchor*) must match the schedule of the
    current pose within ``timing_tol`` of the shortest pose cycle.  Too early: a
    spurious settle (the machine has not reached the pose), dropped and waited again
    for motion.  Matching a later pose: the poses in between were passed unseen (flagged).
    Matching no pose: the window is *doubtful* (flagged, not written).
    """

    def __init__(self, opts: AcquisitionOptions, program: TestProgram) -> None:
        super().__init__()
        self.o = opts
        self.arrive = program.arrive_s
        self.cycle_s = float(program.move_s + program.dwell_s.min())
        self.end_s = float(program.duration_s)
        self.phase = "settle"
        self.buf: deque[tuple[float, np.ndarray]] = deque(maxlen=opts.max_window_samples)
        self._level: np.ndarray | None = None
        self.t_first: float | None = None
        self.run = 0
        self.pose = 0
        self.settle_t = 0.0
        self.anchor: tuple[int, float] | None = None
        self.spikes = 0
        self.spurious = 0

    def begin(self, pose: int, level: np.ndarray | None) -> None:
        super().begin(pose, level)
        self.pose = pose
        self.phase = "motion" if (pose > 0 and level is not None) else "settle"
        self._level = level
        self.buf.clear()
        self.t_first = None
        self.run = 0

    def confirm(self, pose: int) -> None:
        if pose > 0:
            self.anchor = (pose, self.settle_t)

    @property
    def level(self) -> np.ndarray | None:
        return self._level

    def status(self) -> str:
        return {"motion": "waiting for motion", "settle": "settling", "window": "averaging"}[self.phase]

    def _outside(self, r: np.ndarray) -> bool:
        assert self._level is not None
        return bool(np.abs(r - self._level).max() > self.o.tolerance_um)

    def step(self, s: Sample, r: np.ndarray, gap: bool) -> str:
        self._check_program_end(s.t_s)
        if self.phase == "motion":
            return self._step_motion(s, r)
        if self.phase == "settle":
            return self._step_settle(s, r, gap)
        return self._step_window(s, r, gap)

    def _check_program_end(self, t: float) -> None:
        """Stop when the device time runs past the program's end (e.g. a device looping one pose)."""
        if self.anchor is None or not self.o.timing_check:
            return
        a, t_a = self.anchor
        limit = float(self.arrive[-1] - self.arrive[a]) + 2 * self.cycle_s + self.o.window_s
        if t - t_a > limit:
            raise _Stop(f"at pose {self.pose} the device time is {t - t_a:.0f} s past pose {a}, beyond the end of the "
                        "program: the machine stopped or the device repeats itself; restart and use --resume")

    def _step_motion(self, s: Sample, r: np.ndarray) -> str:
        if not self._outside(r):
            self.run = 0
            return "skip"
        self.run += 1
        if self.run > self.o.spike_samples:  # a run longer than a spike: the machine moves
            self.phase = "settle"
            self.buf.clear()
            self.buf.append((s.t_s, r))
        return "skip"

    def _step_settle(self, s: Sample, r: np.ndarray, gap: bool) -> str:
        if gap:
            self.buf.clear()
        self.buf.append((s.t_s, r))
        while self.buf and s.t_s - self.buf[0][0] > self.o.settle_s + 1e-9:
            self.buf.popleft()
        if s.t_s - self.buf[0][0] < self.o.settle_s - 1e-9 or len(self.buf) < 3:
            return "skip"
        level = self._settled_level(np.array([b[1] for b in self.buf]))
        if level is None:
            return "skip"
        previous = self._level
        self._level = level
        self.settle_t = s.t_s
        if self._timing_verdict(s.t_s) == "early":
            self.spurious += 1
            self._level = previous
            self.phase = "motion" if previous is not None else "settle"
            self.buf.clear()
            self.run = 0
            return "skip"
        self.phase = "window"
        self.t_first = None
        self.run = 0
        return "skip"

    def _settled_level(self, arr: np.ndarray) -> np.ndarray | None:
        """Mean of the settled readings, or None: every reading within ``tolerance_um`` peak to peak
        apart from at most one spike (a run of at most ``spike_samples`` readings far from the median).
        """
        tol = self.o.tolerance_um
        out = (np.abs(arr - np.median(arr, axis=0)) > tol).any(axis=1)
        runs = _runs(out)
        if len(runs) > 1 or (runs and runs[0] > self.o.spike_samples):
            return None
        inl = arr[~out]
        if inl.shape[0] < 3 or (inl.max(axis=0) - inl.min(axis=0)).max() > tol:
            return None
        return np.asarray(inl.mean(axis=0))

    def _timing_verdict(self, t: float) -> str:
        """``"early"``, or ``"ok"`` after setting ``assigned``/``doubtful`` (class docstring)."""
        if not self.o.timing_check or self.pose == 0 or self.anchor is None:
            return "ok"
        a, t_a = self.anchor
        elapsed = t - t_a
        tol = self.o.timing_tol * self.cycle_s
        expected = self.arrive[self.pose:] - self.arrive[a]
        if elapsed < expected[0] - tol:
            return "early"
        k = int(np.argmin(np.abs(expected - elapsed)))
        if abs(expected[k] - elapsed) <= tol:
            self.assigned = self.pose + k
        else:
            self.doubtful = (f"settled {elapsed:.1f} s after pose {a}, the program places pose {self.pose} at "
                             f"{expected[0]:.1f} s (and no pose within {tol:.1f} s)")
        return "ok"

    def _step_window(self, s: Sample, r: np.ndarray, gap: bool) -> str:
        if gap and self.t_first is not None:
            self.reason = "data gap"
            return "done"
        if self._outside(r):
            self.run += 1
            if self.run > self.o.spike_samples:
                self.reason = "machine left the pose"
                return "done"
            return "skip"  # perhaps a spike: left out; decided by the next readings
        if self.run:
            self.spikes += self.run
            self.run = 0
        if self.t_first is None:
            self.t_first = s.t_s
        if s.t_s - self.t_first >= self.o.window_s - 1e-9:
            return "done"
        return "take"


class _ScheduleTrigger(_Trigger):
    def __init__(self, opts: AcquisitionOptions, program: TestProgram) -> None:
        super().__init__()
        self.o = opts
        self.arrive = program.arrive_s
        self.t0: float | None = None
        self.lo = self.hi = 0.0

    def begin(self, pose: int, level: np.ndarray | None) -> None:
        super().begin(pose, level)
        self.lo = float(self.arrive[pose]) + self.o.delay_s
        self.hi = self.lo + self.o.window_s

    def status(self) -> str:
        return f"scheduled at {self.lo:.1f} s"

    def step(self, s: Sample, r: np.ndarray, gap: bool) -> str:
        if self.t0 is None:
            self.t0 = s.t_s
        tp = s.t_s - self.t0
        if tp < self.lo - 1e-9:
            return "skip"
        if tp < self.hi - 1e-9:
            return "take"
        return "done"


class _KeyTrigger(_Trigger):
    def __init__(self, opts: AcquisitionOptions, key_source: Callable[[], bool],
                 prompt: Callable[[int], None] | None) -> None:
        super().__init__()
        self.o = opts
        self.key_source = key_source
        self.prompt = prompt
        self.armed = False
        self.t_first: float | None = None

    def begin(self, pose: int, level: np.ndarray | None) -> None:
        super().begin(pose, level)
        self.armed = False
        self.t_first = None
        if self.prompt is not None:
            self.prompt(pose)

    def status(self) -> str:
        return "averaging" if self.armed else "press Enter when in position"

    def step(self, s: Sample, r: np.ndarray, gap: bool) -> str:
        if not self.armed:
            if not self.key_source():
                return "skip"
            self.armed = True
        if self.t_first is None:
            self.t_first = s.t_s
        if s.t_s - self.t_first >= self.o.window_s - 1e-9:
            return "done"
        return "take"
