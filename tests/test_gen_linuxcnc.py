"""``pige gen --target linuxcnc``: the emitted C kinematics against the NumPy kernels and an exact chain.

The pure C99 model (:func:`pige_sym.codegen.c_model.render_model_c`) is compiled with the system compiler
into a small shared library (ctypes) and compared, at random poses, PIGEs (tilts up to 1 mrad, offsets
up to 50 µm, zero-position errors up to 1 mrad), senses, pivots and tool offsets:

* with the NumPy kernels' model (nominal ``linear_commands`` minus the un-zeroed first-order offset
  ``deviation + workpiece_rotation @ reference_jacobian @ errors``), to 1e-9 mm;
* forward ∘ inverse = identity to 1e-9 mm, with the Newton steps counted;
* with an exact rigid-body chain written here from CONVENTIONS §2-§3 (second order apart);
* with LinuxCNC's stock ``xyzac-trt-kins`` / ``xyzbc-trt-kins`` formulas (trtfuncs.c at f1270d6ed7,
  written here) for σ = −1 and no errors, tool offset included.

The component's HAL-free pose layer (identity or the model, by switchkins type) is compiled the same way.
Without a C compiler these tests skip.
"""

from __future__ import annotations

import ctypes
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from shared_results import shared_texts

from pige_sym.codegen.c_model import render_model_c
from pige_sym.codegen.machine_code import parse_machine_code
from pige_sym.codegen.targets import linuxcnc
from pige_sym.kernels import load_kernels

CC = shutil.which("cc") or shutil.which("gcc")
needs_cc = pytest.mark.skipif(CC is None, reason="no C compiler (cc/gcc)")
MACHINES = ("wC'A'bXYZ(C1)t", "wC'B'bXYZ(C1)t", "wbXYZCA(C1)t", "wC'bXYZB(C1)t", "wC'A'Y'X'bZ(C1)t")
TOL_MM = 1e-9

HARNESS = r"""
#define pk_API static
#include "model.h"
#include <string.h>

/* per pose g: pivots (k*3), tool (3), sense (k), errors (n), tool_offset (1) */
#define G_SIZE (4 * pk_N_ROTARY + 3 + pk_N_ERRORS + 1)
static void load(pk_params *p, const double *g)
{
    int i, j, o = 0;
    pk_params_init(p);
    for (i = 0; i < pk_N_ROTARY; i++) for (j = 0; j < 3; j++) p->pivot[i][j] = g[o++];
    for (j = 0; j < 3; j++) p->tool[j] = g[o++];
    for (i = 0; i < pk_N_ROTARY; i++) p->sense[i] = g[o++];
    for (i = 0; i < pk_N_ERRORS; i++) p->errors[i] = g[o++];
    p->tool_offset = g[o++];
}
int h_g_size(void) { return G_SIZE; }
void h_inverse(int n, const double *g, const double *world, const double *angles, double *joints)
{
    int i;
    pk_params p;
    for (i = 0; i < n; i++) {
        load(&p, g + i * G_SIZE);
        pk_inverse(&p, world + 3 * i, angles + pk_N_ROTARY * i, joints + 3 * i);
    }
}
void h_jacobian(int n, const double *g, const double *angles, double *m)
{
    int i;
    pk_params p;
    for (i = 0; i < n; i++) {
        load(&p, g + i * G_SIZE);
        pk_jacobian(&p, angles + pk_N_ROTARY * i, (double (*)[3])(m + 9 * i));
    }
}
void h_forward(int n, const double *g, const double *joints, const double *angles, int max_steps,
               double *world, double *residual, int *steps)
{
    int i;
    pk_params p;
    for (i = 0; i < n; i++) {
        load(&p, g + i * G_SIZE);
        steps[i] = pk_forward_steps(&p, joints + 3 * i, angles + pk_N_ROTARY * i, max_steps, world + 3 * i,
                                    residual + i);
    }
}
"""

_D = np.ctypeslib.ndpointer(dtype=np.float64, flags="C_CONTIGUOUS")
_I = np.ctypeslib.ndpointer(dtype=np.int32, flags="C_CONTIGUOUS")


