"""The LinuxCNC model's error maps (CONVENTIONS §10): the C against the NumPy kernels and an interpolation written here.

The pure C99 model (:func:`pige_sym.codegen.c_model.render_model_c`) carries, beside the PIGEs, the error motions
of the rotary axes' carried bodies (``params.motion``, the kernels' ``MOTION_PARAMETERS``), and turns map values
into them (``map_weights``, ``map_add``).  Compiled here and compared at random poses, geometries and motions:

* the inverse with motions equals the kernels' model (nominal commands minus the un-zeroed offset of the PIGEs and
  of ``motion_jacobian @ motions``) to 1e-9 mm, and the forward inverts it in one Newton step;
* ``map_weights`` equals hat-function weights written here from CONVENTIONS §10 (uniform grid, wrapping on a full
  turn, end values held otherwise), and :class:`~pige_sym.model.error_motions.MapGrid`;
* per axis, ``map_add`` of the interpolated slots gives the kernels' motions of
  :meth:`~pige_sym.model.error_motions.ErrorMaps.pose_motions` (φ times s, the reversal by half with the direction).
"""

from __future__ import annotations

import ctypes
import shutil
from pathlib import Path

import numpy as np
import pytest
from shared_results import shared_texts
from test_gen_linuxcnc import compile_shared, model_pk, numpy_joints, random_case

from pige_sym.codegen.c_model import MAP_SLOTS
from pige_sym.kernels import load_kernels
from pige_sym.model.error_motions import AxisMaps, ErrorMaps, MapGrid, axis_motions

CC = shutil.which("cc") or shutil.which("gcc")
MACHINES = ("wC'A'bXYZ(C1)t", "wC'B'bXYZ(C1)t", "wbXYZCA(C1)t", "wC'bXYZB(C1)t")

HARNESS = r"""
#define pk_API static
#include "model.h"
#define G_SIZE (4 * pk_N_ROTARY + 3 + pk_N_ERRORS + 1)
static void load(pk_params *p, const double *g, const double *m)
{
    int i, j, o = 0;
    pk_params_init(p);
    for (i = 0; i < pk_N_ROTARY; i++) for (j = 0; j < 3; j++) p->pivot[i][j] = g[o++];
    for (j = 0; j < 3; j++) p->tool[j] = g[o++];
    for (i = 0; i < pk_N_ROTARY; i++) p->sense[i] = g[o++];
    for (i = 0; i < pk_N_ERRORS; i++) p->errors[i] = g[o++];
    p->tool_offset = g[o++];
    for (i = 0; i < pk_N_MOTIONS; i++) p->motion[i] = m[i];
}
int h_n_motions(void) { return pk_N_MOTIONS; }
void h_inverse(int n, const double *g, const double *m, const double *world, const double *angles, double *joints)
{
    int i;
    pk_params p;
    for (i = 0; i < n; i++) {
        load(&p, g + i * G_SIZE, m + i * pk_N_MOTIONS);
        pk_inverse(&p, world + 3 * i, angles + pk_N_ROTARY * i, joints + 3 * i);
    }
}
void h_forward(int n, const double *g, const double *m, const double *joints, const double *angles, double *world,
               int *steps)
{
    int i;
    double residual;
    pk_params p;
    for (i = 0; i < n; i++) {
        load(&p, g + i * G_SIZE, m + i * pk_N_MOTIONS);
        steps[i] = pk_forward_steps(&p, joints + 3 * i, angles + pk_N_ROTARY * i, 3, world + 3 * i, &residual);
    }
}
void h_weights(int n, double start, double step, int nodes, int full_turn, const double *theta, int *i0, int *i1,
               double *w1, int *status)
{
    int i;
    for (i = 0; i < n; i++) status[i] = pk_map_weights(start, step, nodes, full_turn, theta[i], i0 + i, i1 + i, w1 + i);
}
void h_add(int axis, const double *slot, double approach, double *motion)
{
    pk_map_add(axis, slot, approach, motion);
}
"""

_D = np.ctypeslib.ndpointer(dtype=np.float64, flags="C_CONTIGUOUS")
_I = np.ctypeslib.ndpointer(dtype=np.int32, flags="C_CONTIGUOUS")


