"""pige check: ISO 14253-1 decision rules at their boundaries, strict tolerance files, honest exit codes."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pige_sym.cli.main import main
from pige_sym.constants import MAX_PIGE
from pige_sym.errors import FileFormatError
from pige_sym.model.trajectories import cone_frustum
from pige_sym.simulation.simulator import random_pige, simulate
from pige_sym.verdict.check import Estimates, check, decide, overall, read_tolerances, tolerances_from_dict
from testdata import REPO

AC = "wC'A'bXYZ(C1)t"
FMT = "pige-tolerances 1"


@pytest.mark.parametrize(("value", "std", "status"), [
    (6.0, 1.0, "pass"),        # |v| + 2u == L exactly: conforms
    (-6.0, 1.0, "pass"),       # symmetric zone
    (6.25, 1.0, "undecided"),  # just inside, but the band crosses L
    (10.0, 1.0, "undecided"),  # |v| - 2u == L exactly: not proven outside
    (-10.0, 1.0, "undecided"),
    (10.25, 1.0, "fail"),      # |v| - 2u > L
    (-10.25, 1.0, "fail"),
    (8.0, 0.0, "pass"),        # exact value on the limit, no uncertainty
])
def test_guard_rule_at_the_boundaries(value: float, std: float, status: str) -> None:
    assert decide(value, std, 8.0, rule="guard", k=2.0)[0] == status


@pytest.mark.parametrize(("value", "status"), [(8.0, "pass"), (-8.0, "pass"), (8.0625, "fail"), (7.9375, "pass")])
def test_simple_rule_ignores_the_uncertainty(value: float, status: str) -> None:
    assert decide(value, 5.0, 8.0, rule="simple")[0] == status


@pytest.mark.parametrize("rule", ["guard", "simple"])
@pytest.mark.parametrize("value", [None, math.nan])
def test_no_value_is_undecided(rule: str, value: float | None) -> None:
    status, reason = decide(value, 0.1, 8.0, rule=rule)
    assert status == "undecided" and "not identifiable" in reason


def test_no_uncertainty_is_undecided_under_the_guard_rule() -> None:
    assert decide(1.0, math.nan, 8.0)[0] == "undecided"
    assert decide(1.0, None, 8.0, rule="simple")[0] == "pass"


@given(v=st.floats(-50, 50), u=st.floats(0, 10), lim=st.floats(0.1, 40), k=st.sampled_from([1.0, 2.0, 3.0]))
def test_guard_rule_matches_the_interval_oracle(v: float, u: float, lim: float, k: float) -> None:
    lo, hi = v - k * u, v + k * u  # expanded-uncertainty interval
    inside = -lim <= lo and hi <= lim
    outside = lo > lim or hi < -lim
    expected = "pass" if inside else "fail" if outside else "undecided"
    assert decide(v, u, lim, k=k)[0] == expected


def test_overall_verdict() -> None:
    assert overall(["pass", "pass"]) == "pass"
    assert overall(["pass", "undecided"]) == "undecided"
    assert overall(["undecided", "fail", "pass"]) == "fail"
    assert overall([]) == "undecided"


def _tol(tmp: Path, data: object, name: str = "tol.json") -> Path:
    p = tmp / name
    p.write_text(data if isinstance(data, str) else json.dumps(data))
    return p


@pytest.mark.parametrize(("content", "field"), [
    ('{"format": "pige-tolerances 1", "limits": {"EX0C": NaN}}', "NaN"),
    ('{"format": "pige-tolerances 1", "limits": {"EX0C": Infinity}}', "Infinity"),
    ({"format": FMT, "limits": {"EX0C": "10"}}, "limits.EX0C"),
    ({"format": FMT, "limits": {"EX0C": True}}, "limits.EX0C"),
    ({"format": FMT, "limits": {"EX0C": -1}}, "limits.EX0C"),
    ({"format": FMT, "limits": {"EX0C": 0}}, "limits.EX0C"),
    ({"format": FMT, "limits": {"EX0C": 1}, "tolerance": 3}, "tolerance"),
    ({"format": FMT, "defaults": {"mm": 1}}, "defaults"),
    ({"format": FMT}, "no limit"),
    ({"limits": {"EX0C": 1}}, "format"),
    ('{"format": "pige-tolerances 1", "limits": {"EX0C": 1, "EX0C": 2}}', "duplicate"),
    ("[1, 2", "not valid JSON"),
])
def test_bad_tolerance_files_are_refused_with_the_field(tmp_path: Path, content: object, field: str) -> None:
    with pytest.raises(FileFormatError) as exc:
        read_tolerances(_tol(tmp_path, content))
    assert str(tmp_path / "tol.json") in str(exc.value) and field in str(exc.value)


@pytest.mark.parametrize(("limits", "field"), [
    ({"EX0B": 1}, "limits.EX0B"),
    ({"wobble_B.rx_cos": 1}, "wobble_B"),
    ({"angular_error_C.amp_urad": 1}, "cos_urad"),
])
def test_names_the_machine_lacks_are_refused(limits: dict[str, float], field: str) -> None:
    tol = tolerances_from_dict({"format": FMT, "limits": limits}, "t.json")
    with pytest.raises(FileFormatError, match=field):
        tol.resolve(AC)


def test_tolerances_for_another_machine_are_refused() -> None:
    tol = tolerances_from_dict({"format": FMT, "machine": "wC'B'bXYZ(C1)t", "defaults": {"um": 1}}, "t.json")
    with pytest.raises(FileFormatError, match="machine"):
        tol.resolve(AC)


def test_shipped_example_is_valid() -> None:
    tol = read_tolerances(REPO / "examples" / "tolerances.json")
    limits = tol.resolve(AC)
    assert limits["EX0C"] == 8 and limits["EB0A"] == 20 and "angular_error_C.cos_urad" in limits


def test_check_items_effects_and_letter_o() -> None:
    est = Estimates(AC, "diagnosis", "run.csv", {"EX0C": 3.0, "EY0C": None, "angular_error_C.cos_urad": 30.0},
                    {"EX0C": 1.0, "EY0C": None, "angular_error_C.cos_urad": 1.0},
                    {"EX0C": "um", "EY0C": "um", "angular_error_C.cos_urad": "urad"}, ["angular_error_C"])
    tol = tolerances_from_dict({"format": FMT, "limits": {"EXOC": 5, "EY0C": 5, "EA0A": 5,
                                                          "angular_error_C.cos_urad": 20, "backlash_C.b_urad": 9}},
                               "t.json")
    res = check(est, tol)
    status = {i.name: i.status for i in res.items}
    assert status == {"EX0C": "pass", "EY0C": "undecided", "EA0A": "undecided", "angular_error_C.cos_urad": "fail"}
    assert "backlash_C.b_urad" in res.not_assessed and res.verdict == "fail" and res.exit_status == 1


def _run(tmp: Path, seed: int = 3, pige: dict[str, float] | None = None) -> Path:
    sim = simulate(AC, cone_frustum(AC, points=30), pige=pige or random_pige(AC, seed), noise_um=0.25, seed=seed)
    csv, _ = sim.write(tmp / f"run{seed}.csv")
    return csv


def test_cli_exit_status_follows_the_verdict(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    csv = _run(tmp_path, pige={"EX0C": 5.0, "EY0C": -4.0})
    loose = _tol(tmp_path, {"format": FMT, "defaults": {"um": 50, "urad": 200}}, "loose.json")
    tight = _tol(tmp_path, {"format": FMT, "limits": {"EX0C": 2}}, "tight.json")
    # EX0C = 5 µm with u ≈ 0.05 µm: a limit at 5 µm is undecided whatever the noise
    edge = _tol(tmp_path, {"format": FMT, "limits": {"EX0C": 5}}, "edge.json")
    assert main(["check", str(csv), "--tolerances", str(loose)]) == 0
    assert "verdict: PASS" in capsys.readouterr().out
    assert main(["check", str(csv), "--tolerances", str(tight), "--json"]) == 1
    out = json.loads(capsys.readouterr().out)
    assert out["verdict"] == "fail" and out["items"][0]["name"] == "EX0C" and out["items"][0]["status"] == "fail"
    assert set(out["items"][0]) >= {"name", "value", "std", "limit", "status"}
    assert main(["check", str(csv), "--tolerances", str(edge), "--json"]) == 1
    assert json.loads(capsys.readouterr().out)["verdict"] == "undecided"
    # a saved identify JSON gives the same verdict as the measurement
    assert main(["identify", str(csv), "--json"]) == 0
    saved = tmp_path / "id.json"
    saved.write_text(capsys.readouterr().out)
    assert main(["check", str(saved), "--tolerances", str(tight), "--json"]) == 1
    assert json.loads(capsys.readouterr().out)["source"] == str(saved)


def test_cli_not_identifiable_is_undecided(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    csv = _run(tmp_path, 4)
    assert main(["identify", str(csv), "--projection", "x", "--json"]) == 0
    saved = json.loads(capsys.readouterr().out)
    missing = [p for p, v in saved["pige"].items() if v is None]
    assert missing
    path = tmp_path / "x.json"
    path.write_text(json.dumps(saved))
    tol = _tol(tmp_path, {"format": FMT, "defaults": {"um": 1000, "urad": 1000}})
    assert main(["check", str(path), "--tolerances", str(tol), "--json"]) == 1
    out = json.loads(capsys.readouterr().out)
    assert out["verdict"] == "undecided"
    for item in out["items"]:
        assert (item["status"] == "undecided") == (item["name"] in missing)
        if item["name"] in missing:
            assert item["value"] is None and item["std"] is None


@pytest.mark.parametrize("problem", ["nan", "string", "unknown-key", "parameter", "result-nan"])
def test_cli_bad_input_is_status_2_with_file_and_field(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                       problem: str) -> None:
    csv = _run(tmp_path, 5)
    target = csv
    if problem == "nan":
        tol = _tol(tmp_path, '{"format": "pige-tolerances 1", "limits": {"EX0C": NaN}}')
        field = "NaN"
    elif problem == "string":
        tol = _tol(tmp_path, {"format": FMT, "limits": {"EX0C": "8 um"}})
        field = "limits.EX0C"
    elif problem == "unknown-key":
        tol = _tol(tmp_path, {"format": FMT, "limits": {"EX0C": 8}, "k": 3})
        field = "unknown key(s) k"
    elif problem == "parameter":
        tol = _tol(tmp_path, {"format": FMT, "limits": {"EX0B": 8}})
        field = "limits.EX0B"
    else:
        tol = _tol(tmp_path, {"format": FMT, "limits": {"EX0C": 8}})
        target = tmp_path / "bad.json"
        target.write_text('{"machine": "' + AC + '", "pige": {"EX0C": NaN}, "std": {}, "units": {}}')
        field = "NaN"
    assert main(["check", str(target), "--tolerances", str(tol)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("pige check: ") and field in err, err
    assert (str(target) if problem == "result-nan" else str(tol)) in err


@pytest.mark.parametrize("k", ["-1", "nan"])
def test_bad_coverage_factor_is_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str], k: str) -> None:
    tol = _tol(tmp_path, {"format": FMT, "defaults": {"um": 10}})
    assert main(["check", str(_run(tmp_path, 6)), "--tolerances", str(tol), "--k", k]) == 2
    assert "--k" in capsys.readouterr().err


def test_effect_limits_from_a_saved_diagnosis(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from pige_sym.model.effects import parse_effect

    eff = [parse_effect("angular_error_C:harmonic=2,cos_urad=12,sin_urad=-8", ("A", "C"))]
    sim = simulate(AC, cone_frustum(AC, points=30), pige=random_pige(AC, 2), effects=eff, noise_um=0.25, seed=2)
    csv, _ = sim.write(tmp_path / "run.csv")
    assert main(["diagnose", str(csv), "--json"]) == 0
    saved = tmp_path / "diagnosis.json"
    saved.write_text(capsys.readouterr().out)
    tol = _tol(tmp_path, {"format": FMT, "limits": {"angular_error_C.cos_urad": 5, "angular_error_C.sin_urad": 50,
                                                    "backlash_C.b_urad": 5}})
    for target in (saved, csv):  # the saved JSON and the measurement itself agree
        assert main(["check", str(target), "--tolerances", str(tol), "--json"]) == 1
        out = json.loads(capsys.readouterr().out)
        status = {i["name"]: i["status"] for i in out["items"]}
        assert status == {"angular_error_C.cos_urad": "fail", "angular_error_C.sin_urad": "pass"}
        assert list(out["not_assessed"]) == ["backlash_C.b_urad"] and out["method"] == "diagnosis"


_values = st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.integers(-5, 50), st.text(max_size=3),
                    st.booleans(), st.none())


@settings(deadline=None)  # the first example loads the kernels
@given(limits=st.dictionaries(st.sampled_from(["EX0C", "EY0A", "EB0C", "EXOC"]), _values, max_size=4),
       defaults=st.dictionaries(st.sampled_from(["um", "urad", "mm"]), _values, max_size=2))
def test_tolerance_parser_accepts_exactly_positive_finite_numbers(limits: dict[str, object],
                                                                   defaults: dict[str, object]) -> None:
    def good(v: object) -> bool:  # a positive finite number, at most MAX_PIGE (issue 47)
        return (not isinstance(v, bool) and isinstance(v, (int, float)) and math.isfinite(v) and 0 < v <= MAX_PIGE)

    data = {"format": FMT, "limits": limits, "defaults": defaults}
    valid = all(good(v) for v in limits.values()) and all(good(v) and u != "mm" for u, v in defaults.items()) \
        and bool(limits or defaults)
    try:
        tol = tolerances_from_dict(data, "t.json")
    except FileFormatError as exc:
        assert not valid and str(exc).startswith("t.json: ")
    else:
        assert valid
        assert tol.limits == {k: float(v) for k, v in limits.items()}  # type: ignore[arg-type]
        resolved = tol.resolve(AC)
        assert all(math.isfinite(x) and x > 0 for x in resolved.values())