def compile_shared(tmp: Path, sources: dict[str, str], main: str) -> ctypes.CDLL:
    """Write ``sources`` into ``tmp`` and build ``main`` as a shared library, warnings as errors."""
    for name, text in sources.items():
        (tmp / name).write_text(text, encoding="utf-8")
    lib = tmp / (Path(main).stem + ".so")
    cmd = [str(CC), "-std=c99", "-O2", "-fPIC", "-shared", "-Wall", "-Wextra", "-pedantic", "-Werror",
           "-Wno-unused-function", "-o", str(lib), str(tmp / main), "-lm"]
    out = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    return ctypes.CDLL(str(lib))


class Model:
    """The compiled C model of one machine, called on arrays of poses."""

    def __init__(self, code: str, tmp: Path, model_h: str) -> None:
        self.code = code
        self.kin = load_kernels(code)
        self.k = len(self.kin.ROTARY_AXES)
        lib = compile_shared(tmp, {"model.h": model_h, "harness.c": HARNESS}, "harness.c")
        lib.h_inverse.argtypes = [ctypes.c_int, _D, _D, _D, _D]
        lib.h_jacobian.argtypes = [ctypes.c_int, _D, _D, _D]
        lib.h_forward.argtypes = [ctypes.c_int, _D, _D, _D, ctypes.c_int, _D, _D, _I]
        self.lib = lib
        self.g_size = lib.h_g_size()

    def pack(self, geo: dict) -> np.ndarray:
        n = geo["errors"].shape[0]
        pivots = np.stack([geo["pivots"][a] for a in self.kin.ROTARY_AXES], axis=1).reshape(n, -1)
        g = np.hstack([pivots, geo["tool"], geo["sense"], geo["errors"], geo["tool_offset"][:, None]])
        assert g.shape[1] == self.g_size
        return np.ascontiguousarray(g)

    def inverse(self, geo: dict, world: np.ndarray, angles: np.ndarray) -> np.ndarray:
        out = np.zeros_like(world)
        self.lib.h_inverse(len(world), self.pack(geo), np.ascontiguousarray(world), np.ascontiguousarray(angles), out)
        return out

    def jacobian(self, geo: dict, angles: np.ndarray) -> np.ndarray:
        out = np.zeros((len(angles), 3, 3))
        self.lib.h_jacobian(len(angles), self.pack(geo), np.ascontiguousarray(angles), out)
        return out

    def forward(self, geo: dict, joints: np.ndarray, angles: np.ndarray, max_steps: int = 3):
        n = len(joints)
        world, residual, steps = np.zeros((n, 3)), np.zeros(n), np.zeros(n, dtype=np.int32)
        self.lib.h_forward(n, self.pack(geo), np.ascontiguousarray(joints), np.ascontiguousarray(angles), max_steps,
                           world, residual, steps)
        return world, residual, steps


def model_pk(code: str) -> dict[str, str]:
    """The C model every harness here and in test_gen_linuxcnc_maps.py includes (prefix ``pk``)."""
    return {"model.h": render_model_c(code, "pk")}


def linuxcnc_files(code: str) -> dict[str, str]:
    """The linuxcnc target's files (test_gen_linuxcnc_hal.py compiles the same)."""
    return linuxcnc.render(parse_machine_code(code))


@pytest.fixture(scope="module")
def models(tmp_path_factory) -> dict[str, Model]:
    if CC is None:
        pytest.skip("no C compiler (cc/gcc)")
    headers = shared_texts(tmp_path_factory, "model_pk", list(MACHINES), model_pk)  # once per run (shared_results)
    return {code: Model(code, tmp_path_factory.mktemp(f"m{i}"), headers[code]["model.h"])
            for i, code in enumerate(MACHINES)}


def random_case(kin, n: int, seed: int, *, um: float = 50.0, urad: float = 1000.0, zero: bool = True) -> tuple:
    """Poses, commanded angles and per-pose geometry: pivots, tool, senses, errors, tool offset."""
    rng = np.random.default_rng(seed)
    k = len(kin.ROTARY_AXES)
    errors = np.zeros((n, len(kin.PARAMETERS)))
    for j, p in enumerate(kin.PARAMETERS):
        zero_error = p in kin.ZERO_PARAMETERS
        scale = (urad if zero else 0.0) if zero_error else (um if kin.UNITS[p] == "um" else urad)
        errors[:, j] = rng.uniform(-scale, scale, n)
    geo = {"pivots": {a: rng.uniform(-150, 150, (n, 3)) for a in kin.ROTARY_AXES},
           "tool": rng.uniform(-20, 20, (n, 3)) + [0.0, 0.0, -200.0],
           "sense": rng.choice([-1.0, 1.0], (n, k)), "errors": errors, "tool_offset": rng.uniform(0, 120, n)}
    world = rng.uniform(-200, 200, (n, 3))
    angles = rng.uniform(-120, 120, (n, k))
    return geo, world, angles


