"""Scale of the error maps (issue 47, item 4): ``pige compensate`` and ``pige identify`` as the map grid gets finer.

Each command runs as a user runs it, in a fresh process (benchmarks/commands.py: wall time of ``main()``, the
process's CPU time and its peak resident memory, VmHWM), all in one run.  With ``--before DIR`` every command is
timed also with the pige_sym of another checkout (``git archive main | tar -x -C DIR``: the code before a change),
up to ``--timeout`` seconds.

* **compensate**: the parameter files are what ``pige identify --map … --json`` writes, built here by the same fit
  (:func:`~pige_sym.identification.maps.identify_maps`) on simulated R-test setups with hidden maps and PIGEs, poses
  at every grid angle (three ball positions on the table; each A angle met with C at twelve angles, C swept fully at
  A 0, −45 and −90°): C and A on 30°, 15°, 6° and 3° grids (96 to 906 map values), and an A map alone on a 0.5°
  grid over −150…0° (301 angles, 1,806 values; one setup, C at six angles per A angle).  Timed:
  ``pige compensate --params FILE --controller siemens`` (every value weighed over the axes' travel, with its
  predictions; :data:`CONTROLLER`) and
  the NC rewrite of a 2,000-pose TRAORI program (``pige compensate PROGRAM --params FILE --out NEW``).  The floor:
  the same commands with the file's PIGEs alone (its maps removed): what compensating costs without maps.
* **identify**: the map test of docs/maps.md as a user runs it — ``pige program --map C,A --map-step 30``, the
  virtual machine's logs (``pige simulate``), ``pige import-probe`` (three setups × 48 poses) — identified with
  ``pige identify … --map C,A --map-step S`` for S from 30° to 0.5° (96 to 5,406 map values; the poses lie on the
  30° grid, so every finer grid adds values no pose determines).  And, in process, the dense case: poses at every
  angle of the grid (the compensate inputs' fits), where every value is determined.

Targets (issue 47): compensate with 800 map values within 5 s; identify --map-step 0.5 within linear time (the 15°
time times the ratio of values, 29) and 300 MB of the 15° case.  ``main()`` prints a markdown section.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import math
import os
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from commands import cell, run_footer, run_pige  # noqa: E402

from pige_sym.identification.maps import MapSpec, identify_maps  # noqa: E402
from pige_sym.kernels import load_kernels  # noqa: E402
from pige_sym.model.error_motions import AxisMaps, ErrorMaps, MapGrid, axis_motions  # noqa: E402
from pige_sym.model.trajectories import Trajectory  # noqa: E402
from pige_sym.simulation.simulator import random_pige, simulate  # noqa: E402

AC = "wC'A'bXYZ(C1)t"
SETUPS = ((110.0, 0.0, 40.0), (-50.0, 95.0, 90.0), (-60.0, -90.0, 140.0))
#: (axes, grid step [deg], A range [deg]) of the compensate inputs.
GRIDS = ((("C", "A"), 30.0, (-90.0, 0.0)), (("C", "A"), 15.0, (-90.0, 0.0)), (("C", "A"), 6.0, (-90.0, 0.0)),
         (("C", "A"), 3.0, (-90.0, 0.0)), (("A",), 0.5, (-150.0, 0.0)))
STEPS = (30.0, 15.0, 5.0, 2.0, 1.0, 0.5)
#: The controller timed: SINUMERIK holds the positioning maps ($AA_ENC_COMP), and every value is weighed and its error
#: predicted over the axes' travel (pige's LinuxCNC component holds at most 73 grid angles per axis: a 3° C grid is
#: refused before any work, issue 47 item 1).
CONTROLLER = "siemens"


def _hidden_maps(a_range: tuple[float, float], rng: np.random.Generator) -> ErrorMaps:
    """Maps of harmonics 2–4 on a 1° grid (finer than any fitted one)."""
    out = {}
    for axis, grid, full in (("C", np.arange(0.0, 360.0, 1.0), True),
                             ("A", np.arange(a_range[0], a_range[1] + 0.5, 1.0), False)):
        t = np.radians(grid)
        out[axis] = AxisMaps(MapGrid(axis, grid, full), {
            m.name: sum(rng.normal(scale=1.5) * np.cos(h * t + rng.uniform(0.0, 6.3)) for h in (2, 3, 4))
            for m in axis_motions(axis)})
    return ErrorMaps(out)


def _poses(axes: tuple[str, ...], step: float, a_range: tuple[float, float]) -> np.ndarray:
    """(A, C) [deg] of one setup: the reference, each A angle of the grid with C at twelve angles (offset from one A
    angle to the next, so every C angle is met), and C swept on its grid at three A angles (both axes mapped)."""
    a_grid = np.arange(a_range[0], a_range[1] + 1e-9, step)
    c_grid = np.arange(0.0, 360.0, step)
    shift = max(1, int(round(30.0 / step)))
    angles = [(0.0, 0.0)]
    for i, a in enumerate(a_grid[::-1]):
        angles += [(a, c_grid[(i + 7 * j * shift) % c_grid.size] if "C" in axes else 60.0 * j)
                   for j in range(12 if "C" in axes else 6)]
    if "C" in axes:
        for a in (0.0, -45.0, -90.0):
            angles += [(a, c) for c in c_grid]
    return np.array(angles)


def map_parameters(folder: Path, axes: tuple[str, ...], step: float, a_range: tuple[float, float],
                   seed: int = 0) -> tuple[Path, Path, int, float]:
    """(the parameter file ``identify --map --json`` writes, the same without its maps, its map values, the fit's
    time [s]) of simulated setups with poses at every grid angle."""
    from pige_sym.files import to_json

    rng = np.random.default_rng(seed)
    maps, truth = _hidden_maps(a_range, rng), random_pige(AC, seed)
    angles = _poses(axes, step, a_range)
    traj = Trajectory("map sweep", ("A", "C"), angles, np.arange(len(angles)) * 8.0, "map sweep")
    setups = SETUPS if "C" in axes else SETUPS[:1]
    items = [(f"setup{i}", simulate(AC, traj, pige=truth, ball_mm=ball, noise_um=0.2, seed=seed + i,
                                    error_maps=maps).measurement) for i, ball in enumerate(setups)]
    t0 = time.process_time()
    doc = json.loads(to_json(identify_maps(items, MapSpec(axes, step)).to_dict()))
    fit_s = time.process_time() - t0
    values = sum(1 for m in doc["error_motions"].values() for k, v in m.items() if isinstance(v, dict)
                 for x in v["value"] if x is not None)
    name = f"maps_{'_'.join(axes)}_{step:g}"
    path, plain = folder / f"{name}.json", folder / f"{name}_pige.json"
    path.write_text(json.dumps(doc), encoding="utf-8")
    plain.write_text(json.dumps(_without_maps(doc)), encoding="utf-8")
    return path, plain, values, fit_s


def _without_maps(doc: dict[str, Any]) -> dict[str, Any]:
    """The parameter file without its maps: no error motions, the covariance of the PIGEs alone (``identify --map``
    writes the map values' rows too, named ``C:EXC@30``)."""
    out = {k: v for k, v in doc.items() if k not in ("error_motions", "map_undetermined", "map_step_deg")}
    cov = doc.get("covariance")
    if isinstance(cov, dict) and any(":" in n for n in cov["parameters"]):
        keep = [i for i, n in enumerate(cov["parameters"]) if ":" not in n]
        out["covariance"] = {"parameters": [cov["parameters"][i] for i in keep],
                             "matrix": [[cov["matrix"][i][j] for j in keep] for i in keep]}
    return out


def _program(folder: Path, poses: int = 2000) -> Path:
    """A TRAORI program of ``poses`` poses over the axes' travel (angles between any grid's angles)."""
    from pige_sym.nc.program import make_rtest_program

    rng = np.random.default_rng(1)
    angles = np.column_stack([rng.uniform(-90.0, 0.0, poses), np.sort(rng.uniform(0.0, 360.0, poses))])
    ball = np.array([120.0, 0.0, 80.0]) + rng.normal(scale=5.0, size=(poses, 3))
    path = folder / "program.mpf"
    path.write_text(make_rtest_program(angles, ball, tuple(load_kernels(AC).ROTARY_AXES), rtcp=True))
    return path


def _quiet(*args: object) -> None:
    from pige_sym.cli.main import main

    with contextlib.redirect_stdout(io.StringIO()):
        code = main([str(a) for a in args])
    if code != 0:
        raise RuntimeError(f"pige {' '.join(map(str, args))} exited {code}")


def probe_map_test(folder: Path) -> list[Path]:
    """docs/maps.md's map test on a 30° grid: three setups' programs, the virtual machine's logs, imported."""
    sphere = ["--sphere", "100,20,60", "--sphere-radius", "12.7", "--stylus-radius", "1.5"]
    kins = ["--rtcp-off", "M429", "--rtcp-on", "M428", "--stylus-tool", "99", "--stylus-length", "120"]
    _quiet("program", "--instrument", "sphere-probe", "--machine", AC, *sphere, *kins, "--map", "C,A", "--map-step",
           30, "--map-setups", 3, "--dialect", "linuxcnc", "--out", folder / "map.ngc")
    pige = "EX0C=4,EY0C=-6,EA0C=12,EB0C=-9,EY0A=8,EZ0A=-5,EB0A=20,EC0A=-14"
    out = []
    for i in (1, 2, 3):
        _quiet("simulate", "--instrument", "sphere-probe", "--dialect", "linuxcnc", "--program",
               folder / f"map_{i}.ngc", "--pige", pige, "--seed", i, "--error-maps",
               ROOT / "examples" / "error_maps_ac.json", "--noise", 0.5, "--out", folder / f"map_log_{i}.txt")
        _quiet("import-probe", folder / f"map_log_{i}.txt", "--format", "linuxcnc", "--program",
               folder / f"map_{i}.ngc", "--out", folder / f"map_{i}.csv")
        out.append(folder / f"map_{i}.csv")
    return out


def _exponent(x: list[float], y: list[float]) -> float:
    ok = [(a, b) for a, b in zip(x, y, strict=True) if a > 0 and b > 0]
    return float(np.polyfit(np.log([a for a, _ in ok]), np.log([b for _, b in ok]), 1)[0]) if len(ok) > 1 else math.nan


def compensate_rows(folder: Path, grids: tuple[Any, ...], before: Path | None, timeout: float) -> list[dict[str, Any]]:
    program = _program(folder)
    rows = []
    for axes, step, a_range in grids:
        path, plain, values, fit_s = map_parameters(folder, axes, step, a_range)
        row: dict[str, Any] = {"grid": f"{','.join(axes)} every {step:g}°", "values": values, "fit_s": fit_s}
        for key, params in (("", path), ("floor_", plain)):
            row[key + "ctl"] = run_pige(["compensate", "--params", str(params), "--controller", CONTROLLER,
                                         "--allow-missing"], folder)
            row[key + "nc"] = run_pige(["compensate", str(program), "--params", str(params), "--allow-missing",
                                        "--out", str(folder / f"{key}out.mpf"), "--force"], folder)
        if before is not None:
            row["before_ctl"] = run_pige(["compensate", "--params", str(path), "--controller", CONTROLLER,
                                          "--allow-missing"], folder, source=before, timeout=timeout)
            row["before_nc"] = run_pige(["compensate", str(program), "--params", str(path), "--allow-missing", "--out",
                                         str(folder / "out_before.mpf"), "--force"], folder, source=before,
                                        timeout=timeout)
            if row["before_nc"] is not None:
                row["same_program"] = (folder / "out.mpf").read_bytes() == (folder / "out_before.mpf").read_bytes()
        rows.append(row)
    return rows


def identify_rows(folder: Path, steps: tuple[float, ...], before: Path | None, timeout: float) -> list[dict[str, Any]]:
    files = [str(p) for p in probe_map_test(folder)]
    rows = []
    for step in steps:
        argv = ["identify", *files, "--map", "C,A", "--map-step", f"{step:g}", "--json"]
        row: dict[str, Any] = {"step": step, "now": run_pige(argv, folder)}
        doc = json.loads(row["now"]["stdout"])
        row["values"] = sum(len(v["value"]) for m in doc["error_motions"].values() for v in m.values()
                            if isinstance(v, dict))
        row["determined"] = sum(x is not None for m in doc["error_motions"].values() for v in m.values()
                                if isinstance(v, dict) for x in v["value"])
        if before is not None:
            row["before"] = run_pige(argv, folder, source=before, timeout=timeout)
            if row["before"] is not None:
                row["same"] = _same_json(json.loads(row["before"]["stdout"]), doc)
        rows.append(row)
    return rows


def _same_json(a: Any, b: Any) -> bool:
    """Equal within round-off (floats to 1e-8 relative)."""
    if isinstance(a, dict):
        return isinstance(b, dict) and a.keys() == b.keys() and all(_same_json(a[k], b[k]) for k in a)
    if isinstance(a, list):
        return isinstance(b, list) and len(a) == len(b) and all(_same_json(x, y) for x, y in zip(a, b, strict=True))
    if isinstance(a, float) and isinstance(b, float):
        return math.isclose(a, b, rel_tol=1e-8, abs_tol=1e-10)
    return bool(a == b)


def _compensate_lines(rows: list[dict[str, Any]], before: bool, timeout: float) -> list[str]:
    head = (f"| map grid | map values | --controller {CONTROLLER} wall [s] | CPU [s] | peak [MB] | without maps CPU "
            "[s] | NC rewrite (2,000 poses) wall [s] | CPU [s] | peak [MB] | without maps CPU [s] |")
    lines = [head + (" before: --controller CPU [s] | before: NC CPU [s] | same program |" if before else ""),
             "|" + "---|" * (10 + (3 if before else 0))]
    for r in rows:
        line = (f"| {r['grid']} | {r['values']:,} | {cell(r['ctl'], 's')} | {cell(r['ctl'], 'cpu_s')} | "
                f"{cell(r['ctl'], 'rss_mb', '.0f')} | {cell(r['floor_ctl'], 'cpu_s')} | {cell(r['nc'], 's')} | "
                f"{cell(r['nc'], 'cpu_s')} | {cell(r['nc'], 'rss_mb', '.0f')} | {cell(r['floor_nc'], 'cpu_s')} |")
        if before:
            same = {True: "yes", False: "NO"}.get(r.get("same_program"), "—")
            line += (f" {cell(r.get('before_ctl'), 'cpu_s', timeout=timeout)} | "
                     f"{cell(r.get('before_nc'), 'cpu_s', timeout=timeout)} | {same} |")
        lines.append(line)
    v = [r["values"] for r in rows]
    b_ctl = _exponent(v, [r["ctl"]["cpu_s"] - r["floor_ctl"]["cpu_s"] for r in rows])
    b_nc = _exponent(v, [r["nc"]["cpu_s"] - r["floor_nc"]["cpu_s"] for r in rows])
    big = [r for r in rows if r["values"] >= 800]
    verdict = ", ".join(f"{r['values']:,} values {r['ctl']['cpu_s']:.2f} s CPU "
                        f"({'PASS' if r['ctl']['cpu_s'] <= 5.0 else 'MISS'}; {r['ctl']['s']:.2f} s wall at this load)"
                        for r in big)
    return lines + ["", f"Growth of the maps' share (CPU minus the same file without maps) with the values: exponent "
                        f"{b_ctl:.2f} (--controller), {b_nc:.2f} (NC rewrite); 1 is linear. Target: 800 map values "
                        f"within 5 s (judged on CPU time, the wall time of an unloaded machine): "
                        f"{verdict or 'no size of 800 values or more run'}."]


def _identify_lines(rows: list[dict[str, Any]], before: bool, timeout: float) -> list[str]:
    lines = ["| --map-step | map values | determined | wall [s] | CPU [s] | peak [MB] |"
             + (" before: wall [s] | before: CPU [s] | before: peak [MB] | same JSON |" if before else ""),
             "|" + "---|" * (6 + (4 if before else 0))]
    for r in rows:
        line = (f"| {r['step']:g}° | {r['values']:,} | {r['determined']} | {cell(r['now'], 's')} | "
                f"{cell(r['now'], 'cpu_s')} | {cell(r['now'], 'rss_mb', '.0f')} |")
        if before:
            same = {True: "yes", False: "NO"}.get(r.get("same"), "—")
            line += (f" {cell(r.get('before'), 's', timeout=timeout)} | {cell(r.get('before'), 'cpu_s')} | "
                     f"{cell(r.get('before'), 'rss_mb', '.0f')} | {same} |")
        lines.append(line)
    by = {r["step"]: r for r in rows}
    if 15.0 in by and 0.5 in by:
        a, b = by[15.0], by[0.5]
        ratio = b["values"] / a["values"]
        ok_t = b["now"]["s"] <= ratio * a["now"]["s"]
        ok_m = b["now"]["rss_mb"] <= a["now"]["rss_mb"] + 300
        cpu = b["now"]["cpu_s"] / a["now"]["cpu_s"]
        lines += ["", f"0.5° against 15°: {ratio:.0f} times the values, {b['now']['s'] / a['now']['s']:.2f} times the "
                      f"wall time ({'PASS' if ok_t else 'MISS'}: within linear), {cpu:.2f} times the CPU, "
                      f"{b['now']['rss_mb'] - a['now']['rss_mb']:+.0f} MB "
                      f"({'PASS' if ok_m else 'MISS'}: within 300 MB of the 15° case)."]
    return lines


def main(argv: list[str] | None = None) -> str:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--quick", action="store_true", help="the two coarsest grids only")
    ap.add_argument("--before", type=Path, help="also time each command with this checkout's pige_sym")
    ap.add_argument("--timeout", type=float, default=600.0, help="for --before's commands [s] (default %(default)s)")
    ap.add_argument("--only", choices=("compensate", "identify"), help="one of the two parts")
    args = ap.parse_args(argv)
    from run import load_average

    load = os.getloadavg()[0]
    load_start = load_average()
    grids = GRIDS[:2] if args.quick else GRIDS
    steps = STEPS[:2] + STEPS[-1:] if args.quick else STEPS
    with tempfile.TemporaryDirectory() as tmp:
        comp = [] if args.only == "identify" else compensate_rows(Path(tmp), grids, args.before, args.timeout)
        ident = [] if args.only == "compensate" else identify_rows(Path(tmp), steps, args.before, args.timeout)
    before = args.before is not None
    lines = ["## Error maps at scale: compensate and identify --map-step (benchmarks/bench_scale_maps.py)", "",
             f"Each command a fresh process (wall time of `main()`, CPU time, peak resident memory); load average "
             f"{load:.1f} on {os.cpu_count()} cores when the run started (a shared machine: CPU times follow the work, "
             "wall times the load)." + (f" Before: the same commands with the pige_sym of `{args.before}`, up to "
                                         f"{args.timeout:g} s." if before else ""), "",
             ]
    if comp:
        lines += ["**pige compensate** (parameter files of `identify --map --json` fits, poses at every grid angle):",
                  "", *_compensate_lines(comp, before, args.timeout), "",
                  "Fitting those files (`identify_maps` in process, every value determined): "
                  + ", ".join(f"{r['values']:,} values {r['fit_s']:.2f} s CPU" for r in comp)
                  + f" (growth exponent {_exponent([r['values'] for r in comp], [r['fit_s'] for r in comp]):.2f}; "
                    "the joint fit's covariance of every determined value is dense, so it is not linear in them).",
                  ""]
    if ident:
        lines += ["**pige identify --map C,A** (docs/maps.md's map test: three probe setups × 48 poses, 30° grid):",
                  "", *_identify_lines(ident, before, args.timeout)]
    lines += ["", run_footer(load_start)]
    text = "\n".join(lines)
    print(text)
    return text


if __name__ == "__main__":
    main()
