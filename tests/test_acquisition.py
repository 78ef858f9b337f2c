"""Acquisition end to end: the virtual R-test over a real pty / TCP, faults, resume, nest geometry."""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from terminal import as_from_a_terminal

from pige_sym.acquisition.device import (
    GaugeQueryAdapter,
    Info,
    RecordError,
    Sample,
    encode_info,
    encode_sample,
    parse_record,
)
from pige_sym.acquisition.engine import acquire
from pige_sym.acquisition.nest import NestGeometry, parse_nest, tripod
from pige_sym.acquisition.options import AcquisitionOptions
from pige_sym.acquisition.outputs import default_raw_log, summary_path
from pige_sym.acquisition.transport import LineFramer, PortSettings, open_port, read_available
from pige_sym.acquisition.virtual_device import DeviceConfig, VirtualRTest
from pige_sym.acquisition.virtual_run import start_virtual_device
from pige_sym.cli.main import main
from pige_sym.errors import AcquisitionError
from pige_sym.identification.least_squares import identify
from pige_sym.measurements.rtest import read_measurement
from pige_sym.nc.program import make_rtest_program
from pige_sym.nc.rtest_program import load_test_program
from pige_sym.simulation.simulator import random_pige

AC = "wC'A'bXYZ(C1)t"
REPO = Path(__file__).resolve().parents[1]
FAST = PortSettings(timeout_s=0.25)


# --------------------------------------------------------------------------------------------- nest geometry


def test_nest_recovers_known_displacement_for_non_orthogonal_point_probes() -> None:
    nest = tripod(tilt_deg=50.0, azimuth_deg=17.0, probe="point", ball_diameter_mm=25.4)
    n = nest.directions
    assert abs(n[0] @ n[1]) > 0.1  # really not orthogonal
    d = np.array([[150.0, -80.0, 40.0], [-300.0, 20.0, -120.0], [0.0, 0.0, 0.0], [5.0, 5.0, -5.0]])
    r = nest.readings(d)
    np.testing.assert_allclose(nest.displacement(r), d, atol=1e-9)
    # the sphere-contact correction matters: the linear (flat-probe) model is off by far more than the noise
    linear = r @ np.linalg.inv(n).T
    assert np.abs(linear - d).max() > 0.5
    # forward model against the exact contact condition |s n − d| = ρ for one sensor
    rho = 12.7e3
    s = rho + r[0, 0]
    assert abs(np.linalg.norm(s * n[0] - d[0]) - rho) < 1e-6


def test_nest_flat_probes_are_linear_and_json_geometry(tmp_path) -> None:
    dirs = [[1.0, 0.2, -0.5], [-0.3, 1.0, -0.6], [-0.6, -0.7, -0.4]]
    spec = tmp_path / "nest.json"
    spec.write_text(json.dumps({"directions": dirs, "probe": ["flat", "point", "point"], "ball_diameter_mm": 20}))
    nest = parse_nest(str(spec))
    d = np.array([40.0, -25.0, 90.0])
    np.testing.assert_allclose(nest.displacement(nest.readings(d)), d, atol=1e-9)
    flat = parse_nest("default")
    assert flat.linear
    np.testing.assert_allclose(flat.readings(d), flat.directions @ d)
    np.testing.assert_allclose(flat.directions @ flat.directions.T, np.eye(3), atol=1e-12)  # cube corner
    with pytest.raises(Exception, match="coplanar"):
        NestGeometry(np.array([[1.0, 0, 0], [0, 1.0, 0], [1.0, 1.0, 0]]), np.full(3, np.inf))
    with pytest.raises(Exception, match="key=value"):
        parse_nest("tilt=45,bogus=1")


# --------------------------------------------------------------------------------------------- protocol, framing


def test_parse_record_accepts_valid_and_names_every_rejection() -> None:
    rec = encode_sample(12, 0.6, [312.4051, -87.113, 15.0042])
    assert rec.startswith(b"$RT,12,0.6000,312.4051,-87.1130,15.0042*") and rec.endswith(b"\r\n")
    s = parse_record(rec[1:-2])
    assert isinstance(s, Sample) and s.seq == 12 and s.readings_um == (312.4051, -87.113, 15.0042)
    info = parse_record(encode_info("END")[1:-2])
    assert isinstance(info, Info) and info.is_end

    def reason(body: bytes) -> str:
        with pytest.raises(RecordError) as exc:
            parse_record(body)
        return exc.value.reason

    from pige_sym.acquisition.device import frame_payload

    assert reason(rec[1:-8]) == "format"
    assert reason(rec[1:-2].replace(b"312.4051", b"312.4061")) == "checksum"
    assert reason(frame_payload(b"XX,1,2")[1:-2]) == "type"
    assert reason(frame_payload(b"RT,1,2,3,4")[1:-2]) == "fields"
    assert reason(frame_payload(b"RT,1,2,nan,4,5")[1:-2]) == "number"
    assert reason(frame_payload(b"RT,-1,2,3,4,5")[1:-2]) == "number"


