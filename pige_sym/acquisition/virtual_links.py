"""The virtual device's end of a serial link: a pseudo-terminal or a TCP socket.

Both links write bytes with the line's timing (baud rate) and can inject link faults (a dropped
connection, a stall); the acquirer opens the port the device prints (``/dev/pts/N`` or
``socket://127.0.0.1:PORT``).  Behaviour is described in :mod:`pige_sym.acquisition.virtual_device`.
"""

from __future__ import annotations

import array
import contextlib
import fcntl
import os
import select
import socket
import sys
import termios
import time
import tty

from pige_sym.acquisition.virtual_device import CONNECT_SETTLE_S, DRAIN_QUIET_S
from pige_sym.constants import FAULT_KINDS as FAULT_KINDS
from pige_sym.errors import AcquisitionError


class DeviceLink:
    """Device end of a link: a client connects, the device sends.

    pyserial discards the input that arrived while it opened a port (``reset_input_buffer`` at the end of
    ``open``), so bytes sent before a client has finished opening are lost, a record cut in two leaving its tail
    as noise.  By default the device waits ``CONNECT_SETTLE_S`` after a client connects, which a client slowed
    down for longer (a loaded machine) can outlast; with ``await_hello`` it sends nothing on a connection until
    the client has sent a byte (a client that writes once it has opened the port, as the tests' does).
    """

    url = ""
    await_hello = False
    heard = False  # the client of the current connection has sent a byte

    def connected(self) -> bool:
        raise NotImplementedError

    def wait_client(self, timeout_s: float) -> bool:
        deadline = time.monotonic() + timeout_s
        while not (self.connected() and (self.heard or not self.await_hello)):
            if time.monotonic() >= deadline:
                return False
            time.sleep(0.002 if self.await_hello else 0.01)
        if self.await_hello:
            return True
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


def pts_index(name: str) -> int | None:
    tail = name.rsplit("/", 1)[-1]
    digits = "".join(c for c in tail if c.isdigit())
    return int(digits) if digits else None


class PtyLink(DeviceLink):
    """A pseudo-terminal; the client opens the slave path (``/dev/pts/N``)."""

    def __init__(self, await_hello: bool = False) -> None:
        self.await_hello = await_hello
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
            self.heard = False
            return False
        if any(ev & select.POLLIN for _, ev in events):
            with contextlib.suppress(OSError):
                if os.read(self.master, 4096):  # the protocol has no commands: discard what the client sends
                    self.heard = True
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
        want = pts_index(self.name)
        os.close(self.master)
        self.heard = False
        held: list[int] = []
        deadline = time.monotonic() + 10.0
        try:
            while True:
                master, name = self._new()
                if name == self.name:
                    self.master = master
                    return
                idx = pts_index(name)
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


class TcpLink(DeviceLink):
    """A TCP server on 127.0.0.1; the client opens ``socket://127.0.0.1:PORT``."""

    def __init__(self, port: int = 0, await_hello: bool = False) -> None:
        self.await_hello = await_hello
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
            self.heard = False
        readable, _, _ = select.select([self.conn], [], [], 0)
        if readable:
            data: bytes | None
            try:
                data = self.conn.recv(4096)  # the protocol has no commands: discard
            except BlockingIOError:
                data = None
            except OSError:
                data = b""
            if data == b"":
                self._close_conn()
                return False
            self.heard = self.heard or data is not None
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
