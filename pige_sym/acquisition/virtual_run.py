"""Running the virtual device: the streaming loop over a program, and the process that hosts it.

:func:`run_device` streams a program's samples over a link (``pige rtest-sim``);
:func:`start_virtual_device` starts it as a child process and returns the port it prints first.
"""

from __future__ import annotations

import json
import os
import select
import subprocess
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any

from pige_sym.acquisition.device import encode_info
from pige_sym.acquisition.virtual_device import DeviceConfig, VirtualRTest
from pige_sym.acquisition.virtual_links import DeviceLink, PtyLink, TcpLink
from pige_sym.constants import DEFAULT_BALL_MM
from pige_sym.constants import FAULT_KINDS as FAULT_KINDS
from pige_sym.errors import AcquisitionError, InputError
from pige_sym.files import atomic_write_text, to_json
from pige_sym.kernels import DEFAULT_MACHINE


def run_device(cfg: DeviceConfig, *, tcp_port: int | None = None, truth_path: str | os.PathLike[str] | None = None,
               announce: Callable[[str], None] = print, connect_timeout_s: float = 300.0,
               await_hello: bool = False) -> dict[str, Any]:
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
    await_hello : bool
        Send nothing on a connection until the client has sent a byte (it has opened the port), instead of
        waiting a fixed time (:class:`~pige_sym.acquisition.virtual_links.DeviceLink`).
    """
    run = DeviceRun(cfg, truth_path)
    link: DeviceLink = (TcpLink(tcp_port, await_hello) if tcp_port is not None
                        else PtyLink(await_hello))
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


class DeviceRun:
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

    def stream_program(self, link: DeviceLink) -> None:
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

    def _link_fault(self, link: DeviceLink, special: str) -> None:
        """A stall (nothing sent for ``stall_s``) or a disconnect (``outage_s`` of samples lost)."""
        dev, cfg = self.dev, self.cfg
        del dev.plan[self.k]
        if special == "stall":
            self.injected["stall"] += 1
            self.save()
            if link.await_hello:  # silent until the client, having timed out, has reconnected and said hello
                link.heard = False
                self.streaming = link.wait_client(max(cfg.stall_s, 10.0))
            else:
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

    def send_end(self, link: DeviceLink) -> None:
        """``$RI,END``, then wait until the client has read everything and left (at most ``linger_s``)."""
        if link.connected():
            link.send(encode_info("END"))
            link.drain()
            deadline = time.monotonic() + self.cfg.linger_s
            while link.connected() and time.monotonic() < deadline:
                time.sleep(0.01)


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