def test_framer_counts_noise_truncated_and_overlong_across_chunk_boundaries() -> None:
    good = [encode_sample(k, k / 20, [1.0 * k, 2.0, 3.0]) for k in range(4)]
    stream = b"xx\n" + good[0] + b"\x00\xffnoise" + good[1] + b"$RT,9,1" + good[2] + b"$" + b"9" * 300 + b"\n" + good[3]
    whole = LineFramer(b"$", max_len=160)
    frames = whole.feed(stream)
    byte_by_byte = LineFramer(b"$", max_len=160)
    frames2 = [f for i in range(len(stream)) for f in byte_by_byte.feed(stream[i:i + 1])]
    assert frames == frames2 == [g[1:-2] for g in good]
    for fr in (whole, byte_by_byte):
        assert (fr.noise_bytes, fr.noise_runs, fr.truncated, fr.overlong) == (10, 2, 1, 1)


@settings(max_examples=60, deadline=None)
@given(st.lists(st.one_of(st.integers(0, 5), st.binary(min_size=1, max_size=40)), min_size=1, max_size=30),
       st.integers(1, 64))
def test_random_bytes_never_yield_a_record_that_was_not_sent(parts, chunk) -> None:
    sent = {k: encode_sample(k, k * 0.05, [k + 0.5, -k - 0.25, 3.0]) for k in range(6)}
    stream = b"".join(sent[p] if isinstance(p, int) else p for p in parts)
    framer = LineFramer(b"$")
    for i in range(0, len(stream), chunk):
        for frame in framer.feed(stream[i:i + chunk]):
            try:
                rec = parse_record(frame)
            except RecordError:
                continue
            assert isinstance(rec, Sample)
            assert rec.seq is not None and sent[rec.seq][1:-2] == frame


def test_loop_url_round_trip() -> None:
    port = open_port("loop://", PortSettings(timeout_s=0.2))
    try:
        port.write(b"junk" + encode_sample(0, 0.0, [1, 2, 3]) + encode_info("hello"))
        framer = LineFramer(b"$")
        frames = []
        deadline = time.monotonic() + 2
        while len(frames) < 2 and time.monotonic() < deadline:
            frames += framer.feed(read_available(port, 0.05))
        recs = [parse_record(f) for f in frames]
        assert isinstance(recs[0], Sample) and recs[0].readings_um == (1.0, 2.0, 3.0)
        assert isinstance(recs[1], Info) and recs[1].text == "hello" and framer.noise_bytes == 4
    finally:
        port.close()
    with pytest.raises(AcquisitionError, match="cannot open port"):
        open_port("/dev/does-not-exist-pige")


# --------------------------------------------------------------------------------------------- in-process stream


class _BytesPort:
    """A port that hands out a fixed byte stream in uneven chunks (no serial stack)."""

    def __init__(self, data: bytes, seed: int = 0) -> None:
        self.data = data
        self.pos = 0
        self.rng = np.random.default_rng(seed)

    def read(self, n: int) -> bytes:
        k = int(min(n, self.rng.integers(1, 3000)))
        out = self.data[self.pos:self.pos + k]
        self.pos += len(out)
        return out

    def write(self, data: bytes) -> int:
        return len(data)

    def close(self) -> None:
        pass


def _stream(dev: VirtualRTest) -> bytes:
    return encode_info("test") + b"".join(dev.record(k) for k in range(dev.n_samples)) + encode_info("END")


def _config(program, seed: int = 2, **kw) -> DeviceConfig:
    return DeviceConfig(program=program, pige=random_pige(AC, seed), seed=seed, **kw)


def test_flagged_pose_gets_no_row_and_the_rest_stay_aligned(tmp_path) -> None:
    program = load_test_program(AC, "cone-frustum", points=6)
    program.dwell_s[3] = 1.6  # too short to settle and average 20 samples
    dev = VirtualRTest(_config(program))
    out = tmp_path / "flag.csv"
    s = acquire("fake", program, out, opener=lambda: _BytesPort(_stream(dev)))
    assert s.completed and [f["pose"] for f in s.flagged] == [3]
    m = read_measurement(out)
    poses = [int(p) for p in m.extra_columns["pose"]]
    assert poses == [0, 1, 2, 4, 5, 6]
    truth = dev.deviation_machine_um[poses]
    assert np.abs(m.deviation_um - truth).max() < 0.2  # right pose on every row (poses differ by um)
    assert (m.optional["n_samples"] == 100).all()


def test_schedule_and_key_triggers_agree_with_stability(tmp_path) -> None:
    program = load_test_program(AC, "cone-frustum", points=5)
    dev = VirtualRTest(_config(program, seed=4))
    rows = {}
    for trig in ("stable", "schedule", "key"):
        out = tmp_path / f"{trig}.csv"
        s = acquire("fake", program, out, options=AcquisitionOptions(trigger=trig), raw_log=None,
                    key_source=lambda: True, echo=lambda msg: None, opener=lambda: _BytesPort(_stream(dev)))
        assert s.completed, s.stop_reason
        rows[trig] = read_measurement(out).deviation_um
    truth = dev.deviation_machine_um
    assert np.abs(rows["stable"] - truth).max() < 0.2  # noise of the mean and of the zero: ~0.035 um
    assert np.abs(rows["schedule"] - truth).max() < 0.2
    # "key" pressed at once: pose 0 is averaged from the first sample (still fine), later windows start while the
    # machine moves, so only the reference row is comparable
    assert rows["key"].shape == truth.shape


