"""The fixed text of a generated kernel module: signatures and docstrings, and the functions that are
the same for every machine (``jacobian`` and ``deviation`` on top of ``basis`` and ``coefficients``).

``{K}`` and ``{P}`` in :data:`SPECS` are filled in with the number of basis columns and parameters.
"""

from __future__ import annotations

#: Signature and docstring of every generated function; ``{K}`` and ``{P}`` are filled in.
SPECS: dict[str, str] = {
    "basis": '''def basis(angles_deg):
    """Trigonometric basis, shape=(n, K={K}) [1]; columns named in BASIS."""''',
    "coefficients": '''def coefficients(ball_mm, pivots_mm=None, tool_mm=None):
    """Coefficient tensor G, shape=(K={K}, 3, P={P}) [µm per µm or µrad]: jacobian = basis @ G."""''',
    "reference_jacobian": '''def reference_jacobian(ball_mm, pivots_mm=None, tool_mm=None):
    """Un-zeroed offset Jacobian at the reference pose J_raw(0), shape=(3, P={P}) [µm per µm or µrad].

    The ball-minus-nest offset before zeroing is, at any pose,
    ``(jacobian + workpiece_rotation @ reference_jacobian) @ params``; effects whose
    size changes with the pose (angle-dependent errors) need it.
    """''',
    "motion_jacobian": '''def motion_jacobian(angles_deg, ball_mm, pivots_mm=None, tool_mm=None):
    """Un-zeroed offset per unit error motion, shape=(n, 3, 6k) [µm per µm or µrad].

    Columns MOTION_PARAMETERS: per rotary axis dx, dy, dz [µm] and rx, ry, rz [µrad],
    a small rigid motion of the body the axis carries (carrier frame, rotations about
    the nominal pivot) applied after the axis' own motion.  Zeroing at the reference
    pose is the caller's business (subtract workpiece_rotation @ value at the reference).
    """''',
    "orientation_jacobian": '''def orientation_jacobian(angles_deg):
    """Tool-orientation error Jacobian, shape=(n, 3, P={P}) [µrad per µm or µrad].

    ω = orientation_jacobian @ params is the small rotation of the spindle frame
    relative to the workpiece, expressed in W: R_rel_actual = (I + [ω]x) R_rel_nominal.
    """''',
    "motion_orientation_jacobian": '''def motion_orientation_jacobian(angles_deg):
    """Tool-orientation error per unit error motion, shape=(n, 3, {P}) [µrad per µm or µrad].

    Columns MOTION_PARAMETERS; ω as orientation_jacobian (the spindle frame relative to the workpiece, in W).
    """''',
    "workpiece_rotation": '''def workpiece_rotation(angles_deg):
    """Nominal rotation of the workpiece frame W into M, shape=(n, 3, 3)."""''',
    "tool_rotation": '''def tool_rotation(angles_deg):
    """Nominal rotation of the spindle frame into M, shape=(n, 3, 3)."""''',
    "linear_commands": '''def linear_commands(angles_deg, ball_mm, pivots_mm=None, tool_mm=None):
    """Commanded X, Y, Z (RTCP, nominal kinematics), shape=(n, 3) [mm]; ball_mm at the reference pose."""''',
    "tool_direction": '''def tool_direction(angles_deg):
    """Spindle direction in the workpiece frame W, shape=(n, 3) [unit vectors]."""''',
    "angles_for_direction": '''def angles_for_direction(direction, branch=1, previous_deg=None):
    """Rotary angles that put a workpiece-frame tool direction on the spindle axis.

    Parameters
    ----------
    direction : array, shape=(n, 3)
        Tool direction in the workpiece frame W (normalised here).
    branch : {{+1, -1}}
        Which of the two solutions of the primary (tilting) axis to take.
    previous_deg : array, shape=(k,), optional
        Angles used where the secondary axis is undetermined (singular pose).

    Returns
    -------
    angles_deg : array, shape=(n, k) [deg], secondary axis unwrapped to be continuous.
    """''',
}


LINEAR_FUNCTIONS = '''_G_CACHE = {}


def _geometry_key(ball_mm, pivots_mm, tool_mm):
    """A hashable key of a geometry (None when it cannot be made: then nothing is cached)."""
    try:
        pivots = None if pivots_mm is None else tuple(
            sorted((str(a), tuple(map(float, np.ravel(v)))) for a, v in pivots_mm.items()))
        tool = None if tool_mm is None else tuple(map(float, np.ravel(tool_mm)))
        return tuple(map(float, np.ravel(ball_mm))), pivots, tool
    except (TypeError, ValueError, AttributeError):
        return None


def _coefficients_cached(ball_mm, pivots_mm, tool_mm):
    """``coefficients`` of a geometry seen before, not recomputed (the cached tensor is read-only)."""
    key = _geometry_key(ball_mm, pivots_mm, tool_mm)
    g = None if key is None else _G_CACHE.get(key)
    if g is None:
        g = coefficients(ball_mm, pivots_mm, tool_mm)
        if key is not None:
            g.flags.writeable = False
            if len(_G_CACHE) >= 64:
                _G_CACHE.clear()
            _G_CACHE[key] = g
    return g


def jacobian(angles_deg, params=None, ball_mm=None, pivots_mm=None, tool_mm=None, out=None):
    """Jacobian of the deviation, shape=(n, 3, P) [µm per µm or µrad].

    The first-order model is linear in the parameters, so ``params`` is accepted
    for a uniform signature but does not change the result.  ``out``, a C-contiguous
    float array of shape (n, 3, P), receives the result without a new allocation.
    """
    if ball_mm is None:
        raise ValueError("jacobian needs ball_mm")
    b = basis(angles_deg)
    g = _coefficients_cached(ball_mm, pivots_mm, tool_mm)
    n = b.shape[0]
    if out is None:
        out = np.empty((n, 3, g.shape[2]))
    elif out.shape != (n, 3, g.shape[2]) or not out.flags.c_contiguous:
        raise ValueError(f"out must be a C-contiguous array of shape {(n, 3, g.shape[2])}, got {out.shape}")
    np.matmul(b, g.reshape(g.shape[0], -1), out=out.reshape(n, -1))
    return out


def deviation(angles_deg, params, ball_mm, pivots_mm=None, tool_mm=None):
    """Ball-minus-nest deviation in the machine frame, shape=(n, 3) [µm].

    Parameters
    ----------
    angles_deg : array, shape=(n, k) [deg]
        Commanded rotary angles, columns in ROTARY_AXES order.
    params : array, shape=(P,) or (8,)-like
        Error parameters in PARAMETERS order [µm, µrad]; the location errors alone
        are accepted (zero-position errors then 0).
    ball_mm : array, shape=(3,) [mm]
    pivots_mm : dict axis -> (3,) [mm], optional
    tool_mm : (3,) [mm], required with tool-side rotary axes
    """
    p = _params(params)
    g = _coefficients_cached(ball_mm, pivots_mm, tool_mm)
    return basis(angles_deg) @ (g @ p)'''
