"""The compensation study: tool-point error before and after compensation on simulated machines.

For each trajectory the residual tool-point [µm] and orientation [µrad] errors of the nominal and the
compensated commands are computed on a machine with known errors; :func:`plot_compensation` draws them.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from pige_sym.compensation.kinematics import compensate_poses, tool_point_error
from pige_sym.compensation.parameters import AngleExtension
from pige_sym.constants import DEFAULT_BALL_MM
from pige_sym.files import make_folder
from pige_sym.kernels import load_kernels
from pige_sym.model.trajectories import approach_directions
from pige_sym.plotting import fixed_layout, pyplot, save_png


@dataclass
class CompensationStudyRow:
    """Before/after on one test program."""

    trajectory: str
    rmse_before_um: float
    rmse_after_um: float
    reduction: float
    predicted_after_um: float
    command_change_rmse_mm: float
    before_um: np.ndarray
    after_um: np.ndarray

    def to_dict(self) -> dict[str, Any]:
        return {"trajectory": self.trajectory, "rmse_before_um": self.rmse_before_um,
                "rmse_after_um": self.rmse_after_um, "reduction": self.reduction,
                "predicted_after_um": self.predicted_after_um,
                "command_change_rmse_mm": self.command_change_rmse_mm}


def compensation_study(machine: str, trajectories: list[Any], *, truth: dict[str, float],
                       identified: dict[str, float], covariance: np.ndarray | None = None,
                       ball_mm: Any = DEFAULT_BALL_MM, tool_mm: Any = None,
                       pivots_mm: dict | None = None, truth_extensions: list[AngleExtension] | tuple[()] = (),
                       extensions: list[AngleExtension] | tuple[()] = ()) -> list[CompensationStudyRow]:
    """Run each test program uncompensated and compensated on a machine with the true errors.

    ``predicted_after_um`` is the RMSE expected from the identification covariance
    alone: ``sqrt(trace(J Σ Jᵀ)/n)`` over the program's poses.  ``pivots_mm`` are the
    nominal pivots of the rotary axes (default: all at the origin).  ``truth_extensions``
    are angle errors the simulated machine has too; ``extensions`` those compensated.
    """
    kern = load_kernels(machine)
    ball = np.asarray(ball_mm, dtype=float)
    rows = []
    for tr in trajectories:
        a = tr.angles_deg
        pts = np.tile(ball, (a.shape[0], 1))
        xyz = kern.linear_commands(a, ball, pivots_mm, tool_mm)
        approach = approach_directions(a)
        comp = compensate_poses(machine, identified, a, xyz, pivots_mm=pivots_mm, tool_mm=tool_mm,
                                extensions=extensions, approach=approach)
        before = tool_point_error(machine, truth, a, xyz, pts, pivots_mm=pivots_mm, tool_mm=tool_mm,
                                  extensions=truth_extensions, approach=approach)
        after = tool_point_error(machine, truth, comp.new_angles_deg, comp.new_xyz_mm, pts, pivots_mm=pivots_mm,
                                 tool_mm=tool_mm, extensions=truth_extensions, approach=approach)
        rms_b = float(np.sqrt((before**2).sum(axis=1).mean()))
        rms_a = float(np.sqrt((after**2).sum(axis=1).mean()))
        pred = float("nan")
        if covariance is not None:
            jac = kern.jacobian(a, None, ball, pivots_mm, tool_mm)[:, :, : covariance.shape[0]]
            rot = kern.workpiece_rotation(a)
            ref = kern.reference_jacobian(ball, pivots_mm, tool_mm)[:, : covariance.shape[0]]
            jac = jac + np.einsum("nij,jp->nip", rot, ref)
            pred = float(np.sqrt(np.einsum("nip,pq,niq->", jac, covariance, jac) / a.shape[0]))
        change = float(np.sqrt(((comp.new_xyz_mm - xyz) ** 2).sum(axis=1).mean()))
        rows.append(CompensationStudyRow(tr.description, rms_b, rms_a, 1 - rms_a / rms_b if rms_b else 0.0, pred,
                                         change, before, after))
    return rows


def before_after(machine: str, truth: dict[str, float], comp: Any, *, description: str,
                 pivots_mm: dict | None = None, tool_mm: Any = None,
                 truth_extensions: list[AngleExtension] | tuple[()] = (),
                 predicted_after_um: float = float("nan")) -> CompensationStudyRow:
    """Before/after tool-point error on a machine with errors ``truth`` of poses the compensation stage corrected.

    Parameters
    ----------
    machine : str
    truth : dict of str to float
        The simulated machine's parameters [µm, µrad].
    comp : CompensatedPoses
        The stage's corrected poses (:attr:`pige_sym.compensation.result.Compensation.poses` or the program's):
        as programmed and as corrected; an RTCP pose's X, Y, Z are workpiece coordinates, which the controller turns
        into machine positions nominally.
    description : str
    predicted_after_um : float
        What the stage predicts the correction leaves [µm] (its weighing), shown beside the simulated figure.

    Returns
    -------
    CompensationStudyRow
        Errors per pose, shape=(n, 3) [µm], before and after.
    """
    kern = load_kernels(machine)
    a, new_a = np.atleast_2d(comp.angles_deg), np.atleast_2d(comp.new_angles_deg)
    n = a.shape[0]
    flags = np.broadcast_to(np.asarray(comp.rtcp, dtype=bool), (n,))
    cmd_before, cmd_after = np.array(comp.xyz_mm, dtype=float), np.array(comp.new_xyz_mm, dtype=float)
    for row in np.flatnonzero(flags):  # the controller turns workpiece coordinates into machine positions nominally
        cmd_before[row] = kern.linear_commands(a[row : row + 1], comp.xyz_mm[row], pivots_mm, tool_mm)[0]
        cmd_after[row] = kern.linear_commands(new_a[row : row + 1], comp.new_xyz_mm[row], pivots_mm, tool_mm)[0]
    approach = approach_directions(a)
    before = tool_point_error(machine, truth, a, cmd_before, comp.points_mm, pivots_mm=pivots_mm, tool_mm=tool_mm,
                              extensions=truth_extensions, approach=approach)
    after = tool_point_error(machine, truth, new_a, cmd_after, comp.points_mm, pivots_mm=pivots_mm, tool_mm=tool_mm,
                             extensions=truth_extensions, approach=approach)
    rms_b = float(np.sqrt((before**2).sum(axis=1).mean()))
    rms_a = float(np.sqrt((after**2).sum(axis=1).mean()))
    change = float(np.sqrt(((cmd_after - cmd_before) ** 2).sum(axis=1).mean()))
    return CompensationStudyRow(description, rms_b, rms_a, 1 - rms_a / rms_b if rms_b else 0.0, predicted_after_um,
                                change, before, after)


def plot_compensation(rows: list[CompensationStudyRow], out_dir: str | Path) -> list[str]:
    """Deviation per point before/after (paper Figures 9 and 10 style); returns PNG paths."""
    plt = pyplot()
    out = Path(out_dir)
    make_folder(out, what="--out")
    paths = []
    for i, r in enumerate(rows):
        fig, axs = plt.subplots(1, 2, figsize=(10, 3.6))
        idx = np.arange(r.before_um.shape[0])
        for k, c in enumerate("xyz"):
            axs[0].plot(idx, r.before_um[:, k], "-", label=f"{c} before")
            axs[0].plot(idx, r.after_um[:, k], "--", label=f"{c} after")
        axs[0].set_xlabel("point")
        axs[0].set_ylabel("tool point error [µm]")
        axs[0].legend(fontsize=7, ncol=2)
        axs[1].plot(idx, np.linalg.norm(r.before_um, axis=1), "o-", label=f"before, RMSE {r.rmse_before_um:.2f} µm")
        axs[1].plot(idx, np.linalg.norm(r.after_um, axis=1), "s-", label=f"after, RMSE {r.rmse_after_um:.2f} µm")
        axs[1].set_xlabel("point")
        axs[1].set_ylabel("|error| [µm]")
        axs[1].legend(fontsize=8)
        fig.suptitle(r.trajectory, fontsize=9)
        fixed_layout(fig, left=0.7, right=0.15, bottom=0.5, top=0.35, wspace=0.8)
        paths.append(str(save_png(fig, out / f"compensation_{i}.png", dpi=90)))
    return paths
