"""SINUMERIK's TOOLCARRIER chain, rebuilt here from the manuals, judges what ``--controller siemens`` prints.

The chains (IM9 Commissioning Manual 6FC5397-1DP40-3BA1, p. 502; W1 Function Manual 6FC5397-0BP10-0BA0,
pp. 2-88/2-89/2-92), written in the test without pige's code:

- ``P`` (swivel table): a table point x stands at ``l2 + R1 (l3 + R2 (l4 + x))`` from the machine reference
  point; l2 reference point → pivot 1, l3 pivot 1 → pivot 2, l4 = −(l2 + l3);
- ``T`` (swivel head): the tool tip stands at ``P − l1 − R1 (l2 + R2 (l3 + L))``; l3 tool adapter →
  pivot 2, l2 pivot 2 → pivot 1, l1 = −(l2 + l3), L tip → adapter, P the toolholder reference point;
- ``M``: the head part with l2 adapter → pivot 1, l1 = −l2, the table part with l3 reference point →
  pivot 2, l4 = −l3;

with Ri the rotation about vi by (axis position − offset angle) "counted positively for clockwise rotation
facing the direction of the rotation vector" (right-handed), vi the axis direction, reversed for an axis
that moves the workpiece (CYCLE800 checklist), the offset ``$TC_CARR24/25`` the axis position of the initial
setting.  The controller's RTCP puts its tool point on its image of the workpiece point; the true machine
(:mod:`test_controller_truth`) has random PIGEs; the test enters the printed lines (fine offsets, then the
commented base-data direction lines) and compares the tool point with pige's model, pose by pose as vectors.
"""

from __future__ import annotations

import math
import re

import numpy as np
import pytest
from test_controller_truth import (
    SHIPPED,
    UNIT,
    Machine,
    assert_follows_model,
    poses,
    random_machine,
    rotation,
)

from pige_sym.compensation.controllers.scope import representable
from pige_sym.compensation.stage import format_controller
from pige_sym.kernels import load_kernels

#: Basic parameters of the offset vectors (x component) and of v1, v2; fine offset = basic + 40.
VECTORS = {1: "l1", 4: "l2", 15: "l3", 18: "l4", 7: "v1", 10: "v2"}
LINE = re.compile(r"^(?:; )?\$TC_CARR(\d+)\[(\d+)\]=\$TC_CARR\1\[\2\]([+-]\d+\.\d+)$")


class Toolcarrier:
    """One swivel data record: kinematics type, l1..l4 [mm], v1, v2, offsets [deg], and its pige axes."""

    def __init__(self, machine: Machine, kind: str, seed: int = 3) -> None:
        rng = np.random.default_rng(seed)
        self.machine, self.kind = machine, kind
        table, head = machine.workpiece_axes[::-1], machine.tool_axes  # each bed first
        self.axes = {"P": table, "T": head, "M": head + table}[kind]  # rotary axis 1, 2
        p1, p2 = (np.asarray(machine.pivots[a], dtype=float) for a in self.axes)
        self.reference = rng.uniform(-40, 40, 3)  # machine (and table) reference point
        self.adapter = machine.tool_ball() + np.array([0.0, 0.0, 120.0]) + rng.uniform(-5, 5, 3)
        self.tool = self.adapter - machine.tool_ball()  # L: tool tip -> tool adapter
        zero = np.zeros(3)
        if kind == "P":
            self.l = {"l1": zero, "l2": p1 - self.reference, "l3": p2 - p1, "l4": self.reference - p2}
        elif kind == "T":
            self.l = {"l1": self.adapter - p1, "l2": p1 - p2, "l3": p2 - self.adapter, "l4": zero}
        else:
            self.l = {"l1": self.adapter - p1, "l2": p1 - self.adapter, "l3": p2 - self.reference,
                      "l4": self.reference - p2}
        sides = [+1 if a in machine.tool_axes else -1 for a in self.axes]  # reversed on the workpiece side
        self.v = {f"v{i + 1}": sides[i] * machine.senses.get(a, 1) * UNIT[a[0]] for i, a in enumerate(self.axes)}
        self.offset = [0.0, 0.0]

    def enter(self, text: str, carrier: int, base_data: bool = False) -> int:
        """Add the printed fine offsets (with ``base_data``: the commented v lines instead); the count entered."""
        count = 0
        for line in text.splitlines():
            m = LINE.match(line)
            if not m or int(m.group(2)) != carrier or line.startswith(";") != base_data:
                continue
            k, value = int(m.group(1)), float(m.group(3))
            if k in (64, 65):
                self.offset[k - 64] += value
            else:
                basic = k - 40 if k > 40 else k
                first = max(b for b in VECTORS if b <= basic)
                name, comp = VECTORS[first], basic - first
                target = self.l if name.startswith("l") else self.v
                target[name] = target[name] + np.eye(3)[comp] * value
            count += 1
        return count

    def _r(self, i: int, pose: dict[str, float]) -> np.ndarray:
        axis = self.axes[i]
        return rotation(self.v[f"v{i + 1}"], math.radians(pose[axis] - self.offset[i]))

    def table(self, w: np.ndarray, pose: dict[str, float]) -> np.ndarray:
        x = np.asarray(w, dtype=float) - self.reference
        if self.kind == "P":
            r1, r2 = self._r(0, pose), self._r(1, pose)
            return self.reference + self.l["l2"] + r1 @ (self.l["l3"] + r2 @ (self.l["l4"] + x))
        if self.kind == "M":
            return self.reference + self.l["l3"] + self._r(1, pose) @ (self.l["l4"] + x)
        return np.asarray(w, dtype=float)

    def tool_tip(self, pose: dict[str, float]) -> np.ndarray:
        """The tool tip with the toolholder reference point at the adapter's reference position."""
        if self.kind == "P":
            return self.machine.tool_ball()
        r1 = self._r(0, pose)
        inner = self.l["l2"] + self._r(1, pose) @ (self.l["l3"] + self.tool) if self.kind == "T" else \
            self.l["l2"] + self.tool
        return self.adapter - self.l["l1"] - r1 @ inner

    def command(self, pose: dict[str, float], point: np.ndarray) -> np.ndarray:
        """RTCP: the linear displacement putting the modelled tool tip on the modelled workpiece point."""
        return self.table(point, pose) - self.tool_tip(pose)


