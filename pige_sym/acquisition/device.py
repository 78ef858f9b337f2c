"""Device protocols: the default R-test nest protocol and the adapter interface.

Default protocol (``rtest``, version 1)
---------------------------------------
A three-sensor nest streams one ASCII record per sample, continuously, at a fixed
sample rate; the host sends nothing.  Grammar (framing by
:class:`~pige_sym.acquisition.transport.LineFramer` with start byte ``$``)::

    record  := "$" payload "*" crc CR? LF
    payload := "RT," seq "," time "," r1 "," r2 "," r3        sample
             | "RI," text                                      information
    seq     := [0-9]{1,10}          sample counter, +1 per sample from 0 at program start
    time    := decimal              device time [s] of the sample
    r1..r3  := decimal              sensor readings [µm], sign optional ("-12.3456")
    text    := printable ASCII without "$", "*", CR, LF
    crc     := [0-9A-F]{4}          CRC-16/XMODEM (poly 0x1021, init 0;
                                    :func:`binascii.crc_hqx`) of the payload bytes

Example: ``$RT,1234,61.7000,312.4051,-87.1130,15.0042*5B1C``.  Information records
carry free text; ``RI,END`` means the device has finished its program.  A CRC-16
detects every error burst up to 16 bits, so any single corrupted byte is caught.

Validation, in this order, each failure a rejection reason: ``format`` (no
``*`` + 4 hex digits, non-ASCII), ``checksum`` (CRC mismatch), ``type`` (unknown
record type), ``fields`` (not exactly 6 fields in a sample), ``number`` (a field is
not a finite number, a reading beyond ±1e5 µm as the measurement readers refuse it, or seq is not a
non-negative integer).  The framer adds
``truncated`` and ``overlong``; the acquisition adds ``duplicate`` (a sequence
number already seen).  Nothing is repaired or guessed.

Adapters
--------
A :class:`DeviceAdapter` turns frames into :class:`Sample` / :class:`Info`
records and may talk to the device (``on_connect``, ``poll``).  Another device is
one small subclass; :class:`GaugeQueryAdapter` is the example of a gauge interface
that answers a query command (samples get a local sequence number and the host
clock as time).
"""

from __future__ import annotations

import binascii
import math
import re
import time
from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import Any

import numpy as np

from pige_sym.acquisition.transport import LineFramer
from pige_sym.errors import InputError
from pige_sym.errors import RecordError as RecordError

REASONS = ("format", "checksum", "type", "fields", "number", "truncated", "overlong", "duplicate")
_HEX = re.compile(rb"[0-9A-F]{4}")


@dataclass(frozen=True)
class Sample:
    """One sample of the three sensors.

    Attributes
    ----------
    seq : int or None
        Device sequence number (None when the device has none).
    t_s : float [s]
        Device time.
    readings_um : tuple of 3 float [µm]
        Raw sensor readings (not zeroed).
    """

    seq: int | None
    t_s: float
    readings_um: tuple[float, float, float]


@dataclass(frozen=True)
class Info:
    """An information record (banner, end of program)."""

    text: str

    @property
    def is_end(self) -> bool:
        return self.text.strip().upper().startswith("END")


def crc16(payload: bytes) -> int:
    """CRC-16/XMODEM of ``payload``."""
    return binascii.crc_hqx(payload, 0)


def frame_payload(payload: bytes) -> bytes:
    """A complete wire record for a payload: ``$payload*CRC\\r\\n``."""
    return b"$" + payload + b"*%04X\r\n" % crc16(payload)


def encode_sample(seq: int, t_s: float, readings_um: Any) -> bytes:
    """Wire record of a sample (time 4 decimals [s], readings 4 decimals [µm])."""
    r = readings_um
    return frame_payload(b"RT,%d,%.4f,%.4f,%.4f,%.4f" % (seq, t_s, r[0], r[1], r[2]))


def encode_info(text: str) -> bytes:
    """Wire record of an information text."""
    if any(c in text for c in "$*\r\n") or not text.isascii():
        raise InputError(f"info text must be ASCII without $, *, CR, LF: {text!r}")
    return frame_payload(b"RI," + text.encode("ascii"))


def _number(text: bytes) -> float:
    try:
        v = float(text)
    except ValueError:
        raise RecordError("number", f"{text!r} is not a number") from None
    if not math.isfinite(v):
        raise RecordError("number", f"{text!r} is not finite")
    return v


def _reading(value: float, text: bytes | str) -> float:
    """A sensor reading [µm] within the physical bound the measurement readers apply (``LIMITS["um"]``)."""
    from pige_sym.measurements.measurement import LIMITS

    if abs(value) > LIMITS["um"]:
        raise RecordError("number", f"{text!r} is beyond ±{LIMITS['um']:g} um: not a physical reading")
    return value


