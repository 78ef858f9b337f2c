"""NumPy's eigen-solver as another processor and BLAS could answer it: the tests of outputs that must not depend on
the processor (issue 46) run pige with it.

Another processor returns, for the same data, a normal matrix that differs in its last bits and, from it, any basis
of each eigenspace: signs are arbitrary, and the eigenvectors of a cluster of equal eigenvalues (a null space) any
rotation of one another.  :func:`answer_eigh` plays that: it adds symmetric noise of 1e-12 relative to the largest
entry of the matrix it is given, flips each eigenvector's sign at random, and turns the eigenvectors of every cluster
of eigenvalues within 1e-10 of the largest of each other by a random rotation.  ``np.linalg.eigh`` is the one
eigen-solver pige's null spaces come from.

- :func:`another_processor`: a context manager, in-process;
- :func:`install`: for good, e.g. in every Python a test starts: ``tests/processor_site/sitecustomize.py`` calls it
  when ``PIGE_TEST_PROCESSOR_SEED`` is set and that folder is on ``PYTHONPATH``.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

import numpy as np

NOISE = 1e-12  # relative to the largest entry of the matrix
CLUSTER = 1e-10  # eigenvalues closer than this (relative to the largest) are one eigenspace


def answer_eigh(real: Callable[..., Any], rng: np.random.Generator) -> Callable[..., tuple[np.ndarray, np.ndarray]]:
    """An ``eigh`` that answers as another processor could (module docstring), built on the ``real`` one."""

    def eigh(a: Any, UPLO: str = "L") -> tuple[np.ndarray, np.ndarray]:  # noqa: N803 (NumPy's name)
        a = np.asarray(a, dtype=float)
        if a.ndim != 2:  # a stack (the held-out folds): each as one matrix
            pairs = [eigh(m, UPLO) for m in a.reshape(-1, *a.shape[-2:])]
            return (np.array([w for w, _ in pairs]).reshape(a.shape[:-1]),
                    np.array([v for _, v in pairs]).reshape(a.shape))
        noise = rng.standard_normal(a.shape)
        w, v = real(a + NOISE * float(np.abs(a).max(initial=0.0)) * (noise + noise.T) / 2, UPLO)
        v = v * rng.choice([-1.0, 1.0], size=w.size)
        tol = CLUSTER * max(float(np.abs(w).max(initial=0.0)), 1e-300)
        start = 0
        for end in range(1, w.size + 1):
            if end == w.size or w[end] - w[end - 1] > tol:
                if end - start > 1:
                    turn, _ = np.linalg.qr(rng.standard_normal((end - start, end - start)))
                    v[:, start:end] = v[:, start:end] @ turn
                start = end
        return w, v

    return eigh


@contextmanager
def another_processor(seed: int) -> Iterator[None]:
    """``np.linalg.eigh`` answering as another processor (module docstring) within the block."""
    real = np.linalg.eigh
    np.linalg.eigh = answer_eigh(real, np.random.default_rng(seed))  # type: ignore[assignment]
    try:
        yield
    finally:
        np.linalg.eigh = real


def install(seed: int) -> None:
    """``np.linalg.eigh`` answering as another processor (module docstring) from now on."""
    np.linalg.eigh = answer_eigh(np.linalg.eigh, np.random.default_rng(seed))  # type: ignore[assignment]
