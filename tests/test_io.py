"""Reader/writer of the pige-rtest 1 format (CONVENTIONS §6)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pige_sym.errors import FileFormatError
from pige_sym.measurements.measurement import Measurement
from pige_sym.measurements.rtest import read_angle_file, read_measurement
from pige_sym.measurements.rtest_writer import MeasurementWriter, write_measurement
from testdata import reference_files, require_shared

GOOD = """# pige-rtest 1
# machine: wC'A'bXYZ(C1)t
# ball_mm: 120.0, 0.0, 80.0
# frame: machine
# trajectory: cone-frustum half_angle=30 incl=10 incl_axis=X
t_s,A_deg,C_deg,dx_um,dy_um,dz_um
0.0,0.0,0.0,0.0,0.0,0.0
5.0,-20.1,12.0,0.412,-1.203,0.088
10.0,-21.0,24.0,0.5,-1.3,0.1
"""


def write(tmp_path: Path, text: str, name: str = "run.csv") -> Path:
    p = tmp_path / name
    p.write_text(text)
    return p


def test_read_good_file(tmp_path) -> None:
    m = read_measurement(write(tmp_path, GOOD))
    assert m.rotary_axes == ("A", "C")
    assert m.n_rows == 3
    np.testing.assert_array_equal(m.ball_mm, [120.0, 0.0, 80.0])
    np.testing.assert_array_equal(m.angles_deg[1], [-20.1, 12.0])
    np.testing.assert_array_equal(m.deviation_um[1], [0.412, -1.203, 0.088])
    assert m.trajectory.startswith("cone-frustum")


def test_round_trip_is_lossless_with_extras(tmp_path) -> None:
    text = GOOD.replace("# frame: machine\n", "# frame: table\n# operator: Ann\n# pivot_A_mm: 0, 10.5, -3\n"
                        "# tool_mm: 0, 0, -250\n")
    text = text.replace("dz_um\n", "dz_um,X_mm,Y_mm,Z_mm,temp_C,note\n")
    text = text.replace("0.0,0.0,0.0,0.0,0.0,0.0\n", "0.0,0.0,0.0,0.0,0.0,0.0,120.0,0.0,80.0,20.1,start\n")
    text = text.replace("0.088\n", "0.088,119.5,1.25,80.5,20.2,\n").replace("0.1\n", "0.1,119.4,1.5,80.75,20.3,x y\n")
    p = write(tmp_path, text)
    m = read_measurement(p)
    assert m.frame == "table" and m.metadata["operator"] == "Ann"
    assert m.extra_columns == {"note": ["start", "", "x y"]}
    np.testing.assert_array_equal(m.pivots_mm["A"], [0, 10.5, -3])
    out = tmp_path / "out.csv"
    write_measurement(m, out)
    assert out.read_text() == text
    m2 = read_measurement(out)
    assert m2.metadata == m.metadata
    np.testing.assert_array_equal(m2.linear_mm, m.linear_mm)
    np.testing.assert_array_equal(m2.optional["temp_C"], m.optional["temp_C"])


@pytest.mark.parametrize(
    ("edit", "line", "fragment"),
    [
        (lambda t: t.replace("# pige-rtest 1", "# pige-rtest 2"), 1, "format pige-rtest version 2: this pige reads"),
        (lambda t: t.replace("# machine: wC'A'bXYZ(C1)t\n", ""), 5, "missing required metadata '# machine"),
        (lambda t: t.replace("# ball_mm: 120.0, 0.0, 80.0\n", ""), 5, "missing required metadata '# ball_mm"),
        (lambda t: t.replace("120.0, 0.0, 80.0", "120.0, 0.0"), 3, "ball_mm: expected 3"),
        (lambda t: t.replace("120.0, 0.0, 80.0", "120.0, zero, 80"), 3, "'zero' is not a number"),
        (lambda t: t.replace("wC'A'bXYZ(C1)t", "wC'Q'bXYZ(C1)t"), 2, "unknown machine code"),
        (lambda t: t.replace("wC'A'bXYZ(C1)t", "wbXYZ(C1)t"), 2, "no rotary axis"),
        (lambda t: t.replace("# frame: machine", "# frame: spindle"), 4, "frame must be"),
        (lambda t: t.replace("A_deg,C_deg", "B_deg,C_deg"), 6, "missing column(s) A_deg"),
        (lambda t: t.replace("dz_um\n", "dz_um,B_deg\n").replace("0.0,0.0,0.0,0.0,0.0,0.0\n",
                                                               "0.0,0.0,0.0,0.0,0.0,0.0,0\n"), 6, "B_deg do not match"),
        (lambda t: t.replace("dy_um,dz_um", "dy_um,dy_um"), 6, "duplicated column"),
        (lambda t: t.replace("t_s,A_deg", "time,A_deg"), 6, "missing column(s) t_s"),
        (lambda t: t.replace("-1.203,0.088", "-1.203"), 8, "expected 6 fields, got 5"),
        (lambda t: t.replace("-1.203", "abc"), 8, "column dy_um: 'abc' is not a number"),
        (lambda t: t.replace("-1.203", "nan"), 8, "column dy_um: NaN"),
        (lambda t: t.replace("-1.203", "inf"), 8, "column dy_um: infinite"),
        (lambda t: t.replace("0.0,0.0,0.0,0.0,0.0,0.0", "0.0,1.5,0.0,0.0,0.0,0.0"), 7, "reference pose"),
        (lambda t: t.replace("0.0,0.0,0.0,0.0,0.0,0.0", "0.0,0.0,0.0,0.0,0.3,0.0"), 7, "dy_um=0.3"),
        (lambda t: t.replace("10.0,-21.0", "4.0,-21.0"), 9, "t_s goes backwards"),
        (lambda t: t.replace("# trajectory:", "# trajectory"), 5, "'# key: value'"),
        (lambda t: t + "\n12.0,1,1,1,1,1\n", 10, "blank line inside"),
        (lambda t: t.split("0.0,0.0,0.0,0.0,0.0,0.0")[0], 6, "no data rows"),
        (lambda t: t.replace("# frame: machine", "# pivot_B_mm: 0,0,0"), 4, "no rotary axis 'B'"),
        (lambda t: t.replace("# frame: machine", "# tool_mm: 0,0"), 4, "tool_mm: expected 3"),
        (lambda t: t.replace("dz_um\n", "dz_um,X_mm\n").replace("0.0,0.0,0.0,0.0,0.0,0.0\n",
                                                               "0.0,0.0,0.0,0.0,0.0,0.0,1\n"), 6, "all of X_mm"),
        (lambda t: t.replace("# frame: machine", "# machine: wC'B'bXYZ(C1)t"), 4, "repeated"),
    ],
)
def test_malformed_files_refused_with_line_and_reason(tmp_path, edit, line, fragment) -> None:
    p = write(tmp_path, edit(GOOD))
    with pytest.raises(FileFormatError) as info:
        read_measurement(p)
    msg = str(info.value)
    assert msg.startswith(f"{p}:{line}: "), msg
    assert fragment in msg, msg


def test_missing_file(tmp_path) -> None:
    with pytest.raises(FileFormatError, match="file not found"):
        read_measurement(tmp_path / "nope.csv")


@settings(max_examples=60, deadline=None)
@given(
    st.lists(
        st.tuples(*[st.floats(allow_nan=False, allow_infinity=False, width=64, min_value=-1e5, max_value=1e5)] * 5),
        min_size=1, max_size=20,
    ),
    st.lists(st.floats(min_value=-1e3, max_value=1e3, allow_nan=False), min_size=3, max_size=3),
)
def test_round_trip_random_floats(tmp_path_factory, rows, ball) -> None:
    n = len(rows) + 1
    arr = np.array([(0.0,) * 5, *rows])
    m = Measurement(
        machine="wC'B'bXYZ(C1)t", ball_mm=np.array(ball), t_s=np.arange(n) * 5.0, angles_deg=arr[:, :2],
        deviation_um=arr[:, 2:5], rotary_axes=("B", "C"),
    )
    p = tmp_path_factory.mktemp("rt") / "r.csv"
    write_measurement(m, p)
    m2 = read_measurement(p)
    np.testing.assert_array_equal(m2.angles_deg, m.angles_deg)
    np.testing.assert_array_equal(m2.deviation_um, m.deviation_um)
    np.testing.assert_array_equal(m2.ball_mm, m.ball_mm)


def test_row_writer_leaves_valid_partial_file(tmp_path) -> None:
    template = read_measurement(write(tmp_path, GOOD))
    out = tmp_path / "live.csv"
    with MeasurementWriter(out, template) as w:
        w.write_row(0.0, [0, 0], [0, 0, 0])
        w.write_row(5.0, [1, 2], [0.1, 0.2, 0.3])
        partial = read_measurement(out)  # readable while still open
        assert partial.n_rows == 2
    with MeasurementWriter(out, template, append=True) as w:
        w.write_row(10.0, [3, 4], [0.4, 0.5, 0.6])
    assert read_measurement(out).n_rows == 3


def test_angle_file(tmp_path) -> None:
    p = write(tmp_path, "# my angles\nt_s,A_deg,C_deg\n0,0,0\n5,10,20\n", "angles.csv")
    axes, angles, t = read_angle_file(p)
    assert axes == ("A", "C")
    np.testing.assert_array_equal(angles, [[0, 0], [10, 20]])
    np.testing.assert_array_equal(t, [0, 5])
    bad = write(tmp_path, "A_deg,foo\n0,0\n", "bad.csv")
    with pytest.raises(FileFormatError, match="unexpected column"):
        read_angle_file(bad)


@pytest.mark.parametrize("path", reference_files("*.csv"), ids=lambda p: p.name)
def test_reference_files_read_and_round_trip(tmp_path, path) -> None:
    require_shared()
    m = read_measurement(path)
    out = tmp_path / path.name
    write_measurement(m, out)
    m2 = read_measurement(out)
    assert m2.metadata == m.metadata
    np.testing.assert_array_equal(m2.deviation_um, m.deviation_um)


@pytest.mark.parametrize("chunk_bytes", [64, 1000, 2**22])
def test_chunked_fast_path_equals_line_by_line_path_with_text_columns(tmp_path, monkeypatch, chunk_bytes) -> None:
    """Many rows, across chunk boundaries, with text columns and CRLF: the vectorised path reads
    exactly what the strict line-by-line path reads (values bit for bit, texts verbatim)."""
    import pige_sym.measurements.rtest_body as io_module

    rng = np.random.default_rng(5)
    rows = 400
    lines = GOOD.split("\n")[:5] + ["t_s,A_deg,C_deg,pose,dx_um,dy_um,dz_um,note"]
    lines.append("0.0,0.0,0.0,0,0.0,0.0,0.0,ref")
    for i in range(1, rows):
        dev = [float(v) for v in rng.normal(0, 3, 3)]
        tilt = float(rng.uniform(-90, 0))
        lines.append(f"{i * 0.5!r},{tilt!r},{rng.uniform(0, 360):.4f},{i},{dev[0]!r},{dev[1]:.6e},"
                     f"{dev[2]:.3f},{'ok' if i % 7 else 'spike at ' + str(i)}")
    path = tmp_path / "crlf.csv"
    path.write_bytes(("\r\n".join(lines) + "\r\n").encode())
    monkeypatch.setattr(io_module, "CHUNK_BYTES", chunk_bytes)
    vectorised = io_module.DataBody._fast
    taken = []
    monkeypatch.setattr(io_module.DataBody, "_fast",
                        lambda self, chunk: (result := vectorised(self, chunk), taken.append(result))[0])
    fast = read_measurement(path)
    assert sum(block is not None for block in taken) >= len(taken) - 1  # only a chunk of the header's tail may not
    monkeypatch.setattr(io_module.DataBody, "_fast", lambda self, chunk: None)
    strict = read_measurement(path)
    assert fast.n_rows == rows
    pairs = ((fast.t_s, strict.t_s), (fast.angles_deg, strict.angles_deg), (fast.deviation_um, strict.deviation_um))
    for a, b in pairs:
        assert np.array_equal(a.view(np.int64), b.view(np.int64))
    assert fast.extra_columns == strict.extra_columns
    assert fast.extra_columns["note"][7] == "spike at 7" and fast.extra_columns["pose"][-1] == str(rows - 1)


@pytest.mark.parametrize("chunk_bytes", [64, 300, 2**22])
def test_a_too_long_line_is_named_exactly_whatever_the_chunks(tmp_path, monkeypatch, chunk_bytes) -> None:
    """The line number of a too-long line is exact although chunks are parsed ahead in threads."""
    import pige_sym.measurements.rtest_body as io_module

    rows = [f"{i}.0,{-i * 0.1!r},{i}.5,0.1,0.2,0.3" for i in range(1, 60)]
    rows[40] += "," + "9" * 500  # line 41 of the data
    head = GOOD.split("t_s,")[0] + "t_s,A_deg,C_deg,dx_um,dy_um,dz_um\n0.0,0.0,0.0,0.0,0.0,0.0\n"
    text = head + "\n".join(rows) + "\n"
    path = write(tmp_path, text)
    monkeypatch.setattr(io_module, "CHUNK_BYTES", chunk_bytes)
    monkeypatch.setattr(io_module, "MAX_LINE_BYTES", 200)
    header_lines = GOOD.split("t_s,")[0].count("\n") + 1
    with pytest.raises(FileFormatError, match="line longer than 200 bytes") as err:
        read_measurement(path)
    assert f":{header_lines + 1 + 41}:" in str(err.value), str(err.value)
