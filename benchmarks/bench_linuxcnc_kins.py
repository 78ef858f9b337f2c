"""The generated LinuxCNC kinematics: time per call in compiled C, and the Newton convergence, in one run.

For the table-table machines (``wC'A'bXYZ(C1)t``, ``wC'B'bXYZ(C1)t``) the pure C99 model that
``pige gen --target linuxcnc`` inlines into its component is compiled with halcompile's own flags
(``-Os -msse -fno-builtin-sin -fno-builtin-cos -fno-builtin-sincos``, ``halcompile --print-modinc``)
into one C program that, over 20,000 random poses (angles ±120°, tool points ±200 mm, tilts up to
1 mrad, offsets up to 50 µm, σ = −1, 50 mm tool offset), times per call (median of 7 loops):

* ``inverse`` (world → joints, closed form): the issue's target is < 1 µs per call;
* ``inverse with maps``: the same after the error maps of both axes (CONVENTIONS §10: 12 and 7 grid angles,
  7 slots each, values in arrays as the component's pins hold them) are interpolated into ``motion[]`` with
  ``map_weights`` and ``map_add``, what pige's component does per call;
* ``forward`` (joints → world: nominal closed form + Newton steps with the generated Jacobian);
* the **floor**: LinuxCNC's stock nominal trt inverse (``xyzacKinematicsInverse`` / ``xyzbc…`` of
  ``trtfuncs.c`` at f1270d6ed7, retyped in the program), what a user runs without pige: no PIGE.

Convergence, from the same program: per pose random PIGEs (offsets up to 50 µm, then up to 1 mm; tilts
and zero-position errors up to 1 mrad), ``world → inverse → forward_steps(max_steps)``: the largest
``|world' − world|`` and residual ``|inverse(world') − joints|`` [mm] after 0 (the nominal start), 1,
2 and 3 Newton steps. The NumPy kernels evaluating the same model for one pose (what a Python tool
would call) are timed for comparison.

Run ``python benchmarks/bench_linuxcnc_kins.py``; prints a markdown section. Skips without a C compiler.
"""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from timing import median_seconds  # noqa: E402

from pige_sym.codegen.c_model import render_model_c  # noqa: E402
from pige_sym.kernels import load_kernels  # noqa: E402

MACHINES = ("wC'A'bXYZ(C1)t", "wC'B'bXYZ(C1)t")
HALCOMPILE_FLAGS = ["-Os", "-msse", "-fno-builtin-sin", "-fno-builtin-cos", "-fno-builtin-sincos"]
TARGET_US = 1.0

