"""Input checks shared by every generated kernel module, kept here as real, linted code.

:func:`pige_sym.codegen.emit.render_module` copies the source of everything below the
``# --- copied into every kernel module ---`` marker into each generated module, where
``ROTARY_AXES``, ``MACHINE_CODE``, ``TOOL_ROTARY``, ``PARAMETERS``, ``LOCATION_PARAMETERS``
and ``ZERO_PARAMETERS`` are that machine's constants.  The placeholders above the marker
only let linters and type checkers read this file; they are never copied.
"""

from __future__ import annotations

from typing import Any

import numpy as np

MACHINE_CODE = ""
ROTARY_AXES: tuple[str, ...] = ()
TOOL_ROTARY: tuple[str, ...] = ()
PARAMETERS: tuple[str, ...] = ()
LOCATION_PARAMETERS: tuple[str, ...] = ()
ZERO_PARAMETERS: tuple[str, ...] = ()

# --- copied into every kernel module ---


def _angles(angles_deg: Any) -> np.ndarray:
    """Rotary angles as an ``(n, k)`` float array [deg] in ROTARY_AXES order."""
    a = np.asarray(angles_deg, dtype=float)
    if a.ndim == 1 and len(ROTARY_AXES) == 1:
        a = a[:, None]
    if a.ndim == 1 and a.shape[0] == len(ROTARY_AXES):
        a = a[None, :]
    if a.ndim != 2 or a.shape[1] != len(ROTARY_AXES):
        raise ValueError(
            f"angles_deg must have shape (n, {len(ROTARY_AXES)}) with columns {ROTARY_AXES}, got {a.shape}"
        )
    return a


def _cos_sin(angles_deg: Any) -> tuple[np.ndarray, np.ndarray]:
    """Cosine and sine of every rotary angle, each ``(k, n)``: evaluated once per call."""
    th = np.array(_angles(angles_deg).T, order="C")  # always a copy: the caller's angles stay untouched
    th *= np.pi / 180.0
    return np.cos(th), np.sin(th)


def _vec3(v: Any, name: str) -> np.ndarray:
    """A 3-vector [mm]."""
    a = np.asarray(v, dtype=float).reshape(-1)
    if a.shape != (3,):
        raise ValueError(f"{name} must be 3 numbers [mm], got shape {a.shape}")
    return a


def _pivots(pivots_mm: Any) -> dict[str, np.ndarray]:
    """Nominal pivot of every rotary axis [mm]; axes not given are at the origin."""
    out = {ax: np.zeros(3) for ax in ROTARY_AXES}
    for key, value in (pivots_mm or {}).items():
        if key not in out:
            raise ValueError(f"pivots_mm: {key!r} is not a rotary axis of {MACHINE_CODE} (axes: {ROTARY_AXES})")
        out[key] = _vec3(value, f"pivots_mm[{key!r}]")
    return out


def _tool(tool_mm: Any) -> np.ndarray:
    """Tool tip in the spindle frame [mm]; required when the tool side carries a rotary axis."""
    if tool_mm is None:
        if TOOL_ROTARY:
            raise ValueError(f"{MACHINE_CODE} has tool-side rotary axes {TOOL_ROTARY}: give tool_mm")
        return np.zeros(3)
    return _vec3(tool_mm, "tool_mm")


def _params(params: Any) -> np.ndarray:
    """All PARAMETERS [µm, µrad]; the location errors alone are padded with zero-position zeros."""
    p = np.asarray(params, dtype=float).reshape(-1)
    if p.shape[0] == len(LOCATION_PARAMETERS):
        p = np.concatenate([p, np.zeros(len(ZERO_PARAMETERS))])
    if p.shape[0] != len(PARAMETERS):
        raise ValueError(
            f"params must hold {len(LOCATION_PARAMETERS)} location errors or all {len(PARAMETERS)} "
            f"parameters in the order {PARAMETERS}, got {p.shape[0]}"
        )
    return p
