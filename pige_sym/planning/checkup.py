"""Planning the check-up: the fewest poses that determine the PIGEs that change between runs.

A check-up re-measures a machine between full calibrations (Heidenhain's cycle 452 re-run with the sphere left
clamped).  It starts from the last full calibration in the history (:class:`~pige_sym.measurements.run_setup.RunSetup`:
instrument, sphere or ball, pivots, sense, tool, the probing program's controller state) and estimates only the
*free* PIGEs, by default the axis lines' positions (the location errors in µm: thermal growth moves the axis lines;
it hardly tilts them), holding the others at the last calibration's values
(:mod:`~pige_sym.identification.subset`).

**Candidates.**  Poses inside the range the full calibration measured (so every reach and clearance check it
passed still applies): the axis parallel to the spindle at 0°, 90°, 180°, 270° (or its range's ends and middle
when it does not turn fully), every other axis at its range's ends and halves; the reference pose (all 0) comes
first.  On a probe machine a candidate the stylus cannot reach with the set-up's contacts is left out.

**Prediction.**  The covariance of the free PIGEs with the others known is ``(I_FF)⁻¹``, ``I = JᵀC⁻¹J`` over the
location PIGEs: R-test rows independent with the full calibration's noise; probe rows with each centre's
covariance from its contacts and the reference centre's error shared by every pose (``C = D + S Σ₀ Sᵀ``, as
:mod:`~pige_sym.planning.probe` and the identification).  A set *determines* the free PIGEs when ``I_FF`` has full
rank with no near-null direction (the identification's rules,
:func:`~pige_sym.identification.spectrum.scaled_spectrum`).

**Search.**  For k = 1, 2, … poses after the reference, every k-set of candidates; the first k with a determining
set wins, and of its sets the one with the smallest worst predicted standard error.  A probe check-up then takes
as many contacts per pose (4 to 9) as the budget holds.  Machine time: probe programs are timed from their moves
(:mod:`~pige_sym.nc.probe_timing`); an R-test takes ``move + dwell`` per pose.  A plan that does not fit the budget
is refused with the time it needs.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from pige_sym.errors import InputError
from pige_sym.identification.spectrum import NULL_RTOL, scaled_spectrum
from pige_sym.kernels import load_kernels
from pige_sym.measurements.run_setup import RunSetup, default_free, parse_free  # noqa: F401 - re-exported
from pige_sym.measurements.sphere_fit import contact_weights
from pige_sym.nc.probe_program import ROUNDING_MARGIN_MM, ProbeSetup, plan_probing
from pige_sym.nc.probe_safety import ProbeController
from pige_sym.nc.probe_timing import MachineSpeeds

#: Default machine-time budget of a check-up [s].
DEFAULT_BUDGET_S = 120.0
#: Most poses after the reference a check-up may take.
MAX_POSES = 6
CONTACT_CHOICES = tuple(range(4, 10))


@dataclass
class CheckupPlan:
    """The check-up's poses and what they are predicted to give.

    Attributes
    ----------
    angles_deg : ndarray, shape=(n, k) [deg]
        CONVENTIONS angles, the reference pose first.
    std : dict of str to float
        Predicted standard error of each free PIGE [µm, µrad].
    covariance : ndarray, shape=(F, F)
    seconds : float
        Predicted machine time [s].
    contacts : int or None
        Contacts per pose (probe).
    candidates : int
        Candidate poses the search had.
    """

    machine: str
    instrument: str
    free: list[str]
    held: list[str]
    rotary_axes: tuple[str, ...]
    angles_deg: np.ndarray
    std: dict[str, float]
    covariance: np.ndarray
    seconds: float
    budget_s: float
    contacts: int | None
    candidates: int
    noise_um: float
    notes: list[str] = field(default_factory=list)

    @property
    def worst(self) -> float:
        return max(self.std.values())

    @property
    def poses(self) -> int:
        return int(self.angles_deg.shape[0])

    def signature(self) -> str:
        """The poses as text (the history pools the scatter of check-ups with the same poses and PIGEs)."""
        rows = ";".join(",".join(f"{v:.4f}" for v in row) for row in self.angles_deg)
        return f"{','.join(self.free)}|{rows}"

    def angle_file_text(self, note: str) -> str:
        """The poses as an angle file (``t_s,<axis>_deg``), the reference first (``pige program --trajectory``)."""
        lines = [f"# {note}", ",".join(["t_s", *(f"{a}_deg" for a in self.rotary_axes)])]
        lines += [",".join([repr(float(i)), *(repr(float(v)) for v in row)]) for i, row in enumerate(self.angles_deg)]
        return "\n".join(lines) + "\n"

    def to_dict(self) -> dict[str, Any]:
        from pige_sym.files import json_ready

        return json_ready({"machine": self.machine, "instrument": self.instrument, "free": self.free,
                           "held": self.held, "rotary_axes": list(self.rotary_axes), "angles_deg": self.angles_deg,
                           "std": self.std, "seconds": self.seconds, "budget_s": self.budget_s,
                           "contacts": self.contacts, "candidates": self.candidates, "noise_um": self.noise_um,
                           "signature": self.signature(), "notes": self.notes})


@dataclass(frozen=True)
class CheckupRequest:
    """What a check-up is planned from.

    Attributes
    ----------
    setup : RunSetup
        The last full calibration's set-up.
    free : list of str
    budget_s : float
    noise_um : float
        Probe: contact scatter; R-test: noise per component [µm].
    probe : ProbeSetup or None
        The probing set-up (:func:`probe_setup_of`); None for an R-test.
    speeds : MachineSpeeds
    move_s, dwell_s : float
        R-test schedule per pose [s].
    dialect : str
        The dialect the probe program is timed in (the moves are the same in every one).
    """

    setup: RunSetup
    free: list[str]
    budget_s: float = DEFAULT_BUDGET_S
    noise_um: float = 0.5
    probe: ProbeSetup | None = None
    speeds: MachineSpeeds = field(default_factory=MachineSpeeds)
    move_s: float = 5.0
    dwell_s: float = 7.0
    dialect: str = "linuxcnc"


def probe_setup_of(setup: RunSetup, controller: ProbeController | None = None, **options: Any) -> ProbeSetup:
    """The probing set-up of the last full calibration: its sphere (where it was fitted, to 0.1 µm), radii, pivots,
    sense, tool, and the controller state its program stated (``controller`` replaces it)."""
    from pige_sym.nc.probe_safety import controller_from_header

    if setup.instrument != "sphere-probe" or setup.probe is None:
        raise InputError(f"the last full calibration is an {setup.instrument} run: a probing check-up needs a "
                         "probe calibration (or plan an R-test check-up)")
    probe = setup.probe
    if controller is None:
        items = dict(probe.get("program") or {}) | {"kinematics": str(probe.get("kinematics", "identity"))}
        controller = controller_from_header(items, "the last full calibration's probing program")
    pivots = {a: np.asarray(v, dtype=float) for a, v in setup.pivots_mm.items()}
    same = len({tuple(v) for v in setup.pivots_mm.values()}) <= 1
    single = next(iter(pivots.values())) if pivots else np.zeros(3)
    sphere = np.round(np.asarray(setup.ball_mm, dtype=float), 4)
    radii = [probe.get("sphere_radius_mm"), probe.get("stylus_radius_mm")]
    if not all(isinstance(r, (int, float)) and r > 0 for r in radii):
        raise InputError("the last full calibration does not state the sphere and stylus radii")
    sphere_r, stylus_r = (float(r) for r in radii)  # type: ignore[arg-type]
    return ProbeSetup(setup.machine, sphere, single if same else np.zeros(3), sphere_r, stylus_r,
                      pivots_mm=None if same else pivots, axis_sense=dict(setup.axis_sense), controller=controller,
                      tool_mm=None if setup.tool_mm is None else np.asarray(setup.tool_mm, dtype=float),
                      **options)


def candidate_poses(setup: RunSetup) -> np.ndarray:
    """Candidate poses inside the full calibration's range (module docstring), shape=(c, k) [deg]."""
    kern = load_kernels(setup.machine)
    axes = tuple(kern.ROTARY_AXES)
    values = []
    for a in axes:
        lo, hi = setup.angle_range_deg.get(a, [0.0, 0.0])
        if "ABC".index(a[0]) == kern.SPINDLE_DIRECTION and hi - lo >= 269.0:
            vals = [v for v in (0.0, 90.0, 180.0, 270.0) if lo - 1e-9 <= v <= hi + 1e-9]
        else:
            vals = [lo, hi, lo / 2, hi / 2, (lo + hi) / 2]
        values.append(sorted({round(v, 4) for v in [0.0, *vals]}))
    grid = np.array(list(itertools.product(*values)), dtype=float)
    return grid[np.abs(grid).max(axis=1) > 1e-9]


