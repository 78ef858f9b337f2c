"""Compensation: compensated kinematics, NC program rewrite, controller corrections, before/after."""

from __future__ import annotations

import json

import numpy as np
import pytest

from pige_sym.cli.main import main
from pige_sym.compensation.controllers.axis_lines import controller_corrections
from pige_sym.compensation.kinematics import compensate_poses, tool_point_error
from pige_sym.compensation.parameters import AngleExtension, CompensationParameters, load_parameters
from pige_sym.compensation.program import compensate_program
from pige_sym.compensation.study import compensation_study
from pige_sym.errors import FileFormatError, InputError
from pige_sym.identification.least_squares import identify
from pige_sym.kernels import load_kernels
from pige_sym.model.effects import EffectSpec
from pige_sym.model.trajectories import cone_frustum, figure_eight, steps
from pige_sym.nc.program import NCProgramError, make_rtest_program
from pige_sym.simulation.simulator import random_pige, simulate

AC, BC, HEAD, MIXED = "wC'A'bXYZ(C1)t", "wC'B'bXYZ(C1)t", "wbXYZCA(C1)t", "wC'bXYZB(C1)t"
TOOL = {HEAD: (0.0, 0.0, -250.0), MIXED: (0.0, 0.0, -250.0)}
BALL = (120.0, 30.0, 80.0)


def _trajectories(code: str) -> list:
    incl = "X" if load_kernels(code).ROTARY_AXES[0] == "A" else "Y"
    return [cone_frustum(code, incl_axis=incl), figure_eight(code)]


def _params(code: str, values: dict[str, float], extensions: list[AngleExtension] | None = None,
            ) -> CompensationParameters:
    tool = TOOL.get(code)
    return CompensationParameters(load_kernels(code).MACHINE_CODE, values, {}, None if tool is None else list(tool),
                                  {}, "test", [], extensions or [])


@pytest.mark.parametrize("code", [AC, BC, HEAD, MIXED])
def test_true_parameters_remove_at_least_95_percent(code):
    truth = random_pige(code, 3)
    truth.update({n: 8.0 for n in load_kernels(code).ZERO_PARAMETERS})
    rows = compensation_study(code, _trajectories(code), truth=truth, identified=truth, ball_mm=BALL,
                              tool_mm=TOOL.get(code))
    for r in rows:
        assert r.rmse_before_um > 5
        assert r.reduction >= 0.95, (r.trajectory, r.rmse_before_um, r.rmse_after_um)


def test_identified_parameters_leave_what_their_standard_errors_predict():
    """Over seeds, the RMSE left after compensating with estimates from noisy data matches the
    RMSE predicted from their covariance (ratio of the means within [0.5, 2])."""
    after, predicted = [], []
    for seed in range(12):
        truth = random_pige(AC, seed)
        cone = cone_frustum(AC, incl_axis="X")
        res = identify(simulate(AC, cone, pige=truth, noise_um=0.5, seed=seed, ball_mm=BALL).measurement)
        ident = dict(zip(res.parameters, res.values, strict=True))
        row = compensation_study(AC, [cone], truth=truth, identified=ident, covariance=res.covariance,
                                 ball_mm=BALL)[0]
        after.append(row.rmse_after_um)
        predicted.append(row.predicted_after_um)
        assert row.reduction > 0.5
    ratio = np.mean(after) / np.mean(predicted)
    assert 0.5 < ratio < 2.0, (np.mean(after), np.mean(predicted))


def test_rtcp_program_compensated_in_workpiece_coordinates():
    truth = random_pige(AC, 5)
    cone = cone_frustum(AC, incl_axis="X")
    ball = np.array(BALL)
    pts = np.tile(ball, (cone.angles_deg.shape[0], 1))
    comp = compensate_poses(AC, truth, cone.angles_deg, pts, rtcp=True)
    kern = load_kernels(AC)
    # the controller's RTCP turns workpiece coordinates into machine positions with the nominal kinematics
    machine_xyz = np.array([kern.linear_commands(comp.new_angles_deg[i : i + 1], comp.new_xyz_mm[i])[0]
                            for i in range(pts.shape[0])])
    err = tool_point_error(AC, truth, comp.new_angles_deg, machine_xyz, pts)
    before = tool_point_error(AC, truth, cone.angles_deg, kern.linear_commands(cone.angles_deg, ball), pts)
    assert np.sqrt((err**2).sum(1).mean()) < 0.05 * np.sqrt((before**2).sum(1).mean())


