"""Plausibility of a probe import: numbers no one should believe are refused where they arise, naming the flag.

A wrong pivot, sphere position, unit, stylus offset or radius is the likeliest set-up mistake with a probe, and
each still yields sphere centres and deviations; identify would then print axis errors of millimetres.  The
import checks, in this order, and refuses with the file, the line and the option to check:

1. **Options** (:func:`check_options`): ``--stylus-offset`` within ±:data:`MAX_STYLUS_OFFSET_MM`.
2. **Repeated contacts** (:func:`check_repeated_contacts`): a contact whose X Y Z and angles repeat another of
   its own pose exactly (to the last written digit), or a pose repeating an earlier one contact for contact.
   The contacts of one pose probe different directions and LinuxCNC writes no line for a trip at the previous
   position, so it is a duplicated line: it would count a contact twice and shrink the contact σ.  Poses
   repeated at the same angles (drift measurements) are not compared contact by contact: a probing axis
   written to 0.1 µm (Heidenhain) can repeat a value.
   **A contact far from its pose** (:func:`check_far_contacts`): a contact farther from the middle of its pose's
   contacts (their coordinate-wise median) than any point of the sphere can be, ``(1 + √3)(R + r)`` plus
   :data:`FAR_MARGIN_MM`, while most of the pose's contacts are within it: that line is wrong (a mistyped or
   wrongly logged contact), not the pattern the pose was probed with.
3. **Poses** (:func:`check_pose_count`): the reference pose and enough others that identify can fit the
   machine's location errors (``3(n − 1) > P``), not a file identify then calls "no data rows".
4. **Contacts on a sphere** (:func:`check_contact_sigma`): the contacts' robust scatter about their own poses'
   spheres below :data:`MAX_CONTACT_SIGMA_UM` (a touch probe repeats to about a micrometre).
5. **The radius** (:func:`check_radius`): the fitted ``R_eff`` against ``R + r`` (a pre-travel is micrometres:
   more than :data:`RADIUS_TOLERANCE_MM` off is a wrong ``--sphere-radius``/``--stylus-radius`` or ``--units``);
   a given ``--radius`` against the radius the contacts lie on (the fit with a free radius, made first: a fit with a
   radius far from the data's has no meaning): off by more than the faulty-contact limit, the option is wrong, not
   the pose.
   Then the import's screen of faulty contacts (one pose off its own sphere: "re-probe the pose").
6. **The reference centre** (:func:`check_reference`): with the program's sphere position (``--program`` or
   ``--sphere``), the fitted ``c(0)`` within :data:`REFERENCE_TOLERANCE_MM` of it (``--sphere``, ``--units``,
   ``--stylus-offset``, the work offset).
7. **Deviations** (:func:`check_deviations`): every pose's centre within :data:`MAX_DEVIATION_UM` of where the
   nominal motion of ``c(0)`` puts it; beyond, the nominal motion is wrong (``--pivot``, ``--axis-sense``,
   ``--kinematics``, ``--units``, ``--stylus-offset``, ``--tool``), not the machine.

Finally the file is written through a temporary file that pige's own reader reads back
(:func:`~pige_sym.measurements.probe_import.verify_written`) before it replaces anything, so import-probe never
writes a file identify refuses.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from pige_sym.errors import FileFormatError, InputError

#: Largest ``|R_eff − (R + r)|`` [mm]: pre-travel and lobing are micrometres to a few tens of micrometres.
RADIUS_TOLERANCE_MM = 0.1
#: Largest distance of the reference pose's centre from the program's sphere position [mm].
REFERENCE_TOLERANCE_MM = 0.5
#: Largest pooled contact scatter [µm] (robust): contacts beyond it lie on no sphere.
MAX_CONTACT_SIGMA_UM = 20.0
#: Largest deviation of a centre from its nominal motion [µm]: 1 mm is far beyond a running machine's axis errors.
MAX_DEVIATION_UM = 1000.0
#: Largest ``--stylus-offset`` [mm]: the stylus centre is a stylus radius or so from the controlled point.
MAX_STYLUS_OFFSET_MM = 100.0
#: Added to the farthest a contact of a pose can lie from the middle of the others [mm] (set-up, pre-travel).
FAR_MARGIN_MM = 1.0
SETUP_FLAGS = "--pivot, --axis-sense, --kinematics, --units, --stylus-offset and --tool"


def check_options(stylus_offset_mm: float) -> None:
    """Refuse option values no set-up has (one-line InputError)."""
    if abs(stylus_offset_mm) > MAX_STYLUS_OFFSET_MM:
        raise InputError(f"--stylus-offset {stylus_offset_mm:g} mm: the stylus centre sits about a stylus radius "
                         f"above the controlled point (at most ±{MAX_STYLUS_OFFSET_MM:g} mm); give it in mm")


def check_repeated_contacts(path: str, xyz_mm: np.ndarray, angles_deg: np.ndarray, lines: np.ndarray,
                            starts: np.ndarray) -> None:
    """Refuse duplicated log lines (module docstring, 2): a contact equal to another of its own pose (two contacts
    of one pose probe different directions), or a whole pose equal, contact for contact, to an earlier one (a
    block pasted twice).  Two poses at the same angles (a repeated pose, a drift measurement) may share a
    coordinate or even a contact to the written digit; they are not compared contact by contact.

    Parameters
    ----------
    xyz_mm : (N, 3), angles_deg : (N, k), lines : (N,)
        The contacts as read, their 1-based lines.
    starts : (n + 1,)
        Where each pose begins (:func:`~pige_sym.measurements.probe_log.pose_starts`).
    """
    key = np.column_stack([xyz_mm, angles_deg])
    if len(key) < 2:
        return
    pose = np.repeat(np.arange(len(starts) - 1), np.diff(starts))
    order = np.lexsort((*key.T[::-1], pose))  # by pose, then by the contact's numbers
    same = (key[order[1:]] == key[order[:-1]]).all(axis=1) & (pose[order[1:]] == pose[order[:-1]])
    found = [tuple(sorted(p)) for p in np.column_stack([order[:-1][same], order[1:][same]])]
    found += _repeated_poses(key, starts)
    if found:
        first, repeat = min(found, key=lambda p: p[1])
        raise FileFormatError(path, int(lines[repeat]), f"this contact repeats line {int(lines[first])} exactly "
                              "(X Y Z and angles to the last digit): a duplicated log line (a probe never trips "
                              "twice at the same point; LinuxCNC writes no line for a trip at the previous "
                              "position); remove it")


def _repeated_poses(key: np.ndarray, starts: np.ndarray) -> list[tuple[int, int]]:
    """(first contact, its repeat) of poses equal contact for contact to an earlier pose of as many contacts."""
    counts = np.diff(starts)
    out = []
    for c in np.unique(counts):
        poses = np.flatnonzero(counts == c)
        rows = starts[poses][:, None] + np.arange(c)
        blocks = np.ascontiguousarray(key[rows].reshape(len(poses), -1))
        _, first, inverse = np.unique(blocks.view(np.dtype((np.void, blocks.dtype.itemsize * blocks.shape[1]))),
                                      return_index=True, return_inverse=True)
        again = np.flatnonzero(first[inverse.reshape(-1)] != np.arange(len(poses)))
        out += [(int(starts[poses[first[inverse.reshape(-1)[i]]]]), int(starts[poses[i]])) for i in again[:1]]
    return out


def check_pose_count(path: str, poses: int, parameters: int, first_line: int) -> None:
    """Refuse a log too short for identify to fit ``parameters`` location errors (module docstring, 2)."""
    need = parameters // 3 + 2  # 3(n − 1) > P
    if poses < need:
        raise FileFormatError(path, first_line, f"the log holds {poses} pose{'s' if poses != 1 else ''}"
                              f"{' (the reference only)' if poses == 1 else ''}: identify needs the reference pose "
                              f"and at least {need - 1} more to fit the {parameters} location errors; probe more poses")


def check_far_contacts(path: str, pts: np.ndarray, starts: np.ndarray, lines: np.ndarray, nominal_mm: float) -> None:
    """Refuse a lone contact no sphere of radius ``nominal_mm`` (R + r) could hold with the others (module
    docstring, 2).

    The coordinate-wise median of a pose's contacts lies in the cube around the sphere, so every contact on the
    sphere is within ``(1 + √3)(R + r)`` of it.  Only contacts that are a minority of their pose are named: when
    most are beyond, the set-up is wrong (``--units``, the radii), which the radius check names.

    Parameters
    ----------
    pts : ndarray, shape=(N, 3) [mm]
        The stylus-tip centres of the contacts, pose by pose (``starts``).
    lines : ndarray, shape=(N,) of int
        Each contact's line in the log.
    """
    counts = np.diff(starts)
    pose = np.repeat(np.arange(counts.size), counts)
    middle = starts[:-1] + (counts - 1) // 2
    median = np.empty((counts.size, 3))
    for k in range(3):  # a pose's contacts sorted by coordinate k, poses in order: the middle one is its median
        median[:, k] = pts[np.lexsort((pts[:, k], pose))[middle], k]
    dist = np.linalg.norm(pts - median[pose], axis=1)
    reach = (1.0 + np.sqrt(3.0)) * nominal_mm + FAR_MARGIN_MM
    far = ~(dist <= reach)
    lone = far & (2 * np.bincount(pose, weights=far, minlength=counts.size)[pose] < counts[pose])
    if lone.any():
        i = int(np.flatnonzero(lone)[0])
        first, last = int(starts[pose[i]]), int(starts[pose[i] + 1]) - 1
        raise FileFormatError(path, int(lines[i]), f"this contact lies {dist[i]:.1f} mm from the middle of its pose's "
                              f"contacts (lines {lines[first]}-{lines[last]}), farther than a sphere of R + r = "
                              f"{nominal_mm:g} mm lets it ({reach:.1f} mm): a mistyped or wrongly logged contact; "
                              "re-probe the pose")


def check_radius(path: str, line: int, data_radius_mm: float, given_mm: float | None, nominal_mm: float,
                 limit_um: float) -> None:
    """Refuse an effective radius that cannot be the set-up's (module docstring, 5).

    Parameters
    ----------
    data_radius_mm : float
        The radius the contacts lie on (the fit with a free radius).
    given_mm : float or None
        ``--radius`` when given.
    nominal_mm : float
        ``R + r`` from ``--sphere-radius`` and ``--stylus-radius``.
    limit_um : float
        The faulty-contact limit [µm].
    """
    if given_mm is not None and not abs(data_radius_mm - given_mm) * 1e3 <= limit_um:
        raise FileFormatError(path, line, f"--radius {given_mm:g} mm, but the contacts lie on a sphere of "
                              f"{data_radius_mm:.4f} mm ({(data_radius_mm - given_mm) * 1e3:+.1f} um): check --radius "
                              "(the calibrated R + r - pre-travel), or leave it out to fit it")
    if abs(data_radius_mm - nominal_mm) > RADIUS_TOLERANCE_MM:
        which = "--radius" if given_mm is not None and abs(given_mm - nominal_mm) > RADIUS_TOLERANCE_MM else \
            "--sphere-radius and --stylus-radius"
        raise FileFormatError(path, line, f"the contacts lie on a sphere of radius {data_radius_mm:.4f} mm, but "
                              f"--sphere-radius + --stylus-radius = {nominal_mm:g} mm (a pre-travel is micrometres): "
                              f"check {which}, and --units (an inch log read as mm, or the reverse, scales it by "
                              "25.4)")


def check_reference(path: str, line: int, centre0_mm: np.ndarray, sphere_mm: Any, source: str) -> None:
    """Refuse a reference centre millimetres from where the program put the sphere (module docstring, 4)."""
    if sphere_mm is None:
        return
    off = float(np.linalg.norm(np.asarray(centre0_mm) - np.asarray(sphere_mm)))
    if off > REFERENCE_TOLERANCE_MM:
        c = ", ".join(f"{v:.3f}" for v in centre0_mm)
        s = ", ".join(f"{v:g}" for v in sphere_mm)
        raise FileFormatError(path, line, f"the reference pose's sphere centre is at {c} mm, {off:.3f} mm from "
                              f"{s} where {source} puts it: check {source}, --units, --stylus-offset and the work "
                              "offset the log was written in")


def check_contact_sigma(path: str, sigma_um: float) -> None:
    """Refuse contacts that lie on no sphere (module docstring, 5)."""
    if sigma_um > MAX_CONTACT_SIGMA_UM:
        raise FileFormatError(path, None, f"the contacts scatter {sigma_um:.1f} um about their poses' spheres (a touch "
                              f"probe repeats to about 1 um; limit {MAX_CONTACT_SIGMA_UM:g} um): they lie on no "
                              "sphere; check --format, --units and that the log holds one sphere's probing")


def check_deviations(path: str, deviation_um: np.ndarray, lines: np.ndarray) -> None:
    """Refuse centres millimetres from the nominal motion of ``c(0)`` (module docstring, 6).

    ``lines`` holds each pose's first log line.
    """
    size = np.linalg.norm(deviation_um, axis=1)
    worst = int(np.argmax(size))
    if size[worst] > MAX_DEVIATION_UM:
        raise FileFormatError(path, int(lines[worst]), f"this pose's sphere centre is {size[worst] / 1e3:.3f} mm from "
                              f"where the nominal motion of the reference centre puts it (a machine's axis errors "
                              f"move it micrometres; limit {MAX_DEVIATION_UM / 1e3:g} mm): the nominal motion is "
                              f"wrong; check {SETUP_FLAGS}")