def numpy_joints(kin, geo: dict, world: np.ndarray, angles: np.ndarray) -> np.ndarray:
    """The kernels' model (c_model docstring), pose by pose: the oracle the C must equal."""
    out = np.zeros_like(world)
    s = kin.SPINDLE_DIRECTION
    for i in range(len(world)):
        th = (angles[i] * geo["sense"][i])[None, :]
        dt = geo["tool_offset"][i]
        ball, tool = world[i].copy(), geo["tool"][i].copy()
        ball[s] -= dt
        tool[s] -= dt
        pivots = {a: geo["pivots"][a][i] for a in kin.ROTARY_AXES}
        e = geo["errors"][i]
        lin = kin.linear_commands(th, ball, pivots, tool)[0]
        r = kin.deviation(th, e, ball, pivots, tool)[0] + \
            kin.workpiece_rotation(th)[0] @ kin.reference_jacobian(ball, pivots, tool) @ e
        out[i] = lin - 1e-3 * r
        out[i, s] += dt
    return out


@needs_cc
@pytest.mark.parametrize("code", MACHINES)
def test_inverse_equals_the_numpy_kernels(models, code: str) -> None:
    m = models[code]
    geo, world, angles = random_case(m.kin, 200, seed=1)
    c_joints = m.inverse(geo, world, angles)
    ref = numpy_joints(m.kin, geo, world, angles)
    assert np.abs(c_joints - ref).max() < TOL_MM
    nominal = dict(geo, errors=np.zeros_like(geo["errors"]))
    assert np.abs(m.inverse(nominal, world, angles) - c_joints).max() > 0.05  # the errors matter here


@needs_cc
@pytest.mark.parametrize("code", MACHINES)
def test_the_jacobian_is_the_derivative_of_the_inverse(models, code: str) -> None:
    m = models[code]
    geo, world, angles = random_case(m.kin, 50, seed=2)
    jac = m.jacobian(geo, angles)
    for j in range(3):
        h = np.zeros(3)
        h[j] = 1.0
        diff = (m.inverse(geo, world + h, angles) - m.inverse(geo, world - h, angles)) / 2.0
        assert np.abs(jac[:, :, j] - diff).max() < 1e-10


@needs_cc
@pytest.mark.parametrize("code", MACHINES)
def test_forward_inverts_the_inverse_in_one_newton_step(models, code: str) -> None:
    """From the nominal start one step is exact (the model is affine in world); measured here."""
    m = models[code]
    geo, world, angles = random_case(m.kin, 300, seed=3)
    joints = m.inverse(geo, world, angles)
    start, res0, steps0 = m.forward(geo, joints, angles, max_steps=0)
    assert (steps0 == 0).all() and res0.max() > 1e-3  # the nominal start is far off with 1 mrad tilts
    one, res1, steps1 = m.forward(geo, joints, angles, max_steps=1)
    assert res1.max() < TOL_MM and np.abs(one - world).max() < TOL_MM
    full, res, steps = m.forward(geo, joints, angles)
    assert (steps <= 1).all() and np.abs(full - world).max() < TOL_MM and res.max() < 1e-10


