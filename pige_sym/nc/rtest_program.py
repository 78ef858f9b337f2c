"""R-test programs: the poses a machine visits, with their move and dwell times.

A test program is given either as a trajectory (a name of
:func:`pige_sym.model.trajectories.make_trajectory`, or an angle CSV) or as an NC program
(any supported dialect, :mod:`pige_sym.nc.program`) in which every measurement pose is a
positioning block followed by a dwell (``G4 F<s>``, ``G04 X<s>``, ``G4 P<s>``) or a stop ``M00``/``M01``
(:func:`pige_sym.nc.program.make_rtest_program` writes such programs).

Schedule: the machine starts at pose 0 (the reference pose, all rotary angles 0)
and dwells there; before each later pose it moves for ``move_s``.  Pose i
therefore dwells over ``[arrive_i, arrive_i + dwell_i)`` with ``arrive_0 = 0`` and
``arrive_i = arrive_{i−1} + dwell_{i−1} + move_s``.  Trajectories and ``M00`` stops
take the default dwell; a ``G4 F<s>`` block gives its own.  The defaults (5 s move,
7 s dwell) leave room for the readings to settle (≈1 s) before a 5 s averaging
window.

A file is read as an NC program when its name ends in ``.mpf``, ``.spf``, ``.nc``,
``.ngc`` or ``.cnc``, or when its first non-comment line is not a CSV header;
otherwise it is an angle CSV.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from pige_sym.constants import DEFAULT_BALL_MM
from pige_sym.constants import DEFAULT_DWELL_S as DEFAULT_DWELL_S
from pige_sym.constants import DEFAULT_MOVE_S as DEFAULT_MOVE_S
from pige_sym.errors import InputError
from pige_sym.files import peek_input, read_input_text
from pige_sym.kernels import load_kernels
from pige_sym.measurements.measurement import missing_tool
from pige_sym.model.trajectories import NAMES, Trajectory, make_trajectory
from pige_sym.nc.program import parse_program, poses_from_program

NC_SUFFIXES = (".mpf", ".spf", ".nc", ".ngc", ".cnc")


@dataclass
class TestProgram:
    """Poses of an R-test, their schedule, and the set-up they are measured with.

    Attributes
    ----------
    machine : str
        Canonical machine code.
    rotary_axes : tuple of str
    angles_deg : ndarray, shape=(n, k) [deg]
        Rotary angles θ per pose (CONVENTIONS' sense; an NC program's commanded angles turned with its
        ``axis_sense``); row 0 is the reference pose.
    dwell_s : ndarray, shape=(n,) [s]
    move_s : float [s]
        Move time before every pose but the first.
    description : str
        Text for the file's ``trajectory:`` metadata.
    ball_mm : ndarray, shape=(3,) [mm]
    pivots_mm : dict of str to ndarray, shape=(3,) [mm]
    tool_mm : ndarray, shape=(3,) [mm] or None
    lines : list of int or None
        NC line number of each pose (NC programs).
    axis_sense : dict of str to int
        Axes the controller commands in the reverse sense (CONVENTIONS §9).
    """

    __test__ = False  # not a pytest class

    machine: str
    rotary_axes: tuple[str, ...]
    angles_deg: np.ndarray
    dwell_s: np.ndarray
    move_s: float
    description: str
    ball_mm: np.ndarray
    pivots_mm: dict[str, np.ndarray] = field(default_factory=dict)
    tool_mm: np.ndarray | None = None
    lines: list[int] | None = None
    axis_sense: dict[str, int] = field(default_factory=dict)

    @property
    def n_poses(self) -> int:
        return int(self.angles_deg.shape[0])

    @property
    def arrive_s(self) -> np.ndarray:
        """Start of each pose's dwell in program time, shape=(n,) [s]."""
        starts = np.zeros(self.n_poses)
        for i in range(1, self.n_poses):
            starts[i] = starts[i - 1] + self.dwell_s[i - 1] + self.move_s
        return starts

    @property
    def duration_s(self) -> float:
        """Program length [s] (end of the last dwell)."""
        return float(self.arrive_s[-1] + self.dwell_s[-1])

    def trajectory(self) -> Trajectory:
        """The poses as a :class:`~pige_sym.model.trajectories.Trajectory` (times = dwell starts)."""
        return Trajectory("program", self.rotary_axes, self.angles_deg.copy(), self.arrive_s, self.description)

    def linear_mm(self) -> np.ndarray:
        """Nominal RTCP linear commands X, Y, Z per pose, shape=(n, 3) [mm]."""
        kern = load_kernels(self.machine)
        return np.asarray(kern.linear_commands(self.angles_deg, self.ball_mm, self.pivots_mm or None, self.tool_mm))


