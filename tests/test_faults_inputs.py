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


# ------------------------------------------- issue 43: what a controller is given is checked before anything is written

HEAD_PIGES = dict(PIGES)  # a fork head C + A has the same eight PIGE names
TRT_INI = """[KINS]
KINEMATICS = xyzac-trt-kins sparm=identityfirst
JOINTS = 5
[HAL]
HALCMD = loadrt xyzac-trt-kins
HALCMD = setp xyzac-trt-kins.x-rot-point {x}
HALCMD = setp xyzac-trt-kins.y-rot-point 0
HALCMD = setp xyzac-trt-kins.z-rot-point 0
{offsets}
"""
SETP_OFFSETS = "HALCMD = setp xyzac-trt-kins.y-offset {y}\nHALCMD = setp xyzac-trt-kins.z-offset 10"
NETTED_OFFSETS = ("HALCMD = net :y-offset xyzac-trt-kins.y-offset\nHALCMD = net :z-offset xyzac-trt-kins.z-offset\n"
                  "HALCMD = sets :y-offset {y}\nHALCMD = sets :z-offset 10")


def _trt_ini(tmp: Path, *, x: float = 0.0, y: float = 20.0, netted: bool = False) -> Path:
    ini = tmp / "machine.ini"
    ini.write_text(TRT_INI.format(x=x, offsets=(NETTED_OFFSETS if netted else SETP_OFFSETS).format(y=y)))
    return ini


def _compensate(capsys, params: Path, *extra: str) -> tuple[int, str, str]:
    return run(capsys, "compensate", "--params", str(params), *extra)


@pytest.mark.parametrize("ini, fragments", [
    (dict(y=50.0), ["the A axis line is at y = 50 mm", "y-offset 50 (", "machine.ini:9", "y = 20 mm (pivots_mm.A)",
                    "by 30 mm", "--pivot A=0,50,10"]),
    (dict(y=50.0, netted=True), ["the A axis line is at y = 50 mm", "signal :y-offset, ", "machine.ini:11",
                                 "y = 20 mm (pivots_mm.A)"]),
    (dict(x=0.25), ["the C axis line is at x = 0.25 mm", "x-rot-point 0.25 (", "machine.ini:6",
                    "x = 0 mm (pivots_mm.C)", "by 0.25 mm"]),
])
@pytest.mark.parametrize("json_out", [False, True])
def test_a_configuration_whose_axis_line_contradicts_the_parameter_file_is_refused_with_both(
        tmp_path, capsys, ini, fragments, json_out) -> None:
    """Issue 43 item 1: the trt pins of ``--current`` and pige's component (the parameter file's pivots) would put
    the same axis line in two places: refused, naming both values and where each comes from."""
    params = _params(tmp_path, {"machine": AC, "pige": dict(PIGES),
                                "pivots_mm": {"A": [0.0, 20.0, 10.0], "C": [0.0, 0.0, 0.0]}})
    extra = ["--json"] if json_out else []
    one_line_refusal(*_compensate(capsys, params, "--controller", "linuxcnc", "--current",
                                  str(_trt_ini(tmp_path, **ini)), *extra)[::2], "params.json", *fragments)
    code, out, _ = _compensate(capsys, params, "--controller", "linuxcnc", "--current", str(_trt_ini(tmp_path)))
    assert code == 0  # the same lines within their rounding: the absolute lines of both, agreeing
    assert "setp xyzac-trt-kins.y-offset 20.0" in out and "setp pige_xyzac_trt.pivot-a-y 20.000000" in out
    silent = _params(tmp_path, {"machine": AC, "pige": dict(PIGES)})  # no pivots: both lines through the origin
    one_line_refusal(*_compensate(capsys, silent, "--controller", "linuxcnc", "--current",
                                  str(_trt_ini(tmp_path)))[::2], "no pivots_mm.A", "y = 20 mm there")


def test_a_configuration_of_another_machine_or_controller_is_refused(tmp_path, capsys) -> None:
    """Issue 43 items 14 and 15: head parameters with a table configuration, a configuration for a controller that
    reads none (or none at all), a missing configuration file: each refused saying what it is."""
    head = _params(tmp_path, {"machine": HEAD, "pige": dict(HEAD_PIGES), "tool_mm": [0.0, 0.0, -100.0]})
    ini = str(_trt_ini(tmp_path))
    for current in (ini, "y-offset=20,z-offset=10"):
        one_line_refusal(*_compensate(capsys, head, "--controller", "linuxcnc", "--current", current)[::2],
                         "tilting rotary table", HEAD, "A (tool), C (tool)")
    table = _params(tmp_path, {"machine": AC, "pige": dict(PIGES), "pivots_mm": {"A": [0, 20, 10], "C": [0, 0, 0]}})
    for controller in ("siemens", "fanuc", "table"):
        one_line_refusal(*_compensate(capsys, table, "--controller", controller, "--current", ini)[::2],
                         "--current", "--controller linuxcnc only")
    one_line_refusal(*_compensate(capsys, table, "--current", ini)[::2], "--current", "--controller linuxcnc")
    for missing in ("missing.ini", "conf/machine.hal", str(tmp_path / "gone")):
        one_line_refusal(*_compensate(capsys, table, "--controller", "linuxcnc", "--current", missing)[::2],
                         f"--current {missing}: no such file")
    one_line_refusal(*_compensate(capsys, table, "--controller", "linuxcnc", "--current", str(tmp_path))[::2],
                     "a directory")


