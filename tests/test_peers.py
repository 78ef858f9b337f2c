"""The benchmark's peers (JAX, CasADi, lambdify with CSE) build the same model as the generated kernel.

Skipped without the ``bench`` extra (``pip install '.[bench]'``, which ``make bench`` installs).
"""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import peers  # noqa: E402


def _poses() -> np.ndarray:
    ang = peers.random_poses(40, 7)
    ang[0] = 0.0
    return ang


def test_lambdify_agrees_with_the_kernel() -> None:
    ang = _poses()
    np.testing.assert_allclose(peers.lambdify_jacobian()(ang), peers.kernel_jacobian(ang), rtol=1e-9, atol=1e-12)


@pytest.mark.skipif(importlib.util.find_spec("jax") is None, reason="JAX not installed (pip install '.[bench]')")
def test_jax_agrees_with_the_kernel() -> None:
    ang = _poses()
    np.testing.assert_allclose(peers.jax_jacobian()(ang), peers.kernel_jacobian(ang), rtol=1e-9, atol=1e-12)


@pytest.mark.skipif(importlib.util.find_spec("casadi") is None, reason="CasADi not installed (pip install '.[bench]')")
@pytest.mark.parametrize("mode", ["vm", "c"])
def test_casadi_agrees_with_the_kernel(mode) -> None:
    import shutil

    if mode == "c" and shutil.which("cc") is None:
        pytest.skip("no C compiler")
    ang = _poses()
    got = peers.casadi_jacobian(mode, len(ang))(ang)
    np.testing.assert_allclose(got, peers.kernel_jacobian(ang), rtol=1e-9, atol=1e-12)
