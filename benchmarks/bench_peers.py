"""Benchmark against the tools a user would pick instead: JAX, CasADi (VM and compiled C), lambdify with CSE.

Every peer builds the AC table's model itself (``benchmarks/peers.py``: the exact chain, its Jacobian at
p = 0) and is checked equal to the generated kernel (relative 1e-9) before it is timed.  In one run, at
N = 30, 10³, 10⁵, 10⁶ poses: the Jacobian J(θ) (N, 3, 8) steady state (median of repeats) and the first call
(trace/compile/generate) apart; a floor that contains the irreducible work (the cos/sin of both angles and
writing J into a preallocated array), measured beside it; and a whole Gauss–Newton identification (J, the
normal equations, the solve; pige: ``identify`` on a measurement in memory).  Targets: the generated kernel
≥ 3× faster than the fastest peer's steady state at every N, and ≤ 2× the floor at 10⁶.

Run ``python benchmarks/bench_peers.py``; prints a markdown section (peers missing: rows say skipped).
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

import peers  # noqa: E402
from timing import median_seconds  # noqa: E402

SIZES = (30, 1_000, 100_000, 1_000_000)



def _reps(n: int) -> int:
    return 50 if n <= 1000 else 7 if n <= 100_000 else 3


def _builders() -> dict[str, Callable[[int], Callable[[np.ndarray], np.ndarray]]]:
    out: dict[str, Callable[[int], Callable[[np.ndarray], np.ndarray]]] = {}
    try:
        import jax  # noqa: F401

        jitted = peers.jax_jacobian()
        out["JAX jit(vmap(jacfwd)), CPU"] = lambda n: jitted
    except ImportError:
        pass
    try:
        import casadi  # noqa: F401

        out["CasADi SX, VM, .map(N)"] = lambda n: peers.casadi_jacobian("vm", n)
        out["CasADi SX, generated C -O3, .map(N)"] = lambda n: peers.casadi_jacobian("c", n)
    except ImportError:
        pass
    lam = peers.lambdify_jacobian()
    out["sympy.lambdify(cse=True)"] = lambda n: lam
    return out


def _floor(angles: np.ndarray, out: np.ndarray) -> None:
    a, c = np.radians(angles[:, 0]), np.radians(angles[:, 1])
    np.cos(a)
    np.sin(a)
    np.cos(c)
    np.sin(c)
    out.fill(1.0)


def _gauss_newton(jac: Callable[[np.ndarray], np.ndarray], angles: np.ndarray, y: np.ndarray) -> np.ndarray:
    a = jac(angles)[1:].reshape(-1, 8)
    return np.linalg.solve(a.T @ a, a.T @ y)


def jacobian_rows() -> list[tuple[str, int, float, float, str]]:
    """(peer, N, steady s, first call s, note) rows; the generated kernel and the floor first."""
    from pige_sym.kernels import load_kernels

    kern = load_kernels(peers.AC)
    rows = []
    builders = _builders()
    missing = [m for m, mod in (("JAX", "jax"), ("CasADi", "casadi")) if not _has(mod)]
    for n in SIZES:
        ang = peers.random_poses(n, 1)
        ang[0] = 0.0
        ref = peers.kernel_jacobian(ang)
        out = np.empty((n, 3, 10))
        floor_out = np.empty((n, 3, 8))
        floor_out.fill(0.0)
        rows.append(("floor: cos/sin + write J", n, median_seconds(lambda a=ang, o=floor_out: _floor(a, o), _reps(n)),
                     float("nan"), ""))
        rows.append(("pige generated kernel (out=)", n,
                     median_seconds(lambda a=ang, o=out: kern.jacobian(a, None, peers.BALL, out=o), _reps(n)),
                     float("nan"),
                     "10 columns (8 PIGEs + 2 zero errors)"))
        for name, build in builders.items():
            t0 = time.perf_counter()
            fn = build(n)
            got = fn(ang)
            first = time.perf_counter() - t0
            err = float(np.abs(got - ref).max() / np.abs(ref).max())
            if err > 1e-9:
                rows.append((name, n, float("nan"), first, f"DISAGREES with the kernel (rel {err:.1e}): not timed"))
                continue
            rows.append((name, n, median_seconds(lambda f=fn, a=ang: f(a), _reps(n)), first, f"agrees to {err:.0e}"))
            if name.startswith("CasADi"):
                import casadi as ca

                mapped, _ = peers.casadi_mapped("c" if "C -O3" in name else "vm", n)
                dm = ca.DM(ang.T)
                rows.append((name.replace(".map(N)", ".map(N), evaluation only (DM in/out)"), n,
                             median_seconds(lambda f=mapped, x=dm: f(x), _reps(n)), float("nan"),
                             "no NumPy conversion, no zeroing: CasADi's own speed"))
    for m in missing:
        rows.append((m, 0, float("nan"), float("nan"), "skipped: not installed (pip install '.[bench]')"))
    return rows


def _has(module: str) -> bool:
    import importlib.util

    return importlib.util.find_spec(module) is not None


def identification_rows() -> list[tuple[str, int, float]]:
    """(who, N, seconds) of a whole Gauss–Newton identification."""
    from pige_sym.identification.least_squares import identify
    from pige_sym.measurements.measurement import Measurement

    rows = []
    truth = np.array([3.0, -4.0, 10.0, -6.0, 5.0, 2.0, -8.0, 7.0])
    builders = _builders()
    for n in SIZES:
        ang = peers.random_poses(n, 2)
        ang[0] = 0.0
        dev = np.einsum("nip,p->ni", peers.kernel_jacobian(ang), truth)
        m = Measurement(machine=peers.AC, ball_mm=np.array(peers.BALL), t_s=np.arange(n, dtype=float),
                        angles_deg=ang, deviation_um=dev, rotary_axes=("A", "C"))
        rows.append(("pige identify", n, median_seconds(lambda mm=m: identify(mm), 3 if n > 1000 else 20)))
        y = dev[1:].reshape(-1)
        for name, build in builders.items():
            fn = build(n)
            fn(ang)
            repeats = 3 if n > 1000 else 20
            rows.append((name, n, median_seconds(lambda f=fn, a=ang, yy=y: _gauss_newton(f, a, yy), repeats)))
    return rows


def main() -> None:
    jac = jacobian_rows()
    ident = identification_rows()
    print("## Peers: JAX, CasADi, lambdify with CSE (benchmarks/bench_peers.py)\n")
    print("Every peer builds the AC table's chain itself and agrees with the generated kernel before it is timed.\n")
    print("| J(θ) | N | steady [ms] | × kernel | first call [s] | note |")
    print("|---|---:|---:|---:|---:|---|")
    kernel = {n: t for who, n, t, _, _ in jac if who.startswith("pige")}
    for who, n, t, first, note in jac:
        ratio = f"{t / kernel[n]:.1f}" if n in kernel and np.isfinite(t) else ""
        print(f"| {who} | {n:,} | {t * 1e3:.3f} | {ratio} | {'' if not np.isfinite(first) else f'{first:.3f}'} | "
              f"{note} |")
    print("\n| Gauss–Newton identification | N | time [ms] | × pige |")
    print("|---|---:|---:|---:|")
    ours = {n: t for who, n, t in ident if who == "pige identify"}
    for who, n, t in ident:
        print(f"| {who} | {n:,} | {t * 1e3:.3f} | {t / ours[n]:.1f} |")
    print("\nTargets:")
    for n in SIZES:
        peers_t = [t for who, m, t, _, _ in jac if m == n and not who.startswith(("pige", "floor")) and np.isfinite(t)
                   and "evaluation only" not in who]
        if peers_t:
            r = min(peers_t) / kernel[n]
            print(f"- N={n:,}: kernel ≥ 3× faster than the fastest peer: {'PASS' if r >= 3 else 'MISS'} ({r:.1f}×)")
    floor = {n: t for who, n, t, _, _ in jac if who.startswith("floor")}
    big = SIZES[-1]
    r = kernel[big] / floor[big]
    print(f"- N={big:,}: kernel ≤ 2× the floor (cos/sin + write J): {'PASS' if r <= 2 else 'MISS'} ({r:.1f}×)")


if __name__ == "__main__":
    main()
