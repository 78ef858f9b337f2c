"""FANUC's tool centre point chains, rebuilt here from A-79348E, judge what ``--controller fanuc`` prints.

Written in the test without pige's code (FANUC Series 30i-MODEL A, Tool center point control for 5-axis
machining, A-79348E):

- table rotation type (No. 19680 = 12, sheets 59/88 and 82/88): the rotary table position A (machine
  origin → a point on the first, master axis) and Nos. 19703–19705 = AB (A → a point B on the second axis),
  both axes at 0°; a table point x stands at ``A + R1 (AB + R2 (x − A − AB))``;
- tool rotation type (No. 19680 = 2, sheets 83/88 and 84/88): D on the tool axis at tool length + holder
  offset from the tip, Nos. 19709–19711 = DE (D → a point E on the second axis), Nos. 19712–19714 = EF
  (E → a point F on the first axis), F the controlled point the linear axes position; the tip stands at
  ``F − R1 (EF + R2 (DE + (L + H) k))``;

with No. 19684/19689 = 0 (tool axes: right-handed) and 1 (table axes: left-handed), sheet 75/88.  The points
A, B, E, F are taken anywhere on the nominal axis lines ("a position that is easy to measure").  The true
machine (:mod:`test_controller_truth`) has random PIGEs; the printed parameter changes are entered and the
tool point is compared with pige's model of what they do not hold, pose by pose as vectors.
"""

from __future__ import annotations

import math
import re

