"""``pige program``: the R-test NC program of a trajectory, read back by the NC parser and the acquirer."""

from __future__ import annotations

import numpy as np

from pige_sym.cli.main import main
from pige_sym.kernels import load_kernels
from pige_sym.model.trajectories import cone_frustum, figure_eight
from pige_sym.nc.program import parse_program, poses_from_program
from pige_sym.nc.rtest_program import load_test_program


def test_machine_coordinate_program_holds_the_rtcp_commands(tmp_path):
    code = "wC'B'bXYZ(C1)t"
    out = tmp_path / "bc.mpf"
    assert main(["program", "--machine", code, "--trajectory", "cone-frustum", "--incl-axis", "Y",
                 "--ball", "100,20,90", "--pivot", "B=0,0,-50", "--out", str(out)]) == 0
    angles, xyz, rtcp, _ = poses_from_program(parse_program(out.read_text(), rotary_axes=("B", "C")))
    traj = cone_frustum(code, incl_axis="Y")
    np.testing.assert_allclose(angles, traj.angles_deg, atol=1e-4)  # 4 decimals in the program
    expected = load_kernels(code).linear_commands(traj.angles_deg, np.array([100.0, 20.0, 90.0]),
                                                  {"B": np.array([0.0, 0.0, -50.0])})
    np.testing.assert_allclose(xyz, expected, atol=1e-4)
    assert not any(rtcp)
    # the acquirer and the virtual device read the same poses, with the program's dwell
    program = load_test_program(code, str(out), ball_mm=(100.0, 20.0, 90.0))
    assert program.n_poses == traj.angles_deg.shape[0]
    assert np.all(program.dwell_s == 7.0)


def test_rtcp_and_fanuc_variants(tmp_path):
    out = tmp_path / "fig8.mpf"
    assert main(["program", "--trajectory", "figure-eight", "--rtcp", "--dwell", "6", "--out", str(out)]) == 0
    angles, xyz, rtcp, _ = poses_from_program(parse_program(out.read_text()))
    assert all(rtcp)
    np.testing.assert_allclose(xyz, np.tile([120.0, 0.0, 80.0], (angles.shape[0], 1)))
    np.testing.assert_allclose(angles, figure_eight("wC'A'bXYZ(C1)t").angles_deg, atol=1e-4)
    nc = tmp_path / "fig8.nc"
    assert main(["program", "--trajectory", "figure-eight", "--dialect", "fanuc", "--out", str(nc)]) == 0
    text = nc.read_text()
    assert text.startswith("%\n") and text.count("G04 X7") == angles.shape[0]


def test_acquire_accepts_the_shape_options(tmp_path, capsys):
    """--turns/--incl-axis go to the program's trajectory (regression: acquire crashed on --turns)."""
    status = main(["acquire", "--port", str(tmp_path / "no-such-port"), "--turns", "2", "--incl-axis", "Y",
                   "--out", str(tmp_path / "x.csv"), "--no-progress"])
    assert status == 2
    assert "no-such-port" in capsys.readouterr().err


def test_bad_input_is_one_line(tmp_path, capsys):
    assert main(["program", "--machine", "wXYZ", "--out", str(tmp_path / "x.mpf")]) == 2
    assert main(["program", "--ball", "1,2", "--out", str(tmp_path / "x.mpf")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 2 and all(line.startswith("pige program:") for line in err)


def test_linuxcnc_and_fanuc_programs_read_back_in_their_dialect(tmp_path):
    code = "wC'A'bXYZ(C1)t"
    traj = cone_frustum(code, incl_axis="X")
    for dialect, suffix in (("linuxcnc", "ngc"), ("fanuc", "nc")):
        out = tmp_path / f"cone.{suffix}"
        assert main(["program", "--trajectory", "cone-frustum", "--dialect", dialect, "--dwell", "6",
                     "--out", str(out)]) == 0
        prog = parse_program(out.read_text())
        assert prog.dialect.name == dialect
        angles, _, rtcp, _ = poses_from_program(prog)
        np.testing.assert_allclose(angles, traj.angles_deg, atol=1e-4)
        assert not any(rtcp)
        program = load_test_program(code, str(out))
        assert np.all(program.dwell_s == 6.0)
        assert main(["program", "--trajectory", "cone-frustum", "--dialect", dialect, "--out", str(out)]) == 2
    assert main(["program", "--trajectory", "cone-frustum", "--dialect", "linuxcnc", "--rtcp",
                 "--out", str(tmp_path / "x.ngc")]) == 2
