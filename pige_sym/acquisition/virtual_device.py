"""Virtual R-test device: a simulated machine and nest streaming the ``rtest`` protocol.

It runs as its own process (``pige rtest-sim``) on a real serial stack: a
pseudo-terminal (the acquirer opens the printed ``/dev/pts/N``) or a TCP socket
(``socket://127.0.0.1:PORT``).  The first line it prints is the port; it exits when
the program ends.

Machine and nest
----------------
The true ball-minus-nest deviation of each pose is the simulator's
(:func:`pige_sym.simulator.simulate`, noise-free: PIGEs and effects) plus a
positioning scatter of ``repeatability_um`` per component drawn for every pose
after the reference (where the nest is zeroed, so it has none by definition).  It
is turned into the nest frame W with the nominal workpiece rotation and into three
sensor readings with the nest geometry (:mod:`pige_sym.acquisition.nest`) plus a raw offset per
sensor (250–350 µm, like a preloaded probe).  Samples come at ``rate_hz`` of device
time, ``t_k = k / rate_hz``, on the program schedule (:mod:`pige_sym.nc.rtest_program`):

* dwell at pose i: readings of the pose + white noise ``noise_um`` + (i ≥ 1) a
  settling transient ``8 µm · exp(−τ/0.15 s) · sin(2π·3 Hz·τ + φ_j)``, τ the time since
  arrival;
* move from pose i to i+1 (``u`` from 0 to 1 over ``move_s``): readings of the
  deviation interpolated with ``s = (1 − cos πu)/2``, plus a following error
  ``15 µm · sin(πu)`` along a random direction, a 4 Hz, 3 µm vibration and noise.

Determinism: every sample is a function of (seed, pose index, segment, sample index
in the segment) — noise comes from ``default_rng([seed, pose, part])`` — so a
restarted device with the same seed sends the same stream.

Time and links
--------------
The device paces samples at ``rate_hz × time_scale`` per wall second and starts the
program when the first client connects.  When the client goes away the device
pauses (no sample is lost) for up to ``linger_s``; after that the program goes on
without a client (samples not sent are counted as ``unsent``) and a new client picks
up the stream where it is.  At the end it sends ``$RI,END``, waits until the client
has read everything and left (at most ``linger_s``), and exits.

Faults (``--faults garbage,checksum=5,...``; a bare name injects 3)
------------------------------------------------------------------
Placed at seeded random samples (one second or more from the ends, never closer
than the outage to each other):

``garbage``     a burst of 8–48 random bytes (any byte but ``$``) between two records
``checksum``    one digit of a reading changed, the CRC left as it was
``drop``        one record not sent (its sequence number is skipped)
``spike``       one record with ``SPIKE_UM`` (50 µm) added to one sensor, its CRC valid (a glitch the
                framer cannot see; the acquisition must not let it move a window or a pose)
``duplicate``   one record sent twice in a row (same sequence number)
``stall``       nothing sent for ``stall_s`` wall seconds (no sample lost)
``disconnect``  the link is dropped after the client has read everything (pty: closed
                and re-created under the same ``/dev/pts/N``; TCP: connection closed,
                a new one accepted); the ``outage_s`` of samples during the outage are
                lost; the device waits for the client to reconnect

Every injected fault is counted in the truth JSON (``injected``; sequence numbers
of affected records in ``affected``), rewritten atomically after each fault and at
exit (also on SIGTERM).
"""

from __future__ import annotations

import array
import contextlib
import fcntl
import json
import math
import os
import select
import socket
import subprocess
import sys
import termios
import time
import tty
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

import numpy as np

from pige_sym.acquisition.device import encode_info, encode_sample
from pige_sym.acquisition.nest import NestGeometry, default_nest
from pige_sym.constants import DEFAULT_BALL_MM
from pige_sym.constants import FAULT_KINDS as FAULT_KINDS
from pige_sym.effects import EffectInstance
from pige_sym.errors import AcquisitionError, InputError
from pige_sym.files import atomic_write_text, to_json
from pige_sym.kernels import DEFAULT_MACHINE, load_kernels
from pige_sym.nc.rtest_program import TestProgram
from pige_sym.simulator import simulate