def test_orientation_is_corrected_to_first_order():
    kern = load_kernels(AC)
    truth = random_pige(AC, 8)
    cone = cone_frustum(AC, incl_axis="X")
    a = cone.angles_deg[1:]
    comp = compensate_poses(AC, truth, a, kern.linear_commands(a, np.array(BALL)))
    p = np.array([truth.get(n, 0.0) for n in kern.PARAMETERS])

    def actual_direction(angles: np.ndarray) -> np.ndarray:
        v = kern.tool_direction(angles)
        omega = np.einsum("nip,p->ni", kern.orientation_jacobian(angles), p) * 1e-6
        return v + np.cross(omega, v)

    wanted = kern.tool_direction(a)
    before = np.linalg.norm(actual_direction(a) - wanted, axis=1)
    after = np.linalg.norm(actual_direction(comp.new_angles_deg) - wanted, axis=1)
    assert before.max() > 5e-6
    assert after.max() < 0.02 * before.max()


@pytest.mark.parametrize("effect,trajectory", [("angular_error_C:harmonic=2,cos_urad=25,sin_urad=-15", "cone"),
                                               ("backlash_C:b_urad=40", "steps")])
def test_angle_extensions_are_compensated(effect, trajectory):
    from pige_sym.model.effects import parse_effect

    eff = parse_effect(effect, ("A", "C"))
    ext = AngleExtension(eff.spec, eff.params)
    truth = random_pige(AC, 2)
    traj = steps(AC) if trajectory == "steps" else cone_frustum(AC, incl_axis="X")
    a = traj.angles_deg
    ball = np.array(BALL)
    pts = np.tile(ball, (a.shape[0], 1))
    xyz = load_kernels(AC).linear_commands(a, ball)
    approach = traj.approach

    def rmse(angles: np.ndarray, commands: np.ndarray) -> float:
        e = tool_point_error(AC, truth, angles, commands, pts, extensions=[ext], approach=approach)
        return float(np.sqrt((e**2).sum(1).mean()))

    plain = compensate_poses(AC, truth, a, xyz)
    full = compensate_poses(AC, truth, a, xyz, extensions=[ext], approach=approach)
    before, without, with_ext = rmse(a, xyz), rmse(plain.new_angles_deg, plain.new_xyz_mm), \
        rmse(full.new_angles_deg, full.new_xyz_mm)
    assert with_ext < 0.05 * before
    assert with_ext < 0.2 * without  # the extension is what is left without it


def test_study_with_an_angle_error_on_the_true_machine():
    """The true machine has an angular positioning error of C: compensating the PIGEs alone leaves it,
    compensating the accepted extension too removes it."""
    from pige_sym.model.effects import parse_effect

    eff = parse_effect("angular_error_C:harmonic=2,cos_urad=20,sin_urad=-10", ("A", "C"))
    ext = [AngleExtension(eff.spec, eff.params)]
    truth = random_pige(AC, 6)
    trajs = _trajectories(AC)
    plain = compensation_study(AC, trajs, truth=truth, identified=truth, truth_extensions=ext, ball_mm=BALL)
    full = compensation_study(AC, trajs, truth=truth, identified=truth, truth_extensions=ext, extensions=ext,
                              ball_mm=BALL)
    for p_row, f_row in zip(plain, full, strict=True):
        assert p_row.rmse_before_um == pytest.approx(f_row.rmse_before_um)
        assert f_row.reduction >= 0.95
        assert f_row.rmse_after_um < 0.2 * p_row.rmse_after_um


