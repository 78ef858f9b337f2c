"""Resuming a partial acquisition file: its set-up must match, its zero is reused, rows are appended.

The rules are in :mod:`pige_sym.acquisition.engine` (Resume).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pige_sym.acquisition.nest import NestGeometry
from pige_sym.acquisition.options import AcquisitionOptions, AcquisitionSummary
from pige_sym.acquisition.outputs import _remove_partial_line
from pige_sym.codegen.machine_code import parse_machine_code
from pige_sym.errors import AcquisitionError, FileFormatError
from pige_sym.measurements.rtest import read_measurement
from pige_sym.nc.rtest_program import TestProgram


@dataclass
class ResumeState:
    start_pose: int
    zero: np.ndarray
    rows: dict[int, np.ndarray]
    last_t: float


def read_resume(path: Path, program: TestProgram, nest: NestGeometry, opts: AcquisitionOptions) -> ResumeState | None:
    """State to continue a partial file, None when it holds no data row yet."""
    lines = path.read_text(encoding="utf-8").splitlines()
    if sum(1 for ln in lines if ln.strip() and not ln.startswith("#")) < 2:
        return None  # no data row (at most the column header): nothing measured yet
    m = read_measurement(path)
    problems = []
    if parse_machine_code(m.machine).canonical != program.machine:
        problems.append(f"machine {m.machine} (now {program.machine})")
    if not np.array_equal(m.ball_mm, program.ball_mm):
        problems.append(f"ball_mm {m.ball_mm.tolist()} (now {program.ball_mm.tolist()})")
    if m.frame != opts.frame:
        problems.append(f"frame {m.frame} (now {opts.frame})")
    if (m.tool_mm is None) != (program.tool_mm is None) or (
            m.tool_mm is not None and program.tool_mm is not None and not np.array_equal(m.tool_mm, program.tool_mm)):
        problems.append("tool_mm")
    if set(m.pivots_mm) != set(program.pivots_mm) or any(
            not np.array_equal(m.pivots_mm[a], program.pivots_mm[a]) for a in m.pivots_mm):
        problems.append("pivots")
    if m.trajectory != program.description:
        problems.append(f"program {m.trajectory!r} (now {program.description!r})")
    if m.metadata.get("nest") != nest.description:
        problems.append(f"nest {m.metadata.get('nest')!r} (now {nest.description!r})")
    if problems:
        raise AcquisitionError(f"{path}: cannot resume, the file was recorded with a different set-up: "
                               + "; ".join(problems) + ". Use the same options, or write to a new --out file")
    if "pose" not in m.extra_columns or "zero_um" not in m.metadata:
        raise AcquisitionError(f"{path}: not written by pige acquire (no pose column or zero_um): cannot resume")
    try:
        poses = [int(p) for p in m.extra_columns["pose"]]
        zero = np.array([float(x) for x in m.metadata["zero_um"].split(",")])
    except ValueError:
        raise FileFormatError(str(path), None, "bad pose column or zero_um metadata") from None
    if zero.shape != (3,) or poses[0] != 0 or any(b <= a for a, b in zip(poses, poses[1:], strict=False)):
        raise FileFormatError(str(path), None, "pose column must start at 0 and increase; zero_um needs 3 numbers")
    if poses[-1] >= program.n_poses:
        raise AcquisitionError(f"{path}: pose {poses[-1]} is beyond the program's {program.n_poses} poses")
    rows = {p: m.deviation_um[i] for i, p in enumerate(poses)}
    return ResumeState(poses[-1] + 1, zero, rows, float(m.t_s[-1]))


def prepare_resume(out: Path, program: TestProgram, nest: NestGeometry, opts: AcquisitionOptions,
                    summary: AcquisitionSummary, say: Callable[[str], None]) -> ResumeState | None:
    """Resume state of ``out`` (None: start a new file); ``summary.completed`` when nothing is left."""
    if not out.exists():
        say(f"resume: {out} does not exist yet, starting a new file")
        return None
    summary.resumed = True
    summary.removed_partial_line = _remove_partial_line(out)
    if summary.removed_partial_line:
        say(f"resume: removed an incomplete last line from {out}")
    state = read_resume(out, program, nest, opts)
    if state is None:
        return None
    summary.first_pose = state.start_pose
    if state.start_pose >= program.n_poses:
        summary.completed = True
        say(f"resume: {out} already holds every pose of the program")
        return state
    say(f"resume: {out} holds poses up to {state.start_pose - 1}; the program is measured again from "
        f"its start and rows are appended from pose {state.start_pose}")
    return state
