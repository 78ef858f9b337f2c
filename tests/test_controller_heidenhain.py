"""A HEIDENHAIN description table, rebuilt here from the manual, judges what ``--controller heidenhain`` prints.

Technical Manual iTNC 530 HSCI, p. 722: the rows act in sequence from the tool reference point; ``Trans``
transforms along (or about) its AXIS by COORD; from a ``MachAxis`` row on, the axis' movement changes the
previous objects relative to the subsequent ones.  Written here as a product of rigid motions, one per row,
for both readings of a ``Trans`` row:

- ``position``: each row is where the next frame lies in the previous one, so a tool-frame point is
  ``G_1 G_2 ⋯ G_n`` applied to the workpiece point; a ``MachAxis`` row is the inverse of the axis' motion
  (the carrier seen from the tool, the table seen from the machine): ``T(−x)``, ``R(e, −θ)``;
- ``shift``: each row moves what came before, so the workpiece point of a tool-frame point is
  ``G_n ⋯ G_2 G_1`` applied to it; ``MachAxis`` rows are the axis' motion ``T(x)``, ``R(e, θ)``;

with R right-handed about the machine axis e of the AXIS letter (ISO 841: the tool turns by +θ relative to
the workpiece).  The nominal table is written from the nominal pivots in the layout under test; the true
machine (:mod:`test_controller_truth`) has random PIGEs; the RTCP solves the table for the linear axes; the
printed deltas are entered group by group and the tool point is compared with pige's model.
"""

from __future__ import annotations

import math
import re

import numpy as np
import pytest
from test_controller_truth import SHIPPED, UNIT, Machine, assert_follows_model, poses, random_machine, rotation

from pige_sym.compensation.stage import format_controller
from pige_sym.errors import InputError

GROUP = re.compile(r"^  Trans rows (before|after|between) MachAxis (\w+)(?: and MachAxis (\w+))? .*?: "
                   r"X ([+-][\d.]+)  Y ([+-][\d.]+)  Z ([+-][\d.]+)$")