class MapModel:
    """The compiled C model of one machine with its map functions."""

    def __init__(self, code: str, tmp: Path, model_h: str) -> None:
        self.kin = load_kernels(code)
        lib = compile_shared(tmp, {"model.h": model_h, "harness.c": HARNESS}, "harness.c")
        lib.h_inverse.argtypes = [ctypes.c_int, _D, _D, _D, _D, _D]
        lib.h_forward.argtypes = [ctypes.c_int, _D, _D, _D, _D, _D, _I]
        lib.h_weights.argtypes = [ctypes.c_int, ctypes.c_double, ctypes.c_double, ctypes.c_int, ctypes.c_int, _D, _I,
                                  _I, _D, _I]
        lib.h_add.argtypes = [ctypes.c_int, _D, ctypes.c_double, _D]
        self.lib = lib
        assert lib.h_n_motions() == len(self.kin.MOTION_PARAMETERS)

    def pack(self, geo: dict) -> np.ndarray:
        n = geo["errors"].shape[0]
        pivots = np.stack([geo["pivots"][a] for a in self.kin.ROTARY_AXES], axis=1).reshape(n, -1)
        return np.ascontiguousarray(np.hstack([pivots, geo["tool"], geo["sense"], geo["errors"],
                                               geo["tool_offset"][:, None]]))

    def inverse(self, geo: dict, motions: np.ndarray, world: np.ndarray, angles: np.ndarray) -> np.ndarray:
        out = np.zeros_like(world)
        self.lib.h_inverse(len(world), self.pack(geo), np.ascontiguousarray(motions), np.ascontiguousarray(world),
                           np.ascontiguousarray(angles), out)
        return out

    def forward(self, geo: dict, motions: np.ndarray, joints: np.ndarray, angles: np.ndarray):
        world, steps = np.zeros_like(joints), np.zeros(len(joints), dtype=np.int32)
        self.lib.h_forward(len(joints), self.pack(geo), np.ascontiguousarray(motions), np.ascontiguousarray(joints),
                           np.ascontiguousarray(angles), world, steps)
        return world, steps

    def weights(self, start: float, step: float, nodes: int, full: bool, theta: np.ndarray):
        n = len(theta)
        i0, i1, st = (np.zeros(n, dtype=np.int32) for _ in range(3))
        w1 = np.zeros(n)
        self.lib.h_weights(n, start, step, nodes, int(full), np.ascontiguousarray(theta, dtype=float), i0, i1, w1, st)
        return i0, i1, w1, st

    def add(self, axis: int, slot: np.ndarray, approach: float, motion: np.ndarray) -> None:
        self.lib.h_add(axis, np.ascontiguousarray(slot, dtype=float), approach, motion)


@pytest.fixture(scope="module")
def models(tmp_path_factory) -> dict[str, MapModel]:
    if CC is None:
        pytest.skip("no C compiler (cc/gcc)")
    headers = shared_texts(tmp_path_factory, "model_pk", list(MACHINES), model_pk)  # test_gen_linuxcnc.py's
    return {code: MapModel(code, tmp_path_factory.mktemp(f"mm{i}"), headers[code]["model.h"])
            for i, code in enumerate(MACHINES)}


def kernel_motion_offset(kin, geo: dict, motions: np.ndarray, world: np.ndarray, angles: np.ndarray) -> np.ndarray:
    """``motion_jacobian @ motions`` [µm] per pose, at the tool point without the tool offset (kernels' model)."""
    out = np.zeros_like(world)
    s = kin.SPINDLE_DIRECTION
    for i in range(len(world)):
        th = (angles[i] * geo["sense"][i])[None, :]
        ball, tool = world[i].copy(), geo["tool"][i].copy()
        ball[s] -= geo["tool_offset"][i]
        tool[s] -= geo["tool_offset"][i]
        pivots = {a: geo["pivots"][a][i] for a in kin.ROTARY_AXES}
        out[i] = kin.motion_jacobian(th, ball, pivots, tool)[0] @ motions[i]
    return out


@pytest.mark.parametrize("code", MACHINES)
def test_the_inverse_with_motions_is_the_kernels_model_and_the_forward_inverts_it(models, code: str) -> None:
    m = models[code]
    geo, world, angles = random_case(m.kin, 150, seed=7)
    rng = np.random.default_rng(8)
    motions = rng.uniform(-20.0, 20.0, (150, len(m.kin.MOTION_PARAMETERS)))  # µm and µrad
    joints = m.inverse(geo, motions, world, angles)
    expected = numpy_joints(m.kin, geo, world, angles) - 1e-3 * kernel_motion_offset(m.kin, geo, motions, world,
                                                                                     angles)
    assert np.abs(joints - expected).max() < 1e-9
    assert np.abs(joints - m.inverse(geo, np.zeros_like(motions), world, angles)).max() > 5e-3  # motions matter
    back, steps = m.forward(geo, motions, joints, angles)
    assert np.abs(back - world).max() < 1e-9 and steps.max() <= 1