@pytest.mark.parametrize("machine, tool, frame", [(AC, None, "table"), ("wbXYZCA(C1)t", (0.0, 0.0, -250.0), "machine")])
def test_point_probe_nest_and_frames_end_to_end(tmp_path, machine, tool, frame) -> None:
    from pige_sym.kernels import load_kernels
    from pige_sym.model.effects import parse_effect

    kern = load_kernels(machine)
    program = load_test_program(machine, "cone-frustum", points=6, tool_mm=tool)
    nest = tripod(tilt_deg=50.0, azimuth_deg=10.0, probe="point", ball_diameter_mm=25.4)
    cfg = DeviceConfig(program=program, pige=random_pige(machine, 7), seed=7, nest=nest,
                       effects=[parse_effect("thermal_drift", tuple(kern.ROTARY_AXES))])
    dev = VirtualRTest(cfg)
    out = tmp_path / "n.csv"
    s = acquire("fake", program, out, nest=nest, options=AcquisitionOptions(frame=frame), raw_log=None,
                opener=lambda: _BytesPort(_stream(dev)))
    assert s.completed, s.stop_reason
    m = read_measurement(out)
    assert m.frame == frame and m.metadata["nest"] == nest.description
    np.testing.assert_allclose(m.deviation_machine_um(), dev.deviation_machine_um, atol=0.2)


def test_resume_refuses_a_different_setup_and_accepts_a_complete_file(tmp_path) -> None:
    program = load_test_program(AC, "cone-frustum", points=4)
    dev = VirtualRTest(_config(program))
    out = tmp_path / "r.csv"
    acquire("fake", program, out, raw_log=None, opener=lambda: _BytesPort(_stream(dev)))
    other = load_test_program(AC, "cone-frustum", points=4, ball_mm=(100.0, 0.0, 80.0))
    with pytest.raises(AcquisitionError, match="ball_mm"):
        acquire("fake", other, out, resume=True, opener=lambda: _BytesPort(b""))
    s = acquire("fake", program, out, resume=True, echo=lambda msg: None, opener=lambda: _BytesPort(b""))
    assert s.completed and s.rows_written == 0
    # a partial file continued from another machine state (other seed: other sensor zero) is refused, untouched
    full = out.read_bytes()
    lines = full.decode().splitlines(keepends=True)
    out.write_text("".join(lines[:-2]))
    stranger = VirtualRTest(_config(program, seed=9))
    with pytest.raises(AcquisitionError, match="nest moved"):
        acquire("fake", program, out, resume=True, echo=lambda msg: None,
                opener=lambda: _BytesPort(_stream(stranger)))
    assert out.read_text() == "".join(lines[:-2])
    s = acquire("fake", program, out, resume=True, echo=lambda msg: None, opener=lambda: _BytesPort(_stream(dev)))
    assert s.completed and s.rows_written == 2 and out.read_bytes() == full


def test_nc_program_dwells_and_poses(tmp_path) -> None:
    traj_prog = load_test_program(AC, "cone-frustum", points=6)
    text = make_rtest_program(traj_prog.angles_deg, traj_prog.linear_mm(), traj_prog.rotary_axes, dwell_s=8)
    path = tmp_path / "rtest.mpf"
    path.write_text(text)
    nc = load_test_program(AC, str(path))
    np.testing.assert_allclose(nc.angles_deg, traj_prog.angles_deg, atol=1e-4)
    assert (nc.dwell_s == 8.0).all() and nc.lines is not None and nc.description.startswith("nc ")


def test_gauge_query_adapter_is_one_small_class(tmp_path) -> None:
    server = socket.create_server(("127.0.0.1", 0))
    port = server.getsockname()[1]
    answered = []

    def gauge() -> None:
        conn, _ = server.accept()
        buf = b""
        with conn:
            while True:
                data = conn.recv(100)
                if not data:
                    return
                buf += data
                while b"?\r" in buf:
                    buf = buf.replace(b"?\r", b"", 1)
                    v = 0.3 + 0.001 * len(answered)
                    conn.sendall(f"{v:+.4f} -0.2500 +0.1000\r\n".encode())
                    answered.append(v)

    threading.Thread(target=gauge, daemon=True).start()
    angles = tmp_path / "angles.csv"
    angles.write_text("A_deg,C_deg\n0,0\n10,20\n20,40\n")
    program = load_test_program(AC, str(angles))
    out = tmp_path / "gauge.csv"
    s = acquire(f"socket://127.0.0.1:{port}", program, out, adapter=GaugeQueryAdapter(period_s=0.01),
                options=AcquisitionOptions(trigger="key", window_s=0.15, min_samples=3), key_source=lambda: True,
                echo=lambda msg: None, settings=FAST)
    server.close()
    assert s.completed and s.rows_written == 3 and len(answered) >= 9
    m = read_measurement(out)
    assert m.n_rows == 3 and float(m.extra_columns["r1_um"][0]) > 300  # 0.3 mm read in mm, stored in um


