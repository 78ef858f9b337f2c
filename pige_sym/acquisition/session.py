"""One acquisition session: the port link with reconnection, the record pipeline, progress bars, the loop.

Bytes flow ``port → raw log → framer → adapter → sequence check → pose engine``; the link faults and
bounds are described in :mod:`pige_sym.acquisition.engine`.
"""

from __future__ import annotations

import contextlib
import math
import sys
import time
from collections import deque
from collections.abc import Callable
from pathlib import Path
from typing import Any

from pige_sym.acquisition.device import DeviceAdapter, Info, RecordError
from pige_sym.acquisition.nest import NestGeometry
from pige_sym.acquisition.options import RECENT_SEQS, AcquisitionOptions, AcquisitionSummary, default_max_bytes
from pige_sym.acquisition.outputs import _write_summary
from pige_sym.acquisition.poses import PoseEngine
from pige_sym.acquisition.transport import PortSettings, RawLog, open_port, read_available
from pige_sym.acquisition.triggers import _StableTrigger, _Stop, _Trigger
from pige_sym.errors import AcquisitionError
from pige_sym.files import clear_interrupt
from pige_sym.nc.rtest_program import TestProgram


def open_session(link: Link, program: TestProgram, out: Path, nest: NestGeometry, state: Any,
                  trigger: _Trigger, raw_log: tuple[Path | None, bool], progress: bool) -> Session:
    """Open the port, then assemble engine, raw log, record pipeline and progress bars.

    Nothing is written before the port is open: a failing port leaves an existing raw log as it was.
    ``raw_log`` is (path or None, append).
    """
    opts, summary = link.opts, link.summary
    bars = ProgressBars(program.n_poses, opts.window_s, progress)
    try:
        link.open()
    except AcquisitionError:
        bars.close()
        raise
    engine = PoseEngine(program, out, nest, opts, summary, state, trigger, bars.on_pose)
    log = RawLog(raw_log[0], append=raw_log[1])
    return Session(link, Records(link.adapter, summary, engine), engine, log, summary, link.settings, opts,
                    opts.max_bytes or default_max_bytes(program), bars, progress)


def run_session(session: Session, started: float, out: Path, say: Callable[[str], None]) -> None:
    """Run the loop; whatever ends it, the file is closed and the summary written (re-raising interrupts)."""
    summary = session.summary
    try:
        session.run()
        summary.completed = True
    except _Stop as stop:
        summary.stop_reason = str(stop)
    except (KeyboardInterrupt, AcquisitionError) as exc:
        interrupted = isinstance(exc, KeyboardInterrupt)
        if interrupted:  # handled here: the summary records it (a noted interrupt would stop its writing)
            clear_interrupt()
        summary.stop_reason = "interrupted (Ctrl-C or SIGTERM)" if interrupted else str(exc)
        finish_session(session, started, out)
        if interrupted:
            say(summary.format())
        raise
    finish_session(session, started, out)


class ProgressBars:
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

    def show(self, engine: PoseEngine, summary: AcquisitionSummary) -> None:
        win = engine.window
        self.point.n = min((win[-1].t_s - win[0].t_s) if len(win) > 1 else 0.0, self.window_s)
        self.point.set_description_str(f"pose {engine.pose}")
        self.point.set_postfix_str(f"{engine.trigger.status()}, {len(win)} samples, "
                                   f"{summary.rejected_total} rejected", refresh=True)

    def close(self) -> None:
        self.overall.close()
        self.point.close()


class Session:
    """The read loop of one acquisition, with every resource bounded.

    Bounds: bytes read per session (``max_bytes``, logged up to the limit), time without a
    valid record (``reconnect_timeout_s``: a silent port, noise, an endless line or a port
    that accepts and closes), reconnections in a row without a valid record
    (``max_reconnects``), samples per window (``max_window_samples``) and frame length (the
    framer's ``max_len``).  Each ends the run through :class:`_Stop` with a reason.
    """

    def __init__(self, link: Link, records: Records, engine: PoseEngine, log: RawLog, summary: AcquisitionSummary,
                 settings: PortSettings, opts: AcquisitionOptions, max_bytes: int, bars: ProgressBars,
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


class Link:
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


class Records:
    """Bytes → frames → records → sequence check → engine."""

    def __init__(self, adapter: DeviceAdapter, summary: AcquisitionSummary, engine: PoseEngine) -> None:
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


def finish_session(session: Session, started: float, out: Path) -> None:
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