#: faults that change the byte stream only (no timing, no link action): :meth:`VirtualRTest.wire`
STREAM_FAULTS = ("garbage", "checksum", "drop", "spike", "duplicate")
SPIKE_UM = 50.0
DEFAULT_FAULT_COUNT = 3
TRANSIENT_UM, TRANSIENT_TAU_S, TRANSIENT_HZ = 8.0, 0.15, 3.0
LAG_UM, VIBRATION_UM, VIBRATION_HZ = 15.0, 3.0, 4.0
SENSOR_PHASES = np.array([0.0, 2.1, 4.2])
CONNECT_SETTLE_S = 0.05
DRAIN_QUIET_S = 0.1


def parse_faults(spec: str | None) -> dict[str, int]:
    """``garbage,drop=5,...`` → {kind: count}; a bare kind means 3."""
    out: dict[str, int] = {}
    for part in filter(None, (p.strip() for p in (spec or "").split(","))):
        kind, eq, count = part.partition("=")
        kind = kind.strip()
        if kind not in FAULT_KINDS:
            raise InputError(f"--faults: unknown fault {kind!r}; use {', '.join(FAULT_KINDS)} (optionally kind=count)")
        try:
            n = int(count) if eq else DEFAULT_FAULT_COUNT
        except ValueError:
            raise InputError(f"--faults: {part!r}: the count must be an integer") from None
        if n < 0:
            raise InputError(f"--faults: {part!r}: the count must be >= 0")
        out[kind] = out.get(kind, 0) + n
    return out


@dataclass
class DeviceConfig:
    """Everything the virtual device simulates (module docstring).

    Attributes
    ----------
    program : TestProgram
    pige : dict of str to float [µm, µrad]
    effects : list of EffectInstance
    seed : int
    noise_um : float [µm]
        White noise of each sensor reading.
    repeatability_um : float [µm]
        Positioning scatter per pose and component (not at the reference pose).
    rate_hz : float [Hz]
        Samples per second of device time.
    time_scale : float
        Device seconds per wall second.
    nest : NestGeometry
    faults : dict of str to int
    stall_s, outage_s, linger_s : float [s]
        Stall length (wall), outage length (device time), wait for a client (wall).
    """

    program: TestProgram
    pige: dict[str, float] = field(default_factory=dict)
    effects: list[EffectInstance] = field(default_factory=list)
    seed: int = 0
    noise_um: float = 0.25
    repeatability_um: float = 0.2
    rate_hz: float = 20.0
    time_scale: float = 1.0
    nest: NestGeometry = field(default_factory=default_nest)
    faults: dict[str, int] = field(default_factory=dict)
    stall_s: float = 2.0
    outage_s: float = 0.5
    linger_s: float = 2.0

    def __post_init__(self) -> None:
        for name in ("rate_hz", "time_scale", "noise_um", "repeatability_um", "stall_s", "outage_s", "linger_s"):
            if not math.isfinite(getattr(self, name)):
                raise InputError(f"{name} must be a finite number, got {getattr(self, name)!r}")
        if not self.rate_hz > 0 or not self.time_scale > 0:
            raise InputError("rate and time scale must be > 0")
        if self.noise_um < 0 or self.repeatability_um < 0:
            raise InputError("noise and repeatability must be >= 0 um")
        if self.stall_s < 0 or self.outage_s < 0 or self.linger_s < 0:
            raise InputError("stall, outage and linger must be >= 0 s")