@dataclass
class _Blocks:
    """Per candidate pose: J (3, P) [µm per unit], the noise Σ (3, 3) [µm²], R (3, 3); and the reference's Σ₀."""

    poses: np.ndarray
    jac: np.ndarray
    cov: np.ndarray
    rot: np.ndarray
    cov0: np.ndarray


def _rtest_blocks(req: CheckupRequest, poses: np.ndarray) -> _Blocks:
    kern = load_kernels(req.setup.machine)
    idx = [kern.PARAMETERS.index(n) for n in kern.LOCATION_PARAMETERS]
    pivots = {a: np.asarray(v) for a, v in req.setup.pivots_mm.items()} or None
    tool = None if req.setup.tool_mm is None else np.asarray(req.setup.tool_mm)
    g = kern.coefficients(np.asarray(req.setup.ball_mm), pivots, tool)[:, :, idx]
    jac = (kern.basis(poses) @ g.reshape(g.shape[0], -1)).reshape(len(poses), 3, len(idx))
    eye = np.tile(np.eye(3) * req.noise_um**2, (len(poses), 1, 1))
    return _Blocks(poses, jac, eye, np.tile(np.eye(3), (len(poses), 1, 1)), np.zeros((3, 3)))


def _probe_block(setup: ProbeSetup, pose: np.ndarray, sigma: float) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """(J (2, 3, P), Σ (2, 3, 3), R (2, 3, 3)) of the reference and one pose; None when the stylus cannot reach it."""
    from pige_sym.errors import PigeError

    kern = load_kernels(setup.machine)
    try:
        plan = plan_probing(setup, np.vstack([np.zeros_like(pose), pose]))
    except PigeError:
        return None
    idx = [kern.PARAMETERS.index(n) for n in kern.LOCATION_PARAMETERS]
    pivots = dict(setup.pivots) if setup.pivots_mm is not None else {a: setup.pivot_mm for a in kern.ROTARY_AXES}
    jac = kern.jacobian(plan.angles_deg, None, setup.sphere_mm, pivots, setup.tool_mm)[:, :, idx]
    normals = []
    for centre, contacts in zip(plan.centres_mm, plan.contacts, strict=True):
        g = np.array([c.target - c.direction * (setup.overtravel_mm + ROUNDING_MARGIN_MM) - centre for c in contacts])
        normals.append(g / np.linalg.norm(g, axis=1, keepdims=True))
    weights = contact_weights(normals, "axes", plan.frames)
    covs = np.array([np.linalg.inv((g * w[:, None]).T @ g) * sigma**2 for g, w in zip(normals, weights, strict=True)])
    return jac, covs, kern.workpiece_rotation(plan.angles_deg)


