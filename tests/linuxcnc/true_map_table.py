"""The true machine of the map loop: a tilting table with PIGEs, error maps and a reversal error, from CONVENTIONS.

Written here from CONVENTIONS §2, §3 and §10, without pige_sym's model: each rotary axis' body moves as
``x ↦ q + R_ρ R(u', s·(θ + E + φ^d(θ)))(x − q) + τ(θ)`` (s = −1: both axes move the workpiece), q and u' its line
with the PIGEs (§3), θ = σ·(motor angle) (§9), the maps τ [µm], ρ [µrad] (vectors in the carrier's frame: the
machine for the outer axis, the outer axis' body for the inner one) and φ^d [µrad] per direction of approach d,
linearly interpolated on their grid (a full-turn grid wraps, §10).  The exact rotations are Rodrigues'.

The hidden maps are §10 representatives on the grid (random harmonics 2–4 with the left-out functions removed:
φ's mean, the span of 1, cos θ, sin θ of every other motion): a map the PIGEs cannot hold, so that pige's
identification can find it.  The reversal φ⁺ − φ⁻ of C is kept whole (a backlash of about 40 µrad that varies with
the angle).

The same mathematics runs twice: in the realtime HAL component ``true_map_table.comp`` (one evaluation per servo
period; it drives ``motion.probe-input`` and shows the tip and the directions of approach), and in
:meth:`TrueMapTable.tip_in_table` (NumPy), which the tests use to check the component.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from true_table import axis_line, true_machine_hal

TEMPLATE = (Path(__file__).resolve().parent / "true_map_table.comp").read_text()
COMPONENT_NAME = "pige_true_map_table"
_AXIS = {"A": 0, "B": 1, "C": 2}


@dataclass(frozen=True)
class TrueMap:
    """One axis' error maps: a uniform grid (CONVENTIONS angle θ) and the motions at its angles.

    tau_um (3, n) and rho_urad (3, n) are vectors in the carrier's frame (the component along the axis of ρ is 0:
    the rotation about the axis is φ); phi_plus_urad / phi_minus_urad (n,) the positioning map per direction.
    """

    start_deg: float
    step_deg: float
    full_turn: bool
    tau_um: np.ndarray
    rho_urad: np.ndarray
    phi_plus_urad: np.ndarray
    phi_minus_urad: np.ndarray

    @property
    def grid(self) -> np.ndarray:
        return self.start_deg + self.step_deg * np.arange(self.tau_um.shape[1])

    def at(self, values: np.ndarray, theta_deg: np.ndarray) -> np.ndarray:
        """Linear interpolation of ``values`` (..., n) at θ (m,): (..., m) (CONVENTIONS §10)."""
        g = self.grid
        theta = np.asarray(theta_deg, dtype=float)
        if self.full_turn:
            nodes, vals = np.append(g, g[0] + 360.0), np.concatenate([values, values[..., :1]], axis=-1)
            t = g[0] + np.mod(theta - g[0], 360.0)
        else:
            nodes, vals, t = g, values, np.clip(theta, g[0], g[-1])
        return np.apply_along_axis(lambda v: np.interp(t, nodes, v), -1, vals)

    def phi(self, theta_deg: np.ndarray, direction: np.ndarray) -> np.ndarray:
        d = np.asarray(direction)
        plus, minus = self.at(self.phi_plus_urad, theta_deg), self.at(self.phi_minus_urad, theta_deg)
        return np.where(d > 0, plus, np.where(d < 0, minus, 0.5 * (plus + minus)))


def _projected(grid: np.ndarray, values: np.ndarray, kind: str) -> np.ndarray:
    """§10's representative, written here: the least-squares residual on 1 (φ) or on 1, cos θ, sin θ."""
    t = np.radians(grid)
    basis = np.ones((t.size, 1)) if kind == "phi" else np.column_stack([np.ones_like(t), np.cos(t), np.sin(t)])
    return np.asarray(values - basis @ np.linalg.lstsq(basis, values, rcond=None)[0])


def hidden_map(axis: str, grid: np.ndarray, full_turn: bool, seed: int, *, tau: float, rho: float, phi: float,
               reversal: float) -> TrueMap:
    """Random harmonics 2–4 of each motion at the grid angles, as §10 representatives; a reversal of about
    ``reversal`` µrad (kept whole)."""
    rng = np.random.default_rng(seed)
    t = np.radians(grid)

    def wave(size: float) -> np.ndarray:
        return sum(rng.normal(scale=size) * np.cos(h * t + rng.uniform(0, 6.3)) for h in (2, 3, 4))

    d = _AXIS[axis[0]]
    taus = np.array([_projected(grid, wave(tau), "tau") for _ in range(3)])
    rhos = np.array([np.zeros_like(t) if j == d else _projected(grid, wave(rho), "rho") for j in range(3)])
    mean = _projected(grid, wave(phi), "phi")
    rev = reversal * (1.0 + 0.25 * np.cos(t + 0.7)) if reversal else np.zeros_like(t)
    step = float(grid[1] - grid[0])
    return TrueMap(float(grid[0]), step, full_turn, taus, rhos, mean + 0.5 * rev, mean - 0.5 * rev)


