"""An independent implementation of CONVENTIONS §2, §3, §4 and §10 for the tests: exact rotations, no kernels.

For a machine whose rotary axes are all on the workpiece side or all on the tool side (a tilting table such
as ``wC'A'bXYZ(C1)t``, a fork head such as ``wbXYZCA(C1)t``) it computes the R-test deviation (ball minus nest,
zeroed at the reference pose, machine frame) of a ball at a point, under PIGEs, zero-position errors and error
maps, with every axis' motion exact:

    x ↦ q + (I + [ρ(θ)]×) · R(u', s·(θ + E + φ(θ))) · (x − q) + τ(θ)

q = p + δ, u' = (u + ε × u)/|…|, R by Rodrigues, maps interpolated linearly on their grid (a C grid wraps).
Written from the text of CONVENTIONS only; pige's own code is not used.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

_DIRECTION = {"A": 0, "B": 1, "C": 2}
# §3 table: position errors (along machine axes), orientation errors (about machine axes)
_LOCATION = {"A": ((1, 2), (1, 2)), "B": ((0, 2), (0, 2)), "C": ((0, 1), (0, 1))}
_POS_NAMES = {"A": ("EY0A", "EZ0A"), "B": ("EX0B", "EZ0B"), "C": ("EX0C", "EY0C")}
_ORI_NAMES = {"A": ("EB0A", "EC0A"), "B": ("EA0B", "EC0B"), "C": ("EA0C", "EB0C")}


def _cross(v: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def _rodrigues(u: np.ndarray, angle: float) -> np.ndarray:
    k = _cross(u)
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k


@dataclass
class OracleMap:
    """Values of the six motions on a grid [deg]; motion names as CONVENTIONS §10's table."""

    grid_deg: np.ndarray
    values: dict[str, np.ndarray]
    wraps: bool

    def at(self, name: str, theta_deg: float) -> float:
        v = self.values.get(name)
        if v is None:
            return 0.0
        g = self.grid_deg
        if self.wraps:
            t = g[0] + (theta_deg - g[0]) % 360.0
            nodes = np.append(g, g[0] + 360.0)
            vals = np.append(v, v[0])
        else:
            t = min(max(theta_deg, g[0]), g[-1])
            nodes, vals = g, v
        return float(np.interp(t, nodes, vals))


@dataclass
class OracleMachine:
    """Rotary axes listed from the body nearest the measured point outward (workpiece side: from the workpiece
    to the bed; tool side: from the tool to the bed), with their side, PIGEs, zero errors and maps."""

    axes: tuple[str, ...]
    side: int  # -1 workpiece side, +1 tool side
    pige: dict[str, float]
    maps: dict[str, OracleMap] = field(default_factory=dict)
    pivots: dict[str, np.ndarray] = field(default_factory=dict)

    def _move(self, axis: str, theta_deg: float, x: np.ndarray, exact: bool) -> np.ndarray:
        d = _DIRECTION[axis]
        u = np.eye(3)[d]
        p = self.pivots.get(axis, np.zeros(3))
        if not exact:  # the nominal motion
            return p + _rodrigues(u, self.side * np.radians(theta_deg)) @ (x - p)
        (i1, i2), (j1, j2) = _LOCATION[axis]
        delta = np.zeros(3)
        delta[i1], delta[i2] = (self.pige.get(n, 0.0) * 1e-3 for n in _POS_NAMES[axis])
        eps = np.zeros(3)
        eps[j1], eps[j2] = (self.pige.get(n, 0.0) * 1e-6 for n in _ORI_NAMES[axis])
        u_act = u + np.cross(eps, u)
        u_act /= np.linalg.norm(u_act)
        q = p + delta
        letter = axis
        m = self.maps.get(axis)
        tau = np.zeros(3)
        rho = np.zeros(3)
        phi = 0.0
        if m is not None:
            for j, c in enumerate("XYZ"):
                tau[j] = m.at(f"E{c}{letter}", theta_deg) * 1e-3
            for j, c in enumerate("ABC"):
                if j != d:
                    rho[j] = m.at(f"E{c}{letter}", theta_deg) * 1e-6
            phi = m.at(f"E{letter}{letter}", theta_deg) * 1e-6
        zero = self.pige.get(f"E{letter}0{letter}", 0.0) * 1e-6
        rot = _rodrigues(u_act, self.side * (np.radians(theta_deg) + zero + phi))
        return q + (np.eye(3) + _cross(rho)) @ rot @ (x - q) + tau

    def place(self, angles: dict[str, float], x: np.ndarray, exact: bool) -> np.ndarray:
        """Where a point fixed in the body nearest the measured point is, in the machine frame [mm]."""
        for axis in self.axes:
            x = self._move(axis, angles[axis], x, exact)
        return x

    def rtest(self, angles: list[dict[str, float]], point: np.ndarray) -> np.ndarray:
        """R-test deviations, shape=(n, 3) [µm]; row 0 must be the reference pose.

        Table: the nest at ``point`` on the table, the ball where the nominal machine puts it (RTCP). Head: the
        ball at ``point`` in the spindle frame, the nest where the nominal machine puts the ball. r = ball − nest,
        d(θ) = r(θ) − R_w(θ) r(0) with R_w the nominal rotation of the workpiece (identity for a head).
        """
        out = []
        for a in angles:
            nominal, actual = self.place(a, point, False), self.place(a, point, True)
            r = (nominal - actual) if self.side < 0 else (actual - nominal)
            out.append(r)
        r = np.array(out) * 1e3
        rows = []
        for a, ri in zip(angles, r, strict=True):
            rot = np.eye(3)
            if self.side < 0:
                for axis in self.axes:
                    rot = _rodrigues(np.eye(3)[_DIRECTION[axis]], -np.radians(a[axis])) @ rot
            rows.append(ri - rot @ r[0])
        return np.array(rows)
