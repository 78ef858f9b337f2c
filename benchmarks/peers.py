"""The tools a user would pick instead of pige's generated kernels, each building the same model itself.

The model: the AC tilting table ``wC'A'bXYZ(C1)t``, the R-test deviation of a ball at ``ball`` when the
C and A axis lines carry the 8 location errors p (CONVENTIONS §2–4).  Each peer writes the *exact* rigid-body
chain (Rodrigues rotations about the erroneous axis lines, as `pige_sym/simulation/exact_table.py` does)
in its own language and takes its Jacobian with respect to p at p = 0, which is exactly the first-order
Jacobian the generated kernel evaluates in closed form:

- JAX: ``jit(vmap(jacfwd(deviation, argnums=1)))`` on CPU, float64;
- CasADi: an SX expression of the chain, ``jacobian`` w.r.t. p, a ``Function`` mapped over N poses
  (``.map(N)``) run in CasADi's virtual machine, and the same function generated as C code and compiled with the
  system C compiler (``-O3``), loaded as an ``external``;
- SymPy: ``lambdify(..., cse=True)`` of the symbolic Jacobian, vectorised over the poses (NumPy arrays in).

Every peer is checked against the generated kernel (relative 1e-9) before it is timed
(``benchmarks/bench_peers.py``; ``tests/test_peers.py`` checks the agreement, skipped without the extra).
"""

from __future__ import annotations

import math
import os
import subprocess
import tempfile
from collections.abc import Callable
from pathlib import Path

import numpy as np

AC = "wC'A'bXYZ(C1)t"
BALL = (120.0, 0.0, 80.0)
NAMES = ("EY0A", "EZ0A", "EB0A", "EC0A", "EX0C", "EY0C", "EA0C", "EB0C")


def _chain(lib: object, cos: Callable, sin: Callable, vec: Callable, a_deg: object, c_deg: object,
           p: object, ball: tuple[float, float, float]) -> list:
    """The un-zeroed deviation (T − P) [µm] of the exact chain, in any array library (list of 3 expressions)."""
    ey_a, ez_a, eb_a, ec_a, ex_c, ey_c, ea_c, eb_c = (p[i] for i in range(8))  # type: ignore[index]

    def rotate(x: list, centre: list, u: list, angle: object) -> list:
        norm = (u[0] * u[0] + u[1] * u[1] + u[2] * u[2]) ** 0.5
        k = [u[0] / norm, u[1] / norm, u[2] / norm]
        v = [x[i] - centre[i] for i in range(3)]
        c, s = cos(angle), sin(angle)
        kv = k[0] * v[0] + k[1] * v[1] + k[2] * v[2]
        cross = [k[1] * v[2] - k[2] * v[1], k[2] * v[0] - k[0] * v[2], k[0] * v[1] - k[1] * v[0]]
        return [centre[i] + v[i] * c + cross[i] * s + k[i] * kv * (1 - c) for i in range(3)]

    a = a_deg * (math.pi / 180.0)  # type: ignore[operator]
    cc = c_deg * (math.pi / 180.0)  # type: ignore[operator]
    q = list(ball)
    # actual table point: C line through (EX0C, EY0C) µm, direction z + (EA0C, EB0C)×z µrad; then A
    x = rotate(q, [ex_c * 1e-3, ey_c * 1e-3, 0.0], [eb_c * 1e-6, -ea_c * 1e-6, 1.0], -cc)
    x = rotate(x, [0.0, ey_a * 1e-3, ez_a * 1e-3], [1.0, ec_a * 1e-6, -eb_a * 1e-6], -a)
    # commanded tool ball: the nominal position of q
    t = rotate(q, [0.0, 0.0, 0.0], [0.0, 0.0, 1.0], -cc)
    t = rotate(t, [0.0, 0.0, 0.0], [1.0, 0.0, 0.0], -a)
    return [(t[i] - x[i]) * 1e3 for i in range(3)]


def kernel_jacobian(angles_deg: np.ndarray) -> np.ndarray:
    """The generated kernel's zeroed Jacobian of the 8 PIGEs, shape=(N, 3, 8)."""
    from pige_sym.kernels import load_kernels

    kern = load_kernels(AC)
    idx = [kern.PARAMETERS.index(n) for n in NAMES]
    return kern.jacobian(angles_deg, None, BALL)[:, :, idx]


def _zeroing(angles_deg: np.ndarray) -> np.ndarray:
    """``R_w(θ)``, shape=(N, 3, 3): the raw Jacobian minus ``R_w·J_raw(0)`` is the zeroed one (CONVENTIONS §4)."""
    a, c = np.radians(angles_deg[:, 0]), np.radians(angles_deg[:, 1])
    ca, sa, cc, sc = np.cos(a), np.sin(a), np.cos(c), np.sin(c)
    rx = np.zeros((a.size, 3, 3))
    rx[:, 0, 0], rx[:, 1, 1], rx[:, 1, 2], rx[:, 2, 1], rx[:, 2, 2] = 1, ca, sa, -sa, ca
    rz = np.zeros((a.size, 3, 3))
    rz[:, 0, 0], rz[:, 0, 1], rz[:, 1, 0], rz[:, 1, 1], rz[:, 2, 2] = cc, sc, -sc, cc, 1
    return rx @ rz