def _probe_blocks(req: CheckupRequest, poses: np.ndarray, setup: ProbeSetup) -> _Blocks:
    kept, jac, cov, rot = [], [], [], []
    cov0 = np.zeros((3, 3))
    for pose in poses:
        block = _probe_block(setup, pose, req.noise_um)
        if block is None:
            continue
        kept.append(pose)
        jac.append(block[0][1])
        cov.append(block[1][1])
        rot.append(block[2][1])
        cov0 = block[1][0]
    if not kept:
        return _Blocks(np.zeros((0, poses.shape[1])), np.zeros((0, 3, 0)), np.zeros((0, 3, 3)), np.zeros((0, 3, 3)),
                       cov0)
    return _Blocks(np.array(kept), np.array(jac), np.array(cov), np.array(rot), cov0)


def predicted_covariance(blocks: _Blocks, chosen: Sequence[int], free: list[int]) -> np.ndarray | None:
    """Covariance of the free PIGEs (F, F) from the chosen candidates, the others known; None when undetermined."""
    k = len(chosen)
    jac = blocks.jac[list(chosen)].reshape(3 * k, -1)
    full = np.zeros((3 * k, 3 * k))
    for i, c in enumerate(chosen):
        full[3 * i:3 * i + 3, 3 * i:3 * i + 3] = blocks.cov[c]
    stack = blocks.rot[list(chosen)].reshape(3 * k, 3)
    full += stack @ blocks.cov0 @ stack.T
    info = jac.T @ np.linalg.solve(full, jac)
    sub = info[np.ix_(free, free)]
    diag = np.sqrt(np.clip(np.diag(sub), 0.0, None))
    if (diag <= 0).any():
        return None
    spec = scaled_spectrum(sub / np.outer(diag, diag))
    if spec.rank < len(free) or spec.near_null.any() or spec.svals[-1] <= math.sqrt(NULL_RTOL) * spec.smax:
        return None
    return np.asarray(np.linalg.inv(sub))


def _search(blocks: _Blocks, free: list[int]) -> tuple[tuple[int, ...], np.ndarray] | None:
    """The fewest candidates determining the free PIGEs, best worst std among them (module docstring)."""
    n = blocks.poses.shape[0]
    for k in range(1, min(MAX_POSES, n) + 1):
        best: tuple[float, tuple[int, ...], np.ndarray] | None = None
        for chosen in itertools.combinations(range(n), k):
            cov = predicted_covariance(blocks, chosen, free)
            if cov is None:
                continue
            worst = float(np.sqrt(np.diag(cov)).max())
            if best is None or worst < best[0] - 1e-12:
                best = (worst, chosen, cov)
        if best is not None:
            return best[1], best[2]
    return None