# --------------------------------------------------------------------------------------------- real serial stack


def _opener(url: str):
    """The port opened as ``acquire`` opens it, then one byte to a device started with ``--await-hello``.

    pyserial discards what arrives while it opens a port; the device sends nothing on a connection before this
    byte, so however late this process runs (a loaded machine), no record is cut at a (re)connection.
    """

    def open_and_say_hello():
        port = open_port(url, FAST)
        port.write(b"\n")
        return port

    return open_and_say_hello


def test_acquire_whole_cone_over_pty_and_identify(tmp_path) -> None:
    truth_path = tmp_path / "dev.truth.json"
    out = tmp_path / "run.csv"
    program = load_test_program(AC, "cone-frustum")
    with start_virtual_device(AC, "cone-frustum", seed=11, time_scale=400, truth=truth_path,
                              extra_args=["--linger", "1", "--await-hello"]) as dev:
        assert dev.url.startswith("/dev/pts/")
        s = acquire(dev.url, program, out, settings=FAST, opener=_opener(dev.url))
    truth = json.loads(truth_path.read_text())
    assert s.completed and s.rows_written == 31 and s.rejected_total == 0 and s.missing == 0, s.format()
    assert default_raw_log(out).stat().st_size == s.bytes_read
    assert json.loads(summary_path(out).read_text())["sessions"][0]["rows_written"] == 31
    m = read_measurement(out)
    assert [int(p) for p in m.extra_columns["pose"]] == list(range(31))
    assert (m.optional["n_samples"] == 100).all() and np.all(np.abs(m.optional["sd_um"] - 0.25) < 0.05)
    assert m.metadata["source"] == "pige acquire" and np.all(np.diff(m.t_s) > 0)
    res = identify(m)
    z = [(res.value(p) - truth["pige"][p]) / res.std[i] for i, p in enumerate(res.parameters)]
    assert res.rank == 8 and np.all(np.abs(z) < 4), dict(zip(res.parameters, np.round(z, 2), strict=True))


def _check_rows_are_clean(out: Path, dev: VirtualRTest, truth: dict) -> None:
    """Every row averages exactly the device's clean readings of the sequence numbers it names."""
    bad = set().union(*(truth["affected"].get(k, []) for k in ("checksum", "drop", "disconnect", "spike")))
    m = read_measurement(out)
    for i in range(m.n_rows):
        first, last = int(m.extra_columns["seq_first"][i]), int(m.extra_columns["seq_last"][i])
        seqs = [k for k in range(first, last + 1) if k not in bad]
        clean = [parse_record(dev.record(k)[1:-2]) for k in seqs]
        mean = np.array([c.readings_um for c in clean if isinstance(c, Sample)]).mean(axis=0)
        assert m.optional["n_samples"][i] == len(seqs)
        got = [float(m.extra_columns[c][i]) for c in ("r1_um", "r2_um", "r3_um")]
        np.testing.assert_allclose(got, mean, rtol=0, atol=1e-9)


FAULT_RUN = ["--points", "10", "--stall-s", "0.6", "--linger", "1.5", "--await-hello"]


@pytest.mark.parametrize("kind", ["garbage", "checksum", "drop", "spike", "stall", "disconnect"])
def test_each_injected_fault_is_counted_and_never_reaches_a_row(tmp_path, kind) -> None:
    seed = 3
    truth_path = tmp_path / "truth.json"
    out = tmp_path / "f.csv"
    program = load_test_program(AC, "cone-frustum", points=10)
    with start_virtual_device(AC, "cone-frustum", seed=seed, time_scale=200, faults=kind, truth=truth_path,
                              extra_args=FAULT_RUN) as dev:
        s = acquire(dev.url, program, out, settings=FAST, options=AcquisitionOptions(reconnect_timeout_s=10),
                    opener=_opener(dev.url))
    truth = json.loads(truth_path.read_text())
    inj = truth["injected"]
    assert inj[kind] == 3, (s.format(), truth.get("stop_reason"), truth["sent"])
    assert s.completed and s.rows_written == 11, s.format()
    assert s.noise_bytes == inj["garbage_bytes"] and s.noise_runs == inj["garbage"]
    assert s.rejected.get("checksum", 0) == inj["checksum"]
    assert s.rejected.get("duplicate", 0) == inj["duplicate"]
    assert s.rejected_total == inj["checksum"] + inj["duplicate"]
    assert s.missing == inj["checksum"] + inj["drop"] + inj["lost_in_outage"]
    assert s.stalls == inj["stall"] and s.disconnects == inj["disconnect"]
    dev_model = VirtualRTest(_config(program, seed=seed))
    _check_rows_are_clean(out, dev_model, truth)