def exact_joints(kin, structure, geo: dict, world: np.ndarray, angles: np.ndarray) -> np.ndarray:
    """Exact rigid-body chain (CONVENTIONS §2-§3), independent of SymPy: x ↦ q + R(u', s(θ+E))(x − q).

    The tool point b = world − t·e_z is carried outward by the workpiece axes; the tool tip y = p_last +
    tool − t·e_z by the tool-side axes (nearest the tool first); the linear axes then put y on b, and the
    joints are those axes' positions read as the gauge point at the reference pose (the kernels'
    ``linear_commands`` coordinates): joints = L + p_last + tool, or b's position for a table-table machine.
    """
    out = np.zeros_like(world)
    col = {a: i for i, a in enumerate(kin.ROTARY_AXES)}
    for i in range(len(world)):
        e = dict(zip(kin.PARAMETERS, geo["errors"][i], strict=True))
        dt = geo["tool_offset"][i]

        def move(ax, x, i=i, e=e):
            d = "ABC".index(ax.name)
            u = np.eye(3)[d]
            delta = np.array([e.get(f"E{'XYZ'[c]}0{ax.name}", 0.0) if c != d else 0.0 for c in range(3)]) * 1e-3
            eps = np.array([e.get(f"E{'ABC'[c]}0{ax.name}", 0.0) if c != d else 0.0 for c in range(3)]) * 1e-6
            u = (u + np.cross(eps, u)) / np.linalg.norm(u + np.cross(eps, u))
            q = geo["pivots"][ax.name][i] + delta
            th = np.radians(geo["sense"][i, col[ax.name]] * angles[i, col[ax.name]]) + e[f"E{ax.name}0{ax.name}"] * 1e-6
            ang = (1 if ax.side == "tool" else -1) * th
            k = np.array([[0, -u[2], u[1]], [u[2], 0, -u[0]], [-u[1], u[0], 0]])
            rot = np.eye(3) + np.sin(ang) * k + (1 - np.cos(ang)) * k @ k
            return q + rot @ (x - q)

        nest = world[i] - [0.0, 0.0, dt]
        for ax in structure.workpiece_axes:
            nest = move(ax, nest) if ax.kind == "rotary" else nest
        tool_rot = [a for a in structure.tool_axes if a.kind == "rotary"]
        if not tool_rot:
            out[i] = nest + [0.0, 0.0, dt]
            continue
        gauge = geo["pivots"][tool_rot[-1].name][i] + geo["tool"][i]
        tip = gauge - [0.0, 0.0, dt]
        for ax in reversed(tool_rot):
            tip = move(ax, tip)
        out[i] = nest - tip + gauge
    return out


@needs_cc
@pytest.mark.parametrize("code", MACHINES)
def test_inverse_agrees_with_an_exact_chain_to_second_order(models, code: str) -> None:
    """Realistic PIGEs (20 µm, 20 µrad): the first-order model is within 1e-5 mm of the exact chain."""
    m = models[code]
    geo, world, angles = random_case(m.kin, 200, seed=4, um=20.0, urad=20.0)
    exact = exact_joints(m.kin, parse_machine_code(code), geo, world, angles)
    c_joints = m.inverse(geo, world, angles)
    nominal = m.inverse(dict(geo, errors=np.zeros_like(geo["errors"])), world, angles)
    assert np.abs(exact - nominal).max() > 5e-3  # what the errors do: micrometres
    assert np.abs(c_joints - exact).max() < 1e-5  # what is left: second order


def trt_inverse(letter: str, world: np.ndarray, angles: np.ndarray, rot_point, offset: float, dz: float,
                dt: float) -> np.ndarray:
    """xyzacKinematicsInverse / xyzbcKinematicsInverse of trtfuncs.c (LinuxCNC f1270d6ed7), one pose."""
    x, y, z = world - rot_point
    t, c = np.radians(angles)
    dz = dz + dt
    if letter == "A":
        dy = offset
        ct, st, cc, sc = np.cos(t), np.sin(t), np.cos(c), np.sin(c)
        return np.array([
            cc * x - sc * y,
            sc * ct * x + cc * ct * y - st * z - ct * dy + st * dz + dy,
            sc * st * x + cc * st * y + ct * z - st * dy - ct * dz + dz,
        ]) + rot_point
    dx = offset
    dpx = -np.cos(t) * dx - np.sin(t) * dz + dx
    dpz = np.sin(t) * dx - np.cos(t) * dz + dz
    return np.array([
        np.cos(c) * np.cos(t) * x - np.sin(c) * np.cos(t) * y + np.sin(t) * z + dpx,
        np.sin(c) * x + np.cos(c) * y,
        -np.cos(c) * np.sin(t) * x + np.sin(c) * np.sin(t) * y + np.cos(t) * z + dpz,
    ]) + rot_point


