"""The stylus on a head (CONVENTIONS §7, "Head and mixed machines"): where the head puts it, how it is turned.

With identity kinematics (RTCP off) the controller commands and logs the linear axes: ``X`` is where the
stylus-tip centre would be with the head at its reference pose.  At the pose ``θ`` the nominal tip centre is
``X + h(θ)`` with

    ``h(θ) = T_nom(θ)(b0) − b0 = (R_t(θ) − I)·tool``   [mm]

``b0 = p_last + tool`` the tip centre on the spindle body, ``tool`` its offset from the nominal pivot of the last
tool-side axis at the reference pose (the R-test's ``--tool``), and ``R_t`` the nominal tool rotation; the rotary
axis lines meet at one pivot, so the head's own position drops out.  The *stylus frame* of a pose is ``R_t(θ)``:
its z axis is the spindle axis (pointing from the tip towards the spindle), and the probing directions of a
head turn with it.  On a table machine ``h = 0`` and the stylus frame is the machine frame.
"""

from __future__ import annotations

from typing import Any

import numpy as np


def stylus_frames(kern: Any, angles_deg: np.ndarray) -> np.ndarray | None:
    """The stylus frame of every pose, ``R_t(θ)``, shape=(n, 3, 3); None on a table machine (the machine frame)."""
    if not kern.TOOL_ROTARY:
        return None
    return np.asarray(kern.tool_rotation(np.atleast_2d(angles_deg)), dtype=float)


def head_offsets(kern: Any, angles_deg: np.ndarray, tool_mm: Any) -> tuple[np.ndarray, np.ndarray | None]:
    """How the head moves the stylus centre, ``h(θ) = (R_t(θ) − I)·tool`` [mm], and the stylus frames.

    Returns
    -------
    head_mm : ndarray, shape=(n, 3) [mm]
        Zero on a table machine.
    stylus_rotations : ndarray, shape=(n, 3, 3), or None
        :func:`stylus_frames`.
    """
    angles = np.atleast_2d(np.asarray(angles_deg, dtype=float))
    frames = stylus_frames(kern, angles)
    if frames is None:
        return np.zeros((len(angles), 3)), None
    tool = np.asarray(tool_mm, dtype=float)
    return frames @ tool - tool, frames
