"""Catalogue of effects beyond the PIGEs: forward physics and Jacobian columns.

Each effect is a parametric term built through the kinematic chain of the
generated kernels, so the simulator (which adds it to data) and the diagnosis
(which fits it) share one definition.  An effect contributes
``columns(ctx) @ params`` [µm] to the ball-minus-nest deviation (machine frame),
zeroed like the data: ``raw(row) − R_w(row) · raw(reference row)``.

Catalogue (ids are stable; ``<AXIS>`` is a rotary axis name):

=========================  ===========================================================  =========================
id                         physics                                                      parameters
=========================  ===========================================================  =========================
``thermal_drift``          tool-to-table offset ``v·(1 − exp(−t/τ))`` (machine frame)    vx_um, vy_um, vz_um; tau_s
``table_drift``            the nest or probed sphere creeps on the table (stand warm-up,   vx_um, vy_um, vz_um; tau_s
                           a loose stand): it moves ``v·(1 − exp(−t/τ))`` in the table
                           frame, so ``d = −R_w·v·(1 − exp(−t/τ))`` (turns with the table)
``angular_error_<AXIS>``   the axis stands at ``θ + e(θ)``, ``e = c·cos hθ + s·sin hθ``    cos_urad, sin_urad; harmonic
``wobble_<AXIS>``          tilt error motion of the carried body about the two axes ⟂ u,  r<a>_cos, r<a>_sin,
                           harmonic h (default 2) of θ, carrier frame                     r<b>_cos, r<b>_sin [µrad]
``radial_runout_<AXIS>``   radial error motion (translation ⟂ u) of the carried body,     d<a>_cos, d<a>_sin,
                           harmonic h (default 2)                                         d<b>_cos, d<b>_sin [µm]
``backlash_<AXIS>``        reversal error: the axis stands at ``θ + (b/2)·approach``       b_urad
``squareness_XY``          Y travel tilted toward X: ``dx = γ·ΔY``                         gamma_urad
``squareness_YZ``          Z travel tilted toward Y: ``dy = γ·ΔZ``                         gamma_urad
``squareness_ZX``          Z travel tilted toward X: ``dx = γ·ΔZ``                         gamma_urad
``setup_offset``           ball/nest set up Δ away from the nominal ``ball_mm``:           dx_um, dy_um, dz_um
                           ``d = (R_t − R_w)·Δ``
``probe_trigger``          diagnosis of probe imports only: a trigger radius that         lobe_cos_um, lobe_sin_um,
                           depends on the probing direction (``L_c cos 3φ + L_s sin 3φ``    vertical_um
                           horizontal, ``V`` vertical) moves each fitted centre by
                           ``S_i·(L_c, L_s, V)`` (the import's ``trig_`` columns):
                           ``d = −S_i·p`` (:mod:`pige_sym.measurements.probe_trigger`)
``pose_cluster``           diagnosis only: an offset of every row at one pose (one angle   dx_um, dy_um, dz_um;
                           value, or a run of rows) — structure outside the catalogue      axis+deg or t_from/to_s
``outliers``               gross reading errors on a few rows (simulation only; the       size_um, count
                           diagnosis handles them with a robust fit)
=========================  ===========================================================  =========================

Harmonic 0 and the co-rotating first harmonic of wobble and radial runout are
location errors or setup in disguise, so the default harmonic is 2; the diagnosis
checks every candidate's identifiability jointly with the PIGEs anyway.  ΔX, ΔY,
ΔZ are the commanded linear travels from the reference pose.
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any

import numpy as np

from pige_sym.errors import InputError
from pige_sym.model.trajectories import approach_directions
from pige_sym.options import parse_number_assignments

_MOTION_COMPONENTS = ("dx", "dy", "dz", "rx", "ry", "rz")
DRIFT_KINDS = ("thermal_drift", "table_drift")  # drifts in time with a time constant τ
_XYZ = "xyz"


@dataclass
class EffectContext:
    """Everything an effect needs to evaluate its columns on a set of rows.

    Row 0 must be the reference pose (all angles 0, t = 0).

    Attributes
    ----------
    kernels : module
        Generated kernels of the machine.
    angles_deg : ndarray, shape=(n, k) [deg]
    t_s : ndarray, shape=(n,) [s]
    ball_mm : ndarray, shape=(3,) [mm]
    pivots_mm : dict or None
    tool_mm : ndarray or None
    approach : ndarray, shape=(n, k), optional
        Direction of approach per axis; derived from the angle sequence when None.
    probe_sensitivity : ndarray, shape=(n, 3, 3), optional
        Probe imports: centre shift per µm of lobing (cos, sin) and vertical pre-travel [µm/µm].
    """

    kernels: Any
    angles_deg: np.ndarray
    t_s: np.ndarray
    ball_mm: np.ndarray
    pivots_mm: dict[str, np.ndarray] | None = None
    tool_mm: np.ndarray | None = None
    approach: np.ndarray | None = None
    probe_sensitivity: np.ndarray | None = None

    def __post_init__(self) -> None:
        self.angles_deg = np.asarray(self.angles_deg, dtype=float)
        if self.approach is None:
            self.approach = approach_directions(self.angles_deg)

    @property
    def n(self) -> int:
        return int(self.angles_deg.shape[0])

    @cached_property
    def rot_w(self) -> np.ndarray:
        """Nominal workpiece rotation, shape=(n, 3, 3)."""
        return np.asarray(self.kernels.workpiece_rotation(self.angles_deg))

    @cached_property
    def rot_t(self) -> np.ndarray:
        """Nominal spindle-frame rotation, shape=(n, 3, 3)."""
        return np.asarray(self.kernels.tool_rotation(self.angles_deg))

    @cached_property
    def motion(self) -> np.ndarray:
        """Error-motion Jacobian (un-zeroed), shape=(n, 3, 6k) [µm per µm or µrad]."""
        return np.asarray(self.kernels.motion_jacobian(self.angles_deg, self.ball_mm, self.pivots_mm, self.tool_mm))

    @cached_property
    def travel_mm(self) -> np.ndarray:
        """Commanded linear travel from the reference pose, shape=(n, 3) [mm]."""
        lin = self.kernels.linear_commands(self.angles_deg, self.ball_mm, self.pivots_mm, self.tool_mm)
        return np.asarray(lin - lin[0])

    def axis_index(self, axis: str) -> int:
        axes = tuple(self.kernels.ROTARY_AXES)
        if axis not in axes:
            raise InputError(f"machine {self.kernels.MACHINE_CODE} has no rotary axis {axis!r} (axes: {axes})")
        return axes.index(axis)

    def motion_column(self, axis: str, component: str) -> np.ndarray:
        """Un-zeroed offset per unit error motion ``component`` of ``axis``, shape=(n, 3)."""
        j = 6 * self.axis_index(axis) + _MOTION_COMPONENTS.index(component)
        return self.motion[:, :, j]

    def zeroed(self, raw: np.ndarray) -> np.ndarray:
        """Subtract the reference-row offset turned with the table: shape=(n, 3, m)."""
        return raw - np.einsum("nij,jm->nim", self.rot_w, raw[0])


@dataclass(frozen=True)
class EffectSpec:
    """One catalogue effect with its shape options (harmonic, time constant …).

    Attributes
    ----------
    id : str
        Catalogue id, e.g. ``angular_error_C``.
    options : dict
        Non-fitted settings: ``harmonic`` (int) or ``tau_s`` (thermal time constant).
    """

    id: str
    options: dict[str, float] = field(default_factory=dict)

    def __post_init__(self) -> None:
        check_options(self.id, self.options)

    @property
    def kind(self) -> str:
        for k in ("angular_error", "wobble", "radial_runout", "backlash", "squareness"):
            if self.id.startswith(k + "_"):
                return k
        return self.id

    @property
    def axis(self) -> str:
        return self.id.split("_")[-1]

    @property
    def param_names(self) -> tuple[str, ...]:
        """Names of the linear parameters, in column order."""
        kind = self.kind
        if kind in DRIFT_KINDS:
            return ("vx_um", "vy_um", "vz_um")
        if kind == "angular_error":
            return ("cos_urad", "sin_urad")
        if kind in ("wobble", "radial_runout"):
            pre = "r" if kind == "wobble" else "d"
            a, b = self._perp()
            return (f"{pre}{a}_cos", f"{pre}{a}_sin", f"{pre}{b}_cos", f"{pre}{b}_sin")
        if kind == "backlash":
            return ("b_urad",)
        if kind == "squareness":
            return ("gamma_urad",)
        if kind in ("setup_offset", "pose_cluster"):
            return ("dx_um", "dy_um", "dz_um")
        if kind == "probe_trigger":
            return ("lobe_cos_um", "lobe_sin_um", "vertical_um")
        raise InputError(f"effect {self.id!r} has no fitted columns")

    @property
    def units(self) -> dict[str, str]:
        u = "um" if self.kind in (*DRIFT_KINDS, "radial_runout", "setup_offset", "pose_cluster",
                                  "probe_trigger") else "urad"
        return {p: u for p in self.param_names}

    def _perp(self) -> tuple[str, str]:
        d = "ABC".index(self.axis[0])
        return tuple(_XYZ[i] for i in range(3) if i != d)  # type: ignore[return-value]

    @property
    def harmonic(self) -> int:
        return int(self.options.get("harmonic", 2 if self.kind in ("wobble", "radial_runout") else 1))

    def columns(self, ctx: EffectContext) -> np.ndarray:
        """Zeroed deviation per unit parameter, shape=(n, 3, m) [µm per parameter unit]."""
        raw, needs_zeroing = self.raw_columns(ctx)
        return ctx.zeroed(raw) if needs_zeroing else raw

    def raw_columns(self, ctx: EffectContext) -> tuple[np.ndarray, bool]:
        """Deviation per unit parameter before zeroing, shape=(n, 3, m), and whether it needs zeroing.

        Callers evaluating many effects zero them all at once (``raw − R_w·raw[0]``).
        """
        kind = self.kind
        n = ctx.n
        if kind in DRIFT_KINDS:
            tau = float(self.options.get("tau_s", 600.0))
            if tau <= 0:
                raise InputError(f"{kind}: tau_s must be > 0")
            f = 1.0 - np.exp(-np.asarray(ctx.t_s, dtype=float) / tau)
            if kind == "table_drift":  # the nest moves v(t) in the table frame: d = −R_w·v(t)
                return -ctx.rot_w * f[:, None, None], True
            cols = np.zeros((n, 3, 3))
            for i in range(3):
                cols[:, i, i] = f
            return cols, True
        if kind == "setup_offset":
            return ctx.rot_t - ctx.rot_w, True
        if kind == "pose_cluster":
            return self._pose_indicator(ctx), False
        if kind == "probe_trigger":
            if ctx.probe_sensitivity is None:
                raise InputError("probe_trigger needs the trig_ columns of a probe import (pige import-probe)")
            return -np.asarray(ctx.probe_sensitivity, dtype=float), True
        if kind == "squareness":
            pair = self.id.split("_")[1]
            travel = ctx.travel_mm * 1e-3  # µm per µrad
            cols = np.zeros((n, 3, 1))
            if pair == "XY":
                cols[:, 0, 0] = travel[:, 1]
            elif pair == "YZ":
                cols[:, 1, 0] = travel[:, 2]
            elif pair == "ZX":
                cols[:, 0, 0] = travel[:, 2]
            else:
                raise InputError(f"unknown squareness pair in {self.id!r}: use XY, YZ or ZX")
            return cols, False
        axis = self.axis
        k = ctx.axis_index(axis)
        theta = np.radians(ctx.angles_deg[:, k])
        sign = float(ctx.kernels.WORKPIECE_ROTARY.count(axis) and -1 or 1)
        u = _XYZ["ABC".index(axis[0])]
        if kind == "angular_error":
            h = self.harmonic
            rot_u = sign * ctx.motion_column(axis, "r" + u)
            raw = np.stack([rot_u * np.cos(h * theta)[:, None], rot_u * np.sin(h * theta)[:, None]], axis=2)
            return raw, True
        if kind == "backlash":
            rot_u = sign * ctx.motion_column(axis, "r" + u)
            assert ctx.approach is not None
            raw = (rot_u * (0.5 * ctx.approach[:, k])[:, None])[:, :, None]
            return raw, True
        if kind in ("wobble", "radial_runout"):
            h = self.harmonic
            pre = "r" if kind == "wobble" else "d"
            a, b = self._perp()
            ca, cb = ctx.motion_column(axis, pre + a), ctx.motion_column(axis, pre + b)
            c, s = np.cos(h * theta)[:, None], np.sin(h * theta)[:, None]
            raw = np.stack([ca * c, ca * s, cb * c, cb * s], axis=2)
            return raw, True
        raise InputError(f"effect {self.id!r} has no fitted columns")

    def _pose_indicator(self, ctx: EffectContext) -> np.ndarray:
        """Offset columns (identity) on the rows of one pose, zero elsewhere and on the reference row.

        Options: ``axis`` (index into the rotary axes) and ``deg`` (the shared angle), or
        ``t_from_s`` and ``t_to_s`` (a run of consecutive rows, inclusive).
        """
        opt = self.options
        if "axis" in opt:
            on = np.isclose(ctx.angles_deg[:, int(opt["axis"])], float(opt["deg"]), rtol=0.0, atol=1e-6)
        else:
            t = np.asarray(ctx.t_s, dtype=float)
            on = (t >= float(opt["t_from_s"])) & (t <= float(opt["t_to_s"]))
        on[0] = False
        cols = np.zeros((ctx.n, 3, 3))
        for i in range(3):
            cols[:, i, i] = on
        return cols

    def contribution(self, ctx: EffectContext, params: dict[str, float]) -> np.ndarray:
        """Deviation added by the effect, shape=(n, 3) [µm]."""
        missing = [p for p in self.param_names if p not in params]
        if missing:
            raise InputError(f"effect {self.id}: missing parameter(s) {', '.join(missing)}")
        vec = np.array([params[p] for p in self.param_names])
        return self.columns(ctx) @ vec


KINDS = ("thermal_drift", "table_drift", "angular_error", "wobble", "radial_runout", "backlash", "squareness",
         "setup_offset", "outliers")
OPTION_KEYS = {"harmonic", "tau_s", "size_um", "count"}
#: Highest harmonic of an angle an effect may have: a test resolves a few (the diagnosis tries 1-4).
MAX_HARMONIC = 64
#: Each option: (smallest, largest, whole numbers only).
OPTION_RANGES: dict[str, tuple[float, float, bool]] = {
    "harmonic": (1, MAX_HARMONIC, True), "tau_s": (1e-6, 1e9, False), "size_um": (0.0, 1e5, False),
    "count": (0, 1e6, True)}


def check_options(effect_id: str, options: Any) -> None:
    """Refuse option values that no effect can have (:data:`OPTION_RANGES`; other keys are internal settings).

    Raises
    ------
    InputError
        Naming the effect, the option and the allowed range.
    """
    if not isinstance(options, dict):
        raise InputError(f"effect {effect_id}: options must be an object of name: value, got {options!r:.40}")
    for key, value in options.items():
        if key not in OPTION_RANGES:
            continue
        lo, hi, whole = OPTION_RANGES[key]
        ok = not isinstance(value, (bool, np.bool_)) and isinstance(value, numbers.Real) and math.isfinite(value)
        if not (ok and lo <= value <= hi and (not whole or float(value).is_integer())):
            kind = "a whole number" if whole else "a number"
            raise InputError(f"effect {effect_id}: {key} {value!r:.40} must be {kind} from {lo:g} to {hi:g}")


def catalogue(rotary_axes: tuple[str, ...]) -> list[str]:
    """Every effect id applicable to a machine with these rotary axes."""
    ids = list(DRIFT_KINDS)
    for ax in rotary_axes:
        ids += [f"angular_error_{ax}", f"wobble_{ax}", f"radial_runout_{ax}", f"backlash_{ax}"]
    ids += ["squareness_XY", "squareness_YZ", "squareness_ZX", "setup_offset", "outliers"]
    return ids


@dataclass
class EffectInstance:
    """An effect with values, as used by the simulator.

    Attributes
    ----------
    spec : EffectSpec
    params : dict of str to float
        Linear parameters (see ``spec.param_names``); for ``outliers``: ``size_um``, ``count``.
    """

    spec: EffectSpec
    params: dict[str, float]

    def to_dict(self) -> dict[str, Any]:
        return {"effect": self.spec.id, **self.spec.options, **self.params}


DEFAULTS: dict[str, dict[str, float]] = {
    "thermal_drift": {"vx_um": 1.5, "vy_um": -1.0, "vz_um": 2.0, "tau_s": 150.0},
    "table_drift": {"vx_um": 1.0, "vy_um": 1.5, "vz_um": -2.0, "tau_s": 150.0},
    "angular_error": {"harmonic": 2, "cos_urad": 15.0, "sin_urad": -10.0},
    "wobble": {"harmonic": 2},
    "radial_runout": {"harmonic": 2},
    "backlash": {"b_urad": 20.0},
    "squareness": {"gamma_urad": 20.0},
    "setup_offset": {"dx_um": 20.0, "dy_um": -10.0, "dz_um": 5.0},
    "outliers": {"size_um": 10.0, "count": 2},
}


def parse_effect(text: str, rotary_axes: tuple[str, ...]) -> EffectInstance:
    """Parse ``NAME[:k=v,...]`` (CLI ``--effect``); unspecified values take realistic defaults.

    Examples: ``angular_error_C:harmonic=2,cos_urad=10,sin_urad=-5``, ``thermal_drift:tau_s=300``,
    ``outliers:count=3,size_um=8``.
    """
    name, _, rest = text.partition(":")
    name = name.strip()
    if name not in catalogue(rotary_axes):
        raise InputError(f"unknown effect {name!r}; known for this machine: {', '.join(catalogue(rotary_axes))}")
    given = parse_number_assignments(rest, f"effect {name}")
    spec0 = EffectSpec(name)
    defaults = dict(DEFAULTS[spec0.kind])
    options = {k: v for k, v in {**defaults, **given}.items() if k in OPTION_KEYS}
    spec = EffectSpec(name, options)
    if spec.kind == "outliers":
        params = {k: v for k, v in options.items()}
        unknown = set(given) - {"size_um", "count"}
    else:
        names = spec.param_names
        base = {p: defaults.get(p, 5.0) for p in names}
        params = {p: given.get(p, base[p]) for p in names}
        unknown = set(given) - set(names) - OPTION_KEYS
    if unknown:
        raise InputError(f"effect {name}: unknown parameter(s) {', '.join(sorted(unknown))}")
    return EffectInstance(spec, params)
