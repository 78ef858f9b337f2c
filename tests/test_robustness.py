"""Robustness: fuzzing the readers, machine codes and the device framer (hypothesis), plus the refusals of
issue 15 one by one.

Every input either reads into finite numbers or is refused with a PigeError that names the file (and the line
or field); never a traceback, never a NaN.  ``PIGE_TALLY=path`` writes the outcome counts of the fuzz targets
to a JSON file (docs/formats.md, "What it refuses and why", quotes them).
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from collections import Counter
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from pige_sym.acquisition.device import RecordError, Sample, encode_sample, parse_record
from pige_sym.acquisition.engine import acquire
from pige_sym.acquisition.options import AcquisitionOptions
from pige_sym.acquisition.transport import LineFramer, PortSettings
from pige_sym.cli.main import main
from pige_sym.codegen.machine_code import parse_machine_code
from pige_sym.errors import FileFormatError, MachineCodeError, PigeError
from pige_sym.measurements.measurement import Measurement
from pige_sym.measurements.rtest import _read_header, read_measurement
from pige_sym.measurements.rtest_body import DataBody
from pige_sym.measurements.rtest_writer import write_measurement
from pige_sym.measurements.schema import MAX_PIGE, read_params_file
from pige_sym.nc.rtest_program import load_test_program

AC = "wC'A'bXYZ(C1)t"
LOCATION = ("EY0A", "EZ0A", "EB0A", "EC0A", "EX0C", "EY0C", "EA0C", "EB0C")
TALLY: dict[str, Counter[str]] = {}
FUZZ = settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])


@pytest.fixture(scope="module", autouse=True)
def _write_tally():
    """After the module: the fuzz outcome counts go to the file named by PIGE_TALLY (README numbers)."""
    yield
    target = os.environ.get("PIGE_TALLY")
    if target:
        Path(target).write_text(json.dumps({k: dict(v) for k, v in TALLY.items()}, indent=1))


def _tally(target: str, outcome: str) -> None:
    TALLY.setdefault(target, Counter())[outcome] += 1


def _good_text(rows: int = 6) -> str:
    rng = np.random.default_rng(rows)
    angles = np.column_stack([np.linspace(0, 30, rows), np.linspace(0, 300, rows)])
    dev = rng.normal(scale=5.0, size=(rows, 3))
    dev[0] = 0.0
    m = Measurement(machine=AC, ball_mm=np.array([120.0, 0.0, 80.0]), t_s=np.arange(rows) * 10.0, angles_deg=angles,
                    deviation_um=dev, rotary_axes=("A", "C"), linear_mm=rng.uniform(-100, 100, (rows, 3)),
                    optional={"n_samples": np.full(rows, 100.0)}, extra_columns={"note": ["a"] * rows})
    from pige_sym.measurements.rtest_writer import format_measurement

    return format_measurement(m)


GOOD = _good_text()
GOOD_BYTES = GOOD.encode()
NASTY = ["1_000", "\u0661\u0662", "\uff11\uff12", "nan", "-inf", "1e308", "1e999", "", " ", "0x1f", "1,2", "\u00b5",
         "#", "\r", "\n", "\n\n", "\x00", "\xff", "--1", ".", "1e", "+", "9" * 400]


def _assert_finite(m: Measurement) -> None:
    for arr in (m.ball_mm, m.t_s, m.angles_deg, m.deviation_um, *m.optional.values(),
                *([] if m.linear_mm is None else [m.linear_mm])):
        assert np.isfinite(arr).all()
    assert np.abs(m.deviation_um).max() <= 1e5 and np.abs(m.ball_mm).max() <= 1e5


def _read_or_refusal(path: Path, target: str) -> Measurement | None:
    try:
        m = read_measurement(path)
    except FileFormatError as exc:
        msg = str(exc)
        assert msg.startswith(str(path)) and "\n" not in msg, msg
        _tally(target, "refused, line named" if re.match(re.escape(str(path)) + r":\d+: ", msg) else "refused")
        return None
    _assert_finite(m)
    _tally(target, "read")
    return m


# --------------------------------------------------------------------------------------------- measurement files


@FUZZ
@given(st.lists(st.tuples(st.integers(0, len(GOOD_BYTES)), st.integers(0, 8),
                          st.one_of(st.sampled_from(NASTY).map(lambda s: s.encode("utf-8", "surrogatepass")),
                                    st.binary(max_size=6))), min_size=1, max_size=4))
def test_fuzzed_measurement_files_read_finite_or_are_refused_with_the_line(tmp_path_factory, edits) -> None:
    data = bytearray(GOOD_BYTES)
    for pos, cut, insert in edits:
        pos = min(pos, len(data))
        data[pos:pos + cut] = insert
    path = tmp_path_factory.mktemp("fz") / "m.csv"
    path.write_bytes(bytes(data))
    _read_or_refusal(path, "measurement file (byte edits)")


NUMERIC_ALPHABET = "0123456789.+-eE, \t\r\n"


number_like = st.one_of(
    st.floats(-1e4, 1e4).map(repr), st.integers(-10**6, 10**6).map(str), st.floats(-1e4, 1e4).map(lambda x: f"{x:.3e}"),
    st.text(alphabet=NUMERIC_ALPHABET, max_size=8))
line_like = st.one_of(st.lists(number_like, min_size=10, max_size=10).map(",".join),
                      st.text(alphabet=NUMERIC_ALPHABET, max_size=60))


def _fast_and_strict(path: Path) -> list[tuple]:
    """The body of ``path`` read with the vectorised path, then with the strict path alone: per read
    ``("parsed", values as bytes, text columns)`` or ``("refused", the message, {})``."""
    outcome: list[tuple] = []
    for fast in (True, False):
        with open(path, "rb") as fh:
            body = DataBody(str(path), _read_header(fh, str(path)))
            if not fast:
                body._fast = lambda chunk: None  # type: ignore[method-assign]
            try:
                body.read(fh)
                outcome.append(("parsed", body.array().tobytes(), body.extras))
            except FileFormatError as exc:
                outcome.append(("refused", str(exc), {}))
    return outcome


@FUZZ
@given(st.lists(line_like, min_size=1, max_size=5))
def test_the_numpy_fast_path_accepts_exactly_what_the_strict_path_accepts(tmp_path_factory, lines) -> None:
    """Differential: the chunked NumPy parser must never accept a line the strict line parser refuses."""
    head, _, body = GOOD.partition("t_s,")
    cols = "t_s," + body.split("\n", 1)[0]
    plain = [c for c in cols.split(",") if c != "note"]
    text = head + ",".join(plain) + "\n0,0,0,0,0,0,1,2,3,100\n" + "\n".join(lines) + "\n"
    path = tmp_path_factory.mktemp("fp") / "d.csv"
    path.write_text(text)
    outcome = [(kind, detail if kind == "parsed" else detail.split(": ", 1)[0])
               for kind, detail, _ in _fast_and_strict(path)]
    assert outcome[0] == outcome[1]
    _tally("numeric body (fast vs strict path)", "agree: " + outcome[0][0])


text_field = st.text(alphabet=st.characters(blacklist_characters=",\n", blacklist_categories=("Cs",)), max_size=6)
line_with_text = st.one_of(
    st.tuples(st.lists(number_like, min_size=10, max_size=10), text_field).map(lambda p: ",".join([*p[0], p[1]])),
    st.text(alphabet=NUMERIC_ALPHABET + "#a\u00b5", max_size=60))


@FUZZ
@given(st.lists(line_with_text, min_size=1, max_size=5))
def test_fast_and_strict_paths_agree_with_a_text_column(tmp_path_factory, lines) -> None:
    """Differential, with a text column: values, kept texts and refusals (with their line) agree."""
    head, _, body = GOOD.partition("t_s,")
    text = head + "t_s," + body.split("\n", 1)[0] + "\n0,0,0,0,0,0,1,2,3,100,x\n" + "\n".join(lines) + "\n"
    path = tmp_path_factory.mktemp("fpt") / "d.csv"
    path.write_bytes(text.encode("utf-8", "surrogatepass"))
    outcome = _fast_and_strict(path)
    assert outcome[0] == outcome[1]
    _tally("numeric body with a text column (fast vs strict path)", "agree: " + outcome[0][0])


@pytest.mark.parametrize("bad, line, fragment", [
    ("1_000", 9, "not a number"),
    ("\u0661\u0662", 9, "not a number"),
    ("\uff11\uff12", 9, "not a number"),
    ("1e308", 9, "not physical"),
    ("nan", 9, "NaN"),
])
def test_non_numbers_and_absurd_values_are_refused_with_line_and_column(tmp_path, bad, line, fragment) -> None:
    lines = GOOD.splitlines()
    fields = lines[line - 1].split(",")
    fields[3] = bad  # dx_um of the second data row
    lines[line - 1] = ",".join(fields)
    path = tmp_path / "bad.csv"
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    with pytest.raises(FileFormatError, match=re.escape(f"{path}:{line}: column dx_um")) as info:
        read_measurement(path)
    assert fragment in str(info.value)


def test_ball_of_1e308_duplicated_rows_fifos_and_very_long_lines_are_refused(tmp_path) -> None:
    path = tmp_path / "m.csv"
    path.write_text(GOOD.replace("# ball_mm: 120.0, 0.0, 80.0", "# ball_mm: 1e308, 0.0, 80.0"))
    with pytest.raises(FileFormatError, match=r":3: ball_mm: 1e308 mm is not physical"):
        read_measurement(path)
    lines = GOOD.splitlines()
    k = len(lines) - 2  # 0-based index of the second-to-last data row
    path.write_text("\n".join([*lines[:k + 1], lines[k], *lines[k + 1:]]) + "\n")
    with pytest.raises(FileFormatError, match=rf":{k + 2}: this row repeats line {k + 1} exactly"):
        read_measurement(path)
    fifo = tmp_path / "fifo.csv"
    os.mkfifo(fifo)
    with pytest.raises(FileFormatError, match="not a regular file"):
        read_measurement(fifo)  # returns at once: a FIFO without a writer must not block
    with pytest.raises(FileFormatError, match="not a regular file"):
        read_measurement("/dev/zero")
    path.write_text(GOOD + "1" * (2**20 + 10))
    with pytest.raises(FileFormatError, match="line longer than"):
        read_measurement(path)


def test_large_file_streams_in_chunks_with_the_same_result(tmp_path, monkeypatch) -> None:
    import pige_sym.measurements.rtest_body as io_mod

    rng = np.random.default_rng(3)
    n = 20000
    angles = rng.uniform(-30, 30, (n, 2))
    angles[0] = 0
    dev = rng.normal(size=(n, 3))
    dev[0] = 0
    m = Measurement(machine=AC, ball_mm=np.array([1.0, 2.0, 3.0]), t_s=np.arange(n) * 0.5, angles_deg=angles,
                    deviation_um=dev, rotary_axes=("A", "C"))
    path = tmp_path / "big.csv"
    write_measurement(m, path)
    monkeypatch.setattr(io_mod, "CHUNK_BYTES", 4093)  # many chunks, cut inside lines
    back = read_measurement(path)
    np.testing.assert_array_equal(back.deviation_um, dev)
    np.testing.assert_array_equal(back.angles_deg, angles)


# --------------------------------------------------------------------------------------------- parameter files


def _params(**pige: object) -> dict:
    values: dict[str, object] = {k: 1.5 for k in LOCATION}
    values.update(pige)
    return {"machine": AC, "pige": values}


def _write_json(tmp_path: Path, doc: object, name: str = "p.json") -> Path:
    path = tmp_path / name
    path.write_text(json.dumps(doc, allow_nan=True))
    return path


@pytest.mark.parametrize("value, fragment", [
    (float("nan"), "NaN is not allowed"), (float("inf"), "Infinity is not allowed"), ("nan", "got a string"),
    ("5", "got a string"), ([1.0], "got a list"), (True, "got a boolean"), (1e9, "not physical"),
    ({"v": 1}, "got an object"),
])
def test_params_values_must_be_finite_physical_numbers(tmp_path, value, fragment) -> None:
    path = _write_json(tmp_path, _params(EX0C=value))
    with pytest.raises(FileFormatError, match=re.escape(fragment)) as info:
        read_params_file(path)
    assert str(info.value).startswith(str(path))
    if fragment not in ("NaN is not allowed", "Infinity is not allowed"):
        assert "pige.EX0C" in str(info.value)


def test_params_missing_unknown_machine_encoding_and_nesting(tmp_path) -> None:
    doc = _params()
    del doc["pige"]["EY0C"]
    path = _write_json(tmp_path, doc)
    with pytest.raises(FileFormatError, match="pige.EY0C: missing or null.*--allow-missing"):
        read_params_file(path)
    got = read_params_file(path, allow_missing=True)
    assert got.set_to_zero == ("EY0C",) and got.pige["EY0C"] == 0.0 and got.pige["EX0C"] == 1.5
    with pytest.raises(FileFormatError, match="unknown key 'colour'"):
        read_params_file(_write_json(tmp_path, {**_params(), "colour": "red"}))
    with pytest.raises(FileFormatError, match="pige.EX0Q: not a parameter"):
        read_params_file(_write_json(tmp_path, _params(EX0Q=1.0)))
    with pytest.raises(PigeError, match="is for machine wC'A'bXYZ\\(C1\\)t, but this run is for wC'B'bXYZ"):
        read_params_file(_write_json(tmp_path, _params()), machine="wC'B'bXYZ(C1)t")
    assert read_params_file(_write_json(tmp_path, _params()), machine="w C' A' b X Y Z (C01) t").machine == AC
    latin = tmp_path / "latin.json"
    latin.write_bytes(json.dumps(_params()).replace('"machine"', '"m\\u00b5"').encode().replace(
        b"\\u00b5", "\u00b5".encode("latin-1")))
    with pytest.raises(FileFormatError, match="not UTF-8"):
        read_params_file(latin)
    deep = tmp_path / "deep.json"
    deep.write_text('{"machine": ' + json.dumps(AC) + ', "pige": {}, "findings": ' + "[" * 100000 + "1" + "]" * 100000
                    + "}")
    with pytest.raises(FileFormatError, match="nested deeper"):
        read_params_file(deep)
    dup = tmp_path / "dup.json"
    dup.write_text('{"machine": ' + json.dumps(AC) + ', "pige": {"EX0C": 1, "EX0C": 2}}')
    with pytest.raises(FileFormatError, match="appears twice"):
        read_params_file(dup)


def test_params_accepts_what_identify_and_diagnose_print(tmp_path, capsys) -> None:
    csv = tmp_path / "s.csv"
    assert main(["simulate", "--out", str(csv), "--seed", "4"]) == 0
    for command in ("identify", "diagnose"):
        capsys.readouterr()
        assert main([command, str(csv), "--json"]) == 0
        out = tmp_path / f"{command}.json"
        out.write_text(capsys.readouterr().out)
        got = read_params_file(out, machine=AC)
        assert set(LOCATION) <= set(got.pige) and all(np.isfinite(list(got.pige.values())))


json_values = st.recursive(
    st.one_of(st.none(), st.booleans(), st.integers(-10**20, 10**20), st.floats(), st.text(max_size=8)),
    lambda inner: st.one_of(st.lists(inner, max_size=3), st.dictionaries(st.text(max_size=6), inner, max_size=3)),
    max_leaves=8)


@FUZZ
@given(st.dictionaries(st.sampled_from([*LOCATION, "EA0A", "EX0Q", "cone.x", "", "é"]),
                       st.one_of(st.floats(-100, 100), json_values), max_size=10),
       st.dictionaries(st.sampled_from(["machine", "units", "tool_mm", "pivots_mm", "findings", "rank", "other"]),
                       json_values, max_size=3), st.booleans())
def test_fuzzed_params_files_give_finite_values_or_a_named_refusal(tmp_path_factory, pige, extra, allow) -> None:
    doc = {"machine": AC, **extra, "pige": {**{k: 2.0 for k in LOCATION}, **pige}}
    path = tmp_path_factory.mktemp("pj") / "p.json"
    path.write_text(json.dumps(doc, allow_nan=True))
    try:
        got = read_params_file(path, allow_missing=allow)
    except PigeError as exc:
        assert str(path) in str(exc) and "\n" not in str(exc)
        _tally("parameter file", "refused")
        return
    values = np.array(list(got.pige.values()) + list(got.effect_values.values()))
    assert np.isfinite(values).all() and np.abs(values).max() <= MAX_PIGE
    assert set(LOCATION) <= set(got.pige)
    _tally("parameter file", "read")


# --------------------------------------------------------------------------------------------- machine codes


VALID_CODES = ["wC'A'bXYZ(C1)t", "wC'B'bXYZ(C1)t", "wbXYZCA(C1)t", "wC'bXYZB(C1)t", "w C1' C2' b X Y Z t"]
mutated_code = st.tuples(st.sampled_from(VALID_CODES), st.integers(0, 20), st.integers(0, 2),
                         st.sampled_from(["", "0", "01", "\u00b2", "\u0661", "'", " ", "C", "(C1)", "X", "9999"])).map(
    lambda t: t[0][:t[1]] + t[3] + t[0][t[1] + t[2]:])


@FUZZ
@given(mutated_code | st.text(alphabet=st.sampled_from(list("wbtXYZUVWABCc'’()0123 \u00b2\u0661\uff11\u2032\t")),
                              max_size=24) | st.text(max_size=80))
def test_fuzzed_machine_codes_parse_canonically_or_name_the_position(code) -> None:
    try:
        m = parse_machine_code(code)
    except MachineCodeError as exc:
        assert 0 <= exc.position <= len(code) and "position" in str(exc)
        _tally("machine code", "refused, position named")
        return
    assert m.canonical.isascii() and len(m.canonical) <= 64
    assert parse_machine_code(m.canonical).canonical == m.canonical
    _tally("machine code", "parsed")


# --------------------------------------------------------------------------------------------- device stream


@FUZZ
@given(st.lists(st.one_of(st.integers(0, 30).map(lambda k: encode_sample(k, k / 20, [300.0 + k, -5.0, 2.5])),
                          st.binary(max_size=300), st.just(b"$" + b"9" * 5000), st.just(b"$RT,1,1,1,1,1*0000\r\n")),
                max_size=12), st.integers(1, 97))
def test_fuzzed_byte_streams_never_leak_a_bad_record_or_grow_the_framer(parts, chunk) -> None:
    stream = b"".join(parts)
    framer = LineFramer(b"$", max_len=160)
    good = 0
    for i in range(0, len(stream), chunk):
        for frame in framer.feed(stream[i:i + chunk]):
            assert len(frame) <= 160
            try:
                rec = parse_record(frame)
            except RecordError as exc:
                assert exc.reason in ("format", "checksum", "type", "fields", "number")
                continue
            if isinstance(rec, Sample):
                assert rec.seq is not None and frame == encode_sample(rec.seq, rec.seq / 20,
                                                                      [300.0 + rec.seq, -5.0, 2.5])[1:-2]
                good += 1
        assert len(framer._buf) <= 160
    _tally("device stream", "valid records only" if good else "no valid record")


class _OncePort:
    def __init__(self, data: bytes) -> None:
        self.data = data

    def read(self, n: int) -> bytes:
        out, self.data = self.data[:n], self.data[n:]
        return out

    def write(self, data: bytes) -> int:
        return len(data)

    def close(self) -> None:
        pass


@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.binary(min_size=0, max_size=20000))
def test_random_bytes_through_the_whole_acquisition_end_with_a_summary(tmp_path_factory, junk) -> None:
    program = load_test_program(AC, "cone-frustum", points=3)
    out = tmp_path_factory.mktemp("acq") / "a.csv"
    # the stop comes from the reconnection bound: every reopening feeds the whole junk again, so the run reads it
    # twice and stops after 0.1 s of silence, not after waiting out a time bound (0.3 s per example, 12 examples)
    s = acquire("fake", program, out, raw_log=None, settings=PortSettings(timeout_s=0.05),
                options=AcquisitionOptions(reconnect_timeout_s=0.3, max_reconnects=1, retry_s=0.05),
                opener=lambda: _OncePort(junk))
    assert not s.completed and s.stop_reason and s.rows_written == 0
    _tally("acquisition stream", "stopped with a reason")


# --------------------------------------------------------------------------------------------- the CLI


def test_cli_refusals_are_one_located_line_with_status_2(tmp_path, capsys) -> None:
    path = tmp_path / "bad.csv"
    path.write_text(GOOD.replace("# ball_mm: 120.0, 0.0, 80.0", "# ball_mm: 1_000, 0.0, 80.0"))
    for command in ("identify", "diagnose"):
        assert main([command, str(path)]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and err[0].startswith(f"pige {command}: {path}:3: ball_mm: '1_000' is not a number")


def test_a_console_that_cannot_print_mu_or_arrows_does_not_crash(tmp_path) -> None:
    out = tmp_path / "run\u2192\u00b5.csv"
    env = dict(os.environ, PYTHONIOENCODING="cp1252")
    proc = subprocess.run([sys.executable, "-m", "pige_sym", "simulate", "--points", "6", "--out", str(out)],
                          capture_output=True, env=env, timeout=120)
    assert proc.returncode == 0, proc.stderr.decode("cp1252", "replace")
    assert out.exists() and b"wrote" in proc.stdout


def test_cli_vectors_are_ascii_decimals_within_physical_limits(tmp_path, capsys) -> None:
    for ball, fragment in (("1e308,0,0", "not physical"), ("1_0,0,0", "'1_0' is not a number"),
                           ("\u0661,0,0", "is not a number"), ("nan,0,0", "is not a number"), ("1,2", "3 numbers")):
        assert main(["simulate", "--ball", ball, "--out", str(tmp_path / "x.csv")]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and err[0].startswith("pige simulate: --ball: ") and fragment in err[0], err
    assert not (tmp_path / "x.csv").exists()


def test_simulate_pige_file_goes_through_the_schema(tmp_path, capsys) -> None:
    good = _write_json(tmp_path, {"machine": AC, "pige": {"EX0C": 5.0, "EA0C": -3.0}}, "good.json")
    out = tmp_path / "s.csv"
    assert main(["simulate", "--pige", str(good), "--out", str(out), "--points", "6", "--noise", "0"]) == 0
    truth = json.loads(out.with_name("s.truth.json").read_text())["pige"]
    assert truth["EX0C"] == 5.0 and truth["EA0C"] == -3.0 and truth["EY0A"] == 0.0
    capsys.readouterr()
    for doc, fragment in (({"machine": AC, "pige": {"EX0C": "nan"}}, "pige.EX0C: expected a number"),
                          ({"machine": "wC'B'bXYZ(C1)t", "pige": {}}, "is for machine"),
                          ({"machine": AC, "pige": {"EX0C": 1e300}}, "not physical")):
        bad = _write_json(tmp_path, doc, "bad.json")
        assert main(["simulate", "--pige", str(bad), "--out", str(tmp_path / "b.csv")]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and fragment in err[0], err


def test_non_finite_options_are_refused_and_nothing_writes_nan(tmp_path, capsys) -> None:
    from pige_sym.errors import InputError
    from pige_sym.measurements.rtest_writer import MeasurementWriter

    for argv, fragment in ((["simulate", "--noise", "nan"], "--noise: nan"),
                           (["acquire", "--port", "x", "--move", "inf"], "--move: inf"),
                           (["acquire", "--port", "x", "--window", "nan"], "window_s must be > 0"),
                           (["rtest-sim", "--noise", "nan"], "noise_um must be a finite number")):
        assert main([*argv, "--out" if argv[0] != "rtest-sim" else "--seed",
                     str(tmp_path / "o.csv") if argv[0] != "rtest-sim" else "1"]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and fragment in err[0], err
    good = tmp_path / "g.csv"
    good.write_text(GOOD)
    template = read_measurement(good)
    with pytest.raises(InputError, match="never writes"):
        write_measurement(Measurement(machine=AC, ball_mm=np.zeros(3), t_s=np.array([0.0, np.nan]),
                                      angles_deg=np.zeros((2, 2)), deviation_um=np.zeros((2, 3)),
                                      rotary_axes=("A", "C")), tmp_path / "w.csv")
    with MeasurementWriter(tmp_path / "r.csv", template) as w, pytest.raises(InputError, match="never writes"):
        w.write_row(1.0, [0.0, 0.0], [float("nan"), 0.0, 0.0], [0.0, 0.0, 0.0], {"n_samples": 1.0}, {"note": "x"})
    assert "nan" not in (tmp_path / "r.csv").read_text()


def test_spreadsheet_exports_are_read_or_named(tmp_path) -> None:
    """Excel's 'CSV UTF-8' (a byte-order mark) is read; ';' fields, decimal commas and UTF-16 are refused by name."""
    good = tmp_path / "good.csv"
    good.write_text(_good_text())
    bom = tmp_path / "bom.csv"
    bom.write_bytes(b"\xef\xbb\xbf" + good.read_bytes())
    np.testing.assert_array_equal(read_measurement(bom).deviation_um, read_measurement(good).deviation_um)
    lines = good.read_text().splitlines()
    header = next(i for i, ln in enumerate(lines) if not ln.startswith("#"))
    semi = tmp_path / "semi.csv"
    semi.write_text("\n".join(lines[:header] + [ln.replace(",", ";") for ln in lines[header:]]) + "\n")
    with pytest.raises(FileFormatError, match=f":{header + 1}: in the column header; the fields are separated by ';'"):
        read_measurement(semi)
    comma = tmp_path / "comma.csv"
    row = lines[header + 2].split(",")
    comma.write_text("\n".join(lines[:header + 2] + [",".join(v.replace(".", ",") for v in row)]
                               + lines[header + 3:]) + "\n")
    with pytest.raises(FileFormatError, match=f":{header + 3}: .*decimal comma"):
        read_measurement(comma)
    utf16 = tmp_path / "u16.csv"
    utf16.write_text(good.read_text(), encoding="utf-16")
    with pytest.raises(FileFormatError, match=":1: UTF-16"):
        read_measurement(utf16)


def test_a_parameter_given_twice_under_its_two_spellings_is_refused(tmp_path, capsys) -> None:
    assert main(["simulate", "--pige", "EX0C=5,EXOC=3", "--out", str(tmp_path / "r.csv")]) == 2
    assert "EX0C is given twice (EX0C, EXOC" in capsys.readouterr().err
    assert not (tmp_path / "r.csv").exists()


def test_pige_alone_prints_usage_and_errors_name_the_command_once(capsys) -> None:
    assert main([]) == 0
    assert "usage: pige" in capsys.readouterr().out
    with pytest.raises(SystemExit) as stop:
        main(["identify"])
    assert stop.value.code == 2
    err = capsys.readouterr().err
    assert err.startswith("pige identify: ") and "pige pige" not in err
