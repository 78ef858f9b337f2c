"""Planning a touch-probe test: how many poses and how many contacts per pose for a probing-time budget.

The predicted covariance of the PIGEs is that of the identification (:mod:`pige_sym.identification.instruments`):
generalised least squares on ``Cov(d_i, d_j) = δ_ij Σ_i + R_i Σ₀ R_jᵀ``, with each pose's centre
covariance ``Σ_i = σ_c² (G_iᵀW_iG_i)⁻¹`` from the contact normals the program will use
(:func:`pige_sym.nc.probe_program.plan_probing`), their weights for probing moves along the stylus-frame axes
(:func:`pige_sym.measurements.sphere_fit.contact_weights`, what ``pige import-probe`` uses) and the contact
scatter σ_c.  On a head or mixed machine the contacts turn with the head and the Jacobian takes the tool.
A test of ``n`` poses and ``k`` contacts takes ``n·(pose_s + k·contact_s)`` seconds; :func:`plan_probe` tries
cone frustums of 6 to 60 poses and 4 to 9 contacts within the budget and keeps the smallest worst predicted
standard error (µm or µrad).
:func:`coupling_study` shows what the reference pose's coupling costs: the standard errors with it and
those an analysis that ignored it would claim.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from pige_sym.errors import InputError
from pige_sym.kernels import load_kernels
from pige_sym.measurements.sphere_fit import contact_weights
from pige_sym.model.trajectories import make_trajectory
from pige_sym.nc.probe_program import ROUNDING_MARGIN_MM, ProbePlan, ProbeSetup, plan_probing

POSE_COUNTS = (6, 8, 12, 16, 24, 32, 45, 60)


@dataclass
class ProbePrediction:
    """Predicted standard errors of one probe test [µm or µrad] and its probing time [s]."""

    poses: int
    contacts: int
    seconds: float
    std: dict[str, float]
    std_ignoring_coupling: dict[str, float]
    angles_deg: np.ndarray
    machine: str = ""

    @property
    def worst(self) -> float:
        return max(self.std.values())


def predict_probe(setup: ProbeSetup, angles_deg: np.ndarray, *, contact_sigma_um: float = 0.5,
                  pose_s: float = 20.0, contact_s: float = 8.0) -> ProbePrediction:
    """Predicted standard errors of the PIGEs of a probe test (module docstring)."""
    kern = load_kernels(setup.machine)
    plan = plan_probing(setup, angles_deg)
    names = list(kern.LOCATION_PARAMETERS)
    idx = [kern.PARAMETERS.index(n) for n in names]
    ball = setup.sphere_mm - setup.pivot_mm
    jac = kern.jacobian(plan.angles_deg, None, ball, None, setup.tool_mm)[1:, :, idx].reshape(-1, len(names))
    covs = centre_covariances(plan, contact_sigma_um)
    rot = kern.workpiece_rotation(plan.angles_deg)[1:].reshape(-1, 3)
    diag = np.zeros((jac.shape[0], jac.shape[0]))
    for i, c in enumerate(covs[1:]):
        diag[3 * i:3 * i + 3, 3 * i:3 * i + 3] = c
    full = diag + rot @ covs[0] @ rot.T
    std = np.sqrt(np.diag(np.linalg.pinv(jac.T @ np.linalg.solve(full, jac))))
    naive = np.sqrt(np.diag(np.linalg.pinv(jac.T @ np.linalg.solve(diag, jac))))
    n, k = plan.angles_deg.shape[0], len(plan.contacts[0])
    return ProbePrediction(n, k, n * (pose_s + k * contact_s), dict(zip(names, std.tolist(), strict=True)),
                           dict(zip(names, naive.tolist(), strict=True)), plan.angles_deg, kern.MACHINE_CODE)


def centre_covariances(plan: ProbePlan, contact_sigma_um: float) -> list[np.ndarray]:
    """Each pose's centre covariance ``σ_c² (GᵀWG)⁻¹`` from its planned contacts, shape (3, 3) each [µm²]
    (module docstring: the normals and weights ``pige import-probe`` uses)."""
    s = plan.setup
    normals = []
    for centre, contacts in zip(plan.centres_mm, plan.contacts, strict=True):
        g = np.array([c.target - c.direction * (s.overtravel_mm + ROUNDING_MARGIN_MM) - centre for c in contacts])
        normals.append(g / np.linalg.norm(g, axis=1, keepdims=True))
    weights = contact_weights(normals, "axes", plan.frames)
    return [np.linalg.inv((g * w[:, None]).T @ g) * contact_sigma_um**2 for g, w in zip(normals, weights, strict=True)]


def plan_probe(setup: ProbeSetup, *, budget_s: float, contact_sigma_um: float = 0.5, pose_s: float = 20.0,
               contact_s: float = 8.0) -> tuple[ProbePrediction, list[ProbePrediction]]:
    """The best cone frustum and contact count within the budget, and every candidate that fits it."""
    if not budget_s > 0:
        raise InputError("--budget must be a positive number of seconds")
    tried = []
    for n in POSE_COUNTS:
        for k in range(4, 10):
            if n * (pose_s + k * contact_s) > budget_s:
                continue
            angles = make_trajectory(setup.machine, "cone-frustum", points=n - 1).angles_deg
            try:
                tried.append(predict_probe(replace(setup, contacts=k), angles, contact_sigma_um=contact_sigma_um,
                                           pose_s=pose_s, contact_s=contact_s))
            except InputError:
                continue  # a pose the stand hides with this many contacts
    if not tried:
        raise InputError(f"no probe test fits in {budget_s:g} s ({pose_s:g} s per pose, {contact_s:g} s per contact, "
                         f"at least {POSE_COUNTS[0]} poses of 4 contacts): give a larger --budget")
    return min(tried, key=lambda p: p.worst), tried


def coupling_study(pred: ProbePrediction) -> str:
    """Text: per PIGE the standard error with the reference pose's coupling and the one ignoring it would claim."""
    lines = [f"probe test: {pred.poses} poses, {pred.contacts} contacts each, {pred.seconds / 60:.1f} min of probing",
             "", f"{'PIGE':<8}{'std with coupling':>20}{'ignoring it':>14}{'ratio':>8}"]
    for n, s in pred.std.items():
        naive = pred.std_ignoring_coupling[n]
        lines.append(f"{n:<8}{s:>20.3f}{naive:>14.3f}{s / naive:>8.2f}")
    table = bool(load_kernels(pred.machine).WORKPIECE_ROTARY) if pred.machine else True
    how = ("turned by the table ((I - R_i) dc0 looks like an axis-line offset)" if table else
           "unchanged (no table axis: c_nom = c(0), the same error in every row)")
    lines += ["", f"the reference pose's centre enters every pose {how}: an analysis that treated the poses as "
              "independent would claim the 'ignoring it' column; pige identify reports the first."]
    return "\n".join(lines)