def _kind(machine: Machine) -> str:
    return "T" if not machine.workpiece_axes else "P" if not machine.tool_axes else "M"


@pytest.mark.parametrize("code", SHIPPED)
@pytest.mark.parametrize(("seed", "reverse"), [(5, False), (6, True)])
def test_the_printed_fine_offsets_put_the_tool_where_pige_says(code: str, seed: int, reverse: bool) -> None:
    """``reverse``: both axes commanded against CONVENTIONS' sense (σ = −1, CONVENTIONS §9): the chain's v
    flip, the offset angles become +E; the printed lines follow the parameter file's axis_sense."""
    senses = dict.fromkeys(load_kernels(code).ROTARY_AXES, -1) if reverse else {}
    machine = random_machine(code, seed, senses=senses)
    angles = poses(machine, seed)
    carrier = Toolcarrier(machine, _kind(machine))
    # the rebuilt chain with the nominal record: the tool deviates exactly as pige's model says
    assert assert_follows_model(machine, carrier.command, angles, None) > 5.0
    text = format_controller(machine.params(), "siemens", carrier=2)
    assert f"$TC_CARR23[2]=\"{carrier.kind}\"" in text and "MD24582 $MC_TRAFO5_TCARR_NO_1 = 2" in text
    assert "SD42974 $SC_TOCARR_FINE_CORRECTION = 1" in text and "MD20190 $MC_TOCARR_FINE_LIM_ROT" in text
    # the fine offsets entered: what is left is pige's model of what they cannot hold (the axis tilts)
    assert carrier.enter(text, 2) == (14 if carrier.kind == "M" else 11)
    held = representable(machine.params(), "siemens")
    left = [n for n in machine.kern.PARAMETERS if n not in held]
    assert sorted(left) == sorted(n for n in machine.kern.LOCATION_PARAMETERS if machine.kern.UNITS[n] == "urad")
    assert assert_follows_model(machine, carrier.command, angles, left) > 0.5
    # and the commented base-data direction lines as well: nothing is left
    assert carrier.enter(text, 2, base_data=True) == 6
    assert assert_follows_model(machine, carrier.command, angles, []) < 1e-3


def test_the_axes_are_named_the_siemens_way() -> None:
    """Rotary axis 1 carries axis 2; with mixed kinematics axis 1 is the head's (CYCLE800 checklist)."""
    expected = {"wC'A'bXYZ(C1)t": ("A", "C", "P"), "wbXYZCA(C1)t": ("C", "A", "T"), "wC'bXYZB(C1)t": ("B", "C", "M")}
    for code, (one, two, kind) in expected.items():
        text = format_controller(random_machine(code, 1).params(), "siemens")
        assert f"rotary axis 1 = {one} " in text and f"rotary axis 2 = {two} " in text, text
        assert f"$TC_CARR23[1]=\"{kind}\"" in text
    head = format_controller(random_machine("wbXYZCA(C1)t", 1).params(), "siemens")
    assert "$TC_CARR58[1]" not in head and "$TC_CARR41[1]" in head  # no l4 on a head, l1 closes its chain
