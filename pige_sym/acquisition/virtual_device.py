"""Virtual R-test device: a simulated machine and nest streaming the ``rtest`` protocol.

It runs as its own process (``pige rtest-sim``) on a real serial stack: a
pseudo-terminal (the acquirer opens the printed ``/dev/pts/N``) or a TCP socket
(``socket://127.0.0.1:PORT``).  The first line it prints is the port; it exits when
the program ends.

Machine and nest
----------------
The true ball-minus-nest deviation of each pose is the simulator's
(:func:`pige_sym.simulation.simulator.simulate`, noise-free: PIGEs and effects) plus a
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
``stall``       nothing sent for ``stall_s`` wall seconds (no sample lost); with ``--await-hello``, nothing
                sent until the client has reconnected (said hello again; at most max(``stall_s``, 10 s))
``disconnect``  the link is dropped after the client has read everything (pty: closed
                and re-created under the same ``/dev/pts/N``; TCP: connection closed,
                a new one accepted); the ``outage_s`` of samples during the outage are
                lost; the device waits for the client to reconnect

Every injected fault is counted in the truth JSON (``injected``; sequence numbers
of affected records in ``affected``), rewritten atomically after each fault and at
exit (also on SIGTERM).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from pige_sym.acquisition.device import encode_info, encode_sample
from pige_sym.acquisition.nest import NestGeometry, default_nest
from pige_sym.constants import FAULT_KINDS as FAULT_KINDS
from pige_sym.errors import InputError
from pige_sym.kernels import load_kernels
from pige_sym.model.effects import EffectInstance
from pige_sym.nc.rtest_program import TestProgram
from pige_sym.simulation.simulator import simulate

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