def hat(grid: np.ndarray, full_turn: bool, theta: float) -> np.ndarray:
    """CONVENTIONS §10's linear interpolation, written here: the weight of each grid angle at θ."""
    n = grid.size
    w = np.zeros(n)
    if n == 1:
        return w + 1.0
    if full_turn:
        t = grid[0] + (theta - grid[0]) % 360.0
        nodes = np.append(grid, grid[0] + 360.0)
    else:
        t = min(max(theta, grid[0]), grid[-1])
        nodes = grid
    for k in range(nodes.size - 1):
        if nodes[k] <= t <= nodes[k + 1]:
            f = (t - nodes[k]) / (nodes[k + 1] - nodes[k])
            w[k % n] += 1.0 - f
            w[(k + 1) % n] += f
            return w
    raise AssertionError(f"theta {theta} not on the grid")


@pytest.mark.parametrize(("start", "step", "nodes", "full"),
                         [(0.0, 30.0, 12, True), (-15.0, 7.5, 48, True), (0.0, 10.0, 7, False), (-90.0, 15.0, 9, False),
                          (5.0, 5.0, 1, False)])
def test_map_weights_are_the_hat_functions_of_conventions(models, start, step, nodes, full) -> None:
    m = models[MACHINES[0]]
    rng = np.random.default_rng(3)
    grid = start + step * np.arange(nodes)
    theta = np.concatenate([rng.uniform(-800.0, 800.0, 300), grid, grid + 360.0, grid - 720.0, grid + step / 2])
    i0, i1, w1, st = m.weights(start, step, nodes, full, theta)
    assert (st == 0).all()
    mg = MapGrid("C", grid, full)
    for k, t in enumerate(theta):
        c = np.zeros(nodes)
        c[i0[k]] += 1.0 - w1[k]
        c[i1[k]] += w1[k]
        assert np.abs(c - hat(grid, full, t)).max() < 1e-9, (t, c)
    assert np.abs(mg.weights(theta) - np.array([hat(grid, full, t) for t in theta])).max() < 1e-9
    assert m.weights(0.0, 0.0, 12, True, theta[:3])[3].tolist() == [-1, -1, -1]  # no step: no map
    assert m.weights(0.0, 30.0, 0, True, theta[:3])[3].tolist() == [-1, -1, -1]


@pytest.mark.parametrize("code", MACHINES)
def test_map_add_gives_the_kernels_motions_of_the_maps(models, code: str) -> None:
    """Random per-direction maps on both axes, the C's slots interpolated as the component does."""
    m = models[code]
    kin = m.kin
    rng = np.random.default_rng(11)
    axes, grids = {}, {}
    for ax in kin.ROTARY_AXES:
        full = ax[0] == "C"
        grid = np.arange(12) * 30.0 if full else np.arange(-60.0, 61.0, 15.0)
        values = {mo.name: rng.normal(scale=5.0, size=grid.size) for mo in axis_motions(ax) if mo.kind != "positioning"}
        phi = next(mo.name for mo in axis_motions(ax) if mo.kind == "positioning")
        values[phi + "+"], values[phi + "-"] = (rng.normal(scale=30.0, size=grid.size) for _ in range(2))
        axes[ax] = AxisMaps(MapGrid(ax, grid, full), values)
        grids[ax] = (grid, full)
    maps = ErrorMaps(axes)
    angles = rng.uniform(-150.0, 150.0, (60, len(kin.ROTARY_AXES)))
    approach = rng.choice([-1, 0, 1], size=angles.shape)
    expected = maps.pose_motions(kin, angles, approach)
    for p in range(len(angles)):
        motion = np.zeros(len(kin.MOTION_PARAMETERS))
        for i, ax in enumerate(kin.ROTARY_AXES):
            grid, full = grids[ax]
            i0, i1, w1, _ = m.weights(grid[0], grid[1] - grid[0], grid.size, full, angles[p, i:i + 1])
            stored = axes[ax].values
            phi = next(mo.name for mo in axis_motions(ax) if mo.kind == "positioning")
            columns = [stored[mo.name] for mo in axis_motions(ax)[:5]]
            columns += [0.5 * (stored[phi + "+"] + stored[phi + "-"]), stored[phi + "+"] - stored[phi + "-"]]
            slot = np.array([(1 - w1[0]) * v[i0[0]] + w1[0] * v[i1[0]] for v in columns])
            assert slot.size == MAP_SLOTS
            m.add(i, slot, float(approach[p, i]), motion)
        assert np.abs(motion - expected[p]).max() < 1e-9, p