@pytest.mark.parametrize("off, on, said", [
    ("M429", "M429", "one code cannot switch the kinematics both on and off"),
    ("M0429", "M429", "one code cannot switch the kinematics both on and off"),
    ("M2", "M428", "M2 already means end"),
    ("M429", "G1", "G1 already means motion:G1"),
])
def test_one_code_for_both_kinematics_switches_is_refused(tmp_path, capsys, off, on, said) -> None:
    """Issue 43 item 3: the program would leave the machine in whichever kinematics one code gives it."""
    out = tmp_path / "probe.ngc"
    one_line_refusal(*run(capsys, "program", "--instrument", "sphere-probe", "--dialect", "linuxcnc", "--sphere",
                          "100,0,50", "--sphere-radius", "12.5", "--stylus-radius", "1.5", "--stylus-tool", "9",
                          "--stylus-length", "120", "--rtcp-off", off, "--rtcp-on", on, "--out", str(out))[::2], said)
    assert not out.exists()
    from pige_sym.compensation.program import with_rtcp_codes
    from pige_sym.nc.dialects import get_dialect

    with pytest.raises(InputError, match=said):  # the NC rewrite declares the same codes the same way
        with_rtcp_codes(get_dialect("linuxcnc"), (on,), (off,))


@pytest.mark.parametrize("name", ["trivkins", "userkins", "pid", "motmod", "xyzab_tdr_kins", "xyzacb_trsrn"])
def test_gen_refuses_the_names_of_linuxcncs_own_modules(tmp_path, capsys, name) -> None:
    """Issue 43 item 21: ``halcompile --install`` of a component named like a shipped module replaces it."""
    one_line_refusal(*run(capsys, "gen", "--target", "linuxcnc", AC, "--name", name, "--out",
                          str(tmp_path / "k"))[::2], f"--name {name}: LinuxCNC ships a module of that name")
    assert not (tmp_path / "k").exists()


def _in_memory(machine: str, **change: object) -> object:
    from pige_sym.compensation.parameters import CompensationParameters
    from pige_sym.kernels import load_kernels

    kern = load_kernels(machine)
    fields: dict = {"machine": kern.MACHINE_CODE, "values": dict(PIGES), "units": dict(kern.UNITS),
                    "tool_mm": [0.0, 0.0, -100.0] if kern.TOOL_ROTARY else None,
                    "pivots_mm": {"A": [0.0, 20.0, 10.0], "C": [0.0, 0.0, 0.0]}, "source": "script", "ignored": []}
    return CompensationParameters(**(fields | change))


@pytest.mark.parametrize("machine, change, said", [
    (AC, {"pivots_mm": {"A": [0.0, 1e300, 10.0], "C": [0.0, 0.0, 0.0]}}, "pivots_mm.A = 1e+300"),
    (AC, {"pivots_mm": {"A": [0.0, float("nan"), 10.0]}}, "pivots_mm.A = nan"),
    (AC, {"pivots_mm": {"B": [0.0, 0.0, 0.0]}}, "pivots_mm.B: not a rotary axis"),
    (AC, {"values": PIGES | {"EY0A": float("inf")}}, "parameters.EY0A = inf"),
    (AC, {"values": PIGES | {"EX0C": 5e4}}, "parameters.EX0C = 50000.0"),
    (HEAD, {"tool_mm": [0.0, 0.0, -1e9]}, "tool_mm = -1000000000.0"),
])
def test_no_controller_entry_is_made_from_values_beyond_physical_bounds(machine, change, said) -> None:
    """Check before writing: whatever built the parameters (a script, not the file reader), every controller refuses
    values no machine has before it renders a line."""
    from pige_sym.compensation.controllers import controller_names
    from pige_sym.compensation.program import compensate_nc
    from pige_sym.compensation.stage import format_controller

    params = _in_memory(machine, **change)
    for style in controller_names():
        with pytest.raises(InputError, match=re.escape(said)) as info:
            format_controller(params, style, heidenhain_trans="position")
        assert str(info.value).startswith("script: ") and "\n" not in str(info.value)
    with pytest.raises(InputError, match=re.escape(said)):  # a program written for a controller: the same check
        compensate_nc("G90 G71\nN10 G1 X1 Y2 Z3 A10 C20\n", params, dialect="siemens")


def test_a_linuxcnc_programs_machine_code_in_brackets_is_read_as_written(tmp_path) -> None:
    """A parenthesised comment cannot hold '(C1)': a LinuxCNC probing program states 'wC'A'bXYZ[C1]t'; compensate
    read that back raw and stopped with "'[' at position 9: unknown character" instead of reading the program."""
    from pige_sym.nc.program_file import program_machine

    text = "(pige machine: wC'A'bXYZ[C1]t)\n(pige dialect: linuxcnc)\nG1 X0\n"
    assert program_machine(text) == "wC'A'bXYZ(C1)t"
    titled = "(pige_sym sphere probing: wC'B'bXYZ[C1]t, sphere R6.35 at 20, 10, 15)\n(generated by pige_sym)\n"
    assert program_machine(titled) in ("wC'B'bXYZ(C1)t", None)