@needs_cc
@pytest.mark.parametrize("code", MACHINES[:2])
def test_sense_minus_one_is_the_stock_trt_kinematics_with_its_tool_offset(models, code: str) -> None:
    """σ = −1 and no errors: LinuxCNC's own formulas, G43 tool offset included (pivot mapping in the docs)."""
    m = models[code]
    tilt = m.kin.ROTARY_AXES[0]
    geo, world, angles = random_case(m.kin, 100, seed=5)
    geo = dict(geo, errors=np.zeros_like(geo["errors"]), sense=-np.ones_like(geo["sense"]))
    rng = np.random.default_rng(6)
    rot_point, offset, dz = rng.uniform(-50, 50, 3), 20.0, -15.0
    index = 1 if tilt == "A" else 0
    tilt_pivot = rot_point.copy()
    tilt_pivot[index] += offset
    tilt_pivot[2] += dz
    geo["pivots"] = {tilt: np.tile(tilt_pivot, (100, 1)), "C": np.tile(rot_point, (100, 1))}
    c_joints = m.inverse(geo, world, angles)
    stock = np.array([trt_inverse(tilt, world[i], angles[i], rot_point, offset, dz, geo["tool_offset"][i])
                      for i in range(100)])
    assert np.abs(c_joints - stock).max() < TOL_MM


POSE_HARNESS = r"""
#include <math.h>
typedef struct { double x, y, z; } PmCartesian;
typedef struct EmcPose { PmCartesian tran; double a, b, c; double u, v, w; } EmcPose;
#define {N}_API static
#include "model.h"
#include "pose_layer.h"
void h_pose(int tcp, const double *g_pivots, const double *errors, double tool_offset, const double *world_in,
            double *joints, double *world_out)
{
    {N}_params p;
    EmcPose pos = {{0.0, 0.0, 0.0}, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0}, back = pos;
    double *angle[3] = {&pos.a, &pos.b, &pos.c};
    int i, j;
    {N}_params_init(&p);
    for (i = 0; i < {N}_N_ROTARY; i++) for (j = 0; j < 3; j++) p.pivot[i][j] = g_pivots[3 * i + j];
    for (i = 0; i < {N}_N_ERRORS; i++) p.errors[i] = errors[i];
    p.tool_offset = tool_offset;
    pos.tran.x = world_in[0]; pos.tran.y = world_in[1]; pos.tran.z = world_in[2];
    for (i = 0; i < 3; i++) *angle[i] = world_in[3 + i];
    {N}_pose_inverse(&p, tcp, &pos, joints);
    {N}_pose_forward(&p, tcp, joints, &back);
    world_out[0] = back.tran.x; world_out[1] = back.tran.y; world_out[2] = back.tran.z;
    world_out[3] = back.a; world_out[4] = back.b; world_out[5] = back.c;
}
"""


@needs_cc
@pytest.mark.parametrize("code", MACHINES)
def test_the_component_switches_between_identity_and_the_model(tmp_path, tmp_path_factory, models, code: str) -> None:
    """The .comp's pose layer, compiled alone: identity copies, TCP is the model; joints X Y Z then letters."""
    st = parse_machine_code(code)
    name = linuxcnc.default_name(st)
    comp = shared_texts(tmp_path_factory, "linuxcnc_files", [code], linuxcnc_files)[code][f"{name}.comp"]
    begin, end = comp.index(f"/* --- {name} pose layer (no HAL) --- */"), comp.index("/* --- end of the pose layer")
    model_h = render_model_c(code, name)
    lib = compile_shared(tmp_path, {"model.h": model_h, "pose_layer.h": comp[begin:end],
                                    "pose.c": POSE_HARNESS.replace("{N}", name)}, "pose.c")
    lib.h_pose.argtypes = [ctypes.c_int, _D, _D, ctypes.c_double, _D, _D, _D]
    m = models[code]
    geo, world, angles = random_case(m.kin, 1, seed=7)
    geo["sense"][:] = 1.0
    pose = np.zeros(6)
    pose[:3] = world[0]
    for a, v in zip(m.kin.ROTARY_AXES, angles[0], strict=True):
        pose[3 + "ABC".index(a)] = v
    pivots = np.concatenate([geo["pivots"][a][0] for a in m.kin.ROTARY_AXES])
    joints, back = np.zeros(3 + m.k), np.zeros(6)
    lib.h_pose(0, pivots, geo["errors"][0], geo["tool_offset"][0], pose, joints, back)
    assert np.array_equal(joints, np.concatenate([world[0], angles[0]])) and np.array_equal(back, pose)
    lib.h_pose(1, pivots, geo["errors"][0], geo["tool_offset"][0], pose, joints, back)
    geo["tool"][:] = 0.0
    assert np.abs(joints[:3] - numpy_joints(m.kin, geo, world, angles)[0]).max() < TOL_MM
    assert np.array_equal(joints[3:], angles[0]) and np.abs(back - pose).max() < TOL_MM