@pytest.mark.parametrize("axis", ["A", "B", "C", "C2"])
def test_the_code_generators_slots_are_the_models_motions(axis: str) -> None:
    from pige_sym.codegen.map_slots import map_slots

    assert map_slots(axis) == [(m.name, m.component, m.kind) for m in axis_motions(axis, per_direction=True)]


def test_the_printed_setp_lines_enter_the_weighed_maps(models, tmp_path, capsys) -> None:
    """pige compensate --controller linuxcnc: its map pins, read back into the compiled map functions as the
    component reads them, give the motions of the maps it weighed, at any pose and direction."""
    import json
    import re

    from pige_sym.cli.main import main
    from pige_sym.codegen.targets.linuxcnc_pins import default_name, map_slot_names
    from pige_sym.compensation.controllers import entered_for_controller
    from pige_sym.compensation.parameters import load_parameters

    code = MACHINES[0]
    m = models[code]
    rng = np.random.default_rng(9)

    def entry(n: int, kind: str, scale: float, unit: str = "um") -> dict:
        return {"value": list(rng.normal(scale=scale, size=n)), "std": [0.2] * n, "unit": unit, "kind": kind}

    grid_c, grid_a = list(np.arange(12) * 30.0), list(np.arange(0.0, 91.0, 30.0))
    def unit(n: str) -> str:  # a rotation's unit is urad (the map file's unit is read, issue 47)
        return "um" if n[1] in "XYZ" else "urad"

    motions_c = {n: entry(12, "radial", 3.0, unit(n)) for n in ("EXC", "EYC", "EZC", "EAC", "EBC")}
    motions_a = {n: entry(4, "radial", 3.0, unit(n)) for n in ("EYA", "EZA", "EXA", "EBA", "ECA", "EAA")}
    doc = {"machine": code, "pige": {n: 0.0 for n in m.kin.LOCATION_PARAMETERS}, "axis_sense": {"A": -1, "C": -1},
           "error_motions": {"C": {"angle_deg": grid_c, "full_turn": True, **motions_c,
                                   "ECC+": entry(12, "positioning", 30.0, "urad"),
                                   "ECC-": entry(12, "positioning", 30.0, "urad")},
                             "A": {"angle_deg": grid_a, "full_turn": False, **motions_a}}}
    path = tmp_path / "maps.json"
    path.write_text(json.dumps(doc))
    assert main(["compensate", "--params", str(path), "--controller", "linuxcnc"]) == 0
    text = capsys.readouterr().out
    name = default_name(code)
    pins = {p: float(v) for p, v in re.findall(rf"^setp {name}\.(\S+) (\S+)$", text, flags=re.M)}
    assert f"net pige-vel-c joint.4.vel-cmd => {name}.vel-c" in text
    entered = entered_for_controller(load_parameters(path)).error_maps
    angles = np.column_stack([rng.uniform(-100, 0, 40), rng.uniform(-700, 700, 40)])  # commanded, sigma -1
    approach_cmd = rng.choice([-1, 1], size=angles.shape)
    expected = entered.pose_motions(m.kin, -angles, -approach_cmd)
    for p in range(len(angles)):
        motion = np.zeros(len(m.kin.MOTION_PARAMETERS))
        for i, ax in enumerate(m.kin.ROTARY_AXES):
            a = ax.lower()
            nodes = int(pins[f"map-{a}-nodes"])
            i0, i1, w1, st = m.weights(pins[f"map-{a}-start"], pins[f"map-{a}-step"], nodes,
                                       bool(pins[f"map-{a}-full-turn"]), -angles[p, i:i + 1])
            assert st[0] == 0
            slot = np.array([(1 - w1[0]) * pins[f"{stem}-{i0[0]:02d}"] + w1[0] * pins[f"{stem}-{i1[0]:02d}"]
                             for stem in map_slot_names(ax)])
            m.add(i, slot, float(-approach_cmd[p, i]), motion)
        assert np.abs(motion - expected[p]).max() < 2e-4, p  # the lines' 4 decimals
