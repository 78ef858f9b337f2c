"""Serial transport: opening ports by URL, the raw byte log, and framing.

Ports
-----
Every port is opened with :func:`serial.serial_for_url`, so a device path
(``/dev/ttyUSB0``, ``/dev/pts/3``, ``COM4``), ``loop://``, ``socket://host:port`` and
``rfc2217://host:port`` all work.  :class:`PortSettings` holds the line settings
(baud rate, byte size, parity, stop bits; ignored by the network URL handlers) and
the *stall timeout*: a port that delivers no byte for ``timeout_s`` seconds is
considered stalled.  Ports are opened non-blocking (pyserial ``timeout=0``) and read
with :func:`read_available`, which returns the bytes that are there, waiting at most
a short poll interval (``min(timeout_s, 0.05)`` s) for the first one.  A blocking
pyserial read would collect bytes inside the call and lose them when the link fails
before it returns; a non-blocking read hands over every byte it took.

Raw log
-------
:class:`RawLog` appends every byte read to a file *before* it is parsed and flushes
it to the operating system at once (``fsync`` at most once per ``sync_s`` and at
close), so a crash of the acquisition loses nothing that was read.  The log holds
the bytes exactly as received, connections one after the other.

Framing
-------
Framing (cutting the byte stream into records) is separate from parsing records
(:mod:`pige_sym.acquisition.device`).  :class:`LineFramer` implements line framing::

    stream := (noise | frame)*
    frame  := START body LF          (START omitted when ``start`` is None; body has no START/LF)

With a start byte (``$`` for the default R-test protocol) a frame begins at the
start byte and ends at the next line feed; bytes outside frames are *noise* and are
counted (bytes and runs), never parsed.  A start byte inside a frame cuts the frame
short: the partial frame is reported as ``truncated`` and a new frame begins.  A
frame longer than ``max_len`` bytes is dropped as ``overlong`` and the framer waits
for the next start byte.  A trailing CR before the LF is removed.  Without a start
byte every line is a frame (empty lines are ignored).
"""

from __future__ import annotations

import os
import select
import time
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any

from pige_sym.errors import AcquisitionError, InputError

#: Option value -> name of the pyserial constant (looked up when a port opens, so building the
#: command line does not import pyserial).
PARITIES = {"N": "PARITY_NONE", "E": "PARITY_EVEN", "O": "PARITY_ODD", "M": "PARITY_MARK", "S": "PARITY_SPACE"}
STOPBITS = {"1": "STOPBITS_ONE", "1.5": "STOPBITS_ONE_POINT_FIVE", "2": "STOPBITS_TWO"}
BYTESIZES = {5: "FIVEBITS", 6: "SIXBITS", 7: "SEVENBITS", 8: "EIGHTBITS"}
POLL_S = 0.05


@dataclass(frozen=True)
class PortSettings:
    """Line settings of a serial port.

    Attributes
    ----------
    baudrate : int [bit/s]
    bytesize : {5, 6, 7, 8}
    parity : {"N", "E", "O", "M", "S"}
    stopbits : {"1", "1.5", "2"}
    timeout_s : float [s]
        Stall timeout: no byte for this long counts as a timeout (then reconnect).
    """

    baudrate: int = 115200
    bytesize: int = 8
    parity: str = "N"
    stopbits: str = "1"
    timeout_s: float = 1.0

    def __post_init__(self) -> None:
        if self.baudrate <= 0:
            raise InputError(f"baud rate must be > 0, got {self.baudrate}")
        if self.bytesize not in BYTESIZES:
            raise InputError(f"byte size must be 5, 6, 7 or 8, got {self.bytesize}")
        if self.parity.upper() not in PARITIES:
            raise InputError(f"parity must be one of {', '.join(PARITIES)}, got {self.parity!r}")
        if str(self.stopbits) not in STOPBITS:
            raise InputError(f"stop bits must be 1, 1.5 or 2, got {self.stopbits!r}")
        if not self.timeout_s > 0:
            raise InputError(f"timeout must be > 0 s, got {self.timeout_s}")

    @property
    def poll_s(self) -> float:
        """Read poll interval [s]."""
        return min(self.timeout_s, POLL_S)


def open_port(url: str, settings: PortSettings | None = None) -> Any:
    """Open a port by URL or device path with :func:`serial.serial_for_url`.

    Raises
    ------
    AcquisitionError
        When the port cannot be opened (the message names the port and the reason).
    """
    import serial

    s = settings or PortSettings()
    try:
        return serial.serial_for_url(
            url, baudrate=s.baudrate, bytesize=getattr(serial, BYTESIZES[s.bytesize]),
            parity=getattr(serial, PARITIES[s.parity.upper()]), stopbits=getattr(serial, STOPBITS[str(s.stopbits)]),
            timeout=0, write_timeout=max(s.timeout_s, 1.0),
        )
    except (serial.SerialException, OSError, ValueError) as exc:
        raise AcquisitionError(f"cannot open port {url!r}: {exc}") from None