def parse_record(body: bytes) -> Sample | Info:
    """Parse one frame body of the default protocol (without ``$`` and line end).

    Raises
    ------
    RecordError
        With the rejection reason (module docstring).
    """
    if len(body) < 6 or body[-5:-4] != b"*" or not _HEX.fullmatch(body[-4:]):
        raise RecordError("format", "missing *CRC")
    payload = body[:-5]
    if not payload.isascii():
        raise RecordError("format", "non-ASCII bytes")
    if crc16(payload) != int(body[-4:], 16):
        raise RecordError("checksum")
    if payload.startswith(b"RI,"):
        return Info(payload[3:].decode("ascii"))
    if not payload.startswith(b"RT,"):
        raise RecordError("type", f"unknown record type {payload[:3]!r}")
    fields = payload.split(b",")
    if len(fields) != 6:
        raise RecordError("fields", f"{len(fields)} fields, expected 6")
    if not fields[1].isdigit() or len(fields[1]) > 10:
        raise RecordError("number", f"sequence number {fields[1]!r}")
    t = _number(fields[2])
    r = (_reading(_number(fields[3]), fields[3]), _reading(_number(fields[4]), fields[4]),
         _reading(_number(fields[5]), fields[5]))
    return Sample(int(fields[1]), t, r)


class DeviceAdapter(ABC):
    """How to talk to one kind of measuring device.

    A subclass gives the framer, parses frames, and may send commands.
    """

    #: name used by ``pige acquire --protocol``
    name = "adapter"

    def new_framer(self) -> LineFramer:
        """A fresh framer for a new connection (default: lines starting with ``$``)."""
        return LineFramer(b"$")

    def on_connect(self, port: Any) -> None:  # noqa: B027 - optional hook
        """Called after every (re)connection (e.g. to send an initialisation command)."""

    def poll(self, port: Any) -> None:  # noqa: B027 - optional hook
        """Called before every read (e.g. to send a query); default: nothing."""

    @abstractmethod
    def parse(self, frame: bytes) -> Sample | Info:
        """Turn one frame into a record or raise :class:`RecordError`."""


class RTestProtocolAdapter(DeviceAdapter):
    """The default streaming protocol (module docstring)."""

    name = "rtest"

    def parse(self, frame: bytes) -> Sample | Info:
        return parse_record(frame)


class GaugeQueryAdapter(DeviceAdapter):
    """A gauge interface that answers a query command with one line of three readings.

    The host sends ``query`` every ``period_s`` (at most one query outstanding, or
    again after ``period_s`` without answer); the answer is ``v1 v2 v3`` separated by
    spaces, commas, semicolons or tabs, in units of ``unit_um`` µm (1000 for mm).
    Samples get a local sequence number (answers are counted, so no gap can be
    seen) and the host's monotonic clock as time.

    Parameters
    ----------
    query : bytes
    period_s : float [s]
    unit_um : float [µm per unit]
    """

    name = "gauge"

    def __init__(self, query: bytes = b"?\r", period_s: float = 0.05, unit_um: float = 1000.0) -> None:
        self.query = query
        self.period_s = period_s
        self.unit_um = unit_um
        self._seq = 0
        self._t0 = time.monotonic()
        self._last_query = -math.inf
        self._waiting = False

    def new_framer(self) -> LineFramer:
        return LineFramer(None, max_len=80)

    def on_connect(self, port: Any) -> None:
        self._waiting = False
        self._last_query = -math.inf

    def poll(self, port: Any) -> None:
        now = time.monotonic()
        since = now - self._last_query
        if since >= self.period_s and (not self._waiting or since > 4 * self.period_s):
            port.write(self.query)
            self._last_query = now
            self._waiting = True

    def parse(self, frame: bytes) -> Sample | Info:
        self._waiting = False
        try:
            text = frame.decode("ascii")
        except UnicodeDecodeError:
            raise RecordError("format", "non-ASCII bytes") from None
        parts = [p for p in re.split(r"[\s,;]+", text.strip()) if p]
        if len(parts) != 3:
            raise RecordError("fields", f"{len(parts)} values, expected 3")
        vals = tuple(_reading(_number(p.encode()) * self.unit_um, p) for p in parts)
        s = Sample(self._seq, time.monotonic() - self._t0, (vals[0], vals[1], vals[2]))
        self._seq += 1
        return s


ADAPTERS: dict[str, type[DeviceAdapter]] = {"rtest": RTestProtocolAdapter, "gauge": GaugeQueryAdapter}


def make_adapter(name: str) -> DeviceAdapter:
    """Adapter by protocol name (``rtest``, ``gauge``)."""
    try:
        return ADAPTERS[name]()
    except KeyError:
        raise InputError(f"unknown protocol {name!r}: use one of {', '.join(ADAPTERS)}") from None


def readings_array(samples: list[Sample]) -> np.ndarray:
    """Readings of samples as an array, shape=(m, 3) [µm]."""
    return np.array([s.readings_um for s in samples], dtype=float).reshape(-1, 3)