def test_all_faults_at_once_over_tcp(tmp_path, monkeypatch) -> None:
    """Every (re)connection is opened slowly, as on a loaded machine: pyserial's flush at the end of its opening
    comes 80 ms after the connection (a device sending 50 ms after accepting lost the head of a record to it, and
    its tail counted as noise)."""
    import serial.urlhandler.protocol_socket as protocol_socket

    flush = protocol_socket.Serial.reset_input_buffer

    def late_flush(port) -> None:
        time.sleep(0.08)
        flush(port)

    monkeypatch.setattr(protocol_socket.Serial, "reset_input_buffer", late_flush)
    seed = 8
    truth_path = tmp_path / "truth.json"
    out = tmp_path / "t.csv"
    program = load_test_program(AC, "cone-frustum", points=10)
    with start_virtual_device(AC, "cone-frustum", seed=seed, time_scale=200, tcp=0, truth=truth_path,
                              faults="garbage=4,checksum=4,drop=4,stall=2,disconnect=2", extra_args=FAULT_RUN) as dev:
        assert dev.url.startswith("socket://127.0.0.1:")
        s = acquire(dev.url, program, out, settings=FAST, options=AcquisitionOptions(reconnect_timeout_s=10),
                    opener=_opener(dev.url))
    truth = json.loads(truth_path.read_text())
    inj = truth["injected"]
    assert s.completed and s.rows_written == 11, s.format()
    assert (s.noise_bytes, s.rejected_total, s.stalls, s.disconnects) == (
        inj["garbage_bytes"], inj["checksum"], inj["stall"], inj["disconnect"])
    assert s.missing == inj["checksum"] + inj["drop"] + inj["lost_in_outage"]
    _check_rows_are_clean(out, VirtualRTest(_config(program, seed=seed)), truth)


def _acquire_cmd(url: str, out: Path) -> list[str]:
    """``pige acquire`` of ``FAULT_RUN``'s program; a held device's silence is no stall (``--timeout`` 600 s)."""
    return [sys.executable, "-m", "pige_sym", "acquire", "--port", url, "--program", "cone-frustum", "--points", "10",
            "--out", str(out), "--no-progress", "--timeout", "600"]


def _held_device(seed: int, poses: int, out: Path) -> _Server:
    """The virtual device of ``FAULT_RUN`` and ``seed`` over TCP, holding the line after the first ``poses`` poses.

    Once the acquisition of ``out`` has opened the port (its raw log exists: it is created after the port is open,
    and pyserial discards what arrived before the opening ended), it sends the banner and every sample before the
    arrival at pose ``poses`` at once, then nothing more while the connection stays open (a machine held
    mid-program): the acquisition writes exactly ``poses`` rows and cannot end by itself, so a signal sent after
    those rows lands mid-run by construction, however loaded the machine.  No later connection comes: the
    acquisition's ``--timeout`` (600 s) outlasts the test.
    """
    cfg = _config(load_test_program(AC, "cone-frustum", points=10), seed=seed)
    dev = VirtualRTest(cfg)
    end = int(np.nonzero(dev.pose_of_sample == poses)[0][0])
    banner = encode_info(f"pige-rtest-device 1;sensors=3;rate_hz={cfg.rate_hz:g};program={cfg.program.description}")
    data = banner + b"".join(dev.record(k) for k in range(end))
    opened = default_raw_log(out)
    sent: list[bool] = []

    def hold(conn, stop) -> None:
        while not sent and not opened.exists():
            if stop.wait(0.005):
                return
        if not sent:
            sent.append(True)
            conn.sendall(data)
        stop.wait()

    return _Server(hold)


def _wait_rows(path: Path, rows: int, proc: subprocess.Popen, timeout_s: float = 60.0) -> None:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if path.exists() and sum(1 for ln in path.read_text().splitlines() if ln[:1].isdigit()) >= rows:
            return
        assert proc.poll() is None, "acquisition ended before it could be interrupted"
        time.sleep(0.02)
    raise AssertionError("no rows appeared")


def test_kill_mid_run_then_resume_gives_the_same_file(tmp_path) -> None:
    seed = 5
    program = load_test_program(AC, "cone-frustum", points=10)
    full = tmp_path / "full.csv"
    with start_virtual_device(AC, "cone-frustum", seed=seed, time_scale=300, extra_args=FAULT_RUN) as dev:
        assert acquire(dev.url, program, full, settings=FAST, opener=_opener(dev.url)).completed
    part = tmp_path / "part.csv"
    with _held_device(seed, 5, part) as dev:  # the device's stream up to pose 5, then held: the crash is mid-run
        proc = subprocess.Popen(_acquire_cmd(dev.url, part), stdout=subprocess.DEVNULL,
                                stderr=subprocess.DEVNULL)
        _wait_rows(part, 5, proc)
        proc.kill()  # a crash: no clean-up at all
        proc.wait()
    partial = read_measurement(part)
    assert partial.n_rows == 5
    with open(part, "a") as fh:
        fh.write("61.3,12.5")  # a row cut in the middle by the crash
    with start_virtual_device(AC, "cone-frustum", seed=seed, time_scale=300, extra_args=FAULT_RUN) as dev:
        s = acquire(dev.url, program, part, resume=True, settings=FAST, echo=lambda msg: None,
                    opener=_opener(dev.url))
    assert s.completed and s.removed_partial_line and s.first_pose == partial.n_rows
    assert s.poses_replayed == partial.n_rows and s.rows_written == 11 - partial.n_rows
    assert part.read_bytes() == full.read_bytes()