class VirtualRTest:
    """The deterministic sample stream of a configured device (no I/O).

    Attributes
    ----------
    t_s : ndarray, shape=(N,) [s]
        Device time of each sample.
    readings_um : ndarray, shape=(N, 3) [µm]
        Raw sensor readings.
    pose_of_sample : ndarray, shape=(N,)
        Pose index whose dwell holds the sample, −1 while moving.
    deviation_machine_um : ndarray, shape=(n, 3) [µm]
        True deviation per pose (with repeatability), machine frame.
    plan : dict of int to str
        Fault per sample index.
    """

    def __init__(self, cfg: DeviceConfig) -> None:
        self.cfg = cfg
        prog = cfg.program
        kern = load_kernels(prog.machine)
        sim = simulate(prog.machine, prog.trajectory(), pige=cfg.pige, ball_mm=prog.ball_mm,
                       pivots_mm=prog.pivots_mm or None, tool_mm=prog.tool_mm, effects=cfg.effects, noise_um=0.0,
                       seed=cfg.seed)
        self.sim_truth = sim.truth
        seed = cfg.seed
        d_m = sim.measurement.deviation_um.copy()
        for i in range(1, prog.n_poses):
            d_m[i] += np.random.default_rng([seed, i, 2]).normal(scale=cfg.repeatability_um, size=3)
        self.deviation_machine_um = d_m
        rot = np.asarray(kern.workpiece_rotation(prog.angles_deg))
        d_w = np.einsum("nji,nj->ni", rot, d_m)
        self.offsets_um = np.random.default_rng([seed, 0, 3]).uniform(250.0, 350.0, size=3)
        rate = cfg.rate_hz
        n_total = int(math.floor(prog.duration_s * rate + 1e-9))
        t = np.arange(n_total) / rate
        r = np.empty((n_total, 3))
        pose_of = np.full(n_total, -1)
        arrive, dwell = prog.arrive_s, prog.dwell_s

        def first(time_s: float) -> int:
            return min(n_total, int(math.ceil(time_s * rate - 1e-9)))

        for i in range(prog.n_poses):
            k0, k1 = first(arrive[i]), first(arrive[i] + dwell[i])
            tau = t[k0:k1] - arrive[i]
            noise = np.random.default_rng([seed, i, 0]).normal(size=(k1 - k0, 3)) * cfg.noise_um
            val = self.offsets_um + cfg.nest.readings(d_w[i]) + noise
            if i > 0:
                val += (TRANSIENT_UM * np.exp(-tau / TRANSIENT_TAU_S))[:, None] * np.sin(
                    2 * np.pi * TRANSIENT_HZ * tau[:, None] + SENSOR_PHASES)
            r[k0:k1] = val
            pose_of[k0:k1] = i
            if i + 1 < prog.n_poses:
                m0, m1 = k1, first(arrive[i + 1])
                rng = np.random.default_rng([seed, i + 1, 1])
                w = rng.normal(size=3)
                w /= np.linalg.norm(w)
                u = (t[m0:m1] - arrive[i] - dwell[i]) / max(prog.move_s, 1e-12)
                s = (1 - np.cos(np.pi * u)) / 2
                d = d_w[i] + s[:, None] * (d_w[i + 1] - d_w[i])
                r[m0:m1] = (self.offsets_um + cfg.nest.readings(d) + (LAG_UM * np.sin(np.pi * u))[:, None] * w
                            + VIBRATION_UM * np.sin(2 * np.pi * VIBRATION_HZ * t[m0:m1, None] + SENSOR_PHASES)
                            + rng.normal(size=(m1 - m0, 3)) * cfg.noise_um)
        self.t_s = t
        self.readings_um = r
        self.pose_of_sample = pose_of
        self.n_samples = n_total
        self.outage_samples = int(round(cfg.outage_s * rate))
        self._plan_faults()

    def _plan_faults(self) -> None:
        cfg = self.cfg
        rng = np.random.default_rng([cfg.seed, 0, 4])
        rate = cfg.rate_hz
        lo = int(rate)
        hi = self.n_samples - int(rate) - self.outage_samples
        spacing = self.outage_samples + 2
        taken: list[int] = []
        self.plan: dict[int, str] = {}
        self.garbage: dict[int, bytes] = {}
        self.corruption: dict[int, tuple[float, int]] = {}
        self.spike_sensor: dict[int, int] = {}
        for kind in FAULT_KINDS:
            for _ in range(cfg.faults.get(kind, 0)):
                for _try in range(10000):
                    k = int(rng.integers(lo, max(hi, lo + 1)))
                    if all(abs(k - x) > spacing for x in taken):
                        break
                else:
                    raise InputError(f"too many faults for a program of {self.n_samples} samples")
                taken.append(k)
                self.plan[k] = kind
                if kind == "garbage":
                    v = rng.integers(0, 255, size=int(rng.integers(8, 49)))
                    self.garbage[k] = bytes((v + (v >= 0x24)).astype(np.uint8).tolist())
                elif kind == "checksum":
                    self.corruption[k] = (float(rng.random()), int(rng.integers(1, 10)))
                elif kind == "spike":
                    self.spike_sensor[k] = int(rng.integers(0, 3))

    def record(self, k: int) -> bytes:
        """Wire record of sample k."""
        return encode_sample(k, self.t_s[k], self.readings_um[k])

    def spiked_record(self, k: int) -> bytes:
        """Record k with ``SPIKE_UM`` added to one sensor and a valid CRC."""
        r = self.readings_um[k].copy()
        r[self.spike_sensor.get(k, 0)] += SPIKE_UM
        return encode_sample(k, self.t_s[k], r)

    def wire(self, k: int) -> tuple[bytes, str | None]:
        """Bytes sent for sample k with its stream fault applied (:data:`STREAM_FAULTS`), and that fault.

        ``stall`` and ``disconnect`` act on the link (:func:`run_device`); here they send the plain record.
        """
        fault = self.plan.get(k)
        if fault == "drop":
            return b"", fault
        if fault == "garbage":
            return self.garbage[k] + self.record(k), fault
        if fault == "checksum":
            return self.corrupted_record(k), fault
        if fault == "spike":
            return self.spiked_record(k), fault
        if fault == "duplicate":
            return self.record(k) * 2, fault
        return self.record(k), None

    def stream(self, banner: str = "virtual") -> bytes:
        """The whole program as one byte stream with the stream faults applied (in-process tests)."""
        body = b"".join(self.wire(k)[0] for k in range(self.n_samples))
        return encode_info(banner) + body + encode_info("END")

    def corrupted_record(self, k: int) -> bytes:
        """Record k with one reading digit changed and the original CRC."""
        rec = bytearray(self.record(k))
        frac, delta = self.corruption.get(k, (0.5, 5))
        start = [i for i, c in enumerate(rec) if c == ord(",")][2] + 1
        star = rec.index(b"*")
        digits = [i for i in range(start, star) if chr(rec[i]).isdigit()]
        j = digits[int(frac * len(digits))]
        rec[j] = ord("0") + (rec[j] - ord("0") + delta) % 10
        return bytes(rec)