import numpy as np
import pytest
from test_controller_truth import (
    HEAD,
    MIXED,
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
from pige_sym.errors import InputError

NUMBER = re.compile(r"No\. (197\d\d) ([+-][\d.]+)")
TABLE_POSITION = re.compile(r"rotary table position .*: X ([+-][\d.]+)  Y ([+-][\d.]+)  Z ([+-][\d.]+)$")


class ToolCentrePoint:
    """The parameters of one machine: the vectors [mm] of its type, its first and second rotation axis."""

    def __init__(self, machine: Machine, seed: int = 4) -> None:
        rng = np.random.default_rng(seed)
        self.machine = machine
        self.table = bool(machine.workpiece_axes)
        self.first, self.second = self.axes(machine.code)

        def on_line(axis: str) -> np.ndarray:  # any point of the nominal axis line
            return np.asarray(machine.pivots[axis], dtype=float) + rng.uniform(-80, 80) * UNIT[axis[0]]

        if self.table:
            self.a = on_line(self.first)
            self.p = {19703: on_line(self.second) - self.a}
        else:
            self.k, self.length = UNIT["C"], 180.0 + rng.uniform(-20, 20)  # tool axis, tool length + holder
            self.d = machine.tool_ball() + self.length * self.k
            e, self.f = on_line(self.second), on_line(self.first)
            self.p = {19709: e - self.d, 19712: self.f - e}

    @staticmethod
    def axes(code: str) -> tuple[str, str]:
        """The first (master) and second rotation axis: the bed-side axis first."""
        from pige_sym.codegen.machine_code import parse_machine_code

        st = parse_machine_code(code)
        table = [a.name for a in reversed(st.workpiece_axes) if a.kind == "rotary"]
        head = [a.name for a in st.tool_axes if a.kind == "rotary"]
        first, second = table if table else head
        return first, second

    def enter(self, text: str) -> int:
        """Add the printed changes; the number of parameters entered."""
        count = 0
        for number, value in NUMBER.findall(text):
            first = max(k for k in self.p if k <= int(number))
            self.p[first] = self.p[first] + np.eye(3)[int(number) - first] * float(value)
            count += 1
        for line in text.splitlines():
            m = TABLE_POSITION.search(line)
            if m:
                self.a = self.a + np.array([float(g) for g in m.groups()])
                count += 3
        return count

    def set_directions(self, text: str) -> None:
        """The rotation directions No. 19684 (first axis) and No. 19689 (second) as printed: 0 right-handed."""
        m = re.search(r"No\. 19684 = ([01]), No\. 19689 = ([01])", text)
        assert m, text
        self.hand = {self.first: 1.0 - 2 * int(m.group(1)), self.second: 1.0 - 2 * int(m.group(2))}

    def _r(self, axis: str, pose: dict[str, float]) -> np.ndarray:
        return rotation(UNIT[axis[0]], self.hand[axis] * math.radians(pose[axis]))

    def command(self, pose: dict[str, float], point: np.ndarray) -> np.ndarray:
        r1, r2 = self._r(self.first, pose), self._r(self.second, pose)
        if self.table:
            ab = self.p[19703]
            target = self.a + r1 @ (ab + r2 @ (np.asarray(point, dtype=float) - self.a - ab))
            return target - self.machine.tool_ball()
        tip = self.f - r1 @ (self.p[19712] + r2 @ (self.p[19709] + self.length * self.k))
        return np.asarray(point, dtype=float) - tip


@pytest.mark.parametrize("code", [c for c in SHIPPED if c != MIXED])
@pytest.mark.parametrize(("seed", "reverse"), [(7, False), (8, True)])
def test_the_printed_parameters_put_the_tool_where_pige_says(code: str, seed: int, reverse: bool) -> None:
    """The chain turns its axes as the printed Nos. 19684/19689 say; ``reverse``: the bed-side axis commanded
    against CONVENTIONS' sense (σ = −1)."""
    senses = {ToolCentrePoint.axes(code)[0]: -1} if reverse else {}
    machine = random_machine(code, seed, senses=senses)
    angles = poses(machine, seed, n=12)
    tcp = ToolCentrePoint(machine, seed)
    text = format_controller(machine.params(), "fanuc")
    tcp.set_directions(text)
    assert assert_follows_model(machine, tcp.command, angles, None) > 5.0
    assert tcp.enter(text) == 6
    assert ("No. 19680 = 2 " if code == HEAD else "No. 19680 = 12 ") in text
    held = representable(machine.params(), "fanuc")
    left = [n for n in machine.kern.PARAMETERS if n not in held]
    assert assert_follows_model(machine, tcp.command, angles, left) > 0.5
    if code == HEAD:  # the master (bed-side) axis' positions stay: they would move the controlled point
        assert sorted(set(machine.kern.LOCATION_PARAMETERS) - set(held)) == sorted(
            n for n in machine.kern.LOCATION_PARAMETERS if machine.kern.UNITS[n] == "urad" or n.endswith("0C"))


def test_fanuc_refuses_the_mixed_type_and_names_the_axes() -> None:
    with pytest.raises(InputError, match="No. 19680 = 21"):
        format_controller(random_machine(MIXED, 1).params(), "fanuc")
    text = format_controller(random_machine(HEAD, 1).params(), "fanuc")
    assert "first (master) rotation axis C, second (slave) A" in text
    assert "No. 19684 = 0, No. 19689 = 0" in text
    table = format_controller(random_machine(SHIPPED[0], 1).params(), "fanuc")
    assert "first (master) rotation axis A, second (slave) C" in table and "No. 19684 = 1, No. 19689 = 1" in table


def test_entries_that_would_make_the_tool_point_worse_are_flagged() -> None:
    """On a fork head the master axis' positions stay: entering the slave's alone can raise the error."""
    from pige_sym.compensation.controllers.scope import tool_point_summary

    values = {"EY0A": 12.0, "EZ0A": -9.0, "EX0C": -14.0, "EY0C": 10.0, "EA0A": 100.0, "EC0C": -50.0}
    worse = Machine(HEAD, values, {}, np.zeros(3), np.array([0.0, 0.0, -250.0])).params()
    scope = tool_point_summary(worse, "fanuc")
    assert scope.controller_only.expected_um > scope.before.expected_um
    assert "WARNING: entering only these values makes the predicted tool-point error LARGER" in \
        format_controller(worse, "fanuc")
    better = Machine(HEAD, {"EY0A": 12.0, "EZ0A": -9.0}, {}, np.zeros(3), np.array([0.0, 0.0, -250.0])).params()
    assert "WARNING" not in format_controller(better, "fanuc")
