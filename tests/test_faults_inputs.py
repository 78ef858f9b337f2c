"""Issue 33, tracebacks: inputs that used to end in a Python stack now end with exit 2 and one line naming what
to fix.  One test per class (hypothesis where a reader is involved):

- a machine with tool-side rotary axes and no tool (ball) offset, in a measurement file, a ballbar file, an
  in-memory measurement and the studies;
- a probe pose whose contacts do not determine a centre (identical, collinear, coplanar points);
- folders, unreadable files and read-only output folders;
- parameter files with absurd values (1e400, an unknown pivot axis, wrong types).
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from pige_sym.cli.main import main
from pige_sym.errors import FileFormatError, InputError, PigeError
from pige_sym.measurements.measurement import Measurement
from pige_sym.measurements.rtest import read_measurement
from pige_sym.measurements.rtest_writer import format_measurement, write_measurement

HEAD = "wbXYZCA(C1)t"
MIXED = "wC'bXYZB(C1)t"
AC = "wC'A'bXYZ(C1)t"
FEW = settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])


def run(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str, str]:
    """``pige argv`` in process: (exit status, stdout, stderr)."""
    code = main(list(argv))
    out = capsys.readouterr()
    return code, out.out, out.err


def one_line_refusal(code: int, err: str, *fragments: str) -> None:
    """Exit 2, exactly one line on stderr, no traceback, every fragment in it."""
    assert code == 2, err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    for f in fragments:
        assert f in err, (f, err)


def _measurement(machine: str, axes: tuple[str, str], tool: np.ndarray | None, rows: int = 8) -> Measurement:
    rng = np.random.default_rng(rows)
    angles = np.column_stack([np.linspace(0, 30, rows), np.linspace(0, 300, rows)])
    dev = rng.normal(scale=3.0, size=(rows, 3))
    dev[0] = 0.0
    return Measurement(machine=machine, ball_mm=np.array([0.0, 0.0, 0.0]), t_s=np.arange(rows, dtype=float),
                       angles_deg=angles, deviation_um=dev, rotary_axes=axes, tool_mm=tool)


# --------------------------------------------------------------------------------------- 1. head machine, no tool


@FEW
@given(machine=st.sampled_from([HEAD, MIXED]), command=st.sampled_from(["identify", "diagnose", "check"]))
def test_a_head_file_without_tool_mm_is_refused_by_the_reader_naming_the_key(tmp_path_factory, capsys, machine,
                                                                             command) -> None:
    axes = ("A", "C") if machine == HEAD else ("B", "C")
    text = format_measurement(_measurement(machine, axes, np.array([0.0, 0.0, -250.0])))
    text = "".join(ln for ln in text.splitlines(keepends=True) if not ln.startswith("# tool_mm"))
    path = tmp_path_factory.mktemp("head") / "run.csv"
    path.write_text(text)
    with pytest.raises(FileFormatError, match=r":2: .* has tool-side rotary axes .*# tool_mm: x, y, z"):
        read_measurement(path)
    tol = Path(__file__).parents[1] / "examples" / "tolerances.json"
    extra = ["--tolerances", str(tol)] if command == "check" else []
    one_line_refusal(*run(capsys, command, str(path), *extra)[::2], "tool_mm")


def test_a_head_machine_in_a_ballbar_file_or_in_memory_is_refused(tmp_path, capsys) -> None:
    code, _, _ = run(capsys, "simulate", "--instrument", "ballbar", "--out", str(tmp_path / "bb.csv"), "--seed", "1")
    assert code == 0
    text = (tmp_path / "bb.csv").read_text().replace(f"# machine: {AC}", f"# machine: {HEAD}")
    (tmp_path / "head_bb.csv").write_text(text)
    for command in ("identify", "diagnose"):
        one_line_refusal(*run(capsys, command, str(tmp_path / "head_bb.csv"))[::2], "head_bb.csv:2:",
                         "tool-side rotary axes", "table machines only")
    with pytest.raises(InputError, match="tool_mm="):  # the writer never writes what the reader refuses
        write_measurement(_measurement(HEAD, ("A", "C"), None), tmp_path / "x.csv")
    assert not (tmp_path / "x.csv").exists()


@pytest.mark.parametrize("study", ["sobol", "projection"])
def test_studies_of_a_head_machine_ask_for_the_tool_option_they_have(capsys, study) -> None:
    one_line_refusal(*run(capsys, "study", study, "--machine", HEAD, "--presets", "2")[::2] if study == "projection"
                     else run(capsys, "study", study, "--machine", HEAD)[::2], "--tool x,y,z")
    code, out, _ = run(capsys, "study", "sobol", "--machine", HEAD, "--tool", "0,0,-250")
    assert code == 0 and "EY0A" in out


def test_pige_errors_from_readers_are_one_line(tmp_path) -> None:
    """A guard for the helper above: a refusal carries the file name and no newline."""
    path = tmp_path / "x.csv"
    path.write_text("# pige-rtest 1\n")
    with pytest.raises(PigeError) as info:
        read_measurement(path)
    assert "\n" not in str(info.value) and re.match(re.escape(str(path)), str(info.value))


# ------------------------------------------------------------------------------ 5. parameter files, absurd values

FINDING = {"effect": "angular_error_C", "options": {"harmonic": 2}, "params": {"cos_urad": 15.6, "sin_urad": -9.9},
           "std": {"cos_urad": 0.4, "sin_urad": 0.5}, "evidence": "a tangential residual about C"}
PIGES = {"EY0A": 4.5, "EZ0A": 3.1, "EB0A": 0.5, "EC0A": 11.4, "EX0C": -5.9, "EY0C": -14.9, "EA0C": 2.3, "EB0C": 2.5}


def _params(tmp: Path, doc: dict, raw: dict[str, str] | None = None) -> Path:
    """A parameter file; ``raw`` puts literal JSON text (``1e400``) in place of placeholder strings."""
    import json

    text = json.dumps(doc)
    for key, literal in (raw or {}).items():
        text = text.replace(json.dumps(key), literal)
    path = tmp / "params.json"
    path.write_text(text)
    return path


@pytest.mark.parametrize("change, raw, said", [
    (lambda d: d["pige"].__setitem__("EY0A", "@big"), {"@big": "1e400"}, "pige.EY0A: expected a finite number"),
    (lambda d: d.__setitem__("pivots_mm", {"Q": [1, 2, 3]}), None, "pivots_mm.Q: not a rotary axis"),
    (lambda d: d["findings"][0]["options"].__setitem__("harmonic", "abc"), None, "harmonic 'abc' must be a whole"),
    (lambda d: d["findings"][0]["options"].__setitem__("harmonic", "@big"), {"@big": "1e400"}, "harmonic inf"),
    (lambda d: d["findings"][0]["options"].__setitem__("harmonic", "@big"), {"@big": "1e300"}, "harmonic 1e+300"),
    (lambda d: d["findings"][0]["options"].__setitem__("harmonic", -3.5), None, "harmonic -3.5 must be a whole"),
    (lambda d: d["findings"][0]["options"].__setitem__("harmonic", 2.5), None, "harmonic 2.5 must be a whole"),
    (lambda d: d["findings"][0].__setitem__("options", [1]), None, "options must be objects"),
    (lambda d: d["findings"][0]["params"].__setitem__("cos_urad", "@big"), {"@big": "1e300"}, "cos_urad 1e+300"),
    (lambda d: d["pige"].__setitem__("angular_error_C.cos_urad", 1e300), None, "not physical"),
])
def test_absurd_parameter_files_are_refused_before_anything_is_compensated(tmp_path, capsys, change, raw,
                                                                          said) -> None:
    doc = {"machine": AC, "pige": dict(PIGES), "findings": [json_copy(FINDING)]}
    change(doc)
    params = _params(tmp_path, doc, raw)
    prog = tmp_path / "prog.mpf"
    assert main(["program", "--trajectory", "cone-frustum", "--out", str(prog), "--points", "8"]) == 0
    capsys.readouterr()
    one_line_refusal(*run(capsys, "compensate", str(prog), "--params", str(params), "--out",
                          str(tmp_path / "o.mpf"))[::2], "params.json", said)
    assert not (tmp_path / "o.mpf").exists()


def json_copy(x: dict) -> dict:
    import json

    return json.loads(json.dumps(x))


option_values = st.one_of(st.integers(-10, 10**6), st.floats(allow_nan=False), st.text(max_size=4), st.none(),
                          st.booleans(), st.lists(st.integers(), max_size=2))


@FEW
@given(options=st.one_of(st.dictionaries(st.sampled_from(["harmonic", "tau_s", "count", "size_um", "other"]),
                                         option_values, max_size=3), option_values),
       params=st.dictionaries(st.sampled_from(["cos_urad", "sin_urad", "b_urad", "x"]), option_values, max_size=3),
       effect=st.sampled_from(["angular_error_C", "backlash_A", "angular_error_Q", "thermal_drift", "zzz"]))
def test_fuzzed_findings_compensate_with_bounded_values_or_are_refused(tmp_path_factory, options, params,
                                                                      effect) -> None:
    from pige_sym.compensation.parameters import load_parameters
    from pige_sym.measurements.schema import MAX_PIGE
    from pige_sym.model.effects import MAX_HARMONIC

    doc = {"machine": AC, "pige": dict(PIGES), "findings": [{"effect": effect, "options": options,
                                                              "params": params}]}
    path = _params(tmp_path_factory.mktemp("find"), doc)
    try:
        got = load_parameters(path)
    except PigeError as exc:
        assert str(exc).startswith(str(path)) and "\n" not in str(exc), exc
        return
    for ext in got.extensions:
        assert 1 <= ext.spec.harmonic <= MAX_HARMONIC
        assert all(np.isfinite(v) and abs(v) <= MAX_PIGE for v in ext.params.values())


# ------------------------------------------------------------------------------ issue 43, 9: a 400-digit integer


BIG = "1" * 400


@pytest.mark.parametrize("slot, said", [
    ("params", "pige.EY0A: expected a finite number"),
    ("finding", "harmonic inf"),
    ("tolerance", "limits.EX0C: a limit must be a positive finite number, got a number beyond"),
    ("default", "defaults.um: a limit must be a positive finite number"),
    ("pige file", "pige.EY0A: expected a finite number, got one beyond ±1.8e308"),
    ("truth", "parameter EY0A: inf is not a finite number"),
])
def test_a_400_digit_integer_in_any_json_input_is_refused_in_one_line(tmp_path, capsys, slot, said) -> None:
    """It passed for a number and ended in OverflowError where a reader called float(); the one JSON reader now
    reads an integer of more than 18 digits as the float it denotes, so every finiteness check sees it."""
    import json

    run_csv = tmp_path / "run.csv"
    assert main(["simulate", "--out", str(run_csv), "--seed", "1", "--points", "8"]) == 0
    prog = tmp_path / "prog.mpf"
    assert main(["program", "--trajectory", "cone-frustum", "--out", str(prog), "--points", "8"]) == 0
    tol = {"format": "pige-tolerances 1", "machine": AC, "defaults": {"um": 10, "urad": 20}, "limits": {"EX0C": 8}}
    doc = {"machine": AC, "pige": dict(PIGES), "findings": [json_copy(FINDING)]}
    if slot in ("params", "pige file", "truth"):
        doc["pige"]["EY0A"] = "@big"
    elif slot == "finding":
        doc["findings"][0]["options"]["harmonic"] = "@big"
    else:
        tol["limits" if slot == "tolerance" else "defaults"]["EX0C" if slot == "tolerance" else "um"] = "@big"
    text = json.dumps(tol if slot in ("tolerance", "default") else doc).replace('"@big"', BIG)
    given = tmp_path / ("run.truth.json" if slot == "truth" else "in.json")
    given.write_text(text)
    capsys.readouterr()
    argv = {"params": ["compensate", str(prog), "--params", str(given), "--out", str(tmp_path / "o.mpf")],
            "finding": ["compensate", str(prog), "--params", str(given), "--out", str(tmp_path / "o.mpf")],
            "tolerance": ["check", str(run_csv), "--tolerances", str(given)],
            "default": ["check", str(run_csv), "--tolerances", str(given)],
            "pige file": ["simulate", "--pige", str(given), "--out", str(tmp_path / "s.csv")],
            "truth": ["report", str(run_csv), "--out", str(tmp_path / "rep"), "--no-figures"]}[slot]
    one_line_refusal(*run(capsys, *argv)[::2], said)
    assert not (tmp_path / "o.mpf").exists() and not (tmp_path / "rep").exists()


@FEW
@given(value=st.integers(-10**500, 10**500))
def test_every_json_integer_reads_as_a_number_float_can_take(value) -> None:
    from pige_sym.measurements.schema import MAX_INT_DIGITS, strict_loads

    got = strict_loads(f'{{"x": [{value}]}}')["x"][0]
    as_float = float(got)  # never OverflowError
    if len(str(abs(value))) <= MAX_INT_DIGITS:
        assert got == value and isinstance(got, int)
    else:
        assert isinstance(got, float) and (as_float == float(str(value)))


def test_a_sense_refusal_names_what_disagrees_not_an_option_never_given(tmp_path, capsys) -> None:
    """Issue 43, 19: a program written with --axis-sense C=-1, compensated with a parameter file in CONVENTIONS'
    sense, was refused with "but --axis-sense says ..." although no --axis-sense was given."""
    prog, out = tmp_path / "prog.mpf", tmp_path / "o.mpf"
    assert main(["program", "--trajectory", "cone-frustum", "--points", "8", "--axis-sense", "C=-1", "--out",
                 str(prog)]) == 0
    params = _params(tmp_path, {"machine": AC, "pige": dict(PIGES)})
    capsys.readouterr()
    code, _, err = run(capsys, "compensate", str(prog), "--params", str(params), "--out", str(out))
    one_line_refusal(code, err, "prog.mpf records the commanded axis sense C=-1",
                     f"but the parameter file {params} records CONVENTIONS' sense", "parameters of the same")
    assert "--axis-sense says" not in err and not out.exists()
    # given, the option is named as before
    code, _, err = run(capsys, "compensate", str(prog), "--params", str(params), "--axis-sense", "C=-1", "--out",
                       str(out))
    one_line_refusal(code, err, "but --axis-sense says C=-1")


def test_report_refuses_ballbar_files_of_two_machines_as_identify_does(tmp_path, capsys) -> None:
    """Issue 43, "not a defect", decided: ``report`` took an AC and a BC ballbar file together (a joint section per
    machine) where ``identify`` refuses them; files fitted jointly must measure one machine in both (one check)."""
    files = []
    for machine in (AC, "wC'B'bXYZ(C1)t"):
        f = tmp_path / f"bb_{len(files)}.csv"
        assert main(["simulate", "--instrument", "ballbar", "--machine", machine, "--setup", "radial", "--axis", "C",
                     "--seed", "1", "--out", str(f)]) == 0
        files.append(str(f))
    capsys.readouterr()
    said = "the files measure different machines (wC'A'bXYZ(C1)t, wC'B'bXYZ(C1)t)"
    one_line_refusal(*run(capsys, "identify", *files)[::2], said, "identify them apart")
    out = tmp_path / "rep"
    one_line_refusal(*run(capsys, "report", *files, "--out", str(out), "--no-figures")[::2], said,
                     "report them apart")
    assert not out.exists()