def plan_checkup(req: CheckupRequest) -> CheckupPlan:
    """The check-up of the request (module docstring).

    Raises
    ------
    InputError
        No candidate set determines the free PIGEs, or the fewest poses do not fit the budget (says how long they
        take).
    """
    if not (math.isfinite(req.budget_s) and req.budget_s > 0):
        raise InputError("--budget must be a positive number of seconds")
    kern = load_kernels(req.setup.machine)
    names = list(kern.LOCATION_PARAMETERS)
    free_idx = [names.index(n) for n in req.free]
    poses = candidate_poses(req.setup)
    if req.setup.instrument == "sphere-probe":
        if req.probe is None:
            raise InputError("a probe check-up needs the probing set-up")
        blocks = _probe_blocks(req, poses, req.probe)
    else:
        blocks = _rtest_blocks(req, poses)
    found = _search(blocks, free_idx) if blocks.poses.shape[0] else None
    if found is None:
        raise InputError(f"no set of up to {MAX_POSES} poses inside the last full calibration's range "
                         f"({_ranges(req.setup)}) determines {', '.join(req.free)} with the others held: choose "
                         "other PIGEs (--pige) or calibrate fully")
    chosen, cov = found
    angles = np.vstack([np.zeros((1, len(kern.ROTARY_AXES))), blocks.poses[list(chosen)]])
    held = [n for n in names if n not in req.free]
    if req.probe is None:
        seconds = (len(angles) - 1) * (req.move_s + req.dwell_s) + req.dwell_s
        return _finish(req, kern, held, angles, cov, seconds, None, len(poses))
    return _probe_contacts(req, kern, held, angles, free_idx, len(poses))


def _probe_contacts(req: CheckupRequest, kern: Any, held: list[str], angles: np.ndarray, free_idx: list[int],
                    candidates: int) -> CheckupPlan:
    """The most contacts per pose (4 to 9) the budget holds for the chosen poses; refused when even 4 do not fit."""
    assert req.probe is not None
    timed = []
    for k in CONTACT_CHOICES:
        setup = replace(req.probe, contacts=k)
        blocks = _probe_blocks(req, angles[1:], setup)
        if blocks.poses.shape[0] != len(angles) - 1:
            continue  # a pose the stand hides with this many contacts
        cov = predicted_covariance(blocks, range(len(angles) - 1), free_idx)
        if cov is not None:
            timed.append((probe_seconds(setup, angles, req.dialect, req.speeds), k, cov))
    if not timed:
        raise InputError("the stylus cannot reach the check-up's poses with 4 to 9 contacts")
    fits = [t for t in timed if t[0] <= req.budget_s]
    if not fits:
        need = min(t[0] for t in timed)
        raise InputError(f"the fewest poses that determine {', '.join(req.free)} ({len(angles)} with the reference) "
                         f"take {need:.0f} s of machine time at the least, more than --budget {req.budget_s:g} s: "
                         "give a larger budget or fewer PIGEs (--pige)")
    seconds, k, cov = min(fits, key=lambda t: (float(np.sqrt(np.diag(t[2])).max()), t[0]))
    return _finish(req, kern, held, angles, cov, seconds, k, candidates)


def probe_seconds(setup: ProbeSetup, angles: np.ndarray, dialect: str, speeds: MachineSpeeds) -> float:
    """Machine time of the probing program of ``angles`` [s] (:mod:`~pige_sym.nc.probe_timing`)."""
    from pige_sym.nc.probe_render import render_probe_program
    from pige_sym.nc.probe_timing import program_seconds

    plan = plan_probing(setup, angles, "check-up")
    text = render_probe_program(plan, dialect)
    return program_seconds(text, dialect, setup, plan.rotary_axes, speeds).seconds


def _finish(req: CheckupRequest, kern: Any, held: list[str], angles: np.ndarray, cov: np.ndarray, seconds: float,
            contacts: int | None, candidates: int) -> CheckupPlan:
    std = {n: float(np.sqrt(cov[i, i])) for i, n in enumerate(req.free)}
    notes = [] if seconds <= req.budget_s else [f"the R-test check-up takes {seconds:.0f} s, more than the budget "
                                                f"{req.budget_s:g} s (move {req.move_s:g} s + dwell {req.dwell_s:g} s "
                                                "per pose): shorten the dwell or give a larger budget"]
    if notes and req.probe is None:
        raise InputError(notes[0])
    return CheckupPlan(kern.MACHINE_CODE, req.setup.instrument, list(req.free), held, tuple(kern.ROTARY_AXES), angles,
                       std, cov, float(seconds), req.budget_s, contacts, candidates, req.noise_um, notes)


def _ranges(setup: RunSetup) -> str:
    return ", ".join(f"{a} {lo:g}..{hi:g} deg" for a, (lo, hi) in setup.angle_range_deg.items())
