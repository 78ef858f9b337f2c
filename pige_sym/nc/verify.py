"""Read-back: the written program, interpreted again from scratch, against the original.

Checks (any failure means nothing is written):

- the output has the input's lines plus the header lines, in order;
- every line the rewriter did not change is byte-identical (line ending included);
- every block is of the same kind (no move became something else) in the same modal state
  (units, distance mode, RTCP, work offset, frame);
- at every block the output pose and the original pose are both known or both unknown, and
  differ by at most the change limit (``max_mm`` for X/Y/Z, ``max_deg`` for rotary axes),
  so an uncompensated block that inherits a compensated position (an incremental move, an
  axis not programmed) is also within it.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from pige_sym.nc.interpreter import Program, interpret
from pige_sym.nc.state import MM_PER_INCH, Block


@dataclass
class Verification:
    """Result of the read-back.

    Attributes
    ----------
    ok : bool
    problems : list of str
        One line each (``line N: …``), empty when ``ok``.
    max_change_mm, max_change_deg : float
        Largest difference between output and original pose over all blocks [mm], [deg].
    """

    ok: bool
    problems: list[str] = field(default_factory=list)
    max_change_mm: float = 0.0
    max_change_deg: float = 0.0
    read_back: Program | None = None


def verify(original: Program, out_text: str, changed_lines: set[int], header_lines: int, header_at: int, *,
           max_mm: float, max_deg: float, pass_through: bool = False,
           targets: dict[int, tuple[float, ...]] | None = None) -> Verification:
    """Interpret ``out_text`` and compare it with ``original`` (module docstring).

    ``changed_lines`` are input line numbers the rewriter changed; the header occupies output
    lines ``header_at + 1 … header_at + header_lines`` (0-based insertion index ``header_at``).
    ``targets`` (input line → pose [mm, deg]) must be reached by the changed blocks to within the
    rounding of their words (half a unit of the last decimal written).
    """
    out = interpret(out_text, original.dialect, original.rotary_axes, path=f"{original.path} (read back)",
                    pass_through=pass_through)
    problems: list[str] = []
    blocks = out.blocks[:header_at] + out.blocks[header_at + header_lines:] if header_lines else out.blocks
    if len(blocks) != len(original.blocks):
        return Verification(False, [f"the output has {len(out.blocks)} lines, expected {len(original.blocks)} + "
                                    f"{header_lines} header lines"])
    for a, b in zip(original.blocks, blocks, strict=True):
        where = f"line {a.line_no}"
        if a.line_no not in changed_lines and (a.text != b.text or a.ending != b.ending):
            problems.append(f"{where}: changed although it should be byte-identical")
        if a.kind != b.kind or (a.state is not b.state and _modal(a) != _modal(b)):
            problems.append(f"{where}: reads back as a different kind of block or modal state")
        if targets and a.line_no in changed_lines:
            problems += _missed(b, targets[a.line_no], where)
    worst_mm, worst_deg = _compare_poses(original, blocks, max_mm, max_deg, problems)
    return Verification(not problems, problems, worst_mm, worst_deg, out)


def _compare_poses(original: Program, blocks: list[Block], max_mm: float, max_deg: float,
                   problems: list[str]) -> tuple[float, float]:
    """Poses known in both or neither, and within the limits; returns the largest changes [mm], [deg]."""
    a = np.array([b.after for b in original.blocks], dtype=float).reshape(len(blocks), -1)
    b = np.array([b.after for b in blocks], dtype=float).reshape(len(blocks), -1)
    known = ~np.isnan(a)
    for i, j in zip(*np.nonzero(known != ~np.isnan(b)), strict=True):
        problems.append(f"line {original.blocks[i].line_no}: {original.axes[j]} is "
                        f"{'un' if np.isnan(b[i, j]) else ''}known after the rewrite")
    diff = np.where(known & ~np.isnan(b), np.abs(a - b), 0.0)
    limit = np.array([max_mm] * 3 + [max_deg] * (a.shape[1] - 3))
    for i, j in zip(*np.nonzero(diff > limit), strict=True):
        unit = "mm" if j < 3 else "deg"
        problems.append(f"line {original.blocks[i].line_no}: {original.axes[j]} moved by {diff[i, j]:.4f} {unit} "
                        f"(limit {limit[j]:g} {unit})")
    return float(diff[:, :3].max(initial=0.0)), float(diff[:, 3:].max(initial=0.0))


def _missed(block: Block, target: tuple[float, ...], where: str) -> list[str]:
    out = []
    for i, (got, want) in enumerate(zip(block.after, target, strict=True)):
        tol = (0.51e-5 * MM_PER_INCH if i < 3 and block.state.inch else 0.51e-4) + 1e-9
        if got is None or abs(got - want) > tol:
            out.append(f"{where}: the rewritten block reaches {block.axes[i]}={got} instead of {want:.6f}")
    return out


def _modal(block: Block) -> tuple:
    st = block.state
    return (st.incremental, st.inch, st.rtcp, st.offset, bool(st.frame), st.motion)