def test_extension_equals_a_zero_position_error_per_pose():
    """angular_error_C at a pose acts exactly like EC0C = e(θ) (CONVENTIONS §3): same raw offset."""
    spec = EffectSpec("angular_error_C", {"harmonic": 3})
    ext = AngleExtension(spec, {"cos_urad": 7.0, "sin_urad": -4.0})
    a = np.array([[20.0, 40.0]])
    e = 7.0 * np.cos(np.radians(120.0)) - 4.0 * np.sin(np.radians(120.0))
    pts = np.array([BALL])
    xyz = load_kernels(AC).linear_commands(a, np.array(BALL))
    via_ext = tool_point_error(AC, {}, a, xyz, pts, extensions=[ext])
    via_zero = tool_point_error(AC, {"EC0C": e}, a, xyz, pts)
    np.testing.assert_allclose(via_ext, via_zero, atol=1e-12)


@pytest.mark.parametrize("effect", ["angular_error_C:harmonic=2,cos_urad=25,sin_urad=-15",
                                    "angular_error_A:harmonic=1,cos_urad=-9,sin_urad=12", "backlash_C:b_urad=40",
                                    "backlash_A:b_urad=-30"])
def test_extensions_act_like_the_effect_catalogue(effect):
    """The compensated angle error is the same physics as the simulator's effect: the machine with the
    extension (per-pose zero errors) shows, zeroed at the reference, exactly the effect's contribution."""
    from pige_sym.compensation.kinematics import raw_offset
    from pige_sym.model.effects import EffectContext, parse_effect

    kern = load_kernels(AC)
    eff = parse_effect(effect, ("A", "C"))
    traj = steps(AC)
    a, ball = traj.angles_deg, np.array(BALL)
    pts = np.tile(ball, (a.shape[0], 1))
    ctx = EffectContext(kern, a, traj.t_s, ball, None, None)
    expected = eff.spec.contribution(ctx, eff.params)
    from pige_sym.compensation.parameters import pose_parameters

    raw = raw_offset(kern, a, pts, pose_parameters(kern, {}, a, [AngleExtension(eff.spec, eff.params)]), None, None)
    zeroed = raw - np.einsum("nij,j->ni", kern.workpiece_rotation(a), raw[0])
    assert np.abs(expected).max() > 1.0
    np.testing.assert_allclose(zeroed, expected, atol=1e-9)


@pytest.mark.parametrize("machine", ["wC'A'bXYZ(C1)t", "wC'B'bXYZ(C1)t", "wbXYZCA(C1)t", "wC'bXYZB(C1)t"])
@pytest.mark.parametrize("per_pose", [False, True])
def test_raw_offset_equals_the_jacobian_written_out(machine, per_pose):
    """Oracle: for each pose, the kernel's (3, P) Jacobian at that pose's own point plus the rotated
    reference Jacobian, times that pose's parameters (the contraction order of ``raw_offset`` differs)."""
    from pige_sym.compensation.kinematics import raw_offset

    kern = load_kernels(machine)
    rng = np.random.default_rng(11)
    n, n_par = 25, len(kern.PARAMETERS)
    a = rng.uniform(-60, 60, (n, 2))
    pts = rng.uniform(-150, 150, (n, 3))
    tool = (0.0, 0.0, -250.0) if kern.TOOL_ROTARY else None
    pivots = {ax: rng.uniform(-50, 50, 3) for ax in kern.ROTARY_AXES}
    params = rng.normal(0, 20, (n, n_par)) if per_pose else rng.normal(0, 20, n_par)
    rows = []
    for i in range(n):
        p = params[i] if per_pose else params
        jac = kern.jacobian(a[i : i + 1], None, pts[i], pivots, tool)[0]
        ref = kern.workpiece_rotation(a[i : i + 1])[0] @ kern.reference_jacobian(pts[i], pivots, tool)
        rows.append((jac + ref) @ p)
    np.testing.assert_allclose(raw_offset(kern, a, pts, params, pivots, tool), np.array(rows), rtol=1e-12,
                               atol=1e-9)