def angle_file_text(pred: ProbePrediction, axes: tuple[str, ...], note: str) -> str:
    """The planned poses as an angle file (``t_s,<axis>_deg``; ``pige program --trajectory`` reads it)."""
    lines = [f"# {note}", ",".join(["t_s", *(f"{a}_deg" for a in axes)])]
    for i, row in enumerate(pred.angles_deg):
        lines.append(",".join([repr(float(i)), *(repr(float(v)) for v in row)]))
    return "\n".join(lines) + "\n"


TILTS_DEG = (15.0, 30.0, 45.0, 60.0, 90.0)


def tilt_grid(machine: str, tilt_deg: float, steps: int = 12) -> np.ndarray:
    """Reference pose, then the tilt axis at a third, two thirds and all of ``tilt_deg``, each at ``steps`` positions
    of the axis parallel to the spindle: shape (1 + 3·steps, 2) [deg]."""
    kern = load_kernels(machine)
    axes = tuple(kern.ROTARY_AXES)
    rotary = [i for i, a in enumerate(axes) if "ABC".index(a[0]) == kern.SPINDLE_DIRECTION]
    if len(axes) != 2 or len(rotary) != 1:
        raise InputError(f"{kern.MACHINE_CODE}: the tilt study needs a tilt axis and an axis parallel to the spindle")
    rot, tilt = rotary[0], 1 - rotary[0]
    out = [np.zeros(2)]
    for t in (tilt_deg / 3, 2 * tilt_deg / 3, tilt_deg):
        for c in np.arange(steps) * 360.0 / steps:
            row = np.zeros(2)
            row[tilt], row[rot] = t, c
            out.append(row)
    return np.array(out)


def tilt_study(setup: ProbeSetup, tilts_deg: tuple[float, ...] = TILTS_DEG, *,
               contact_sigma_um: float = 0.5) -> list[tuple[float, ProbePrediction | str]]:
    """Per largest tilt, the predicted standard errors of a 37-pose test (:func:`tilt_grid`), or why it is refused."""
    out: list[tuple[float, ProbePrediction | str]] = []
    for t in tilts_deg:
        try:
            out.append((t, predict_probe(setup, tilt_grid(setup.machine, t), contact_sigma_um=contact_sigma_um)))
        except InputError as exc:
            out.append((t, str(exc)))
    return out


def format_tilt_study(setup: ProbeSetup, rows: list[tuple[float, ProbePrediction | str]], sigma: float) -> str:
    """Text: which PIGEs the probe sees for each tilt range (standard errors [µm or µrad]), refusals named."""
    kern = load_kernels(setup.machine)
    names = list(kern.LOCATION_PARAMETERS)
    reasons = {p for _, p in rows if isinstance(p, str)}
    if len(reasons) == 1 and all(isinstance(p, str) for _, p in rows):
        return f"tilt study: {reasons.pop()}"
    tilt = [a for a in kern.ROTARY_AXES if "ABC".index(a[0]) != kern.SPINDLE_DIRECTION][0]
    head = f"{'PIGE':<8}" + "".join(f"{f'{tilt} <= {t:g}':>11}" for t, _ in rows)
    lines = [f"what the probe sees with the tilt range ({tilt} at a third, two thirds and all of it, 12 positions "
             f"of the other axis each; 5 contacts, contact scatter {sigma:g} um): predicted std [um or urad]", "",
             head]
    for n in names:
        cells = [f"{p.std[n]:>11.3g}" if isinstance(p, ProbePrediction) else f"{'refused':>11}" for _, p in rows]
        lines.append(f"{n:<8}" + "".join(cells))
    for t, p in rows:
        if isinstance(p, str):
            lines.append(f"\n{tilt} <= {t:g}: {p}")
    ok = [p for _, p in rows if isinstance(p, ProbePrediction)]
    if ok:
        best = ok[-1]
        weak = [n for n in names if best.std[n] > 5 * np.median(list(best.std.values()))]
        lines += ["", "seen least (std over 5x the median even at the largest tilt): "
                  + (", ".join(weak) if weak else "none")
                  + ("; a head's tilt-axis orientation errors move the stylus centre by |tool|·(1 − cos θ) and "
                     "|tool|·sin θ, so they need large tilts and a long tool" if kern.TOOL_ROTARY else "")]
    return "\n".join(lines)
