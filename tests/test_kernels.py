"""Generated kernels vs an independent exact NumPy chain, finite differences and reference data."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from pige_sym import load_kernels, parse_machine_code
from pige_sym.errors import UnsupportedMachineError
from pige_sym.kernels import SHIPPED_MACHINES
from testdata import REPO, load_reference, reference_files, require_shared

UNIT = {0: np.array([1.0, 0, 0]), 1: np.array([0, 1.0, 0]), 2: np.array([0, 0, 1.0])}
# per rotary letter: the machine-axis index of (position error 1, position error 2, orientation 1, orientation 2)
LOCATION_INDEX = {"A": (1, 2, 1, 2), "B": (0, 2, 0, 2), "C": (0, 1, 0, 1)}


def rodrigues(u: np.ndarray, angle: float) -> np.ndarray:
    u = u / np.linalg.norm(u)
    k = np.array([[0, -u[2], u[1]], [u[2], 0, -u[0]], [-u[1], u[0], 0]])
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k


class ExactChain:
    """Exact rigid-body chain of CONVENTIONS §2–4, written independently of the generator.

    Linear axes are assumed to sit outside the rotary axes (true for every machine tested),
    so they only add the RTCP translation, which cancels in ball − nest.
    """

    def __init__(self, code: str, ball, pivots=None, tool=None):
        self.m = parse_machine_code(code)
        self.ball = np.asarray(ball, float)
        self.pivots = {a.name: np.zeros(3) for a in self.m.rotary_axes}
        self.pivots.update({k: np.asarray(v, float) for k, v in (pivots or {}).items()})
        tool_rot = [a for a in self.m.tool_axes if a.kind == "rotary"]
        self.y_ball = self.pivots[tool_rot[-1].name] + np.asarray(tool, float) if tool_rot else self.ball
        self.names = [a.name for a in self.m.rotary_axes]

    def _motion(self, axis, theta, x, err):
        u = UNIT[axis.direction].copy()
        q = self.pivots[axis.name].copy()
        e = 0.0
        if err is not None:
            i1, i2, j1, j2 = LOCATION_INDEX[axis.letter]
            loc = err.get(axis.name, (0, 0, 0, 0, 0))
            delta = np.zeros(3)
            delta[i1], delta[i2] = loc[0] * 1e-3, loc[1] * 1e-3
            eps = np.zeros(3)
            eps[j1], eps[j2] = loc[2] * 1e-6, loc[3] * 1e-6
            u = u + np.cross(eps, u)
            q = q + delta
            e = loc[4] * 1e-6
        moved = q + rodrigues(u, axis.sign * (theta + e)) @ (x - q)
        motion = (err or {}).get("motion:" + axis.name)
        if motion is not None:  # small rigid error motion of the carried body, carrier frame
            d, w = np.asarray(motion[:3]) * 1e-3, np.asarray(motion[3:]) * 1e-6
            p = self.pivots[axis.name]
            moved = p + rodrigues(w, np.linalg.norm(w)) @ (moved - p) + d if np.linalg.norm(w) else moved + d
        return moved

    def raw(self, angles_deg, err):
        th = dict(zip(self.names, np.radians(angles_deg), strict=True))
        x = self.ball.copy()
        for ax in self.m.workpiece_axes:
            if ax.kind == "rotary":
                x = self._motion(ax, th[ax.name], x, err)
        y = self.y_ball.copy()
        for ax in reversed(self.m.tool_axes):
            if ax.kind == "rotary":
                y = self._motion(ax, th[ax.name], y, err)
        return y - x

    def relative_rotation(self, angles_deg, err):
        """Rotation of the spindle frame relative to W (exact, with errors)."""
        th = dict(zip(self.names, np.radians(angles_deg), strict=True))
        origin = np.zeros(3)
        basis = np.eye(3)

        def rotate(axes, reverse):
            r = np.eye(3)
            for ax in (reversed(axes) if reverse else axes):
                if ax.kind == "rotary":
                    moved = np.array([self._motion(ax, th[ax.name], v, err) for v in basis])
                    lin = (moved - self._motion(ax, th[ax.name], origin, err)).T
                    r = lin @ r
            return r

        return rotate(self.m.workpiece_axes, False).T @ rotate(self.m.tool_axes, True)

    def rot_w(self, angles_deg):
        th = dict(zip(self.names, np.radians(angles_deg), strict=True))
        r = np.eye(3)
        for ax in self.m.workpiece_axes:
            if ax.kind == "rotary":
                r = rodrigues(UNIT[ax.direction], -th[ax.name]) @ r
        return r

    def deviation(self, angles_deg, err):
        """Ball minus nest [µm], zeroed in the nest frame at the reference pose."""
        zero = np.zeros(len(self.names))
        out = []
        for a in np.atleast_2d(angles_deg):
            d = self.raw(a, err) - self.raw(a, None)
            d0 = self.raw(zero, err) - self.raw(zero, None)
            out.append((d - self.rot_w(a) @ d0) * 1e3)
        return np.array(out)

    def nest_position(self, angles_deg):
        """Nominal position of the nest in M [mm]."""
        th = dict(zip(self.names, np.radians(angles_deg), strict=True))
        x = self.ball.copy()
        for ax in self.m.workpiece_axes:
            if ax.kind == "rotary":
                x = self._motion(ax, th[ax.name], x, None)
        return x


def errors_dict(kern, params):
    """Map a kernel parameter vector to {axis: (pos1, pos2, ori1, ori2, zero)}."""
    out = {}
    for i, ax in enumerate(kern.ROTARY_AXES):
        loc = list(params[4 * i : 4 * i + 4])
        zero = params[len(kern.LOCATION_PARAMETERS) + i]
        out[ax] = (*loc, zero)
    return out


CASES = [
    ("wC'A'bXYZ(C1)t", None),
    ("wC'B'bXYZ(C1)t", None),
    ("wbXYZCA(C1)t", (0.0, 0.0, -250.0)),
    ("wC'bXYZB(C1)t", (0.0, 0.0, -180.0)),
]


@pytest.mark.parametrize(("code", "tool"), CASES)
def test_kernel_matches_exact_chain(code, tool) -> None:
    rng = np.random.default_rng(7)
    kern = load_kernels(code)
    for trial in range(4):
        ball = rng.uniform(-150, 150, 3)
        pivots = {ax: rng.uniform(-100, 100, 3) for ax in kern.ROTARY_AXES} if trial % 2 else None
        params = rng.uniform(-15, 15, len(kern.PARAMETERS)) * 1e-3  # small errors: 2nd order negligible
        angles = rng.uniform(-120, 120, (12, len(kern.ROTARY_AXES)))
        chain = ExactChain(code, ball, pivots, tool)
        exact = chain.deviation(angles, errors_dict(kern, params))
        ours = kern.deviation(angles, params, ball, pivots, tool)
        scale = np.abs(exact).max()
        assert scale > 0
        np.testing.assert_allclose(ours, exact, rtol=0, atol=1e-6 * scale)


@pytest.mark.parametrize(("code", "tool"), CASES)
def test_kernel_second_order_is_small_for_realistic_errors(code, tool) -> None:
    rng = np.random.default_rng(11)
    kern = load_kernels(code)
    ball = np.array([120.0, -40.0, 80.0])
    params = rng.uniform(-15, 15, len(kern.PARAMETERS))
    angles = rng.uniform(-90, 90, (20, len(kern.ROTARY_AXES)))
    exact = ExactChain(code, ball, None, tool).deviation(angles, errors_dict(kern, params))
    ours = kern.deviation(angles, params, ball, None, tool)
    assert np.abs(ours - exact).max() < 5e-3  # µm: 2nd-order terms of 15 µm / 15 µrad errors


@pytest.mark.parametrize(("code", "tool"), CASES)
def test_jacobian_matches_central_differences_of_exact_chain(code, tool) -> None:
    rng = np.random.default_rng(3)
    kern = load_kernels(code)
    ball = rng.uniform(-100, 100, 3)
    pivots = {ax: rng.uniform(-50, 50, 3) for ax in kern.ROTARY_AXES}
    angles = rng.uniform(-100, 100, (6, len(kern.ROTARY_AXES)))
    chain = ExactChain(code, ball, pivots, tool)
    jac = kern.jacobian(angles, None, ball, pivots, tool)
    h = 1e-2
    for j in range(len(kern.PARAMETERS)):
        step = np.zeros(len(kern.PARAMETERS))
        step[j] = h
        fd = (chain.deviation(angles, errors_dict(kern, step)) - chain.deviation(angles, errors_dict(kern, -step))) / (
            2 * h
        )
        # rounding of the mm-scale chain limits absolute agreement to ~1e-9 of the largest entry
        np.testing.assert_allclose(jac[:, :, j], fd, rtol=1e-6, atol=1e-6 * np.abs(jac).max())


@pytest.mark.parametrize(("code", "tool"), CASES)
def test_jacobian_equals_central_differences_of_deviation_kernel(code, tool) -> None:
    rng = np.random.default_rng(5)
    kern = load_kernels(code)
    ball = rng.uniform(-100, 100, 3)
    angles = rng.uniform(-100, 100, (9, len(kern.ROTARY_AXES)))
    p0 = rng.uniform(-10, 10, len(kern.PARAMETERS))
    jac = kern.jacobian(angles, p0, ball, None, tool)
    for j in range(len(p0)):
        e = np.zeros_like(p0)
        e[j] = 1e-3
        plus = kern.deviation(angles, p0 + e, ball, None, tool)
        fd = (plus - kern.deviation(angles, p0 - e, ball, None, tool)) / 2e-3
        np.testing.assert_allclose(jac[:, :, j], fd, rtol=1e-6, atol=1e-9)


@pytest.mark.parametrize(("code", "tool"), CASES)
def test_reference_pose_gives_zero_deviation_and_reference_jacobian(code, tool) -> None:
    kern = load_kernels(code)
    ball = np.array([50.0, 60.0, 70.0])
    params = np.arange(1, len(kern.PARAMETERS) + 1, dtype=float)
    zero = np.zeros((1, len(kern.ROTARY_AXES)))
    assert np.abs(kern.deviation(zero, params, ball, None, tool)).max() < 1e-12
    chain = ExactChain(code, ball, None, tool)
    raw0 = (chain.raw(zero[0], errors_dict(kern, params * 1e-3)) - chain.raw(zero[0], None)) * 1e3
    np.testing.assert_allclose(kern.reference_jacobian(ball, None, tool) @ (params * 1e-3), raw0, atol=1e-9)


def test_nominal_kinematics_of_ac_table_with_offset_pivots() -> None:
    kern = load_kernels("wC'A'bXYZ(C1)t")
    ball = np.array([120.0, 10.0, 80.0])
    pivots = {"A": np.array([0.0, 15.0, -40.0]), "C": np.array([3.0, -5.0, 0.0])}
    rng = np.random.default_rng(1)
    angles = rng.uniform(-110, 110, (10, 2))
    chain = ExactChain("wC'A'bXYZ(C1)t", ball, pivots)
    expect = np.array([chain.nest_position(a) for a in angles])
    np.testing.assert_allclose(kern.linear_commands(angles, ball, pivots), expect, atol=1e-10)
    rw = kern.workpiece_rotation(angles)
    for a, r in zip(angles, rw, strict=True):
        np.testing.assert_allclose(r, chain.rot_w(a), atol=1e-12)
        np.testing.assert_allclose(kern.tool_direction(a[None])[0], r.T @ np.array([0, 0, 1.0]), atol=1e-12)


@pytest.mark.parametrize("code", ["wC'A'bXYZ(C1)t", "wC'B'bXYZ(C1)t", "wbXYZCA(C1)t", "wC'bXYZB(C1)t"])
def test_angles_for_direction_inverts_tool_direction(code) -> None:
    kern = load_kernels(code)
    rng = np.random.default_rng(2)
    angles = np.column_stack([rng.uniform(5, 80, 40), rng.uniform(-170, 170, 40)])
    v = kern.tool_direction(angles)
    for branch in (1, -1):
        back = kern.angles_for_direction(v, branch=branch)
        np.testing.assert_allclose(kern.tool_direction(back), v, atol=1e-12)


@pytest.mark.parametrize("path", reference_files("*_exact.csv"), ids=lambda p: p.name)
def test_reference_exact_files_reproduced(path) -> None:
    require_shared()
    meta, cols, truth = load_reference(path)
    kern = load_kernels(meta["machine"])
    angles = np.column_stack([cols[f"{a}_deg"] for a in kern.ROTARY_AXES])
    ball = [float(x) for x in meta["ball_mm"].split(",")]
    params = [truth["pige"][n] for n in kern.LOCATION_PARAMETERS]
    dev = kern.deviation(angles, params, ball)
    measured = np.column_stack([cols["dx_um"], cols["dy_um"], cols["dz_um"]])
    assert np.abs(dev - measured).max() < 1e-3


def test_reference_data_present_or_skipped() -> None:
    if not reference_files("*_exact.csv"):
        pytest.skip("../shared/reference is absent")
    assert len(reference_files("*_exact.csv")) >= 3


def test_params_of_location_errors_only_are_accepted() -> None:
    kern = load_kernels("wC'A'bXYZ(C1)t")
    angles = np.array([[10.0, 20.0], [30.0, -40.0]])
    p8 = np.arange(8.0)
    np.testing.assert_allclose(
        kern.deviation(angles, p8, [1, 2, 3]), kern.deviation(angles, np.r_[p8, 0, 0], [1, 2, 3])
    )
    with pytest.raises(ValueError, match="location errors"):
        kern.deviation(angles, np.arange(5.0), [1, 2, 3])
    with pytest.raises(ValueError, match="angles_deg must have shape"):
        kern.deviation(np.zeros((3, 3)), p8, [1, 2, 3])
    with pytest.raises(ValueError, match="not a rotary axis"):
        kern.deviation(angles, p8, [1, 2, 3], {"B": [0, 0, 0]})


def test_generated_modules_do_not_import_sympy() -> None:
    code = (
        "import sys, pige_sym\n"
        "from pige_sym import load_kernels\n"
        "for c in " + repr(list(SHIPPED_MACHINES)) + ": load_kernels(c)\n"
        "assert 'sympy' not in sys.modules, 'sympy imported at run time'\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True, cwd=REPO, timeout=60)


def test_on_demand_generation_for_a_new_machine(tmp_path, monkeypatch) -> None:
    monkeypatch.setenv("PIGE_KERNEL_DIR", str(tmp_path))
    from pige_sym import kernels

    monkeypatch.setattr(kernels, "_CACHE", {})
    kern = load_kernels("wC'A'Y'X'bZ(C1)t")
    assert (tmp_path / "kin_wCpApYpXpbZ_C1_t.py").exists()
    angles = np.array([[20.0, 30.0]])
    monkeypatch.setattr(kernels, "_CACHE", {})
    monkeypatch.delenv("PIGE_KERNEL_DIR")
    ac = load_kernels("wC'A'bXYZ(C1)t")
    p = np.arange(1.0, 9.0)
    # linear axes on the workpiece side do not change the rotary-axis error model
    np.testing.assert_allclose(kern.deviation(angles, p, [10, 20, 30]), ac.deviation(angles, p, [10, 20, 30]))


@pytest.mark.parametrize(
    ("code", "fragment"),
    [("wbXYZ(C1)t", "no rotary axis"), ("wC'A'bXY(C1)t", "no linear axis along Z"), ("wX'C'bYZ(C1)t", "singular")],
)
def test_unsupported_machines_are_refused(code, fragment) -> None:
    from pige_sym.codegen.symbolic import build_model

    with pytest.raises(UnsupportedMachineError, match=fragment):
        build_model(code)


@pytest.mark.slow  # CI's own stage: .ci/run runs `make check-generated`, this very command (5 s of CPU here)
def test_check_generated_is_clean(monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    """`pige gen --check` of the shipped machines, in this process (SymPy already imported here; `make
    check-generated` runs the same command in CI, a stage of its own: this test runs with make test-slow)."""
    from pige_sym.cli.main import main

    monkeypatch.delenv("PIGE_KERNEL_DIR", raising=False)
    monkeypatch.chdir(REPO)
    status = main(["gen", "--check", *SHIPPED_MACHINES])
    out = capsys.readouterr()
    assert status == 0, out.out + out.err
    assert out.out.count("ok      ") == len(SHIPPED_MACHINES)


@pytest.mark.parametrize(("code", "tool"), CASES)
def test_orientation_jacobian_matches_exact_chain(code, tool) -> None:
    rng = np.random.default_rng(13)
    kern = load_kernels(code)
    chain = ExactChain(code, [10.0, 20.0, 30.0], None, tool)
    angles = rng.uniform(-100, 100, (5, len(kern.ROTARY_AXES)))
    jac = kern.orientation_jacobian(angles)
    h = 1e-2
    for i, a in enumerate(angles):
        nominal = chain.relative_rotation(a, None)
        for j in range(len(kern.PARAMETERS)):
            step = np.zeros(len(kern.PARAMETERS))
            step[j] = h
            plus = chain.relative_rotation(a, errors_dict(kern, step))
            minus = chain.relative_rotation(a, errors_dict(kern, -step))
            skew = (plus - minus) @ nominal.T / (2 * h) * 1e6
            omega = np.array([skew[2, 1], skew[0, 2], skew[1, 0]])
            np.testing.assert_allclose(jac[i, :, j], omega, atol=1e-5)


@pytest.mark.parametrize(("code", "tool"), CASES)
def test_motion_jacobian_matches_exact_chain(code, tool) -> None:
    rng = np.random.default_rng(17)
    kern = load_kernels(code)
    ball = rng.uniform(-100, 100, 3)
    pivots = {ax: rng.uniform(-50, 50, 3) for ax in kern.ROTARY_AXES}
    chain = ExactChain(code, ball, pivots, tool)
    angles = rng.uniform(-100, 100, (5, len(kern.ROTARY_AXES)))
    jac = kern.motion_jacobian(angles, ball, pivots, tool)
    assert jac.shape == (5, 3, 6 * len(kern.ROTARY_AXES))
    h = 1e-2
    for j, name in enumerate(kern.MOTION_PARAMETERS):
        axis, comp = name.split("_")
        vec = np.zeros(6)
        vec["dx dy dz rx ry rz".split().index(comp)] = h
        fd = np.array([
            (chain.raw(a, {"motion:" + axis: vec}) - chain.raw(a, {"motion:" + axis: -vec})) / (2 * h) * 1e3
            for a in angles
        ])
        np.testing.assert_allclose(jac[:, :, j], fd, rtol=1e-6, atol=1e-6 * np.abs(jac).max())


@pytest.mark.parametrize("code", ["wC'A'bXYZ(C1)t", "wbXYZCA(C1)t", "wC'bXYZB(C1)t", "wA'B'bXYZ(C1)t"])
def test_rendered_kernels_are_lint_clean(code: str, tmp_path: Path) -> None:
    """No unused locals, undefined names or `(0.001)*` literals in generated code."""
    import shutil

    from pige_sym.codegen.emit import render_module

    text = render_module(code)
    assert "(0.001)" not in text
    assert "_HELPERS" not in text
    ruff = shutil.which("ruff") or str(Path(sys.executable).with_name("ruff"))
    if not Path(ruff).exists():
        pytest.skip("ruff is not installed")
    path = tmp_path / "kernel.py"
    path.write_text(text, encoding="utf-8")
    proc = subprocess.run([ruff, "check", "--isolated", "--select", "F,E9", str(path)], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stdout


def test_jacobian_into_a_preallocated_array() -> None:
    kern = load_kernels("wC'A'bXYZ(C1)t")
    angles = np.random.default_rng(3).uniform(-90, 90, (50, 2))
    out = np.full((50, 3, len(kern.PARAMETERS)), np.nan)
    result = kern.jacobian(angles, None, [120, 0, 80], None, None, out=out)
    assert result is out
    np.testing.assert_array_equal(out, kern.jacobian(angles, None, [120, 0, 80]))
    with pytest.raises(ValueError, match="C-contiguous"):
        kern.jacobian(angles, None, [120, 0, 80], out=np.empty((49, 3, len(kern.PARAMETERS))))


def test_check_generated_ignores_the_sympy_version_line() -> None:
    from pige_sym.codegen.emit import render_module, same_code

    text = render_module("wC'A'bXYZ(C1)t")
    other = "\n".join("# sympy version: 0.0" if ln.startswith("# sympy version") else ln for ln in text.splitlines())
    assert same_code(text, other + "\n")
    assert not same_code(text, text.replace("np.zeros", "np.ones", 1))


@pytest.mark.parametrize("shape", [(1, 2), (2,), (5, 2)])
def test_kernels_never_modify_the_callers_angles(shape: tuple[int, ...]) -> None:
    kern = load_kernels("wC'A'bXYZ(C1)t")
    angles = np.full(shape, 30.0)
    for fn in (kern.basis, kern.workpiece_rotation, kern.tool_direction, kern.orientation_jacobian):
        fn(angles)
    kern.jacobian(angles, None, [120, 0, 80])
    assert np.all(angles == 30.0)


def test_reduce_trig_is_the_polynomial_reduction_by_cos2_plus_sin2() -> None:
    """codegen.symbolic.reduce_trig (term by term) against the reduction of a Poly in each sin written here: the same
    expression, of degree at most 1 in each sin, and equal to the input wherever cos² + sin² = 1."""
    import sympy as sp

    from pige_sym.codegen.symbolic import reduce_trig

    c1, s1, c2, s2, x, y = sp.symbols("c1 s1 c2 s2 x y", real=True)
    pairs = [(c1, s1), (c2, s2)]

    def oracle(expr: sp.Expr) -> sp.Expr:
        expr = sp.expand(expr)
        for c, s in pairs:
            poly = sp.Poly(expr, s)
            expr = sp.expand(sum((coeff * s ** (d % 2) * (1 - c**2) ** (d // 2) for (d,), coeff in poly.terms()),
                                 sp.Integer(0)))
        return expr

    rng = np.random.default_rng(5)
    atoms = [c1, s1, c2, s2, x, y, sp.Rational(1, 1000)]
    for _ in range(8):
        expr = sum((int(rng.integers(-3, 4)) * sp.Mul(*[atoms[i] ** int(rng.integers(0, 4)) for i in range(7)])
                    for _ in range(3)), sp.Integer(0)) * (s1 - 2 * c2 * s2 + x)
        out = reduce_trig(expr, pairs)
        assert out == oracle(expr)
        assert sp.degree(out, s1) <= 1 and sp.degree(out, s2) <= 1
        a, b = rng.uniform(0, 6.3, 2)
        at = {c1: np.cos(a), s1: np.sin(a), c2: np.cos(b), s2: np.sin(b), x: 0.7, y: -1.3}
        assert abs(float(out.subs(at)) - float(expr.subs(at))) < 1e-9 * (1 + abs(float(expr.subs(at))))