class DescriptionTable:
    """Rows ``[key, axis, coord]`` of one layout, the Trans groups keyed as printed."""

    def __init__(self, machine: Machine, sense: str, layout: str) -> None:
        self.machine, self.sense, self.layout = machine, sense, layout
        self.tool_reference = machine.tool_ball() + np.array([0.0, 0.0, 100.0])
        pivot = {a: np.asarray(machine.pivots[a], dtype=float) for a in machine.rotary}
        head = list(reversed(machine.tool_axes))  # met from the tool first
        table = machine.workpiece_axes[::-1]  # met from the machine base first
        self.rows: list[list] = []
        self._side(head, pivot, self.tool_reference, layout)
        self.rows += [["MachAxis", "X", None], ["MachAxis", "Y", None], ["MachAxis", "Z", None]]
        self._side(table, pivot, np.zeros(3), layout)

    def _trans(self, group: str, vector: np.ndarray) -> None:
        for k, axis in enumerate("XYZ"):  # position sense: the vector itself; shift: its negative
            self.rows.append(["Trans", axis, float(vector[k]) * (1 if self.sense == "position" else -1), group])

    def _side(self, axes: list[str], pivot: dict[str, np.ndarray], start: np.ndarray, layout: str) -> None:
        if not axes:
            return
        previous = start
        for k, axis in enumerate(axes):
            if layout == "per-axis" and len(axes) > 1:
                self._trans(f"before {axis}", pivot[axis] - start)
            else:
                self._trans(f"before {axis}" if k == 0 else f"between {axes[k - 1]} {axis}", pivot[axis] - previous)
            self.rows.append(["Trans", axis, 0.0, f"rotation {axis}"])
            self.rows.append(["MachAxis", axis, None])
            if layout == "per-axis" and len(axes) > 1:
                self._trans(f"after {axis}", start - pivot[axis])
            previous = pivot[axis]
        if layout != "per-axis" or len(axes) == 1:
            self._trans(f"after {axes[-1]}", start - previous)

    def enter(self, text: str) -> int:
        """Add the printed group deltas (and the rotation rows) to COORD; the number of groups entered."""
        count, section = 0, None
        for line in text.splitlines():
            if line.endswith(":") and " side" in line:  # a side's heading: one layout, or both alike
                section = "chained" if "layout chained" in line else "per-axis" if "per axis" in line else None
            m = GROUP.match(line)
            if m and section in (None, self.layout):
                where, first, second = m.group(1), m.group(2), m.group(3)
                key = f"between {first} {second}" if where == "between" else f"{where} {first}"
                rows = [r for r in self.rows if len(r) == 4 and r[3] == key]
                assert len(rows) == 3, key
                for row, value in zip(rows, (float(m.group(i)) for i in (4, 5, 6)), strict=True):
                    row[2] += value
                count += 1
        for axis, value in re.findall(r"Trans (\w+) ([+-][\d.]+) deg", text):
            row = next(r for r in self.rows if len(r) == 4 and r[3] == f"rotation {axis}")
            row[2] += float(value)
        return count

    @staticmethod
    def _motion(axis: str, value: float, sign: float):
        if axis in "XYZ":
            shift = sign * value * UNIT["ABC"["XYZ".index(axis)]]
            return lambda x: x + shift
        r = rotation(UNIT[axis], sign * math.radians(value))
        return lambda x: r @ x

    def workpiece_point(self, tool_point: np.ndarray, pose: dict[str, float], linear: np.ndarray) -> np.ndarray:
        """The workpiece coordinates of a tool-frame point (origin at the tool reference point).

        Both senses run through the rows in order: ``shift`` applies each row's own motion (the previous
        objects moved relative to the next), ``position`` applies the inverse of each row's pose
        (``G_n⁻¹ ⋯ G_1⁻¹``): a Trans row by −COORD, a MachAxis row by the axis' motion.
        """
        values = dict(pose) | dict(zip("XYZ", linear, strict=True))
        x = np.asarray(tool_point, dtype=float)
        for row in self.rows:
            if row[0] == "MachAxis":
                x = self._motion(row[1], values[row[1]], 1.0)(x)
            else:
                x = self._motion(row[1], row[2], -1.0 if self.sense == "position" else 1.0)(x)
        return x

    def command(self, pose: dict[str, float], point: np.ndarray) -> np.ndarray:
        """RTCP: the linear axes that put the tool ball on the workpiece ``point`` in this table's model.

        The linear MachAxis values are the tool reference point's machine position; the workpiece point is
        affine in them, so three evaluations give the exact solve.  Returned as the true machine's linear
        displacement (its tool-side pivots are given with the tool reference point at ``tool_reference``).
        """
        ball = self.machine.tool_ball() - self.tool_reference
        origin = self.workpiece_point(ball, pose, np.zeros(3))
        jac = np.column_stack([self.workpiece_point(ball, pose, e) - origin for e in np.eye(3)])
        linear = np.linalg.solve(jac, np.asarray(point, dtype=float) - origin)
        return linear - self.tool_reference


@pytest.mark.parametrize("code", SHIPPED)
@pytest.mark.parametrize("sense", ["position", "shift"])
@pytest.mark.parametrize("layout", ["chained", "per-axis"])
def test_the_printed_rows_put_the_tool_where_pige_says(code: str, sense: str, layout: str) -> None:
    machine = random_machine(code, 21)
    angles = poses(machine, 21, n=12)
    table = DescriptionTable(machine, sense, layout)
    assert assert_follows_model(machine, table.command, angles, None) > 5.0
    text = format_controller(machine.params(), "heidenhain", heidenhain_trans=sense)
    # two axes on one side: out, between, back (chained) or out and back per axis; mixed: out and back twice
    assert table.enter(text) == (4 if code == SHIPPED[3] else 3 if layout == "chained" else 4)
    tilts = [n for n in machine.kern.LOCATION_PARAMETERS if machine.kern.UNITS[n] == "urad"]
    assert assert_follows_model(machine, table.command, angles, tilts) > 0.5
    without_tilts = Machine(code, {k: v for k, v in machine.values.items() if k not in tilts}, machine.pivots,
                            machine.ball, machine.tool)
    table_only = DescriptionTable(without_tilts, sense, layout)
    table_only.enter(format_controller(without_tilts.params(), "heidenhain", heidenhain_trans=sense))
    assert assert_follows_model(without_tilts, table_only.command, angles, []) < 1e-3


def test_heidenhain_refuses_without_the_trans_sense_or_with_a_reversed_axis() -> None:
    with pytest.raises(InputError, match="--heidenhain-trans"):
        format_controller(random_machine(SHIPPED[0], 1).params(), "heidenhain")
    reversed_c = random_machine(SHIPPED[0], 1, senses={"C": -1}).params()
    with pytest.raises(InputError, match="axis C is commanded in the reverse sense"):
        format_controller(reversed_c, "heidenhain", heidenhain_trans="position")