@needs_cc
@pytest.mark.parametrize("code", MACHINES[:4])
def test_the_pins_pige_compensate_prints_correct_the_exact_machine(models, code: str) -> None:
    """``pige compensate --controller linuxcnc``: its setp lines, entered into the model, put the tool point of
    the exact machine on target (second order apart); an undetermined PIGE gets no line."""
    from pige_sym.codegen.targets import linuxcnc_pins
    from pige_sym.compensation.parameters import CompensationParameters
    from pige_sym.compensation.stage import format_controller

    m = models[code]
    kin, n = m.kin, 100
    rng = np.random.default_rng(8)
    values = {p: float(rng.uniform(-20, 20)) for p in kin.PARAMETERS}
    pivots = {a: [float(x) for x in rng.uniform(-100, 100, 3)] for a in kin.ROTARY_AXES}
    params = CompensationParameters(kin.MACHINE_CODE, values, dict(kin.UNITS), None, pivots, "test", [],
                                    axis_sense={kin.ROTARY_AXES[0]: -1})  # as the parameter file records it
    name = linuxcnc_pins.default_name(code)
    text = format_controller(params, "linuxcnc")
    assert f"setp {name}.sense-{kin.ROTARY_AXES[0].lower()} -1" in text
    assert f"setp {name}.sense-{kin.ROTARY_AXES[1].lower()} 1" in text
    setp = {ln.split()[1]: float(ln.split()[2]) for ln in text.splitlines() if ln.startswith(f"setp {name}.")}
    axes = kin.ROTARY_AXES
    geo = {"pivots": {a: np.tile([setp[f"{name}.pivot-{a.lower()}-{c}"] for c in "xyz"], (n, 1)) for a in axes},
           "tool": np.tile([3.0, -2.0, -180.0], (n, 1)), "tool_offset": rng.uniform(0, 100, n),
           "sense": np.tile([setp[f"{name}.sense-{a.lower()}"] for a in axes], (n, 1)),
           "errors": np.tile([setp[linuxcnc_pins.error_pin(name, p)] for p in kin.PARAMETERS], (n, 1))}
    world, angles = rng.uniform(-150, 150, (n, 3)), rng.uniform(-100, 100, (n, len(axes)))
    truth = dict(geo, errors=np.tile([values[p] for p in kin.PARAMETERS], (n, 1)))
    exact = exact_joints(kin, parse_machine_code(code), truth, world, angles)
    nominal = m.inverse(dict(geo, errors=np.zeros_like(geo["errors"])), world, angles)
    assert np.abs(nominal - exact).max() > 5e-3
    assert np.abs(m.inverse(geo, world, angles) - exact).max() < 1e-5
    missing = CompensationParameters(kin.MACHINE_CODE, values, dict(kin.UNITS), None, pivots, "test",
                                     [f"{kin.PARAMETERS[0]} (no value in the file: set to 0 by --allow-missing)"])
    text = format_controller(missing, "linuxcnc")
    pin = linuxcnc_pins.error_pin(name, kin.PARAMETERS[0])
    assert f"setp {pin} " not in text and f"# {pin}: no value in the parameter file" in text
    located = {p: v for p, v in values.items() if p in kin.LOCATION_PARAMETERS}  # as pige identify writes them
    text = format_controller(CompensationParameters(kin.MACHINE_CODE, located, dict(kin.UNITS), None, pivots, "t",
                                                    []), "linuxcnc")
    for p in kin.ZERO_PARAMETERS:
        pin = linuxcnc_pins.error_pin(name, p)
        assert f"setp {pin} " not in text and f"# {pin}: not estimated" in text