def test_closed_form_svd_matches_lapack_down_to_rank_one():
    """``svd_3x2`` against ``np.linalg.svd``: random, nearly parallel columns (the orientation pole),
    rank one, zero; reconstruction, orthonormal vectors, the same singular values, and the same
    least-squares step ``sum_i (u_i . t / s_i) v_i`` wherever ``s_i`` is clearly non-zero."""
    from pige_sym.compensation.kinematics import svd_3x2

    rng = np.random.default_rng(8)
    m = rng.normal(0, 1, (400, 3, 2))
    m[100:200, :, 1] = m[100:200, :, 0] * rng.uniform(-2, 2, (100, 1)) + rng.normal(0, 1, (100, 3)) * 10.0 ** \
        rng.uniform(-12, -3, (100, 1))
    m[200:250, :, 1] = 0.0
    m[250:260] = 0.0
    m[260:300, :, 0] *= 1e-6
    u, s, vt = svd_3x2(m)
    u_ref, s_ref, vt_ref = np.linalg.svd(m, full_matrices=False)
    assert np.all(np.abs(s - s_ref) <= 1e-10 * s_ref + 1e-14 * s_ref[:, :1])
    np.testing.assert_allclose(np.einsum("nik,nk,nkj->nij", u, s, vt), m, atol=1e-12)
    np.testing.assert_allclose(np.einsum("nki,nkj->nij", vt, vt), np.broadcast_to(np.eye(2), (400, 2, 2)), atol=1e-12)
    full = s > 1e-9 * s[:, :1]
    gram = np.einsum("nki,nkj->nij", u, u)
    assert np.allclose(gram[full[:, 1]], np.eye(2), atol=1e-9)
    t = rng.normal(0, 1, (400, 3))

    def step(u_, s_, vt_):
        safe = s_ > 1e-9 * np.maximum(s_[:, :1], 1e-300)
        comp = np.where(safe, np.einsum("nik,ni->nk", u_, t) / np.where(safe, s_, 1.0), 0.0)
        return np.einsum("nk,nkj->nj", comp, vt_)

    clear = (s_ref[:, 1] > 1e-7 * s_ref[:, 0]) | (s_ref[:, 1] < 1e-11 * np.maximum(s_ref[:, 0], 1e-300))
    np.testing.assert_allclose(step(u, s, vt)[clear], step(u_ref, s_ref, vt_ref)[clear], rtol=1e-6, atol=1e-9)


PROGRAM = (
    "%_N_RTEST_MPF\r\n"
    "; R-test program (keep me)\r\n"
    "G90 G17\r\n"
    "TRAFOOF\r\n"
    "N10 G1 X120 Y30 Z80 A0 C0 F2000 ; reference\r\n"
    "N15 G4 F5\r\n"
    "N20 G1 X34.5626 Y-56.2372 Z128.2295 A=31.4749 C=DC(73.2604)\r\n"
    "N25 M00\r\n"
    "N30 G91 C10\r\n"
    "N35 G90\r\n"
    "M30\r\n"
)


def test_rewrite_keeps_untouched_lines_byte_for_byte():
    params = _params(AC, random_pige(AC, 1))
    out = compensate_program(PROGRAM, params, path="p.mpf")
    orig_lines = PROGRAM.splitlines(keepends=True)
    new_lines = out.splitlines(keepends=True)
    assert new_lines[0] == orig_lines[0]  # the header never goes before %_N_
    header = [ln for ln in new_lines if ln.startswith("; compensated")]
    assert len(header) == 1 and header[0].endswith("\r\n") and new_lines[1] == header[0]
    body = [ln for ln in new_lines if ln not in header]
    assert len(body) == len(orig_lines)
    changed = {i for i, (o, n) in enumerate(zip(orig_lines, body, strict=True)) if o != n}
    # only the motion blocks away from the reference pose change (N20, and the incremental N30)
    assert changed == {6, 8}
    assert "A=" in body[6] and "C=DC(" in body[6] and body[6].endswith("\r\n")
    assert body[8].startswith("N30 G91 C") and "AC(" not in body[8]  # incremental stays incremental