def _is_nc_file(path: str) -> bool:
    if path.lower().endswith(NC_SUFFIXES):
        return True
    lines = peek_input(path, 1 << 16).decode("utf-8", errors="replace").splitlines()
    first = next((ln for ln in lines if ln.strip() and not ln.lstrip().startswith("#")), "")
    return not first.strip().endswith("_deg") and "_deg," not in first and "t_s," not in first


def _nc_program(kern: Any, path: str, dwell_s: float,
                sense: dict[str, int] | None) -> tuple[np.ndarray, np.ndarray, list[int], dict[str, int]]:
    from pige_sym.measurements.axis_sense import to_conventions
    from pige_sym.nc.program_header import program_axis_sense

    text = read_input_text(path, what="program")
    axes = tuple(kern.ROTARY_AXES)
    recorded = program_axis_sense(text, axes, path, sense)
    prog = parse_program(text, path=path, rotary_axes=axes)
    commanded, _, _, lines = poses_from_program(prog)
    angles = to_conventions(commanded, recorded, axes)
    if angles.shape[0] == 0:
        raise InputError(f"{path}: no measurement pose (a positioning block followed by G4 F<s> or M00)")
    blocks = {b.line_no: b for b in prog.blocks}
    dwell = []
    for ln in lines:
        b = blocks[ln]
        dwell.append(b.dwell_s if b.dwell and b.dwell_s is not None and b.dwell_s > 0 else dwell_s)
    if np.abs(angles[0]).max() > 1e-9:
        got = ", ".join(f"{a}={v:g}" for a, v in zip(kern.ROTARY_AXES, angles[0], strict=True))
        raise InputError(f"{path}:{lines[0]}: the first measurement pose must be the reference pose "
                         f"(all rotary axes at 0), got {got}")
    return angles, np.array(dwell), lines, recorded


def load_test_program(machine: str, spec: str, *, ball_mm: Any = DEFAULT_BALL_MM,
                      pivots_mm: dict[str, Any] | None = None, tool_mm: Any = None,
                      move_s: float = DEFAULT_MOVE_S, dwell_s: float = DEFAULT_DWELL_S,
                      axis_sense: dict[str, int] | None = None, **trajectory_options: Any) -> TestProgram:
    """Test program from a trajectory name, an angle CSV or an NC program file.

    Parameters
    ----------
    machine : str
    spec : str
        ``cone-frustum``, ``figure-eight``, ``steps``, an angle CSV, or an NC file.
    ball_mm, pivots_mm, tool_mm
        Set-up (CONVENTIONS §4).
    move_s, dwell_s : float [s]
        Schedule (module docstring).
    axis_sense : dict of str to int, optional
        ``--axis-sense``: an NC program's commanded angles are read with it (a program whose header records
        another sense is refused); a trajectory's angles are θ and the sense goes to the files written.
    **trajectory_options
        Passed to :func:`~pige_sym.model.trajectories.make_trajectory` (``points``, ``turns`` …).
    """
    kern = load_kernels(machine)
    if move_s < 0 or dwell_s <= 0:
        raise InputError("move time must be >= 0 s and dwell > 0 s")
    ball = np.asarray(ball_mm, dtype=float)
    if ball.shape != (3,) or not np.isfinite(ball).all():
        raise InputError(f"ball position must be three finite numbers, got {ball_mm!r}")
    pivots = {k: np.asarray(v, dtype=float) for k, v in (pivots_mm or {}).items()}
    for axis in pivots:
        if axis not in kern.ROTARY_AXES:
            raise InputError(f"pivot {axis}: not a rotary axis of {kern.MACHINE_CODE} ({', '.join(kern.ROTARY_AXES)})")
    tool = None if tool_mm is None else np.asarray(tool_mm, dtype=float)
    why = missing_tool(kern.MACHINE_CODE, tool)
    if why:
        raise InputError(why)
    lines = None
    sense = {a: -1 for a in kern.ROTARY_AXES if (axis_sense or {}).get(a, 1) == -1}
    if spec not in NAMES and os.path.isfile(spec) and _is_nc_file(spec):
        angles, dwell, lines, sense = _nc_program(kern, spec, dwell_s, axis_sense)
        desc = f"nc {Path(spec).name} ({len(lines)} poses)"
    else:
        traj = make_trajectory(kern.MACHINE_CODE, spec, **trajectory_options)
        angles = traj.angles_deg
        dwell = np.full(angles.shape[0], float(dwell_s))
        desc = traj.description
    return TestProgram(kern.MACHINE_CODE, tuple(kern.ROTARY_AXES), np.asarray(angles, dtype=float), dwell,
                       float(move_s), desc, ball, pivots, tool, lines, sense)