# --------------------------------------------------------------------------------------------- links


class _Link:
    """Device end of a link: a client connects, the device sends."""

    url = ""

    def connected(self) -> bool:
        raise NotImplementedError

    def wait_client(self, timeout_s: float) -> bool:
        deadline = time.monotonic() + timeout_s
        while not self.connected():
            if time.monotonic() >= deadline:
                return False
            time.sleep(0.01)
        time.sleep(CONNECT_SETTLE_S)  # let the client finish opening (pyserial flushes its input on open)
        return self.connected()

    def send(self, data: bytes) -> bool:
        raise NotImplementedError

    def drain(self, timeout_s: float = 2.0) -> None:
        """Wait until the client has read everything sent."""

    def drop_client(self) -> None:
        raise NotImplementedError

    def close(self) -> None:
        raise NotImplementedError


def _pts_index(name: str) -> int | None:
    tail = name.rsplit("/", 1)[-1]
    digits = "".join(c for c in tail if c.isdigit())
    return int(digits) if digits else None


class PtyLink(_Link):
    """A pseudo-terminal; the client opens the slave path (``/dev/pts/N``)."""

    def __init__(self) -> None:
        self.master, self.name = self._new()
        self.url = self.name

    @staticmethod
    def _new() -> tuple[int, str]:
        master, slave = os.openpty()
        name = os.ttyname(slave)
        tty.setraw(slave)
        os.close(slave)  # the device keeps no slave open, so a hang-up shows when the client leaves
        os.set_blocking(master, False)
        return master, name

    def connected(self) -> bool:
        p = select.poll()
        p.register(self.master, select.POLLIN)
        events = p.poll(0)
        if any(ev & select.POLLHUP for _, ev in events):
            return False
        if any(ev & select.POLLIN for _, ev in events):
            with contextlib.suppress(OSError):
                os.read(self.master, 4096)  # the protocol has no commands: discard what the client sends
        return True

    def send(self, data: bytes) -> bool:
        view = memoryview(data)
        off = 0
        while off < len(data):
            try:
                off += os.write(self.master, view[off:])
            except BlockingIOError:
                if not self.connected():
                    return False
                select.select([], [self.master], [], 0.05)
            except OSError:
                return False
        return True

    def drain(self, timeout_s: float = 2.0) -> None:
        try:
            fd = os.open(self.name, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
        except OSError:
            return
        try:
            # the kernel moves written bytes to the slave's input queue asynchronously, so the queue must be
            # seen empty for a while (longer than that hand-over, shorter than anything else)
            deadline = time.monotonic() + timeout_s
            buf = array.array("i", [0])
            empty_since: float | None = None
            while (now := time.monotonic()) < deadline:
                fcntl.ioctl(fd, termios.FIONREAD, buf)
                if buf[0] != 0:
                    empty_since = None
                elif empty_since is None:
                    empty_since = now
                elif now - empty_since >= DRAIN_QUIET_S:
                    break
                time.sleep(0.005)
        finally:
            os.close(fd)

    def drop_client(self) -> None:
        """Close the pty and create it again under the same name (like a cable pulled and plugged back)."""
        want = _pts_index(self.name)
        os.close(self.master)
        held: list[int] = []
        deadline = time.monotonic() + 10.0
        try:
            while True:
                master, name = self._new()
                if name == self.name:
                    self.master = master
                    return
                idx = _pts_index(name)
                if idx is not None and want is not None and idx < want:
                    held.append(master)  # fill a lower free number so the next one can be ours
                    continue
                if time.monotonic() >= deadline:
                    print(f"rtest-sim: could not re-create {self.name}; the port is now {name}", file=sys.stderr)
                    self.master, self.name = master, name
                    self.url = name
                    return
                os.close(master)  # ours is still held by the client's old descriptor: wait for it to close
                time.sleep(0.01)
        finally:
            for m in held:
                os.close(m)

    def close(self) -> None:
        with contextlib.suppress(OSError):
            os.close(self.master)


class TcpLink(_Link):
    """A TCP server on 127.0.0.1; the client opens ``socket://127.0.0.1:PORT``."""

    def __init__(self, port: int = 0) -> None:
        try:
            self.listener = socket.create_server(("127.0.0.1", port))
        except OSError as exc:
            raise AcquisitionError(f"cannot listen on 127.0.0.1:{port}: {exc}") from None
        self.port = int(self.listener.getsockname()[1])
        self.url = f"socket://127.0.0.1:{self.port}"
        self.conn: socket.socket | None = None

    def _close_conn(self) -> None:
        if self.conn is not None:
            with contextlib.suppress(OSError):
                self.conn.shutdown(socket.SHUT_RDWR)
            self.conn.close()
            self.conn = None

    def connected(self) -> bool:
        if self.conn is None:
            self.listener.settimeout(0.0)
            try:
                conn, _ = self.listener.accept()
            except (TimeoutError, BlockingIOError):
                return False
            conn.setblocking(False)
            self.conn = conn
        readable, _, _ = select.select([self.conn], [], [], 0)
        if readable:
            try:
                data = self.conn.recv(4096)  # the protocol has no commands: discard
            except BlockingIOError:
                data = b"-"
            except OSError:
                data = b""
            if not data:
                self._close_conn()
                return False
        return True

    def send(self, data: bytes) -> bool:
        view = memoryview(data)
        off = 0
        while off < len(data):
            if self.conn is None:
                return False
            try:
                off += self.conn.send(view[off:])
            except BlockingIOError:
                if not self.connected():
                    return False
                select.select([], [self.conn], [], 0.05)
            except OSError:
                self._close_conn()
                return False
        return True

    def drop_client(self) -> None:
        if self.conn is not None:
            with contextlib.suppress(OSError):
                self.conn.shutdown(socket.SHUT_WR)  # FIN after everything sent
            self.conn.close()
            self.conn = None

    def close(self) -> None:
        self._close_conn()
        self.listener.close()


# --------------------------------------------------------------------------------------------- the device


def run_device(cfg: DeviceConfig, *, tcp_port: int | None = None, truth_path: str | os.PathLike[str] | None = None,
               announce: Callable[[str], None] = print, connect_timeout_s: float = 300.0) -> dict[str, Any]:
    """Run the virtual device until its program ends; return the truth record.

    Parameters
    ----------
    cfg : DeviceConfig
    tcp_port : int or None
        Listen on 127.0.0.1:tcp_port (0: any free port); None: a pseudo-terminal.
    truth_path : path-like or None
        Truth JSON, rewritten after each fault and at exit.
    announce : callable
        Receives the port URL once the link exists (``pige rtest-sim`` prints it).
    connect_timeout_s : float [s]
        Longest wait for the first client.
    """
    run = _DeviceRun(cfg, truth_path)
    link: _Link = TcpLink(tcp_port) if tcp_port is not None else PtyLink()
    run.truth["port"] = link.url
    run.save()
    announce(link.url)
    try:
        if not link.wait_client(connect_timeout_s):
            run.truth["stop_reason"] = f"no client within {connect_timeout_s:g} s"
            return run.truth
        link.send(encode_info(f"pige-rtest-device 1;sensors=3;rate_hz={cfg.rate_hz:g};"
                              f"program={cfg.program.description}"))
        run.stream_program(link)
        run.send_end(link)
        run.truth["finished"] = True
        return run.truth
    finally:
        link.close()
        run.save()


class _DeviceRun:
    """One run of the virtual device: the paced stream, the link faults and the truth record."""

    def __init__(self, cfg: DeviceConfig, truth_path: str | os.PathLike[str] | None) -> None:
        self.cfg = cfg
        self.truth_path = truth_path
        self.dev = dev = VirtualRTest(cfg)
        prog = cfg.program
        self.injected = {"garbage": 0, "garbage_bytes": 0, "checksum": 0, "drop": 0, "spike": 0, "duplicate": 0,
                         "stall": 0, "disconnect": 0, "lost_in_outage": 0}
        self.affected: dict[str, list[int]] = {"checksum": [], "drop": [], "spike": [], "duplicate": [],
                                               "disconnect": []}
        self.truth: dict[str, Any] = dict(dev.sim_truth)
        self.truth.update({
            "device": {
                "program": prog.description, "poses": prog.n_poses, "samples": dev.n_samples,
                "rate_hz": cfg.rate_hz, "time_scale": cfg.time_scale, "move_s": prog.move_s,
                "dwell_s": prog.dwell_s.tolist(), "noise_um": cfg.noise_um,
                "repeatability_um": cfg.repeatability_um, "nest": cfg.nest.description,
                "offsets_um": dev.offsets_um.tolist(), "faults_requested": dict(cfg.faults),
                "stall_s": cfg.stall_s, "outage_s": cfg.outage_s, "outage_samples": dev.outage_samples,
            },
            "deviation_with_repeatability_um": dev.deviation_machine_um.tolist(),
            "injected": self.injected, "affected": self.affected, "sent": 0, "unsent": 0, "interrupted_sends": 0,
            "finished": False, "port": None,
        })
        self.k = 0
        self.streaming = True

    def save(self) -> None:
        if self.truth_path is not None:
            atomic_write_text(self.truth_path, to_json(self.truth) + "\n")

    def stream_program(self, link: _Link) -> None:
        """Send every sample at its pace, pausing while no client listens, applying the faults."""
        speed = self.cfg.rate_hz * self.cfg.time_scale
        n = self.dev.n_samples
        origin_wall, origin_k = time.monotonic(), 0
        while self.k < n:
            due = min(n, origin_k + int((time.monotonic() - origin_wall) * speed) + 1)
            if self.k >= due:
                time.sleep(min(0.005, 1.0 / speed))
                continue
            if not link.connected():
                self.streaming = link.wait_client(self.cfg.linger_s if self.streaming else 0.0)
                if self.streaming:
                    origin_wall, origin_k = time.monotonic(), self.k
                    continue
                self.truth["unsent"] += due - self.k  # nobody listening: the machine goes on
                self.k = due
                continue
            batch, special = self._batch(due)
            if batch and not link.send(batch):
                self.truth["interrupted_sends"] += 1
                continue
            if special is not None:
                self._link_fault(link, special)
                origin_wall, origin_k = time.monotonic(), self.k

    def _batch(self, due: int) -> tuple[bytes, str | None]:
        """Wire bytes of the samples up to ``due`` (at most 400), stopping before a link fault."""
        dev = self.dev
        batch = bytearray()
        end = min(due, self.k + 400)
        while self.k < end:
            k = self.k
            data, fault = dev.wire(k)
            if dev.plan.get(k) in ("stall", "disconnect"):
                return bytes(batch), dev.plan[k]
            if fault is not None:
                self.injected[fault] += 1
                if fault in self.affected:
                    self.affected[fault].append(k)
                if fault == "garbage":
                    self.injected["garbage_bytes"] += len(dev.garbage[k])
            if fault != "drop":
                self.truth["sent"] += 1
            batch += data
            self.k += 1
        return bytes(batch), None

    def _link_fault(self, link: _Link, special: str) -> None:
        """A stall (nothing sent for ``stall_s``) or a disconnect (``outage_s`` of samples lost)."""
        dev, cfg = self.dev, self.cfg
        del dev.plan[self.k]
        if special == "stall":
            self.injected["stall"] += 1
            self.save()
            time.sleep(cfg.stall_s)
            return
        link.drain()
        link.drop_client()
        lost = list(range(self.k, min(dev.n_samples, self.k + dev.outage_samples)))
        self.affected["disconnect"].extend(lost)
        self.injected["disconnect"] += 1
        self.injected["lost_in_outage"] += len(lost)
        self.k += len(lost)
        self.save()
        self.streaming = link.wait_client(max(cfg.linger_s, 10.0))

    def send_end(self, link: _Link) -> None:
        """``$RI,END``, then wait until the client has read everything and left (at most ``linger_s``)."""
        if link.connected():
            link.send(encode_info("END"))
            link.drain()
            deadline = time.monotonic() + self.cfg.linger_s
            while link.connected() and time.monotonic() < deadline:
                time.sleep(0.01)


# --------------------------------------------------------------------------------------------- as a process


@dataclass
class VirtualDeviceProcess:
    """A running ``pige rtest-sim`` process.

    Attributes
    ----------
    url : str
        Port to open (``/dev/pts/N`` or ``socket://127.0.0.1:PORT``).
    process : subprocess.Popen
    truth_path : Path or None
    """

    url: str
    process: subprocess.Popen[str]
    truth_path: Path | None

    def wait(self, timeout_s: float | None = None) -> int:
        """Wait for the device to end its program; returns the exit status."""
        return self.process.wait(timeout_s)

    def stop(self, timeout_s: float = 10.0) -> int:
        """Terminate (SIGTERM: the truth file is written) and wait; returns the exit status."""
        if self.process.poll() is None:
            self.process.terminate()
            try:
                self.process.wait(timeout_s)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()
        if self.process.stdout is not None:
            self.process.stdout.close()
        return int(self.process.returncode)

    def truth(self) -> dict[str, Any]:
        """The truth JSON (needs ``truth_path``)."""
        if self.truth_path is None:
            raise InputError("this device was started without a truth file")
        return dict(json.loads(self.truth_path.read_text(encoding="utf-8")))

    def __enter__(self) -> VirtualDeviceProcess:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()


def start_virtual_device(machine: str = DEFAULT_MACHINE, trajectory: str = "cone-frustum", *,
                         ball_mm: Sequence[float] = DEFAULT_BALL_MM, pige: str | dict[str, float] = "random",
                         effects: Sequence[str] = (), seed: int | None = 0, faults: str | dict[str, int] | None = None,
                         truth: str | os.PathLike[str] | None = None, tcp: int | None = None, rate_hz: float = 20.0,
                         time_scale: float = 1.0, noise_um: float = 0.25, repeatability_um: float = 0.2,
                         nest: str = "default", extra_args: Sequence[str] = (), startup_timeout_s: float = 60.0,
                         stderr: int | IO[Any] | None = None) -> VirtualDeviceProcess:
    """Start ``pige rtest-sim`` as a subprocess and return its port URL and process.

    Parameters mirror the command's options (``pige rtest-sim --help``); ``extra_args``
    are appended verbatim (e.g. ``["--points", "12", "--stall-s", "0.5"]``).

    Raises
    ------
    AcquisitionError
        The device did not print its port within ``startup_timeout_s``.
    """
    args = [sys.executable, "-m", "pige_sym", "rtest-sim", "--machine", machine, "--trajectory", trajectory,
            "--ball", ",".join(f"{float(x)!r}" for x in ball_mm),
            "--pige", pige if isinstance(pige, str) else ",".join(f"{k}={float(v)!r}" for k, v in pige.items()),
            "--rate", repr(float(rate_hz)), "--time-scale", repr(float(time_scale)), "--noise", repr(float(noise_um)),
            "--repeatability", repr(float(repeatability_um)), "--nest", nest]
    for e in effects:
        args += ["--effect", e]
    if seed is not None:
        args += ["--seed", str(seed)]
    if faults:
        args += ["--faults", faults if isinstance(faults, str) else ",".join(f"{k}={v}" for k, v in faults.items())]
    if truth is not None:
        args += ["--truth", str(truth)]
    if tcp is not None:
        args += ["--tcp", str(tcp)]
    args += list(extra_args)
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    proc = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=stderr, text=True, env=env)
    assert proc.stdout is not None
    ready, _, _ = select.select([proc.stdout], [], [], startup_timeout_s)
    line = proc.stdout.readline().strip() if ready else ""
    if not line:
        if proc.poll() is None:
            proc.kill()
        proc.wait()
        raise AcquisitionError(f"the virtual device did not start (exit status {proc.returncode}); "
                               f"command: {' '.join(args)}")
    return VirtualDeviceProcess(line, proc, Path(truth) if truth is not None else None)