def test_program_without_motion_is_unchanged():
    text = "; just comments\nG90 G17\nM30\n"
    assert compensate_program(text, _params(AC, random_pige(AC, 1))) == text


@pytest.mark.parametrize("bad,line,words", [
    ("G90\nN10 G1 X1 Y2 Z3 A0 C0\nCYCLE800(1)\nL100\n", 4, "subprogram call"),
    ("G90\nN10 G1 X1 Y2 Z3 A0 C0\nGOTOF LABELC1\n", 3, "control flow"),
    ("G90\nN10 G1 X1 Y2 Z3 A0 B7 C0\n", 2, "B is not an axis"),
    ("G90\nN10 G1 X1 Y2 Z3 A0 CX0\n", 2, "unknown code CX0"),
    ("G90\nN10 G1 X1e400 Y2 Z3 A0 C0\n", 2, "unknown code X1E400"),
    ("G90\nN10 G1 X=R1+2 Y2 Z3 A0 C0\n", 2, "expression"),
])
def test_unsupported_programs_are_refused_with_the_line(bad, line, words):
    with pytest.raises(NCProgramError) as exc:
        compensate_program(bad, _params(AC, {}), path="bad.mpf", dialect="siemens")
    assert f"bad.mpf:{line}:" in str(exc.value) and words in str(exc.value)


def test_block_with_unknown_pose_passes_through():
    text = "G90 G71\nN10 G0 Z200\nN20 G1 X1 Y2 A10 C0\nN30 G1 X120 Y0 Z80 A20 C30\n"
    out = compensate_program(text, _params(AC, random_pige(AC, 1)), path="p.mpf", dialect="siemens")
    lines = out.splitlines()
    assert "N10 G0 Z200" in lines and "N20 G1 X1 Y2 A10 C0" in lines
    assert not any(ln == "N30 G1 X120 Y0 Z80 A20 C30" for ln in lines)


def test_pass_through_keeps_refused_blocks_verbatim():
    text = "G90 G71\nN10 G1 X120 Y0 Z80 A0 C0\nN20 L100 ; call\nN30 G1 A20 C30\n"
    with pytest.raises(NCProgramError, match="--pass-through"):
        compensate_program(text, _params(AC, random_pige(AC, 1)), dialect="siemens")
    out = compensate_program(text, _params(AC, random_pige(AC, 1)), pass_through=True, dialect="siemens")
    assert out == text  # after the call nothing is known: nothing else may change


def test_load_parameters_from_identify_and_diagnose_json(tmp_path):
    zeros = dict.fromkeys(("EY0A", "EZ0A", "EB0A", "EC0A", "EA0C", "EB0C"), 0.0)
    data = {"machine": AC, "pige": {"EX0C": 3.0, "EY0C": None, **zeros}, "units": {}}
    path = tmp_path / "r.json"
    path.write_text(json.dumps(data))
    with pytest.raises(FileFormatError, match="EY0C: null"):
        load_parameters(path)
    params = load_parameters(path, allow_missing=True)
    assert params.values["EY0C"] == 0.0
    assert params.ignored == ["EY0C (no value in the file: set to 0 by --allow-missing)"]
    with pytest.raises(InputError, match="machine"):
        load_parameters(path, "wC'B'bXYZ(C1)t", allow_missing=True)
    data = {"machine": AC, "pige": {"EX0C": 3.0, "EY0C": 0.0, **zeros,
                                    "angular_error_C.cos_urad": 5.0, "angular_error_C.sin_urad": 1.0,
                                    "thermal_drift.vx_um": 1.0, "thermal_drift.vy_um": 0.0,
                                    "thermal_drift.vz_um": 0.0},
            "findings": [{"effect": "angular_error_C", "options": {"harmonic": 2},
                          "params": {"cos_urad": 5.0, "sin_urad": 1.0}},
                         {"effect": "thermal_drift", "options": {"tau_s": 300},
                          "params": {"vx_um": 1.0, "vy_um": 0.0, "vz_um": 0.0}}]}
    path.write_text(json.dumps(data))
    params = load_parameters(path)
    assert [e.spec.id for e in params.extensions] == ["angular_error_C"]
    assert params.extensions[0].spec.harmonic == 2
    assert params.ignored == ["thermal_drift (time-dependent (depends on when the program runs))"]
    text = compensate_program("G90\nN10 G1 X120 Y0 Z80 A0 C0\nN20 G1 A20 C30\n", params, dialect="siemens")
    assert "; compensated extension: angular_error_C harmonic=2: cos_urad=5, sin_urad=1" in text


