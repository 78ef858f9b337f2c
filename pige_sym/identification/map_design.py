"""Predicted precision of a map test before it is run: the design of ``identify --map`` on planned poses.

The planner (:mod:`pige_sym.planning.map_test`) builds the files a test will produce — R-test runs, probe
imports, ballbar setups — at the planned poses, with no data: zero deviations, and for a probe file the
centre covariances its planned contacts give.  This module builds from them the very system
:func:`~pige_sym.identification.maps.identify_maps` fits (:func:`~pige_sym.identification.maps.map_blocks`,
:func:`~pige_sym.identification.maps.design_maps`: the blocks from the kernels' error-motion columns, the
per-angle check, the §10 projection, the left-out functions fitted beside the map), each file's rows divided
by its noise σ_f (:func:`design_sigma`).  No second model is written.

The predicted covariance of the fitted columns is ``(AᵀA)⁺`` of that whitened system — the variance factor is
1, the σ_f being the noise rather than estimated from residuals — and every map value's standard error
follows as identify reports it, ``Σ_v = Q Σ_z Qᵀ`` (:func:`~pige_sym.identification.maps.map_values`).  What
the per-angle check refuses, or the joint fit cannot determine, is undetermined with identify's reason.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from pige_sym.identification.instruments import instrument
from pige_sym.identification.joint import Block, whitened_system
from pige_sym.identification.map_check import Undetermined
from pige_sym.identification.maps import AxisMap, MapSpec, design_maps, map_blocks, map_values, n_location
from pige_sym.identification.result import json_float
from pige_sym.identification.spectrum import solve_scaled
from pige_sym.measurements.ballbar import BallbarRun
from pige_sym.measurements.measurement import Measurement
from pige_sym.measurements.probe_import import row_covariances


@dataclass
class MapPrediction:
    """Predicted standard errors of a map test [µm, µrad] and what it cannot determine.

    Attributes
    ----------
    machine : str
    spec : MapSpec
    maps : dict of str to AxisMap
        Per axis: ``std`` the predicted standard error of every value (NaN: undetermined); ``value`` 0 where
        determined (a prediction has no data).
    undetermined : list of Undetermined
        As ``identify --map`` would report them.
    pige_std : dict of str to float or None
        The PIGEs' and zero-position errors' predicted standard errors (None: undetermined).
    """

    machine: str
    spec: MapSpec
    maps: dict[str, AxisMap]
    undetermined: list[Undetermined]
    pige_std: dict[str, float | None]

    def counts(self) -> tuple[int, int]:
        """(determined, total) map values, φ per direction counted as its mean and reversal maps."""
        stds = [s for m in self.maps.values() for mo in m.motions for s in m.std[mo.name]]
        return int(np.isfinite(stds).sum()), len(stds)

    @property
    def complete(self) -> bool:
        """Whether every map value is determined."""
        done, total = self.counts()
        return done == total

    def worst(self, axis: str, motion: str) -> float:
        """Largest predicted standard error of a motion's determined values (NaN when none is)."""
        s = self.maps[axis].std[motion]
        return float(np.nanmax(s)) if np.isfinite(s).any() else math.nan

    def worst_std(self) -> float:
        """The largest predicted standard error of a determined value [µm or µrad] (inf when none is)."""
        stds = np.concatenate([m.std[mo.name] for m in self.maps.values() for mo in m.motions])
        return float(np.nanmax(stds)) if np.isfinite(stds).any() else math.inf

    def to_dict(self) -> dict[str, Any]:
        """``{"error_motions": {axis: {"angle_deg", motion: {"std": [...]}}}, "undetermined", "pige_std"}``."""
        motions = {ax: {"angle_deg": [float(a) for a in m.grid.angles_deg], "full_turn": m.grid.full_turn,
                        **{mo.name: {"std": [json_float(v) for v in m.std[mo.name]], "unit": mo.unit,
                                     "kind": mo.kind} for mo in m.motions}} for ax, m in self.maps.items()}
        done, total = self.counts()
        return {"machine": self.machine, "map_step_deg": self.spec.step_deg, "error_motions": motions,
                "worst_std": json_float(self.worst_std()),
                "determined": done, "values": total, "undetermined": [u.to_dict() for u in self.undetermined],
                "pige_std": self.pige_std}


def design_sigma(item: Measurement | BallbarRun, noise_um: float) -> float:
    """The σ_f [µm] identify divides a file's rows by, when its data carry their nominal noise.

    An R-test or ballbar file: its noise per reading.  A probe file: its rows are whitened with the centre
    covariances scaled to a mean variance of 1 (:mod:`~pige_sym.identification.instruments`), so σ_f is the
    root of that mean, ``√(mean_i (tr Σ_i + tr Σ_0) / 3)`` over the poses after the reference.
    """
    if isinstance(item, BallbarRun) or instrument(item) == "rtest":
        return float(noise_um)
    cov = row_covariances(item)
    return math.sqrt(float(np.mean(np.trace(cov[1:], axis1=1, axis2=2) + np.trace(cov[0]))) / 3.0)


def predict_maps(items: Sequence[tuple[str, Measurement | BallbarRun]], sigmas: Sequence[float],
                 spec: MapSpec) -> MapPrediction:
    """Predicted standard errors of the PIGEs, zero-position errors and maps of these planned files
    (module docstring); ``sigmas`` [µm] per file (:func:`design_sigma`)."""
    machine, names, layout, blocks = map_blocks(items, spec)
    sig = [float(s) for s in sigmas]
    p = len(names)
    pige_only = [Block(b.label, b.instrument, b.design[:, :p], b.data, b.nuisance, b.nuisance_names) for b in blocks]
    a0, _ = whitened_system(pige_only, sig)
    seen = np.isfinite(solve_scaled(a0.T @ a0, np.zeros(a0.shape[1]), 0.0).vif[:p])
    fitted_zero = [j for j in range(p) if j < n_location(machine) or seen[j]]
    design = design_maps(names, layout, blocks, sig, fitted_zero)
    a, _ = whitened_system(design.blocks, sig)
    sol = solve_scaled(a.T @ a, np.zeros(a.shape[1]), 0.0)
    determined = np.isfinite(sol.vif)
    values = np.where(determined, 0.0, np.nan)
    maps, more = map_values(values, sol.cov_unit, layout, design.groups)
    std = np.sqrt(np.clip(np.diag(sol.cov_unit), 0.0, None))
    pige_std: dict[str, float | None] = {n: None for n in names}
    for k, j in enumerate(fitted_zero):
        pige_std[names[j]] = float(std[k]) if determined[k] else None
    return MapPrediction(machine, spec, maps, design.undetermined + more, pige_std)