def jax_jacobian() -> Callable[[np.ndarray], np.ndarray]:
    """JAX peer: jit(vmap(jacfwd)) of the chain, zeroed inside the jitted function."""
    import jax

    jax.config.update("jax_enable_x64", True)
    import jax.numpy as jnp

    def raw(a: object, c: object, p: object) -> object:
        return jnp.stack(_chain(jnp, jnp.cos, jnp.sin, jnp.array, a, c, p, BALL))

    jac = jax.jacfwd(raw, argnums=2)
    p0 = jnp.zeros(8)

    @jax.jit
    def batch(angles: object) -> object:
        j = jax.vmap(lambda ac: jac(ac[0], ac[1], p0))(angles)
        j0 = jac(0.0, 0.0, p0)
        a, c = jnp.radians(angles[:, 0]), jnp.radians(angles[:, 1])
        ca, sa, cc, sc = jnp.cos(a), jnp.sin(a), jnp.cos(c), jnp.sin(c)
        zero, one = jnp.zeros_like(a), jnp.ones_like(a)
        rx = jnp.stack([jnp.stack([one, zero, zero], -1), jnp.stack([zero, ca, sa], -1),
                        jnp.stack([zero, -sa, ca], -1)], -2)
        rz = jnp.stack([jnp.stack([cc, sc, zero], -1), jnp.stack([-sc, cc, zero], -1),
                        jnp.stack([zero, zero, one], -1)], -2)
        return j - jnp.einsum("nij,jp->nip", rx @ rz, j0)

    return lambda angles: np.asarray(batch(jnp.asarray(angles)))


def _casadi_function() -> object:
    import casadi as ca

    a, c = ca.SX.sym("a"), ca.SX.sym("c")
    p = ca.SX.sym("p", 8)
    raw = ca.vertcat(*_chain(ca, ca.cos, ca.sin, ca.vertcat, a, c, p, BALL))
    jac = ca.jacobian(raw, p)
    jac = ca.substitute(jac, p, ca.DM.zeros(8))
    return ca.Function("pige_jacobian", [ca.vertcat(a, c)], [ca.reshape(jac, 24, 1)])


def casadi_mapped(mode: str = "vm", n: int = 1) -> tuple[object, np.ndarray]:
    """The CasADi function mapped over ``n`` poses (DM (2, n) in, DM (24, n) out) and the reference J (3, 8)."""
    import casadi as ca

    f = _casadi_function()
    if mode == "c":
        folder = Path(tempfile.mkdtemp(prefix="pige_casadi_"))
        cwd = os.getcwd()
        os.chdir(folder)
        try:
            f.generate("jac_gen.c")  # type: ignore[attr-defined]
        finally:
            os.chdir(cwd)
        subprocess.run(["cc", "-O3", "-fPIC", "-shared", str(folder / "jac_gen.c"), "-o", str(folder / "jac_gen.so")],
                       check=True, capture_output=True)
        f = ca.external("pige_jacobian", str(folder / "jac_gen.so"))
    mapped = f.map(n, "serial")  # type: ignore[attr-defined]
    j0 = f(ca.DM([0.0, 0.0])).full().reshape(8, 3).T  # type: ignore[operator]
    return mapped, j0


def casadi_jacobian(mode: str = "vm", n: int = 1) -> Callable[[np.ndarray], np.ndarray]:
    """CasADi peer mapped over ``n`` poses: ``vm`` (its virtual machine) or ``c`` (generated C, -O3); NumPy in/out."""
    import casadi as ca

    mapped, j0 = casadi_mapped(mode, n)

    def evaluate(angles: np.ndarray) -> np.ndarray:
        out = mapped(ca.DM(angles.T)).full().T.reshape(-1, 8, 3).transpose(0, 2, 1)  # type: ignore[operator]
        return out - np.einsum("nij,jp->nip", _zeroing(angles), j0)

    return evaluate


def lambdify_jacobian() -> Callable[[np.ndarray], np.ndarray]:
    """SymPy peer: ``lambdify(cse=True)`` of the symbolic Jacobian, vectorised over NumPy arrays of poses."""
    import sympy as sp

    a, c = sp.symbols("a c", real=True)
    p = sp.symbols("p0:8", real=True)
    raw = sp.Matrix(_chain(sp, sp.cos, sp.sin, sp.Matrix, a, c, p, BALL))
    jac = raw.jacobian(sp.Matrix(p)).subs({pi: 0 for pi in p})
    entries = [jac[i, j] for i in range(3) for j in range(8)]
    fn = sp.lambdify((a, c), entries, modules="numpy", cse=True)  # a list: constant entries stay scalars
    j0 = np.array(fn(0.0, 0.0), dtype=float).reshape(3, 8)

    def evaluate(angles: np.ndarray) -> np.ndarray:
        out = fn(angles[:, 0], angles[:, 1])
        full = np.empty((angles.shape[0], 24))
        for k, v in enumerate(out):
            full[:, k] = v
        return full.reshape(-1, 3, 8) - np.einsum("nij,jp->nip", _zeroing(angles), j0)

    return evaluate


def random_poses(n: int, seed: int = 0) -> np.ndarray:
    """``n`` poses, shape=(n, 2) [deg] (A in [−90, 90], C in [0, 360))."""
    rng = np.random.default_rng(seed)
    return np.column_stack([rng.uniform(-90, 90, n), rng.uniform(0, 360, n)])