PROGRAM = r"""
#define K_API static
#include "model.h"
#include <stdio.h>
#include <time.h>
#define N 20000
#define REPS 7
static double world[N][3], ang[N][K_N_ROTARY], joints[N][3], back[N][3];
/* error maps of both axes: 12 grid angles on a full turn (the second axis, C) and 7 over 0..60 (the first) */
static const int map_nodes[K_N_ROTARY] = {7, 12};
static const double map_start[K_N_ROTARY] = {0.0, 0.0}, map_step[K_N_ROTARY] = {10.0, 30.0};
static const int map_full[K_N_ROTARY] = {0, 1};
static double map_values[K_N_ROTARY][K_MAP_SLOTS][12];
/* what the component does per call before the inverse: both axes' maps into motion[] */
static void set_motions(K_params *p, const double *angles)
{
    double slot[K_MAP_SLOTS], w1;
    int i, j, i0, i1;
    for (i = 0; i < K_N_MOTIONS; i++) p->motion[i] = 0.0;
    for (i = 0; i < K_N_ROTARY; i++) {
        if (K_map_weights(map_start[i], map_step[i], map_nodes[i], map_full[i], p->sense[i] * angles[i], &i0, &i1, &w1))
            continue;
        for (j = 0; j < K_MAP_SLOTS; j++) slot[j] = (1.0 - w1) * map_values[i][j][i0] + w1 * map_values[i][j][i1];
        K_map_add(i, slot, p->sense[i], p->motion);
    }
}
static unsigned long long rs = 88172645463325252ULL;
static double urand(double lo, double hi)
{
    rs ^= rs << 13; rs ^= rs >> 7; rs ^= rs << 17;
    return lo + (hi - lo) * (double)(rs >> 11) * (1.0 / 9007199254740992.0);
}
static double now(void) { struct timespec t; clock_gettime(CLOCK_MONOTONIC, &t); return t.tv_sec + 1e-9 * t.tv_nsec; }
static int cmp(const void *a, const void *b)
{
    const double d = *(const double *)a - *(const double *)b;
    return (d > 0) - (d < 0);
}
static double median(double *v) { qsort(v, REPS, sizeof(double), cmp); return v[REPS / 2]; }
static double best(double *v) { qsort(v, REPS, sizeof(double), cmp); return v[0]; }
/* trtfuncs.c (LinuxCNC f1270d6ed7) xyzac/xyzbc KinematicsInverse, rot points 0: the nominal floor */
static void trt_inverse(const double *w, const double *a, double offset, double dz, double dt, double *j)
{
    const double t = a[0] * 0.017453292519943295, c = a[1] * 0.017453292519943295;
    const double ct = cos(t), st = sin(t), cc = cos(c), sc = sin(c);
    dz += dt;
    if (TILT_IS_A) {
        j[0] = cc * w[0] - sc * w[1];
        j[1] = sc * ct * w[0] + cc * ct * w[1] - st * w[2] - ct * offset + st * dz + offset;
        j[2] = sc * st * w[0] + cc * st * w[1] + ct * w[2] - st * offset - ct * dz + dz;
    } else {
        j[0] = cc * ct * w[0] - sc * ct * w[1] + st * w[2] - ct * offset - st * dz + offset;
        j[1] = sc * w[0] + cc * w[1];
        j[2] = -cc * st * w[0] + sc * st * w[1] + ct * w[2] + st * offset - ct * dz + dz;
    }
}
static void random_params(K_params *p, double um, double urad)
{
    int i;
    K_params_init(p);
    for (i = 0; i < K_N_ROTARY; i++) p->sense[i] = -1.0;
    p->pivot[0][TILT_IS_A ? 1 : 0] = 20.0;
    p->pivot[0][2] = -15.0;
    for (i = 0; i < K_N_ERRORS; i++) p->errors[i] = IS_UM(i) ? urand(-um, um) : urand(-urad, urad);
    p->tool_offset = 50.0;
}
int main(void)
{
    K_params p;
    double t_inv[REPS], t_fwd[REPS], t_nom[REPS], t_trt[REPS], t_map[REPS], sink = 0.0, t0;
    int i, r, j, steps, scale;
    for (i = 0; i < K_N_ROTARY; i++) for (j = 0; j < K_MAP_SLOTS; j++) for (r = 0; r < 12; r++)
        map_values[i][j][r] = urand(-20.0, 20.0);
    for (i = 0; i < N; i++) {
        for (j = 0; j < 3; j++) world[i][j] = urand(-200.0, 200.0);
        for (j = 0; j < K_N_ROTARY; j++) ang[i][j] = urand(-120.0, 120.0);
    }
    random_params(&p, 50.0, 1000.0);
    for (r = 0; r < REPS; r++) {
        t0 = now(); for (i = 0; i < N; i++) K_inverse(&p, world[i], ang[i], joints[i]); t_inv[r] = (now() - t0) / N;
        t0 = now(); for (i = 0; i < N; i++) K_forward(&p, joints[i], ang[i], back[i]); t_fwd[r] = (now() - t0) / N;
        t0 = now(); for (i = 0; i < N; i++) K_forward_nominal(&p, joints[i], ang[i], back[i]);
        t_nom[r] = (now() - t0) / N;
        t0 = now(); for (i = 0; i < N; i++) trt_inverse(world[i], ang[i], 20.0, -15.0, 50.0, back[i]);
        t_trt[r] = (now() - t0) / N;
        t0 = now();
        for (i = 0; i < N; i++) {
            set_motions(&p, ang[i]);
            K_inverse(&p, world[i], ang[i], back[i]);
        }
        t_map[r] = (now() - t0) / N;
        for (i = 0; i < N; i++) sink += joints[i][0] + back[i][1];
    }
    printf("{\"best_inverse_s\": %.6g, \"best_inverse_maps_s\": %.6g, \"best_trt_s\": %.6g, ",
           best(t_inv), best(t_map), best(t_trt));
    printf("\"inverse_s\": %.6g, \"forward_s\": %.6g, \"nominal_forward_s\": %.6g, \"trt_s\": %.6g, "
           "\"inverse_maps_s\": %.6g, \"sink\": %g,",
           median(t_inv), median(t_fwd), median(t_nom), median(t_trt), median(t_map), sink);
    printf("\"convergence\": [");
    for (scale = 0; scale < 2; scale++) {
        for (steps = 0; steps <= 3; steps++) {
            double err = 0.0, res_max = 0.0, res;
            int used_max = 0;
            rs = 12345ULL + scale;
            for (i = 0; i < N; i++) {
                int used;
                random_params(&p, scale ? 1000.0 : 50.0, 1000.0);
                K_inverse(&p, world[i], ang[i], joints[i]);
                used = K_forward_steps(&p, joints[i], ang[i], steps, back[i], &res);
                for (j = 0; j < 3; j++) err = fmax(err, fabs(back[i][j] - world[i][j]));
                res_max = fmax(res_max, res);
                used_max = used > used_max ? used : used_max;
            }
            printf("%s{\"um\": %g, \"max_steps\": %d, \"steps_used\": %d, \"error_mm\": %.3g, \"residual_mm\": %.3g}",
                   scale + steps ? ", " : "", scale ? 1000.0 : 50.0, steps, used_max, err, res_max);
        }
    }
    printf("]}\n");
    return 0;
}
"""