def test_controller_corrections_follow_the_pige_definitions():
    values = {"EX0C": 3.0, "EY0C": -2.0, "EA0C": 5.0, "EB0C": 7.0, "EY0A": 1.0, "EZ0A": 4.0, "EB0A": -6.0,
              "EC0A": 2.0, "EC0C": 50.0}
    rows = {r["axis"]: r for r in controller_corrections(_params(AC, values))}
    np.testing.assert_allclose(rows["C"]["pivot_mm"], [3e-3, -2e-3, 0.0])
    np.testing.assert_allclose(rows["C"]["direction"], [7e-6, -5e-6, 1.0], atol=1e-12)  # (EB0C, −EA0C, 1)
    np.testing.assert_allclose(rows["A"]["pivot_mm"], [0.0, 1e-3, 4e-3])
    np.testing.assert_allclose(rows["A"]["direction"], [1.0, 2e-6, 6e-6], atol=1e-12)  # (1, EC0A, −EB0A)
    assert rows["C"]["zero_offset_deg"] == pytest.approx(np.degrees(50e-6))


def test_cli_compensate_end_to_end(tmp_path, capsys):
    code = AC
    cone = cone_frustum(code, incl_axis="X")
    sim = simulate(code, cone, pige=random_pige(code, 4), noise_um=0.1, seed=4, ball_mm=BALL)
    csv = tmp_path / "run.csv"
    sim.write(csv)
    assert main(["identify", str(csv), "--json"]) == 0
    result = tmp_path / "result.json"
    result.write_text(capsys.readouterr().out)
    program = tmp_path / "rtest.mpf"
    program.write_text(make_rtest_program(cone.angles_deg, sim.measurement.linear_mm, ("A", "C")))
    out = tmp_path / "comp.mpf"
    assert main(["compensate", str(program), "--params", str(result), "--out", str(out)]) == 0
    assert out.read_text().count("\nN") == program.read_text().count("\nN")
    assert main(["compensate", "--params", str(result), "--controller", "siemens"]) == 0
    assert "$TC_CARR44[1]=$TC_CARR44[1]" in capsys.readouterr().out
    bad = tmp_path / "bad.mpf"
    bad.write_text("G90\nN10 G1 X1 Y2 Z3 A0 C0\nN20 G3 X1 Y1 R=R1\n")
    assert main(["compensate", str(bad), "--params", str(result), "--out", str(tmp_path / "x.mpf")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "bad.mpf:3:" in err[0]


def test_json_output_of_simulate_and_compensate(tmp_path, capsys):
    csv = tmp_path / "run.csv"
    assert main(["simulate", "--out", str(csv), "--seed", "3", "--effect", "backlash_C", "--trajectory", "steps",
                 "--json"]) == 0
    sim = json.loads(capsys.readouterr().out)
    assert sim["rows"] == 70 and sim["truth"]["effects"][0]["effect"] == "backlash_C"
    assert main(["diagnose", str(csv), "--json"]) == 0
    diag = tmp_path / "diag.json"
    diag.write_text(capsys.readouterr().out)
    program = tmp_path / "steps.mpf"
    assert main(["program", "--trajectory", "steps", "--out", str(program)]) == 0
    capsys.readouterr()
    assert main(["compensate", str(program), "--params", str(diag), "--out", str(tmp_path / "c.mpf"), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert [e["effect"] for e in out["extensions"]] == ["backlash_C"]
    assert main(["compensate", "--params", str(diag), "--controller", "table", "--json"]) == 0
    axes = json.loads(capsys.readouterr().out)["axes"]
    assert [a["axis"] for a in axes] == ["A", "C"]


def test_controller_styles_print_the_deltas_with_their_signs():
    """Hand-checked values; every style's chain is rebuilt from its manual in tests/test_controller_<name>.py."""
    from pige_sym.compensation.stage import format_controller

    values = {"EY0A": 12.0, "EZ0A": -9.0, "EX0C": -14.0, "EY0C": 10.0, "EA0A": 100.0}
    params = _params(AC, values)
    siemens = dict(line.split("=", 1) for line in format_controller(params, "siemens", carrier=3).splitlines()
                   if line.startswith("$"))
    # l2 fine offset = shift of axis 1 (A), l3 = shift of C minus shift of A, l4 = minus shift of C
    assert siemens["$TC_CARR45[3]"] == "$TC_CARR45[3]+0.0120000"
    assert siemens["$TC_CARR46[3]"] == "$TC_CARR46[3]-0.0090000"
    assert siemens["$TC_CARR55[3]"] == "$TC_CARR55[3]-0.0140000"
    assert siemens["$TC_CARR56[3]"] == "$TC_CARR56[3]-0.0020000"
    assert siemens["$TC_CARR58[3]"] == "$TC_CARR58[3]+0.0140000"
    # the offset angle is the axis position of the initial setting: minus the zero-position error
    assert siemens["$TC_CARR64[3]"] == f"$TC_CARR64[3]-{np.degrees(100e-6):.8f}"
    linuxcnc = format_controller(params, "linuxcnc")
    assert "# xyzac-trt-kins.y-rot-point: add +0.0100000" in linuxcnc
    assert "# xyzac-trt-kins.y-offset: add +0.0020000" in linuxcnc
    assert "# xyzac-trt-kins.z-offset: add -0.0090000" in linuxcnc
    fanuc = format_controller(params, "fanuc")
    # rotary table position = shift of a point on A; 19703-5 = shift of the point on C minus it (A-79348E)
    assert "point A on A, A-79348E sheet 59/88): X +0.0000000  Y +0.0120000  Z -0.0090000" in fanuc
    assert "No. 19703 -0.0140000   No. 19704 -0.0020000   No. 19705 +0.0090000" in fanuc
    assert "No. 19680 = 12" in fanuc and "first (master) rotation axis A, second (slave) C" in fanuc
    heidenhain = format_controller(params, "heidenhain", heidenhain_trans="position")
    assert "Trans rows between MachAxis A and MachAxis C (A -> C): X -0.0140000  Y -0.0020000  Z +0.0090000" \
        in heidenhain
    for style, options in (("heidenhain", {"heidenhain_trans": "shift"}), ("fanuc", {}), ("siemens", {})):
        text = format_controller(params, style, **options)
        assert "not run on a" in text and "NOT representable" in text
    with pytest.raises(InputError):
        format_controller(params, "okuma")


def test_compensate_refuses_params_of_another_machine_than_the_programs(tmp_path):
    """The program's header names its machine; parameters of another machine are refused (exit 2)."""
    from pige_sym.cli import main

    prog = tmp_path / "rtest.mpf"
    assert main(["program", "--machine", AC, "--out", str(prog)]) == 0
    bc = "wC'B'bXYZ(C1)t"
    params = tmp_path / "bc.json"
    params.write_text(json.dumps({"machine": bc, "pige": random_pige(bc, 2)}))
    assert main(["compensate", str(prog), "--params", str(params), "--out", str(tmp_path / "o.mpf")]) == 2
    assert not (tmp_path / "o.mpf").exists()
    assert main(["compensate", str(prog), "--params", str(params), "--machine", bc,
                 "--out", str(tmp_path / "o.mpf")]) == 2
    good = tmp_path / "ac.json"
    good.write_text(json.dumps({"machine": AC, "pige": random_pige(AC, 2)}))
    assert main(["compensate", str(prog), "--params", str(good), "--out", str(tmp_path / "o.mpf")]) == 0
