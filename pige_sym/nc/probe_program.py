"""Sphere-probing programs: visit each pose, touch the calibration sphere k times, log every contact.

Geometry (machine frame, mm; CONVENTIONS §7)
-------------------------------------------
The sphere's nominal centre at a pose is ``c(θ) = pivot + R_w(θ)·(sphere − pivot)`` (the nominal
workpiece-side rotation of the kernels); ``R_eff = R + r`` is the stylus-centre radius.  Contacts are
probed along machine axes, what every controller's basic probing cycle does: one from above (−Z onto the
top) and rings of horizontal probes (±X, ±Y) at elevations ε above the centre (the contact normal is
``cos ε·u + sin ε·z``).  A contact whose normal points within ``stand_cone_deg`` of the sphere's stand
(the table's −z, turned with the table) is left out; a pose needs at least four contacts.  Pattern
``fixed`` uses the rings in the order given at every pose; ``alternate`` starts pose ``i`` at ring
``i mod rings`` (with the default rings: the 15° ring, then the 50° ring, …), so a trigger radius that
depends on the probing direction shifts the centres by different amounts from pose to pose and the
diagnosis can see it (docs/probe.md §5); with one pattern it is indistinguishable from axis-line offsets.

Every probing move starts ``clearance`` outside the ``R_eff`` sphere and its target lies ``overtravel``
(plus ``ROUNDING_MARGIN_MM`` for the written decimals) inside it (so the probe trips; a probe that does
not trip stops LinuxCNC's G38.2 with an error and raises an alarm on Fanuc and Siemens, checked after the
move).  Between contacts the probe goes up to the
pose's clearance plane ``c_z + R_eff + clearance``, horizontally over the next start, then straight
down to it (a vertical line outside the ``R_eff + clearance`` circle of every height above the contact
cannot meet the sphere); before the rotary axes move it retracts to ``safe_z``, which must be above every
pose's clearance plane.  RTCP is off: X Y Z are machine-axis coordinates (work offset such that the
coordinates are those of ``--sphere`` and ``--pivot``), the tool length set to the stylus centre.

Head and mixed machines (CONVENTIONS §7): the contacts turn with the head.  Every direction above is read
in the pose's stylus frame ``R_t(θ)`` (:mod:`pige_sym.measurements.probe_head`): one contact along the stylus
axis from the spindle side, the rings around it, each probing move along the stylus axis or across it; the
clearance plane is normal to the stylus axis, ``R_eff + clearance`` from the centre, and the probe comes to
every start along the stylus axis from the point over it on that plane (:attr:`Contact.above`).  The program
writes the linear axes, every stylus-centre point minus ``h(θ) = (R_t − I)·tool``.  The sphere's stem and
the table are checked against the stylus (:mod:`pige_sym.nc.probe_reach`): a contact the stylus cannot
reach is left out with the reason, a pose whose stylus points below the table plane or with fewer than four
reachable contacts is refused.  ``safe_z`` allows for the stylus' swing about the head's pivot.

Dialects and their logs (read by :mod:`pige_sym.measurements.probe_log`)
-----------------------------------------------------------------------
``linuxcnc``: ``G38.2``, log by ``(PROBEOPEN pige_probe.txt)`` … ``(PROBECLOSE)``;
``fanuc``: ``G31`` and ``DPRNT`` of the skip position ``#5061–#5063`` between ``POPEN``/``PCLOS``;
``siemens``: ``MEAS=1`` and ``WRITE`` of ``$AA_MW`` to the file ``PIGE_PROBE``;
``heidenhain``: ``TCH PROBE 0`` (reference plane) and ``FN 16: F-PRINT`` with the format file written
beside the program (:func:`heidenhain_format_file`).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from pige_sym.errors import InputError
from pige_sym.kernels import load_kernels
from pige_sym.measurements.measurement import missing_tool
from pige_sym.measurements.probe_head import head_offsets
from pige_sym.nc.probe_reach import Stem, blocked, refusal, stylus_elevation_deg
from pige_sym.nc.probe_safety import ProbeController

#: A nominal pivot: one intersection of the axis lines (3,) [mm], or one per axis.
Pivots = np.ndarray | Mapping[str, np.ndarray]
HEIDENHAIN_LOG = "TNC:\\PIGE\\PROBE.TXT"
HEIDENHAIN_FORMAT = "TNC:\\PIGE\\PROBE.A"


@dataclass(frozen=True)
class ProbeSetup:
    """What a probing program is planned from.

    Attributes
    ----------
    machine : str
    sphere_mm : ndarray, shape=(3,) [mm]
        Nominal sphere centre at the reference pose (all angles 0), program coordinates.
    pivot_mm : ndarray, shape=(3,) [mm]
        Nominal intersection of the rotary axis lines, program coordinates.
    sphere_radius_mm, stylus_radius_mm : float [mm]
    clearance_mm : float [mm]
        Start of each probing move outside the ``R + r`` sphere.
    overtravel_mm : float [mm]
        How far inside the sphere each probing move's target lies.
    elevations_deg : tuple of float [deg]
        Elevations of the rings of horizontal contacts.
    contacts : int
        Contacts per pose (4–9): the top, then the rings' ±X, ±Y in order.
    stand_cone_deg : float [deg]
        Half-angle around the stand direction where no contact is placed.
    safe_z_mm : float or None [mm]
        Retract height before rotary moves (default: 20 mm above the highest clearance plane).
    feed_mm_min, probe_feed_mm_min : float [mm/min]
    pattern : {"fixed", "alternate"}
        The same contact pattern at every pose, or the rings taken in turn (module docstring).
    pivots_mm : dict of str to ndarray, shape=(3,) [mm], optional
        Nominal pivot of each rotary axis, program coordinates (the lines of a LinuxCNC trt configuration do
        not meet); None: every axis line through ``pivot_mm``.
    axis_sense : dict of str to int
        Axes the controller commands in the reverse of CONVENTIONS' sense (CONVENTIONS §9): the plan is in
        θ, the program and its log hold θ_cmd = σ·θ.
    controller : ProbeController
        What the program sets and checks on the controller: kinematics, stylus tool, work offset and the
        window of the confirming first contacts (:mod:`pige_sym.nc.probe_safety`).
    tool_mm : ndarray, shape=(3,) [mm], or None
        Head and mixed machines: the stylus centre from the last tool-side pivot at the reference pose
        (CONVENTIONS §7); the contacts turn with the head.
    stem : Stem
        The sphere's stem and the stylus shank checked against it (:mod:`pige_sym.nc.probe_reach`).
    checkup : tuple of str
        A check-up program (``pige program --checkup``): the PIGEs it re-measures, stated in the header so that the
        import expects only as many poses as they need; empty for a full calibration.
    machine_id : str or None
        The shop's name of the machine (check-ups), stated in the header; ``pige checkup`` refuses another one.
    """

    machine: str
    sphere_mm: np.ndarray
    pivot_mm: np.ndarray
    sphere_radius_mm: float
    stylus_radius_mm: float
    clearance_mm: float = 3.0
    overtravel_mm: float = 1.0
    elevations_deg: tuple[float, ...] = (15.0, 50.0)
    contacts: int = 5
    stand_cone_deg: float = 60.0
    safe_z_mm: float | None = None
    feed_mm_min: float = 2000.0
    probe_feed_mm_min: float = 100.0
    pattern: str = "fixed"
    pivots_mm: Mapping[str, np.ndarray] | None = None
    axis_sense: Mapping[str, int] = field(default_factory=dict)
    controller: ProbeController = field(default_factory=ProbeController)
    tool_mm: np.ndarray | None = None
    stem: Stem = field(default_factory=Stem)
    checkup: tuple[str, ...] = ()
    machine_id: str | None = None

    @property
    def r_eff_mm(self) -> float:
        return self.sphere_radius_mm + self.stylus_radius_mm

    @property
    def pivots(self) -> Pivots:
        """The nominal pivots: per axis (``pivots_mm``) or the one intersection ``pivot_mm``."""
        if self.pivots_mm is None:
            return np.asarray(self.pivot_mm, dtype=float)
        return {a: np.asarray(v, dtype=float) for a, v in self.pivots_mm.items()}


@dataclass
class Contact:
    """One probing move of the stylus centre, machine frame [mm]: from ``start`` to ``target``.

    ``above`` is the point over the start on the pose's clearance plane (normal to the stylus axis), where the
    probe comes from and returns to.  ``axis`` and ``sign``: the stylus-frame axis the move runs along (the
    machine axis on a table machine).
    """

    start: np.ndarray
    target: np.ndarray
    axis: str  # "X", "Y" or "Z"
    sign: int  # direction of the move along it
    above: np.ndarray | None = None

    @property
    def direction(self) -> np.ndarray:
        """Unit vector of the probing move."""
        d = self.target - self.start
        return np.asarray(d / np.linalg.norm(d))


@dataclass
class ProbePlan:
    """Poses and their contacts.

    Attributes
    ----------
    setup : ProbeSetup
    rotary_axes : tuple of str
    angles_deg : ndarray, shape=(n, k) [deg]
    centres_mm : ndarray, shape=(n, 3) [mm]
        Nominal sphere centre at each pose.
    contacts : list of list of Contact
    clear_z_mm : ndarray, shape=(n,) [mm]
        Clearance plane of each pose (on a head: the height of its sphere's top plus the clearance).
    safe_z_mm : float [mm]
        Retract height before rotary moves, in the program's coordinates (the linear axes).
    description : str
    head_mm : ndarray, shape=(n, 3) [mm]
        How the head moves the stylus centre, ``(R_t − I)·tool`` (zero on a table machine): the program
        writes every point minus it (:mod:`pige_sym.measurements.probe_head`).
    frames : ndarray, shape=(n, 3, 3), or None
        The stylus frame of every pose on a head machine.
    """

    setup: ProbeSetup
    rotary_axes: tuple[str, ...]
    angles_deg: np.ndarray
    centres_mm: np.ndarray
    contacts: list[list[Contact]]
    clear_z_mm: np.ndarray
    safe_z_mm: float
    description: str
    head_mm: np.ndarray | None = None
    frames: np.ndarray | None = None


def nominal_centres(machine: str, angles_deg: np.ndarray, sphere_mm: np.ndarray, pivot_mm: Pivots) -> np.ndarray:
    """Nominal sphere centre at each pose, shape=(n, 3) [mm].

    ``pivot + R_w(θ)(sphere − pivot)`` for one pivot (an array); with a pivot per axis (a dict) each
    workpiece-side axis turns the point about its own line, which is the kernels' RTCP command of a
    tool point at the sphere (``linear_commands``, table machines).  ``angles_deg`` are θ (CONVENTIONS).
    """
    kern = load_kernels(machine)
    angles = np.atleast_2d(np.asarray(angles_deg, dtype=float))
    sphere = np.asarray(sphere_mm, dtype=float)
    if isinstance(pivot_mm, Mapping):
        return np.asarray(kern.linear_commands(angles, sphere, dict(pivot_mm) or None, None))
    rot = kern.workpiece_rotation(angles)
    return pivot_mm + np.einsum("nij,j->ni", rot, sphere - pivot_mm)


def table_frames(machine: str, angles_deg: np.ndarray, pivots: Pivots) -> tuple[np.ndarray, np.ndarray]:
    """The nominal table motion ``x ↦ R x + t`` of every pose: where the controller's TCP kinematics put a
    work-coordinate point, R shape=(n, 3, 3), t shape=(n, 3) [mm]; ``angles_deg`` θ, shape=(n, k) [deg]."""
    angles = np.atleast_2d(np.asarray(angles_deg, dtype=float))
    t = nominal_centres(machine, angles, np.zeros(3), pivots)
    cols = [nominal_centres(machine, angles, np.eye(3)[k], pivots) - t for k in range(3)]
    return np.stack(cols, axis=2), t


PATTERNS = ("fixed", "alternate")
#: Extra overtravel so that the program as written (coordinates and angles to 4 decimals) still ends every
#: probing move the stated overtravel past the surface: on the 50° ring a z rounding moves the crossing by
#: tan 50° times itself, and an angle rounding moves the centre (up to 3e-4 mm together at 200 poses).
ROUNDING_MARGIN_MM = 0.002


def _candidates(setup: ProbeSetup, pose: int) -> list[tuple[np.ndarray, str, int]]:
    """(contact normal, move axis, move sign) in contact order at pose number ``pose``."""
    out = [(np.array([0.0, 0.0, 1.0]), "Z", -1)]
    rings = list(setup.elevations_deg)
    if setup.pattern == "alternate":
        k = pose % len(rings)
        rings = rings[k:] + rings[:k]
    for elev in rings:
        e = np.radians(elev)
        for axis, sign in (("X", 1), ("Y", 1), ("X", -1), ("Y", -1)):
            u = np.zeros(3)
            u["XY".index(axis)] = sign
            out.append((np.cos(e) * u + np.sin(e) * np.array([0.0, 0.0, 1.0]), axis, -sign))
    return out


def _pose_contacts(setup: ProbeSetup, centre: np.ndarray, stand: np.ndarray, frame: np.ndarray,
                   pose: int) -> tuple[list[Contact], dict[str, int]]:
    """The reachable contacts of a pose (stylus frame ``frame``) and how many candidates were left out why."""
    r = setup.r_eff_mm
    limit = np.cos(np.radians(setup.stand_cone_deg))
    k = frame[:, 2]
    out, hidden = [], {"stand": 0, "stem": 0, "table": 0}
    for local, axis, sign in _candidates(setup, pose):
        normal = frame @ local
        if normal @ stand > limit:
            hidden["stand"] += 1
            continue
        contact = centre + r * normal
        move = frame[:, "XYZ".index(axis)] * sign
        start = contact - move * setup.clearance_mm
        target = contact + move * (setup.overtravel_mm + ROUNDING_MARGIN_MM)
        above = start + k * (k @ (centre - start) + r + setup.clearance_mm)
        why = blocked([above, start, target], k, centre, stand, setup.stem, setup.sphere_radius_mm,
                      setup.stylus_radius_mm)
        if why:
            hidden[why] += 1
            continue
        out.append(Contact(start, target, axis, sign, above))
        if len(out) == setup.contacts:
            break
    return out, hidden


def plan_probing(setup: ProbeSetup, angles_deg: np.ndarray, description: str = "") -> ProbePlan:
    """Contacts of every pose, clearance planes and the safe height (module docstring).

    Raises
    ------
    InputError
        Bad geometry, fewer than four reachable contacts at a pose, or ``safe_z`` too low.
    """
    kern = load_kernels(setup.machine)
    why = missing_tool(kern.MACHINE_CODE, setup.tool_mm)
    if why:
        raise InputError(why + " (the stylus turns with the head)")
    if setup.tool_mm is not None and not kern.TOOL_ROTARY:
        raise InputError(f"--tool: {kern.MACHINE_CODE} has no tool-side rotary axis; leave --tool out")
    if kern.TOOL_ROTARY and (setup.pivots_mm is not None or setup.controller.kinematics == "tcp"):
        raise InputError(f"{kern.MACHINE_CODE}: a head is probed with one --pivot x,y,z (the axis lines meet) and "
                         "RTCP off (identity kinematics)")
    setup.stem.check(setup.sphere_radius_mm)
    if not (0 < setup.sphere_radius_mm <= 100 and 0 < setup.stylus_radius_mm <= 20):
        raise InputError("--sphere-radius must be in (0, 100] mm and --stylus-radius in (0, 20] mm")
    if not 4 <= setup.contacts <= 1 + 4 * len(setup.elevations_deg):
        raise InputError(f"--contacts {setup.contacts}: give 4 to {1 + 4 * len(setup.elevations_deg)}")
    if setup.pattern not in PATTERNS or (setup.pattern == "alternate" and len(setup.elevations_deg) < 2):
        raise InputError(f"--pattern {setup.pattern}: use fixed, or alternate with two rings of contacts or more")
    if not (0 < setup.clearance_mm <= 50 and 0 < setup.overtravel_mm < setup.r_eff_mm):
        raise InputError("--clearance must be in (0, 50] mm and --overtravel in (0, R + r) mm")
    angles = np.atleast_2d(np.asarray(angles_deg, dtype=float))
    centres = nominal_centres(setup.machine, angles, setup.sphere_mm, setup.pivots)
    stands = np.einsum("nij,j->ni", kern.workpiece_rotation(angles), setup.stem.unit())
    head, frames = head_offsets(kern, angles, setup.tool_mm)
    axes = np.tile(np.eye(3), (len(angles), 1, 1)) if frames is None else frames
    contacts = []
    for i, (c, s, frame) in enumerate(zip(centres, stands, axes, strict=True)):
        ang = ", ".join(f"{a}={v:g}" for a, v in zip(kern.ROTARY_AXES, angles[i], strict=True))
        elevation = stylus_elevation_deg(frame[:, 2], s)
        if elevation < -1e-6:
            raise InputError(f"pose {i} ({ang} deg): the stylus axis points {-elevation:.1f} deg towards the "
                             "sphere's stem side (past the plane the stem stands on, the table): the probe would come "
                             "from below the sphere and meet the stem or the table; leave this pose out (or tilt "
                             "less)")
        cs, hidden = _pose_contacts(setup, c, s, frame, i)
        if len(cs) < 4:
            raise InputError(f"pose {i} ({ang} deg): only {len(cs)} contacts can be reached away from the sphere's "
                             f"stand and stem ({refusal(hidden)}); a sphere centre needs 4 (leave this pose out, or "
                             "lower --stand-cone)")
        contacts.append(cs)
    return _finish_plan(setup, kern, angles, centres, contacts, head, frames, description)


def _finish_plan(setup: ProbeSetup, kern: Any, angles: np.ndarray, centres: np.ndarray, contacts: list[list[Contact]],
                 head: np.ndarray, frames: np.ndarray | None, description: str) -> ProbePlan:
    """Clearance planes and the safe height of the plan (module docstring)."""
    clear = centres[:, 2] + setup.r_eff_mm + setup.clearance_mm
    highest = max(float(clear.max()), max(float(c.above[2]) for cs in contacts for c in cs if c.above is not None))
    # a head swings the stylus centre about its pivot: at the program's Z the centre is at least this much lower
    slack = 0.0 if setup.tool_mm is None else max(0.0, float(np.linalg.norm(setup.tool_mm) + setup.tool_mm[2]))
    needed = highest + slack
    safe = needed + 20.0 if setup.safe_z_mm is None else float(setup.safe_z_mm)
    if safe < needed:
        raise InputError(f"--safe-z {safe:g} mm is below {needed:.3f} mm, the clearance plane of a pose (with the "
                         "stylus' swing on a head): the rotary axes would turn the sphere into the probe")
    return ProbePlan(setup, tuple(kern.ROTARY_AXES), angles, centres, contacts, clear, safe, description,
                     head, frames)
