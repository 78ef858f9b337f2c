"""R-test simulator: synthetic measurements for any supported machine.

The deviation is the first-order PIGE model of the generated kernels plus the
chosen effects (:mod:`pige_sym.model.effects`) plus Gaussian sensor noise on every row
but the reference (which is zero by definition of zeroing).  The commanded
linear positions are the RTCP commands of the nominal kinematics.

Random PIGEs (``--pige random``), after the paper's Fourier-series preset
generator: for the P location errors, ``F_i = Σ_{k=1..3} a_k cos(kφ_i) + b_k sin(kφ_i)``
with ``a_k, b_k ~ U(−1, 1)`` and ``φ_i = 2π(i + u)/P`` (u ~ U(0, 1)), normalised to
``max |F| = 1``; each value is ``sign(F_i)·(lo + (hi − lo)·|F_i|)`` with
``[lo, hi] = [1, 15] µrad`` for orientation errors (the paper's range) and
``offset_range`` (default ``[1, 15] µm``; the paper's text gives 0–1.0 with its unit
lost) for position errors.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from pige_sym.constants import DEFAULT_BALL_MM
from pige_sym.errors import FileFormatError, InputError
from pige_sym.files import to_json
from pige_sym.kernels import load_kernels
from pige_sym.measurements.measurement import Measurement, missing_tool
from pige_sym.measurements.rtest_writer import write_measurement
from pige_sym.measurements.schema import MAX_PIGE
from pige_sym.model.effects import EffectContext, EffectInstance
from pige_sym.model.error_motions import ErrorMaps
from pige_sym.model.trajectories import Trajectory
from pige_sym.options import parse_number_assignments

ORIENTATION_RANGE_URAD = (1.0, 15.0)
OFFSET_RANGE_UM = (1.0, 15.0)


def normalise_parameter_name(name: str) -> str:
    """Accept the letter O for the digit zero (``EXOC`` → ``EX0C``)."""
    n = name.strip().upper()
    if len(n) >= 4 and n[0] == "E" and n[2] == "O":
        n = n[:2] + "0" + n[3:]
    return n


def random_pige(machine: str, seed: int | None = None, *, offset_range: tuple[float, float] = OFFSET_RANGE_UM,
                orientation_range: tuple[float, float] = ORIENTATION_RANGE_URAD) -> dict[str, float]:
    """Preset location errors from the Fourier-series generator (module docstring)."""
    kern = load_kernels(machine)
    rng = np.random.default_rng(seed)
    names = kern.LOCATION_PARAMETERS
    p = len(names)
    a, b = rng.uniform(-1, 1, 3), rng.uniform(-1, 1, 3)
    phi = 2 * np.pi * (np.arange(p) + rng.uniform()) / p
    k = np.arange(1, 4)
    f = (a * np.cos(np.outer(phi, k)) + b * np.sin(np.outer(phi, k))).sum(axis=1)
    f /= np.abs(f).max()
    out = {}
    for name, fi in zip(names, f, strict=True):
        lo, hi = offset_range if kern.UNITS[name] == "um" else orientation_range
        out[name] = float(np.sign(fi) * (lo + (hi - lo) * abs(fi)))
    return out


def parse_pige(spec: str, machine: str, seed: int | None = None, **ranges: Any) -> dict[str, float]:
    """PIGE values from ``random``, ``NAME=VALUE,...`` or a JSON file with a ``"pige"`` object."""
    kern = load_kernels(machine)
    if spec.strip() == "random":
        return random_pige(machine, seed, **ranges)
    if os.path.exists(spec):
        from pige_sym.measurements.schema import load_json

        data = load_json(spec, "PIGE file")
        if not isinstance(data, dict) or not isinstance(data.get("pige"), dict):
            raise FileFormatError(spec, None, 'expected a JSON object with a "pige" object of name: value')
        given: dict[str, Any] = data["pige"]
    else:
        given = parse_number_assignments(spec, "--pige")
    items: dict[str, Any] = {}
    for name, value in given.items():
        key = normalise_parameter_name(name)
        if key in items:
            spellings = ", ".join(n for n in given if normalise_parameter_name(n) == key)
            raise InputError(f"--pige: {key} is given twice ({spellings}; the letter O reads as the digit 0): "
                             "give it once")
        items[key] = value
    unknown = [k for k in items if k not in kern.PARAMETERS]
    if unknown:
        raise InputError(f"unknown parameter(s) {', '.join(unknown)} for {kern.MACHINE_CODE}; "
                         f"known: {', '.join(kern.PARAMETERS)}")
    out = {}
    for k, v in items.items():
        if v is None or not isinstance(v, (int, float)) or not np.isfinite(v):
            raise InputError(f"parameter {k}: {v!r} is not a finite number")
        if abs(v) > MAX_PIGE:
            raise InputError(f"parameter {k}: {v:g} is beyond ±{MAX_PIGE:g} {kern.UNITS[k]}: not a machine that runs "
                             "(pige's parameter files refuse it too)")
        out[k] = float(v)
    return out


@dataclass
class SimulationResult:
    """A simulated measurement and everything used to make it.

    Attributes
    ----------
    measurement : Measurement
    truth : dict
        JSON-ready record: machine, ball, pivots, tool, trajectory, pige, effects, noise, seed,
        outlier rows.
    """

    measurement: Measurement
    truth: dict[str, Any] = field(default_factory=dict)

    def write(self, path: str | os.PathLike[str]) -> tuple[Path, Path]:
        """Write the CSV and its sidecar ``<stem>.truth.json``."""
        p = write_measurement(self.measurement, path)
        truth_path = p.with_name(p.stem + ".truth.json")
        truth_path.write_text(to_json(self.truth) + "\n")
        return p, truth_path


def _check_inputs(kern: Any, trajectory: Trajectory, noise_um: float, frame: str, tool_mm: Any) -> None:
    if tuple(trajectory.rotary_axes) != tuple(kern.ROTARY_AXES):
        raise InputError(f"trajectory axes {trajectory.rotary_axes} do not match {kern.ROTARY_AXES}")
    if noise_um < 0:
        raise InputError("noise must be >= 0 µm")
    if frame not in ("machine", "table"):
        raise InputError("frame must be 'machine' or 'table'")
    why = missing_tool(kern.MACHINE_CODE, tool_mm)
    if why:
        raise InputError(why)


def add_effects(dev: np.ndarray, effects: list[EffectInstance], ctx: EffectContext,
                 rng: np.random.Generator) -> tuple[np.ndarray, list[int]]:
    """Deviations (n, 3) [µm] with every effect added, and the rows that received an outlier.

    Parameters
    ----------
    dev : ndarray, shape=(n, 3) [µm]
        Deviations without the effects (machine frame).
    effects : list of EffectInstance
    ctx : EffectContext
        The rows (row 0 the reference pose) and the point the effects act on.
    rng : numpy.random.Generator
        Draws the ``outliers`` rows and directions.
    """
    outlier_rows: set[int] = set()
    n = dev.shape[0]
    for eff in effects:
        if eff.spec.kind != "outliers":
            dev = dev + eff.spec.contribution(ctx, eff.params)
            continue
        count = int(eff.params.get("count", 2))
        size = float(eff.params.get("size_um", 10.0))
        if count >= n:
            raise InputError("outliers: count must be smaller than the number of rows")
        rows = np.sort(rng.choice(np.arange(1, n), size=count, replace=False))
        direction = rng.normal(size=(count, 3))
        direction /= np.linalg.norm(direction, axis=1, keepdims=True)
        dev[rows] += size * direction
        outlier_rows |= {int(r) for r in rows}
    return dev, sorted(outlier_rows)


def simulate(machine: str, trajectory: Trajectory, *, pige: dict[str, float] | None = None,
             ball_mm: Any = DEFAULT_BALL_MM, pivots_mm: dict[str, Any] | None = None, tool_mm: Any = None,
             effects: list[EffectInstance] | None = None, noise_um: float = 0.25, seed: int | None = None,
             frame: str = "machine", axis_sense: dict[str, int] | None = None,
             error_maps: ErrorMaps | None = None) -> SimulationResult:
    """Simulate an R-test measurement.

    Parameters
    ----------
    machine : str
    trajectory : Trajectory
    pige : dict of str to float
        Error parameters by name [µm, µrad] (missing ones are 0).
    ball_mm : (3,) [mm]
    pivots_mm : dict axis -> (3,) [mm]
    tool_mm : (3,) [mm], required for tool-side rotary axes
    effects : list of EffectInstance
    noise_um : float
        Standard deviation of the Gaussian sensor noise per component [µm].
    seed : int
    frame : {"machine", "table"}
    axis_sense : dict of str to int, optional
        Axes the controller commands in the reverse sense (CONVENTIONS §9): the trajectory's angles are θ,
        the file written from the result holds θ_cmd = σ·θ and records the sense.
    error_maps : ErrorMaps, optional
        Error motions of rotary axes (CONVENTIONS §10), added to first order; recorded in the truth as
        ``error_motions``.

    Returns
    -------
    SimulationResult
    """
    kern = load_kernels(machine)
    _check_inputs(kern, trajectory, noise_um, frame, tool_mm)
    rng = np.random.default_rng(seed)
    ball = np.asarray(ball_mm, dtype=float)
    pivots = {k: np.asarray(v, dtype=float) for k, v in (pivots_mm or {}).items()}
    tool = None if tool_mm is None else np.asarray(tool_mm, dtype=float)
    pige = dict(pige or {})
    params = np.array([pige.get(p, 0.0) for p in kern.PARAMETERS])
    angles = trajectory.angles_deg
    dev = kern.deviation(angles, params, ball, pivots or None, tool)
    ctx = EffectContext(kern, angles, trajectory.t_s, ball, pivots or None, tool)
    dev, outlier_rows = add_effects(dev, effects or [], ctx, rng)
    if error_maps is not None:
        dev = dev + error_maps.deviation(kern, angles, ball, pivots or None, tool, trajectory.approach)
    effect_records = [eff.to_dict() for eff in effects or []]
    noise = rng.normal(scale=noise_um, size=dev.shape) if noise_um > 0 else np.zeros_like(dev)
    dev = dev + noise
    dev[0] = 0.0  # the reference row is zero by definition (zeroing), not just to rounding
    if frame == "table":
        dev = np.einsum("nji,nj->ni", kern.workpiece_rotation(angles), dev)
    linear = kern.linear_commands(angles, ball, pivots or None, tool)
    meta = {"machine": kern.MACHINE_CODE, "ball_mm": "", "frame": frame, "trajectory": "", "source": "pige simulate"}
    m = Measurement(
        machine=kern.MACHINE_CODE, ball_mm=ball, t_s=trajectory.t_s.copy(), angles_deg=angles.copy(),
        deviation_um=dev, rotary_axes=tuple(kern.ROTARY_AXES), frame=frame, tool_mm=tool, pivots_mm=pivots,
        trajectory=trajectory.description, linear_mm=linear, metadata=meta, axis_sense=dict(axis_sense or {}),
    )
    truth = {
        "machine": kern.MACHINE_CODE,
        "pige": {p: float(pige.get(p, 0.0)) for p in kern.PARAMETERS},
        "units": dict(kern.UNITS),
        "effects": effect_records,
        "outlier_rows": outlier_rows,
        "sigma_um": float(noise_um),
        "seed": seed,
        "ball_mm": ball.tolist(),
        "pivots_mm": {k: v.tolist() for k, v in pivots.items()},
        "tool_mm": None if tool is None else tool.tolist(),
        "trajectory": trajectory.description,
        "frame": frame,
        **({"axis_sense": dict(axis_sense)} if axis_sense else {}),
        **({"error_motions": error_maps.to_dict()} if error_maps is not None else {}),
    }
    return SimulationResult(m, truth)