def read_available(port: Any, wait_s: float, max_bytes: int = 65536) -> bytes:
    """The bytes a non-blocking port has now, waiting up to ``wait_s`` for the first one.

    Raises what the port raises (``serial.SerialException``, ``OSError``) when the link
    fails; no byte already taken from the port is lost then.
    """
    data = port.read(max_bytes)
    if data:
        return bytes(data)
    try:
        fd = port.fileno()
    except Exception:  # noqa: BLE001 - URL handlers without a file descriptor (loop://, rfc2217://)
        fd = None
    if fd is not None:
        select.select([fd], [], [], wait_s)
    else:
        time.sleep(min(wait_s, 0.01))
    return bytes(port.read(max_bytes))


class RawLog:
    """Append-only log of the raw bytes read from the device.

    Parameters
    ----------
    path : path-like or None
        None disables logging.
    sync_s : float [s]
        Longest time between two ``fsync`` calls (every write is flushed at once).
    append : bool
        Continue an existing log (resume); otherwise an existing log is replaced (the caller
        has checked that it may be, :func:`pige_sym.files.check_output`).
    """

    def __init__(self, path: str | os.PathLike[str] | None, *, sync_s: float = 1.0, append: bool = True) -> None:
        self.path = Path(path) if path is not None else None
        self.sync_s = sync_s
        self.bytes = 0
        self._last_sync = time.monotonic()
        self._fh: IO[bytes] | None = open(self.path, "ab" if append else "wb") if self.path is not None else None  # noqa: SIM115

    def write(self, data: bytes) -> None:
        """Append ``data`` and flush it (fsync when ``sync_s`` has passed)."""
        self.bytes += len(data)
        if self._fh is None:
            return
        self._fh.write(data)
        self._fh.flush()
        now = time.monotonic()
        if now - self._last_sync >= self.sync_s:
            os.fsync(self._fh.fileno())
            self._last_sync = now

    def close(self) -> None:
        if self._fh is not None and not self._fh.closed:
            self._fh.flush()
            os.fsync(self._fh.fileno())
            self._fh.close()

    def __enter__(self) -> RawLog:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()


class LineFramer:
    """Cut a byte stream into line frames (module docstring).

    Parameters
    ----------
    start : bytes of length 1 or None
        Start-of-frame byte (``b"$"``), or None: every line is a frame.
    max_len : int
        Longest frame body accepted [bytes].

    Attributes
    ----------
    noise_bytes, noise_runs : int
        Bytes outside frames, and maximal runs of them.
    truncated, overlong : int
        Frames cut short by a start byte or a reset, and frames longer than ``max_len``.
    frames : int
        Complete frames returned.
    """

    def __init__(self, start: bytes | None = b"$", max_len: int = 160) -> None:
        if start is not None and len(start) != 1:
            raise ValueError("start must be one byte")
        self.start = start
        self.max_len = max_len
        self.noise_bytes = 0
        self.noise_runs = 0
        self.truncated = 0
        self.overlong = 0
        self.frames = 0
        self._buf = bytearray()
        self._in_frame = start is None
        self._in_noise = False
        self._skipping = False  # inside an overlong frame: wait for LF or a start byte

    def _noise(self, n: int) -> None:
        if n <= 0:
            return
        self.noise_bytes += n
        if not self._in_noise:
            self.noise_runs += 1
            self._in_noise = True

    def feed(self, data: bytes) -> list[bytes]:
        """Consume bytes; return the complete frame bodies (without START, CR, LF)."""
        out: list[bytes] = []
        i, n = 0, len(data)
        lf = 10
        while i < n:
            if not self._in_frame:
                j = data.find(self.start, i) if self.start is not None else i
                if j < 0:
                    self._noise(n - i)
                    return out
                self._noise(j - i)
                self._in_noise = False
                self._in_frame = True
                self._buf.clear()
                i = j + 1
                continue
            # inside a frame: find the end (LF) or a new start byte
            ends = [x for x in (data.find(b"\n", i), data.find(self.start, i) if self.start is not None else -1)
                    if x >= 0]
            k = min(ends) if ends else n
            if not self._skipping:
                self._buf += data[i:k]
                if len(self._buf) > self.max_len:
                    self.overlong += 1
                    self._skipping = True
                    self._buf.clear()
            if k == n:
                return out
            if data[k] == lf:
                if self._skipping:
                    self._skipping = False
                else:
                    body = bytes(self._buf).rstrip(b"\r")
                    if body or self.start is not None:
                        out.append(body)
                        self.frames += 1
                self._buf.clear()
                self._in_frame = self.start is None
                i = k + 1
            else:  # a start byte inside a frame
                if not self._skipping:
                    self.truncated += 1
                self._skipping = False
                self._buf.clear()
                i = k + 1  # the new frame starts after this start byte
        return out

    def reset(self) -> None:
        """Forget a partial frame (on reconnect); it is counted as truncated."""
        if self.start is not None:
            if self._in_frame and not self._skipping:
                self.truncated += 1
        elif self._buf:
            self.truncated += 1
        self._buf.clear()
        self._skipping = False
        self._in_frame = self.start is None
        self._in_noise = False
