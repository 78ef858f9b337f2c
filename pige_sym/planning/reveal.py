"""Which catalogue effects (:mod:`pige_sym.model.effects`) a test can reveal, and why (not).

Rule
----
An effect is *revealable* by a test when its parameters are determined jointly with the
PIGEs on the test's poses and times (the identification's rank/null rules, see
:mod:`pige_sym.planning.prediction`), with the effect's default shape options
(:data:`pige_sym.model.effects.DEFAULTS`: harmonic 2, thermal time constant 150 s).  The
predicted standard errors of its parameters are given at the planned noise.  ``outliers``
(gross reading errors) are revealable when every row is backed up by the others: the
largest leverage of a row (largest eigenvalue of its block of the hat matrix) is at most
0.5, so at least half of a gross error shows in that row's residual.

What each effect needs (and the reason given when it is not revealable):

- ``backlash_<AXIS>``: positions of the axis approached from both sides (reversals);
- ``thermal_drift``: time spread and the same pose measured again later (repeated
  reference poses), otherwise a drift looks like pose-dependent errors;
- ``angular_error``/``wobble``/``radial_runout_<AXIS>``: the axis moved over enough of a
  turn for the harmonic to differ from the PIGEs' own first-harmonic signature;
- ``squareness_<PAIR>``: linear travel along the axis it tilts (Y for XY, Z for YZ and ZX);
- ``setup_offset``: tool and table orientations differing between poses;
- ``outliers``: redundancy (leverage rule above).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from pige_sym.errors import InputError
from pige_sym.model.effects import DRIFT_KINDS, EffectContext, EffectSpec, catalogue, parse_effect
from pige_sym.model.trajectories import approach_directions
from pige_sym.planning.prediction import Setup, design_rows, predict

MAX_LEVERAGE = 0.5

NEEDS = {
    "thermal_drift": "time spread and the reference pose measured again later in the test",
    "table_drift": "time spread, the table turned, and the reference pose measured again later in the test",
    "backlash": "positions of {axis} approached from both sides (reversals)",
    "angular_error": "{axis} moved over enough of a turn to separate harmonic {h} from the PIGEs",
    "wobble": "{axis} moved over enough of a turn to separate harmonic {h} from the PIGEs",
    "radial_runout": "{axis} moved over enough of a turn to separate harmonic {h} from the PIGEs",
    "squareness": "linear travel along {second}",
    "setup_offset": "tool and table orientations that differ between poses",
    "outliers": "redundant poses: every row's leverage at most 0.5",
}


@dataclass
class RevealStatus:
    """Whether a test can reveal one effect.

    Attributes
    ----------
    effect : str
        Catalogue id.
    revealable : bool
    needs : str
        What the effect needs from a test.
    reason : str
        Why it is (not) revealable by this test.
    std : dict of str to float or None
        Predicted standard errors of the effect's parameters jointly with the PIGEs
        (None for undetermined ones; empty for ``outliers``).
    forced : bool
        Requested with ``--reveal``.
    """

    effect: str
    revealable: bool
    needs: str
    reason: str
    std: dict[str, float | None]
    forced: bool = False

    def to_dict(self) -> dict[str, Any]:
        return {"revealable": self.revealable, "needs": self.needs, "reason": self.reason, "std": self.std,
                "forced": self.forced}


def parse_reveal(text: str | None, axes: tuple[str, ...]) -> tuple[str, ...]:
    """Comma-separated catalogue ids (``--reveal``)."""
    items = tuple(x.strip() for x in (text or "").split(",") if x.strip())
    known = catalogue(axes)
    bad = [x for x in items if x not in known]
    if bad:
        raise InputError(f"--reveal: unknown effect(s) {', '.join(bad)}; known for this machine: {', '.join(known)}")
    return items


def effect_spec(effect: str, axes: tuple[str, ...]) -> EffectSpec:
    """The catalogue effect with its default shape options (as ``pige simulate --effect`` uses)."""
    return parse_effect(effect, axes).spec


def effect_columns(setup: Setup, spec: EffectSpec, angles_deg: np.ndarray, t_s: np.ndarray) -> np.ndarray:
    """Projected, zeroed columns of an effect on every row, shape=(n, m, q)."""
    kern = setup.kernels
    ctx = EffectContext(kern, angles_deg, t_s, setup.ball_mm, setup.pivots_mm or None, setup.tool_mm)
    assert setup.projection is not None
    return np.einsum("mi,niq->nmq", setup.projection.directions, spec.columns(ctx))


SQUARENESS_TRAVEL = {"XY": 1, "YZ": 2, "ZX": 2}  # the travel each squareness acts on (effects.py: dx = γ·ΔY …)


def _needs(spec: EffectSpec) -> str:
    pair = spec.id.split("_")[-1]
    second = "XYZ"[SQUARENESS_TRAVEL[pair]] if spec.kind == "squareness" else ""
    return NEEDS[spec.kind].format(axis=spec.axis, h=spec.harmonic, second=second)


def _structural_reason(spec: EffectSpec, kern: Any, setup: Setup, angles: np.ndarray, t_s: np.ndarray) -> str | None:
    """A missing structural ingredient, in words, or None."""
    axes = tuple(kern.ROTARY_AXES)
    if spec.kind == "backlash":
        appr = approach_directions(angles)[:, axes.index(spec.axis)]
        if not ((appr > 0).any() and (appr < 0).any()):
            return f"every position of {spec.axis} is approached from the same side: no reversal"
    if spec.kind in DRIFT_KINDS:
        if np.ptp(t_s) <= 0:
            return "no time spread"
        again = [i for i in range(1, angles.shape[0]) if np.any(np.all(np.abs(angles[:i] - angles[i]) < 1e-6, axis=1))]
        if not again:
            return "no pose is measured again later: a drift looks like pose-dependent errors"
    if spec.kind in ("angular_error", "wobble", "radial_runout"):
        if np.ptp(angles[:, axes.index(spec.axis)]) < 1e-9:
            return f"{spec.axis} does not move"
    if spec.kind == "squareness":
        j = SQUARENESS_TRAVEL[spec.id.split("_")[-1]]
        lin = np.asarray(kern.linear_commands(angles, setup.ball_mm, setup.pivots_mm or None, setup.tool_mm))
        if np.ptp(lin[:, j]) < 1e-6:
            return f"no {'XYZ'[j]} travel: the RTCP moves never move {'XYZ'[j]}"
    return None


def _outliers(setup: Setup, angles: np.ndarray) -> RevealStatus:
    rows = design_rows(setup, angles[1:])
    flat = rows.reshape(-1, rows.shape[2])
    hat_inv = np.linalg.pinv(flat.T @ flat)
    lev = max(float(np.linalg.eigvalsh(r @ hat_inv @ r.T).max()) for r in rows) if rows.size else 1.0
    ok = lev <= MAX_LEVERAGE
    reason = (f"largest row leverage {lev:.2f} (<= {MAX_LEVERAGE}): a gross error shows in its row's residual" if ok
              else f"largest row leverage {lev:.2f} > {MAX_LEVERAGE}: a gross error on that row is absorbed by the fit")
    return RevealStatus("outliers", ok, NEEDS["outliers"], reason, {})


def reveal_status(setup: Setup, effect: str, angles_deg: np.ndarray, t_s: np.ndarray, *,
                  forced: bool = False) -> RevealStatus:
    """Whether the test (angles, times) can reveal one catalogue effect (module docstring)."""
    kern = setup.kernels
    axes = tuple(kern.ROTARY_AXES)
    angles = np.asarray(angles_deg, dtype=float)
    if effect == "outliers":
        status = _outliers(setup, angles)
        status.forced = forced
        return status
    spec = effect_spec(effect, axes)
    needs = _needs(spec)
    missing = _structural_reason(spec, kern, setup, angles, t_s)
    cols = effect_columns(setup, spec, angles, np.asarray(t_s, dtype=float))
    names = [f"{effect}.{p}" for p in spec.param_names]
    pred = predict(setup, angles, extra=cols, extra_names=names, extra_units={n: "" for n in names})
    sd = pred.std_dict()
    std = {p: sd[f"{effect}.{p}"] for p in spec.param_names}
    ok = missing is None and all(v is not None for v in std.values())
    if ok:
        reason = "its parameters are determined jointly with the PIGEs"
    elif missing is not None:
        reason = missing
    else:
        reason = "confounded with the PIGEs on these poses: " + ", ".join(p for p, v in std.items() if v is None)
    return RevealStatus(effect, ok, needs, reason, std, forced)


def reveal_report(setup: Setup, angles_deg: np.ndarray, t_s: np.ndarray, forced: tuple[str, ...] = ()
                  ) -> dict[str, RevealStatus]:
    """Reveal status of every catalogue effect of the machine."""
    axes = tuple(setup.kernels.ROTARY_AXES)
    return {e: reveal_status(setup, e, angles_deg, t_s, forced=e in forced) for e in catalogue(axes)}