def _rodrigues(v: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Rows of v (n, 3) turned by the rows of w (n, 3) [rad] (about w/|w| by |w|)."""
    a = np.linalg.norm(w, axis=1)[:, None]
    u = np.divide(w, a, out=np.zeros_like(w), where=a > 0)
    c, s = np.cos(a), np.sin(a)
    return c * v + s * np.cross(u, v) + (1 - c) * np.einsum("ni,ni->n", u, v)[:, None] * u


@dataclass
class TrueMapTable:
    """The true machine: axis lines with PIGEs (:func:`true_table.axis_line`), senses, maps, stylus and sphere."""

    code: str
    outer: str
    pivot_mm: dict[str, np.ndarray]
    pige: dict[str, float]
    sense: dict[str, int]
    maps: dict[str, TrueMap]
    tool_length_mm: float = 0.0
    sphere_mm: np.ndarray = field(default_factory=lambda: np.zeros(3))
    trip_radius_mm: float = 1.0

    @property
    def axes(self) -> tuple[str, str]:
        return (self.outer, "C")

    def lines(self) -> list[tuple[str, np.ndarray, np.ndarray, float]]:
        return [(ax, *axis_line(ax, self.pivot_mm[ax], self.pige)) for ax in self.axes]

    def tip_in_table(self, joints: np.ndarray, approach: np.ndarray) -> np.ndarray:
        """Stylus-tip centre in table coordinates for motor rows (n, 5) [mm, deg] and the directions of approach
        (n, 2) in θ's sense (outer, inner) -> (n, 3) [mm]."""
        j = np.atleast_2d(np.asarray(joints, dtype=float))
        d = np.atleast_2d(np.asarray(approach))
        y = j[:, :3] - np.array([0.0, 0.0, self.tool_length_mm])
        for k, (ax, q, u, zero) in enumerate(self.lines()):  # undo the outer axis, then the inner one
            m = self.maps[ax]
            theta = self.sense[ax] * j[:, 3 + k]
            v = y - m.at(m.tau_um, theta).T * 1e-3 - q
            v = _rodrigues(v, -m.at(m.rho_urad, theta).T * 1e-6)
            alpha = np.radians(theta) + zero + m.phi(theta, d[:, k]) * 1e-6
            y = q + _rodrigues(v, alpha[:, None] * u[None, :])
        return y

    def maps_c(self) -> str:
        """The hidden maps as C arrays for the component."""
        ms = [self.maps[a] for a in self.axes]
        n = max(m.tau_um.shape[1] for m in ms)

        def row(v: np.ndarray) -> str:
            return "{" + ", ".join(repr(float(x)) for x in np.pad(v, (0, n - v.size))) + "}"

        def arr(name: str, rows: list[str], shape: str) -> str:
            return f"static const double {name}{shape} = {{{', '.join(rows)}}};"

        return "\n".join([
            f"#define MAXN {n}",
            f"static const int NODES[2] = {{{', '.join(str(m.tau_um.shape[1]) for m in ms)}}};",
            f"static const double START[2] = {{{', '.join(repr(m.start_deg) for m in ms)}}};",
            f"static const double STEP[2] = {{{', '.join(repr(m.step_deg) for m in ms)}}};",
            f"static const int FULL[2] = {{{', '.join(str(int(m.full_turn)) for m in ms)}}};",
            arr("TAU", ["{" + ", ".join(row(v) for v in m.tau_um) + "}" for m in ms], "[2][3][MAXN]"),
            arr("RHO", ["{" + ", ".join(row(v) for v in m.rho_urad) + "}" for m in ms], "[2][3][MAXN]"),
            arr("PHI_PLUS", [row(m.phi_plus_urad) for m in ms], "[2][MAXN]"),
            arr("PHI_MINUS", [row(m.phi_minus_urad) for m in ms], "[2][MAXN]"),
            arr("PHI_MEAN", [row(0.5 * (m.phi_plus_urad + m.phi_minus_urad)) for m in ms], "[2][MAXN]")])

    def component_source(self) -> str:
        return TEMPLATE.replace("@MAPS@", self.maps_c())

    def pin_values(self) -> dict[str, float]:
        vals: dict[str, float] = {}
        for k, ax in enumerate(self.axes, start=1):
            vals[f"sense{k}"] = float(self.sense[ax])
        for r, (_, q, u, zero) in zip(("r1", "r2"), self.lines(), strict=True):
            vals |= {f"{r}-p{c}": float(v) for c, v in zip("xyz", q, strict=True)}
            vals |= {f"{r}-u{c}": float(v) for c, v in zip("xyz", u, strict=True)}
            vals[f"{r}-zero"] = float(zero)
        vals |= {f"sphere-{c}": float(v) for c, v in zip("xyz", self.sphere_mm, strict=True)}
        return vals | {"tool-length": float(self.tool_length_mm), "trip-radius": float(self.trip_radius_mm)}

    def hal_lines(self, name: str = "ptm") -> list[str]:
        return true_machine_hal(COMPONENT_NAME, name, ("joint-r1", "joint-r2"), self.pin_values())