def test_ctrl_c_leaves_a_valid_partial_file_and_summary(tmp_path) -> None:
    """Ctrl-C after two rows, the device holding the line after them: the interrupt lands mid-run by construction.

    The command is started with SIGINT at its default, as from a terminal: under a test runner started in the
    background SIGINT is ignored all the way down, and the run used to go on to its end (exit 0).
    """
    out = tmp_path / "c.csv"
    with _held_device(6, 2, out) as dev:
        proc = subprocess.Popen(as_from_a_terminal(_acquire_cmd(dev.url, out)),
                                stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        _wait_rows(out, 2, proc)
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    m = read_measurement(out)
    assert m.n_rows == 2
    session = json.loads(summary_path(out).read_text())["sessions"][-1]
    assert session["stop_reason"].startswith("interrupted") and session["rows_written"] == m.n_rows
    assert "interrupted" in err and "rows written" in err


def test_cli_bad_input_is_one_line_and_status_2(capsys, tmp_path) -> None:
    assert main(["rtest-sim", "--faults", "gremlins"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "unknown fault 'gremlins'" in err[0]
    assert main(["acquire", "--port", "/dev/does-not-exist-pige", "--out", os.devnull, "--no-progress",
                 "--no-raw-log"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "not a regular file" in err[0]
    assert main(["acquire", "--port", "/dev/does-not-exist-pige", "--out", str(tmp_path / "x.csv"), "--no-progress",
                 "--no-raw-log"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "cannot open port" in err[0]


# --------------------------------------------------------------------------------------------- rows tied to poses


def _rows(out: Path) -> dict[int, np.ndarray]:
    m = read_measurement(out)
    return {int(p): m.deviation_um[i] for i, p in enumerate(m.extra_columns["pose"])}


def _acquire_stream(out: Path, program, data: bytes, **kw):
    return acquire("fake", program, out, raw_log=None, opener=lambda: _BytesPort(data), **kw)


_CLEAN_SEQ_LAST: dict[int, int] = {}


@pytest.fixture(scope="module")
def clean_run(tmp_path_factory):
    """The 9-pose cone of seed 2 acquired from a clean stream: the oracle every faulty run is compared with."""
    program = load_test_program(AC, "cone-frustum", points=8)
    out = tmp_path_factory.mktemp("clean") / "clean.csv"
    s = _acquire_stream(out, program, VirtualRTest(_config(program)).stream())
    assert s.completed and s.rows_written == 9 and not s.flagged
    m = read_measurement(out)
    _CLEAN_SEQ_LAST.update({int(p): int(q) for p, q in zip(m.extra_columns["pose"], m.extra_columns["seq_last"],
                                                           strict=True)})
    return program, _rows(out)


def _assert_same_rows(out: Path, clean: dict[int, np.ndarray], tol_um: float = 0.03) -> None:
    rows = _rows(out)
    assert sorted(rows) == sorted(clean)
    for pose, row in rows.items():
        assert np.abs(row - clean[pose]).max() < tol_um, (pose, row, clean[pose])


@pytest.mark.parametrize("faults", ["spike=1", "spike=30", "drop=12,duplicate=12",
                                    "spike=12,drop=6,duplicate=6,garbage=6,checksum=6"])
def test_spikes_drops_and_duplicates_leave_every_row_as_in_the_clean_run(tmp_path, clean_run, faults) -> None:
    from pige_sym.acquisition.virtual_device import parse_faults

    program, clean = clean_run
    dev = VirtualRTest(_config(program, faults=parse_faults(faults)))
    assert list(dev.plan.values()).count("spike") == parse_faults(faults).get("spike", 0)
    out = tmp_path / "f.csv"
    s = _acquire_stream(out, program, dev.stream())
    assert s.completed and not s.flagged, s.format()
    assert s.rejected.get("duplicate", 0) == parse_faults(faults).get("duplicate", 0)
    _assert_same_rows(out, clean)
    np.testing.assert_allclose(read_measurement(out).deviation_um, dev.deviation_machine_um, atol=0.2)


def clean_run_seq_last(pose: int) -> int:
    """Last sequence number averaged for ``pose`` in the clean run (set by the fixture)."""
    return _CLEAN_SEQ_LAST[pose]


def _dwell_samples(dev: VirtualRTest, pose: int) -> np.ndarray:
    return np.nonzero(dev.pose_of_sample == pose)[0]


@pytest.mark.parametrize("burst", [1, 2, 3, 6])
def test_a_spike_burst_while_waiting_for_motion_never_shifts_a_pose(tmp_path, clean_run, burst) -> None:
    """The original defect: a glitch after a window looked like motion, the pose settled again at the same
    level and every later row held the previous pose's samples.  Short bursts are spikes (ignored), longer ones
    settle too early for the program's timing (dropped as spurious)."""
    program, clean = clean_run
    dev = VirtualRTest(_config(program))
    k0 = clean_run_seq_last(3) + 2  # after pose 3's window, before the move
    assert dev.pose_of_sample[k0 + 15] == 3
    dev.readings_um[k0:k0 + burst, 1] += 50.0
    out = tmp_path / "b.csv"
    s = _acquire_stream(out, program, dev.stream())
    assert s.completed and not s.flagged, s.format()
    assert s.spurious_settles == (1 if burst > 2 else 0)
    _assert_same_rows(out, clean)


def test_a_spike_inside_a_window_is_left_out_of_the_average(tmp_path, clean_run) -> None:
    program, clean = clean_run
    dev = VirtualRTest(_config(program))
    k = int(_dwell_samples(dev, 5)[80])
    dev.readings_um[k] += [0.0, 0.0, 50.0]
    out = tmp_path / "w.csv"
    s = _acquire_stream(out, program, dev.stream())
    assert s.completed and s.spikes == 1
    m = read_measurement(out)
    assert m.optional["n_samples"][5] == 99  # one reading fewer; the row still matches the clean run closely
    _assert_same_rows(out, clean)


def test_a_pose_passed_without_motion_is_flagged_and_the_next_keeps_its_angles(tmp_path, clean_run) -> None:
    program, clean = clean_run
    dev = VirtualRTest(_config(program))
    still = np.arange(_dwell_samples(dev, 3)[-1] + 1, _dwell_samples(dev, 4)[-1] + 1)
    level = dev.readings_um[_dwell_samples(dev, 3)[-40:]].mean(axis=0)
    dev.readings_um[still] = level + np.random.default_rng(1).normal(scale=0.25, size=(still.size, 3))
    out = tmp_path / "u.csv"
    s = _acquire_stream(out, program, dev.stream())
    assert s.completed and [f["pose"] for f in s.flagged] == [4] and "unseen" in s.flagged[0]["reason"]
    rows = _rows(out)
    assert sorted(rows) == [0, 1, 2, 3, 5, 6, 7, 8]
    for pose in rows:
        assert np.abs(rows[pose] - clean[pose]).max() < 0.03


def test_a_settle_at_a_time_no_pose_has_is_flagged_not_written(tmp_path, clean_run) -> None:
    program, clean = clean_run
    dev = VirtualRTest(_config(program))
    dwell = _dwell_samples(dev, 5)
    shaky = dwell[:90]  # 4.5 s of vibration: the pose settles 4.5 s late, beyond the timing tolerance (3.6 s)
    dev.readings_um[shaky] += 10.0 * np.sin(2 * np.pi * 2.0 * dev.t_s[shaky])[:, None]
    out = tmp_path / "d.csv"
    s = _acquire_stream(out, program, dev.stream())
    assert s.completed and [f["pose"] for f in s.flagged] == [5] and "doubtful" in s.flagged[0]["reason"]
    rows = _rows(out)
    assert 5 not in rows and sorted(rows) == [0, 1, 2, 3, 4, 6, 7, 8]
    for pose in rows:
        assert np.abs(rows[pose] - clean[pose]).max() < 0.03


# --------------------------------------------------------------------------------------------- bounded resources


class _Server:
    """A loopback TCP server running ``behave(conn)`` for every client until stopped (bad devices)."""

    def __init__(self, behave) -> None:
        self.sock = socket.create_server(("127.0.0.1", 0))
        self.sock.settimeout(0.1)
        self.url = f"socket://127.0.0.1:{self.sock.getsockname()[1]}"
        self.stop = threading.Event()
        self.accepted = 0
        self.behave = behave
        self.thread = threading.Thread(target=self._serve, daemon=True)
        self.thread.start()

    def _serve(self) -> None:
        while not self.stop.is_set():
            try:
                conn, _ = self.sock.accept()
            except TimeoutError:
                continue
            self.accepted += 1
            with conn:
                try:
                    self.behave(conn, self.stop)
                except OSError:
                    pass

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.stop.set()
        self.thread.join(5)
        self.sock.close()


def _endless_line(conn, stop) -> None:
    conn.sendall(b"$RT,0,0.0000,1")
    while not stop.wait(0.005):  # ~1 MB/s: the time bound ends the run before the byte budget does
        conn.sendall(b"7" * 4096)


def _random_bytes(conn, stop) -> None:
    rng = np.random.default_rng(0)
    while not stop.wait(0.005):
        conn.sendall(rng.integers(0, 256, 4096, dtype=np.uint8).tobytes())


def _accept_and_close(conn, stop) -> None:
    return


def _flood(conn, stop) -> None:
    """Valid records, as fast as the link takes them, one constant reading: nothing ever moves."""
    k = 0
    while not stop.is_set():
        conn.sendall(b"".join(encode_sample(k + j, (k + j) / 20, [300.0, 310.0, 320.0]) for j in range(2000)))
        k += 2000


TIME_BOUND = AcquisitionOptions(reconnect_timeout_s=0.5)
RECONNECT_BOUND = AcquisitionOptions(reconnect_timeout_s=60, max_reconnects=3)
BYTE_BOUND = AcquisitionOptions(max_bytes=2_000_000)


@pytest.mark.parametrize("behave, opts, why", [
    (_endless_line, TIME_BOUND, "no valid record"), (_random_bytes, TIME_BOUND, "no valid record"),
    (_accept_and_close, RECONNECT_BOUND, "reconnected 3 times"), (_accept_and_close, TIME_BOUND, "no valid record"),
    (_flood, BYTE_BOUND, "byte budget")])
def test_bad_devices_end_the_run_quickly_with_a_summary(tmp_path, behave, opts, why) -> None:
    program = load_test_program(AC, "cone-frustum", points=4)
    out = tmp_path / "bad.csv"
    started = time.monotonic()
    with _Server(behave) as server:
        s = acquire(server.url, program, out, settings=FAST, options=opts)
    assert time.monotonic() - started < 20
    assert not s.completed and why in s.stop_reason, s.stop_reason
    assert s.bytes_read <= (2_000_000 if behave is _flood else 10**9)
    log = default_raw_log(out)
    assert log.stat().st_size == s.bytes_read  # every byte read is logged, and no more than the budget
    if behave is _flood:
        assert s.rows_written == 1  # the reference pose, then nothing moved
        session = json.loads(summary_path(out).read_text())["sessions"][-1]
        assert session["stop_reason"] == s.stop_reason
    else:
        assert not out.exists() and not summary_path(out).exists()  # nothing measured: no file claims otherwise


def test_cli_reconnect_timeout_exits_1_with_a_summary(tmp_path, capsys) -> None:
    out = tmp_path / "silent.csv"
    cmd = ["acquire", "--program", "cone-frustum", "--points", "4", "--out", str(out), "--no-progress",
           "--timeout", "0.25", "--reconnect-timeout", "1"]
    with _Server(lambda conn, stop: stop.wait(0.1) or conn.sendall(b"hello") or stop.wait(30)) as server:
        status = main([*cmd, "--port", server.url])
    captured = capsys.readouterr()
    assert status == 1 and "acquisition stopped: no valid record" in captured.out
    assert "link: " in captured.out and "rows written" in captured.out
    log = default_raw_log(out)
    assert log.read_bytes() == b"hello" and not out.exists()
    with _Server(lambda conn, stop: stop.wait(0.1) or conn.sendall(b" again") or stop.wait(30)) as server:
        assert main([*cmd, "--port", server.url]) == 1  # a second attempt appends to the raw log
    assert log.read_bytes() == b"hello again"


def test_schedule_trigger_leaves_spikes_out_and_flags_a_window_that_is_not_still(tmp_path) -> None:
    program = load_test_program(AC, "cone-frustum", points=5)
    opts = AcquisitionOptions(trigger="schedule")
    clean = VirtualRTest(_config(program, seed=4))
    s0 = _acquire_stream(tmp_path / "c.csv", program, clean.stream(), options=opts)
    assert s0.completed and not s0.flagged and s0.spikes == 0
    dev = VirtualRTest(_config(program, seed=4))
    k = int(_dwell_samples(dev, 2)[60])
    dev.readings_um[k, 0] += 50.0  # a spike inside pose 2's scheduled window
    shaky = _dwell_samples(dev, 4)
    dev.readings_um[shaky] += 6.0 * np.sin(2 * np.pi * 1.5 * dev.t_s[shaky])[:, None]  # pose 4 never still
    s = _acquire_stream(tmp_path / "f.csv", program, dev.stream(), options=opts)
    assert s.completed and s.spikes == 1 and [f["pose"] for f in s.flagged] == [4], s.format()
    assert "not still" in s.flagged[0]["reason"]
    rows, ref = _rows(tmp_path / "f.csv"), _rows(tmp_path / "c.csv")
    assert sorted(rows) == [0, 1, 2, 3, 5]
    for pose, row in rows.items():
        assert np.abs(row - ref[pose]).max() < 0.03


def test_records_sent_again_out_of_order_are_duplicates_not_a_restart(tmp_path, clean_run) -> None:
    """A gateway that replays the last records of its buffer after a hiccup must not stop the run."""
    program, clean = clean_run
    dev = VirtualRTest(_config(program))
    k = int(_dwell_samples(dev, 4)[50])
    records = [dev.record(i) for i in range(dev.n_samples)]
    replay = b"".join(records[k - 5:k])  # five records already sent, sent again after record k
    from pige_sym.acquisition.device import encode_info

    data = encode_info("x") + b"".join(records[:k + 1]) + replay + b"".join(records[k + 1:]) + encode_info("END")
    out = tmp_path / "r.csv"
    s = _acquire_stream(out, program, data)
    assert s.completed and s.rejected.get("duplicate") == 5 and not s.flagged, s.format()
    _assert_same_rows(out, clean, tol_um=1e-9)