def run_machine(code: str, cc: str, work: Path) -> dict:
    """Compile the timing program for one machine and return what it measured."""
    kin = load_kernels(code)
    um = [i for i, p in enumerate(kin.PARAMETERS) if kin.UNITS[p] == "um"]
    (work / "model.h").write_text(render_model_c(code, "K"), encoding="utf-8")
    source = "#include <stdlib.h>\n#include <math.h>\n" + \
        f"#define TILT_IS_A {int(kin.ROTARY_AXES[0] == 'A')}\n" + \
        "#define IS_UM(i) (" + " || ".join(f"(i) == {i}" for i in um) + ")\n" + PROGRAM
    (work / "bench.c").write_text(source, encoding="utf-8")
    exe = work / "bench"
    subprocess.run([cc, "-std=gnu99", *HALCOMPILE_FLAGS, "-o", str(exe), str(work / "bench.c"), "-lm"],
                   check=True, capture_output=True, text=True, timeout=300)
    out = subprocess.run([str(exe)], check=True, capture_output=True, text=True, timeout=600)
    return json.loads(out.stdout)


def numpy_per_call(code: str, repeats: int = 200) -> float:
    """The kernels evaluating the same model for one pose (linear_commands + un-zeroed deviation) [s]."""
    kin = load_kernels(code)
    rng = np.random.default_rng(0)
    e = rng.uniform(-50, 50, len(kin.PARAMETERS))
    ball, th = np.array([100.0, 20.0, 50.0]), np.array([[30.0, 45.0]])

    def one() -> np.ndarray:
        r = kin.deviation(th, e, ball) + kin.workpiece_rotation(th)[0] @ kin.reference_jacobian(ball) @ e
        return kin.linear_commands(th, ball) - 1e-3 * r

    return median_seconds(one, repeats)


def _us(seconds: float) -> str:
    return f"{seconds * 1e6:.3f} µs"


def main() -> None:
    cc = shutil.which("cc") or shutil.which("gcc")
    load = Path("/proc/loadavg").read_text().split()[0] if Path("/proc/loadavg").is_file() else "unknown"
    print("## LinuxCNC kinematics with every PIGE (benchmarks/bench_linuxcnc_kins.py)\n")
    if cc is None:
        print("skipped: no C compiler")
        return
    rows, conv = [], []
    with tempfile.TemporaryDirectory() as tmp:
        for code in MACHINES:
            work = Path(tmp) / code.replace("'", "p").replace("(", "_").replace(")", "_")
            work.mkdir()
            m = run_machine(code, cc, work)
            py = numpy_per_call(code)
            verdict = "PASS" if m["inverse_s"] * 1e6 < TARGET_US else "MISS"
            with_maps = "PASS" if m["inverse_maps_s"] * 1e6 < TARGET_US else "MISS"
            rows += [f"| {code} | inverse (world → joints) | {_us(m['inverse_s'])} | "
                     f"{m['inverse_s'] / m['trt_s']:.1f}x floor | target < {TARGET_US:g} µs: {verdict} (best loop "
                     f"{_us(m['best_inverse_s'])}) |",
                     f"| {code} | inverse with both axes' error maps | {_us(m['inverse_maps_s'])} | "
                     f"{m['inverse_maps_s'] / m['trt_s']:.1f}x floor | target < {TARGET_US:g} µs: {with_maps} (best "
                     f"loop {_us(m['best_inverse_maps_s'])}, floor's {_us(m['best_trt_s'])}) |",
                     f"| {code} | forward (joints → world, Newton) | {_us(m['forward_s'])} | "
                     f"{m['forward_s'] / m['trt_s']:.1f}x floor | nominal start alone {_us(m['nominal_forward_s'])} |",
                     f"| {code} | floor: stock trt inverse, no PIGE | {_us(m['trt_s'])} | 1.0x | trtfuncs.c retyped |",
                     f"| {code} | NumPy kernels, same model, one pose | {_us(py)} | {py / m['trt_s']:.0f}x floor | "
                     "Python, for comparison |"]
            conv += [f"| {code} | {c['um']:g} µm, 1 mrad | {c['max_steps']} | {c['steps_used']} | "
                     f"{c['error_mm']:.1e} | {c['residual_mm']:.1e} |" for c in m["convergence"]]
    print("Compiled with halcompile's flags (-Os -msse -fno-builtin-sin/cos/sincos); medians of 7 loops over "
          f"20,000 poses, per call, and the best loop (the least disturbed by other processes); load average {load} "
          "when the run started.\n")
    print("| machine | what | per call | ratio | note |\n|---|---|---:|---|---|")
    print("\n".join(rows))
    print("\nNewton convergence (20,000 random poses and PIGEs each; step 0 is the nominal closed form):\n")
    print("| machine | PIGEs up to | max steps | steps used | max error of world [mm] | max residual [mm] |")
    print("|---|---|---:|---:|---:|---:|")
    print("\n".join(conv))


if __name__ == "__main__":
    main()
