"""Issue 33, scale: the probe path is linear in the data and gives the same numbers as the direct forms.

- the O(n) whitening of the reference-pose coupling against the dense Cholesky of the full covariance
  (normal equations to 1e-9 relative);
- the vectorised LinuxCNC log reader against the strict line-by-line reader (bit for bit; hypothesis), and the
  strict reader's located refusal whenever the fast path declines;
- the vectorised sphere fits (all poses at once) against one pose at a time;
- the chunked measurement writer against the row-by-row text;
- issue 43: every reader of configuration and log text reads a megabyte line in linear time.

Timings live in benchmarks/bench_scale.py; here only the readers' growth with a line's length, with wide margins.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.linalg import solve_triangular
from scipy.spatial.transform import Rotation

from pige_sym.errors import FileFormatError
from pige_sym.identification.instruments import _whitening
from pige_sym.measurements import probe_log
from pige_sym.measurements.sphere_fit import fit_centres, fit_own_radius, flatten, inverse3, pose_grams, pose_sums

SOME = settings(max_examples=40, deadline=None)


def _spd(rng: np.random.Generator, n: int, scale: float) -> np.ndarray:
    a = rng.normal(size=(n, 3, 3))
    return scale * (a @ a.transpose(0, 2, 1) + 0.1 * np.eye(3))


@pytest.mark.parametrize("rows", [1, 2, 7, 40])
def test_the_linear_whitening_gives_the_dense_normal_equations(rows) -> None:
    rng = np.random.default_rng(rows)
    sigma = _spd(rng, rows, 0.3)
    sigma0 = _spd(rng, 1, 2.0)[0]  # a reference centre worse than the others: strong coupling
    rot = Rotation.random(rows, random_state=rows).as_matrix()
    design = rng.normal(size=(rows, 3, 8))
    data = rng.normal(size=(rows, 3))
    dense = np.einsum("rij,jk,slk->rsil", rot, sigma0, rot).transpose(0, 2, 1, 3).reshape(3 * rows, 3 * rows)
    for r in range(rows):
        dense[3 * r:3 * r + 3, 3 * r:3 * r + 3] += sigma[r]
    dense /= np.mean(np.diag(dense))
    chol = np.linalg.cholesky(dense)
    a_ref = solve_triangular(chol, design.reshape(-1, 8), lower=True)
    y_ref = solve_triangular(chol, data.reshape(-1), lower=True)
    whiten = _whitening(sigma, sigma0, rot)
    a, y = whiten(design), whiten(data[:, :, None])[:, 0]
    for got, ref in ((a.T @ a, a_ref.T @ a_ref), (a.T @ y, a_ref.T @ y_ref), (y @ y, y_ref @ y_ref)):
        assert np.max(np.abs(got - ref)) <= 1e-9 * np.max(np.abs(ref))


def test_a_probe_import_identifies_the_same_with_the_dense_covariance(tmp_path) -> None:
    from pige_sym.cli.main import main
    from pige_sym.identification.instruments import probe_covariance, whitened_rows
    from pige_sym.identification.problem import build_problem
    from pige_sym.kernels import load_kernels
    from pige_sym.measurements.rtest import read_measurement

    log, csv = tmp_path / "log.txt", tmp_path / "p.csv"
    assert main(["simulate", "--instrument", "sphere-probe", "--sphere", "100,20,60", "--sphere-radius", "12.7",
                 "--stylus-radius", "1.5", "--points", "30", "--seed", "4", "--rtcp-off", "M429", "--rtcp-on", "M428",
                 "--out", str(log)]) == 0
    assert main(["import-probe", str(log), "--format", "linuxcnc", "--sphere-radius", "12.7", "--stylus-radius",
                 "1.5", "--out", str(csv)]) == 0
    m = read_measurement(csv)
    prob = build_problem(m, "xyz", explicit=True)
    rot = load_kernels(m.machine).workpiece_rotation(m.angles_deg)
    for rows in (prob.rows, prob.rows[::3]):  # every pose, and a subset (the diagnosis leaves outliers out)
        a, y = whitened_rows(m, prob.design, prob.data, rot, rows)
        cov = probe_covariance(m, rot, rows)
        chol = np.linalg.cholesky(cov / np.mean(np.diag(cov)))
        a_ref = solve_triangular(chol, prob.design[rows].reshape(-1, prob.design.shape[2]), lower=True)
        y_ref = solve_triangular(chol, prob.data[rows].reshape(-1), lower=True)
        np.testing.assert_allclose(a.T @ a, a_ref.T @ a_ref, rtol=1e-9, atol=1e-9 * np.abs(a_ref.T @ a_ref).max())
        np.testing.assert_allclose(a.T @ y, a_ref.T @ y_ref, rtol=1e-9, atol=1e-9 * np.abs(a_ref.T @ y_ref).max())


# ------------------------------------------------------------------------------------------ the log reader

number = st.one_of(st.floats(-99999, 99999, allow_nan=False).map(lambda v: f"{v:f}"),
                   st.integers(-10**5, 10**5).map(str), st.sampled_from(["-0.000000", "0.0", ".5", "+1.25", "7."]))
angle = st.sampled_from(["0.000000", "10.000000", "-35.500000", "359.999999"])
log_line = st.tuples(number, number, number, angle, st.just("0.000000"), angle, number, number, number).map(
    " ".join)


@SOME
@given(lines=st.lists(log_line, min_size=1, max_size=30), blank=st.lists(st.integers(0, 30), max_size=3),
       crlf=st.booleans(), tail=st.booleans())
def test_the_vectorised_linuxcnc_reader_reads_exactly_what_the_strict_one_reads(lines, blank, crlf, tail) -> None:
    for i in blank:
        lines.insert(min(i, len(lines)), "")
    end = "\r\n" if crlf else "\n"
    raw = (end.join(lines) + (end if tail else "")).encode("ascii")
    strict = _strict(raw)
    fast = probe_log._linuxcnc_fast("log", raw, ("A", "C"), 1.0)
    if isinstance(strict, str):
        assert fast is None, strict  # the fast path never accepts what the strict one refuses
        return
    assert fast is not None
    for name in ("xyz_mm", "angles_deg", "lines"):
        assert np.array_equal(getattr(fast, name), getattr(strict, name)), name


def _strict(raw: bytes) -> probe_log.ProbeLog | str:
    try:
        return probe_log._read_linuxcnc("log", probe_log._read_lines("log", raw), ("A", "C"), 1.0)
    except FileFormatError as exc:
        return str(exc)


@SOME
@given(lines=st.lists(log_line, min_size=2, max_size=12), at=st.integers(0, 11),
       bad=st.sampled_from(["1  2", " 1", "nan", "1e999", "1,5", "\t", "x", "1e5", "-", "200000.000000", "١"]))
def test_a_line_the_fast_path_declines_is_refused_by_the_strict_path_with_its_line(lines, at, bad) -> None:
    at %= len(lines)
    fields = lines[at].split(" ")
    fields[1] = bad
    lines[at] = " ".join(fields)
    raw = ("\n".join(lines) + "\n").encode("utf-8")
    strict = _strict(raw) if raw.isascii() else "not ASCII"
    try:
        got = probe_log.parse_probe_log("log", raw, "linuxcnc", ("A", "C"))
    except FileFormatError as exc:
        assert isinstance(strict, str) and (strict == str(exc) or not raw.isascii()), (strict, exc)
        assert f"log:{at + 1}:" in str(exc) or not raw.isascii()
        return
    assert not isinstance(strict, str)
    assert np.array_equal(got.xyz_mm, strict.xyz_mm)


# ---------------------------------------------------------------------------------------------- the fits


def _poses(rng: np.random.Generator, n: int, counts: list[int]) -> list[np.ndarray]:
    out = []
    for i in range(n):
        k = counts[i % len(counts)]
        d = rng.normal(size=(k, 3))
        d[:, 2] = np.abs(d[:, 2]) + 0.3
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        out.append(rng.normal(size=3) + 14.2 * d + rng.normal(0, 1e-3, (k, 1)) * d)
    return out


@pytest.mark.parametrize("counts", [[5], [4, 5, 9, 6]])
def test_all_poses_at_once_fit_as_one_pose_at_a_time(counts) -> None:
    rng = np.random.default_rng(len(counts))
    pts = _poses(rng, 12, counts)
    together = fit_centres(pts, radius_mm=14.2, moves="axes")
    alone = np.array([fit_centres([p], radius_mm=14.2, moves="axes").centres_mm[0] for p in pts])
    np.testing.assert_allclose(together.centres_mm, alone, atol=1e-12)
    own = fit_own_radius(pts, moves="axes")
    for p, r in zip(pts, np.split(own, np.cumsum([len(p) for p in pts])[:-1]), strict=True):
        expected = np.zeros(len(p)) if len(p) == 4 else fit_centres([p], moves="axes").residuals_um[0]
        np.testing.assert_allclose(r, expected, atol=1e-6)
    flat, starts = flatten(pts)
    np.testing.assert_allclose(pose_sums(flat, starts), [p.sum(axis=0) for p in pts], atol=1e-12)
    np.testing.assert_allclose(pose_grams(flat, flat, starts), [p.T @ p for p in pts], rtol=1e-12)
    mats = np.array([p.T @ p for p in pts])
    np.testing.assert_allclose(inverse3(mats) @ mats, np.tile(np.eye(3), (len(pts), 1, 1)), atol=1e-9)


def test_the_chunked_writer_writes_exactly_the_rows(tmp_path) -> None:
    from pige_sym.measurements.measurement import Measurement
    from pige_sym.measurements.rtest_writer import header_text, measurement_chunks, row_text

    rng = np.random.default_rng(5)
    n = 50
    dev = rng.normal(size=(n, 3)) * 10 ** rng.uniform(-9, 4, size=(n, 3))
    dev[0] = 0.0
    m = Measurement(machine="wC'A'bXYZ(C1)t", ball_mm=np.array([1.0, 2.0, 3.0]), t_s=np.arange(n) / 3.0,
                    angles_deg=np.column_stack([np.linspace(0, 30, n), np.linspace(0, 300, n)]), deviation_um=dev,
                    rotary_axes=("A", "C"), optional={"sd_um": rng.uniform(0, 1, n), "cov_xx_um2": rng.uniform(size=n)},
                    extra_columns={"note": [f"n{i}" for i in range(n)]})
    text = "".join(measurement_chunks(m, rows=7))
    assert text == header_text(m) + "".join(row_text(m, i) + "\n" for i in range(n))


@settings(max_examples=60, deadline=None)
@given(rows=st.integers(2, 12), big=st.sampled_from([0.0, 2e5, -3e5, 1e4]), where=st.integers(0, 11),
       repeat=st.booleans(), reference=st.sampled_from([0.0, 1e-6, 0.5]), backwards=st.booleans(),
       column=st.sampled_from(["dx_um", "sd_um", "cov_xy_um2", "cx_mm", "A_deg"]))
def test_the_written_file_is_checked_exactly_as_the_reader_would(tmp_path_factory, rows, big, where, repeat,
                                                                  reference, backwards, column) -> None:
    """``check_as_read`` (import-probe's check before publishing its file) refuses exactly what ``read_measurement``
    refuses in the same file, with the same message: the rows are not parsed twice, the verdict is the same."""
    from pige_sym.measurements.measurement import Measurement
    from pige_sym.measurements.rtest import check_as_read, read_measurement
    from pige_sym.measurements.rtest_writer import write_measurement

    rng = np.random.default_rng(rows)
    dev = rng.normal(size=(rows, 3))
    dev[0] = reference
    angles = np.column_stack([np.linspace(0, 30, rows), np.linspace(0, 300, rows)])
    t = np.arange(rows, dtype=float)
    if backwards and rows > 2:
        t[-1] = 0.5
    optional = {"sd_um": rng.uniform(0, 1, rows), "cov_xy_um2": rng.normal(size=rows), "cx_mm": rng.normal(size=rows)}
    i = where % rows
    if column == "dx_um":
        dev[i, 0] += big
    elif column == "A_deg":
        angles[i, 0] += big
    else:
        optional[column][i] += big
    if repeat:
        dev[-1], angles[-1], t[-1] = dev[-2], angles[-2], t[-2]
        for v in optional.values():
            v[-1] = v[-2]
    log_line = [str(k) for k in range(rows)]
    if repeat:
        log_line[-1] = log_line[-2]
    m = Measurement(machine="wC'A'bXYZ(C1)t", ball_mm=np.array([1.0, 2.0, 3.0]), t_s=t, angles_deg=angles,
                    deviation_um=dev, rotary_axes=("A", "C"), optional=optional, extra_columns={"log_line": log_line})
    path = tmp_path_factory.mktemp("w") / "m.csv"
    write_measurement(m, path)
    outcomes = []
    for check in (lambda: read_measurement(path), lambda: check_as_read(path, m)):
        try:
            check()
            outcomes.append("read")
        except FileFormatError as exc:
            outcomes.append(str(exc))
    assert outcomes[0] == outcomes[1]


# --------------------------------------- issue 43 item 10: every reader of configuration and log text, megabyte lines
#
# A reader that spends more than linear time on a line (``shlex.split`` per HAL line: 79 s for one 2 MB word) hangs
# on a damaged file.  Each reader reads a file with one hostile line at two lengths, L/4 and L: linear time gives a
# ratio near 4, quadratic near 16; the bound 6·t(L/4) + 1 s leaves room for a loaded machine, not for a square.

MIB = 2**20
LOG_LINE = "PIGE P0 K{k} X100.000000 Y0.000000 Z63.999490 A0.000000 C0.000000\n"
LINUXCNC_LINE = "100.000000 0.000000 63.999490 0.000000 0.000000 0.000000 0.000000 0.000000 0.000000\n"
RTEST_HEAD = "# pige-rtest 1\n# machine: wC'A'bXYZ(C1)t\n# ball_mm: 120.0, 0.0, 80.0\n"
RTEST_ROWS = "t_s,A_deg,C_deg,dx_um,dy_um,dz_um\n0.0,0.0,0.0,0.0,0.0,0.0\n1.0,10.0,20.0,1.5,-2.0,0.5\n"
BALLBAR_HEAD = ("# pige-ballbar 1\n# machine: wC'A'bXYZ(C1)t\n# table_ball_mm: 100.0, 0.0, 50.0\n"
                "# offset_mm: 100.0, 0.0, 0.0\n# zero: relative\n# setup: radial\n# axis: C\n")
BALLBAR_ROWS = "t_s,A_deg,C_deg,dL_um\n0.0,0.0,0.0,0.0\n2.0,0.0,10.0,-2.59\n"
TRT_HAL = "loadrt xyzac-trt-kins\n{line}\nsetp xyzac-trt-kins.y-offset 20\n"
TRT_INI = "[KINS]\nKINEMATICS = xyzac-trt-kins\n[HAL]\nHALCMD = setp xyzac-trt-kins.x-rot-point 0\n{line}\n"


def _readers() -> dict[str, tuple[str, str, Callable[[str], object]]]:
    """Reader name → (file name, text with ``{line}`` where the long line goes, the reader)."""
    from pige_sym.compensation.controllers.hal_config import read_current
    from pige_sym.measurements.ballbar import read_ballbar
    from pige_sym.measurements.rtest import read_angle_file, read_measurement

    out: dict[str, tuple[str, str, Callable[[str], object]]] = {
        "hal": ("machine.hal", TRT_HAL, read_current),
        "ini": ("machine.ini", TRT_INI, read_current),
        "ini_halcmd": ("machine.ini", TRT_INI.replace("{line}", "HALCMD = {line}"), read_current),
        "rtest_metadata": ("run.csv", RTEST_HEAD + "# {line}\n" + RTEST_ROWS, read_measurement),
        "rtest_rows": ("run.csv", RTEST_HEAD + RTEST_ROWS + "{line}\n", read_measurement),
        "ballbar_metadata": ("bb.csv", BALLBAR_HEAD + "# {line}\n" + BALLBAR_ROWS, read_ballbar),
        "ballbar_rows": ("bb.csv", BALLBAR_HEAD + BALLBAR_ROWS + "{line}\n", read_ballbar),
        "angles": ("angles.csv", "A_deg,C_deg\n0,0\n{line}\n10,20\n", read_angle_file),
        "log_linuxcnc": ("log.txt", LINUXCNC_LINE * 3 + "{line}\n" + LINUXCNC_LINE,
                         lambda p: probe_log.read_probe_log(p, "linuxcnc", ("A", "C"))),
    }
    for fmt in ("fanuc", "siemens", "heidenhain"):
        text = "".join(LOG_LINE.format(k=k) for k in range(3)) + "{line}\n" + LOG_LINE.format(k=3)
        out[f"log_{fmt}"] = ("log.txt", text, lambda p, fmt=fmt: probe_log.read_probe_log(p, fmt, ("A", "C")))
    return out


READERS = sorted(_readers())
#: Lines that cost a careless reader the most (a word, blanks, digits, quotes, comments, separators, fields).
HOSTILE = {
    "word": lambda n: "x" * n, "blanks": lambda n: " " * n + "x", "digits": lambda n: "1" * n,
    "decimal": lambda n: "1." + "0" * n, "exponent": lambda n: "1e" + "9" * n, "open_quote": lambda n: '"' + "x" * n,
    "quotes": lambda n: "'" * n, "hashes": lambda n: "#" * n, "commas": lambda n: "1," * (n // 2),
    "fields": lambda n: "X1 " * (n // 3), "brackets": lambda n: "[a" * (n // 2),
    "letter_digits": lambda n: "X" + "1" * n, "newlines": lambda n: "\n" * n + "x",
    "pige_fields": lambda n: "PIGE P1 K1 X" + " " * n + "1",
}


def _read_seconds(path: Path, text: str, reader: Callable[[str], object]) -> float:
    """Seconds to read (or refuse) ``text``; anything but a reading or a PigeError fails the test."""
    from pige_sym.errors import PigeError

    path.write_text(text, encoding="utf-8")
    t0 = time.perf_counter()
    try:
        reader(str(path))
    except PigeError as exc:
        assert "\n" not in str(exc)  # one located line, not a dump of the long line's neighbours
    return time.perf_counter() - t0


def _assert_linear(tmp: Path, reader_name: str, shape: str, length: int) -> float:
    name, text, reader = _readers()[reader_name]
    path = tmp / name
    quarter = min(_read_seconds(path, text.replace("{line}", HOSTILE[shape](length // 4)), reader) for _ in range(2))
    whole = _read_seconds(path, text.replace("{line}", HOSTILE[shape](length)), reader)
    assert whole <= 6 * quarter + 1.0, (reader_name, shape, f"{quarter:.3f} s at {length // 4} -> {whole:.3f} s "
                                        f"at {length} characters")
    return whole


def test_a_two_megabyte_hal_word_is_read_in_linear_time(tmp_path) -> None:
    """The issue's case: one 2 MB word in a HAL file (79 s with ``shlex.split``; 0.2 s now on a loaded 2-core
    machine), in a HALCMD line of an INI, and a megabyte of blank lines (``^\\s*`` under re.M was quadratic)."""
    assert _assert_linear(tmp_path, "hal", "word", 2 * MIB) < 10.0
    _assert_linear(tmp_path, "ini_halcmd", "word", 2 * MIB)
    _assert_linear(tmp_path, "hal", "newlines", MIB)


@pytest.mark.parametrize("reader", READERS)
@pytest.mark.parametrize("shape", ["word", "fields", "open_quote"])
def test_every_reader_of_configuration_and_log_text_reads_a_megabyte_line_in_linear_time(tmp_path, reader,
                                                                                         shape) -> None:
    _assert_linear(tmp_path, reader, shape, MIB)


@pytest.mark.slow
@pytest.mark.parametrize("reader", READERS)
@pytest.mark.parametrize("shape", sorted(HOSTILE))
def test_every_reader_is_linear_in_every_hostile_megabyte_line(tmp_path, reader, shape) -> None:
    _assert_linear(tmp_path, reader, shape, 2 * MIB)
