"""Why a map fit (:mod:`~pige_sym.identification.maps`) leaves a PIGE or a zero-position error without a value, and
what would determine it: the sentences ``pige identify --map`` prints under "not identifiable".

Three causes, each with its own words (CONVENTIONS §10; docs/maps.md §2):

- **the inner axis' zero-position error** (the axis nearest the measured point: C of an AC table, A of a fork
  head's stylus): a probe or an R-test measures a point of that axis' body against where the reference pose put it;
  a zero of the axis turns every measured point as the point's own angular position about the axis would, so no set
  of these files separates it from the set-up.  Remedy: none with these instruments, and none needed for a part set up
  on the machine (setting up the part measures its angular position); it stays uncorrected.
- **the outer axis' zero-position error with the inner axis' tilt about the same direction** (EA0A with EA0C on an
  AC table): they turn the measured points alike at every pose, the files see their difference only, and the fit
  puts it in the tilt (the zero taken as 0).  Remedy: an instrument that references the axis to gravity or the
  machine's axes (a precision level or inclinometer on the table at the axis' 0), not a pige instrument; the
  correction needs only the difference, entered with the tilt.
- **a PIGE hidden by a map the setups do not determine**: a PIGE is the mean and first harmonic of its axis' radial
  and tilt motions (CONVENTIONS §10).  Where the per-angle test holds an axis' motions free at every grid angle (two
  measured points leave the rotation about the line through them unseen), those free values take the PIGEs'
  functions too, so the PIGEs of that axis have no value.  Remedy: a third setup with the point off that line (the
  map test's plan proposes it), or the PIGEs identified without that axis' map (these files determine them alone).

Other combinations the fit does not see are given as the combination, with the generic remedy (a test that moves the
axes so that it changes the measured points).
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np


@dataclass
class NotIdentifiable:
    """PIGEs or zero-position errors without a value: which, the combination (when the fit names one), why, and what
    would determine them."""

    parameters: list[str]
    combination: str
    why: str
    remedy: str

    def to_dict(self) -> dict[str, Any]:
        return {"parameters": list(self.parameters), "combination": self.combination, "why": self.why,
                "remedy": self.remedy}

    def text(self) -> str:
        """One line: the combination (or the names), why, and what would determine them."""
        head = self.combination or f"{', '.join(self.parameters)} {'is' if len(self.parameters) == 1 else 'are'} " \
                                   "not identifiable"
        return f"{head}: {self.why}; to determine it: {self.remedy}"


def _names_in(combination: str, names: Sequence[str]) -> list[str]:
    return [n for n in names if re.search(rf"\b{re.escape(n)}\b", combination)]


def explain(kern: Any, names: Sequence[str], values: np.ndarray, combinations: Sequence[str],
            held_axes: dict[str, str], points: dict[str, list[np.ndarray]]) -> list[NotIdentifiable]:
    """Why each PIGE or zero-position error without a value has none (module docstring).

    Parameters
    ----------
    kern : KernelModule
    names : sequence of str
        The PIGEs and zero-position errors, in ``values``' order.
    values : (P,) [µm, µrad], NaN where undetermined
    combinations : sequence of str
        The combinations the fit of the PIGEs and zero-position errors does not see (``... is not identifiable``).
    held_axes : dict
        Axis → the per-angle test's reason, for each axis whose radial and tilt motions are held free at every grid
        angle (:func:`~pige_sym.identification.map_check.local_check`).
    points : dict
        Axis → the distinct measured points on its body [mm] (sphere or ball positions, stylus offsets).
    """
    out: list[NotIdentifiable] = []
    explained: set[str] = set()
    for combo in combinations:
        involved = _names_in(combo, names)
        if not involved:
            continue
        determined = {n for n in involved if np.isfinite(values[list(names).index(n)])}
        why, remedy = _zero_words(kern, involved, determined)
        out.append(NotIdentifiable(involved, combo, why, remedy))
        explained |= {n for n in involved if n in kern.ZERO_PARAMETERS or len(involved) == 1}
    for axis, reason in held_axes.items():
        hidden = [n for j, n in enumerate(names) if n.endswith("0" + axis) and n not in explained
                  and not np.isfinite(values[j]) and n in kern.LOCATION_PARAMETERS]
        if hidden:
            out.append(NotIdentifiable(hidden, "", *_hidden_words(kern, axis, hidden, reason, points.get(axis, []))))
            explained |= set(hidden)
    rest = [n for j, n in enumerate(names) if not np.isfinite(values[j]) and n not in explained]
    if rest:
        out.append(NotIdentifiable(rest, "", "the joint fit of the PIGEs and the maps does not determine it (a "
                                   "combination with map values that these setups do not see)",
                                   "a test whose setups determine every map value (pige's map test plan says which "
                                   "setups do)"))
    return out


def held_axes(layout: Any, undetermined: Sequence[Any]) -> dict[str, str]:
    """Axis → the per-angle test's reason, for each mapped axis whose radial or tilt motions are undetermined at every
    grid angle (a value the test holds free there takes the PIGEs' functions too)."""
    out: dict[str, str] = {}
    for axis, grid in layout.grids.items():
        motions = {m.name for m in layout.motions[axis] if m.kind in ("radial", "tilt")}
        angles: dict[float, str] = {}
        for u in undetermined:
            if u.angle_deg is not None and (u.motion in motions or u.motion == f"{axis} maps"):
                angles.setdefault(float(u.angle_deg), u.why.split("; not seen")[0])
        if grid.n and all(any(abs(a - float(g)) < 1e-9 for a in angles) for g in grid.angles_deg):
            first = angles[min(angles)]
            out[axis] = re.sub(r"near \S+ -?[\d.]+°", "near every grid angle", first)
    return out


def measured_points(items: Sequence[tuple[str, Any]], kern: Any) -> dict[str, list[np.ndarray]]:
    """Axis → the distinct measured points on its body [mm]: the ball or sphere positions for the axis nearest the
    workpiece, the tool offsets for the axis nearest the tool (1 µm apart at least)."""
    inner = inner_axis(kern)
    if inner is None:
        return {}
    found: list[np.ndarray] = []
    for _, x in items:
        if inner in kern.WORKPIECE_ROTARY:
            p = getattr(x, "ball_mm", None)
            if p is None:
                p = np.asarray(x.table_ball_mm) + np.asarray(x.offset_mm)
        else:
            p = getattr(x, "tool_mm", None)
        if p is not None and not any(np.abs(np.asarray(p, dtype=float) - q).max() < 1e-3 for q in found):
            found.append(np.asarray(p, dtype=float))
    return {inner: found}


def inner_axis(kern: Any) -> str | None:
    """The rotary axis nearest the measured point: the first on the workpiece side, else the last on the tool side."""
    if kern.WORKPIECE_ROTARY:
        return str(kern.WORKPIECE_ROTARY[0])
    return str(kern.TOOL_ROTARY[-1]) if kern.TOOL_ROTARY else None


def _zero_words(kern: Any, involved: list[str], determined: set[str]) -> tuple[str, str]:
    """Why and remedy of a combination of zero-position errors (and a tilt about the same direction); ``determined``:
    those of ``involved`` that have a value."""
    zeros = [n for n in involved if n in kern.ZERO_PARAMETERS]
    inner = inner_axis(kern)
    body = "table" if inner in kern.WORKPIECE_ROTARY else "spindle"
    if zeros == involved and len(zeros) == 1 and zeros[0].endswith("0" + str(inner)):
        return (f"a probe or an R-test measures a point on the {body} against where the reference pose put it; a "
                f"zero of {inner} turns every measured point as the point's own angular position about {inner} would "
                "(the set-up), so no set of these files separates them (CONVENTIONS §10)",
                f"no probe, R-test or ballbar setup does; it stays uncorrected (the controller's {inner} zero as it "
                f"is), which a part set up on the machine does not need: setting it up measures its angular position "
                f"about {inner}")
    if len(zeros) == 1 and len(involved) == 2:
        other = next(n for n in involved if n not in zeros)
        axis = zeros[0][-1]
        put = (f", which the fit puts in {other} ({zeros[0]} taken as 0)" if other in determined else
               f" ({other} has no value here either: see below)")
        return (f"{zeros[0]} (the zero of {axis}) and {other} turn the measured points alike at every pose these files "
                f"hold: they see one combination of the two{put}",
                f"not a probe, R-test or ballbar: an instrument that references {axis} to gravity or the machine's "
                f"axes (a precision level or inclinometer on the table at {axis} 0°) measures {zeros[0]} alone; the "
                f"correction needs only the combination, entered with {other}")
    return ("these files do not see this combination of them",
            "a test that moves the axes so that this combination changes the measured points (pige's plan of a test "
            "says what each test determines)")


def _hidden_words(kern: Any, axis: str, hidden: list[str], reason: str,
                  points: list[np.ndarray]) -> tuple[str, str]:
    """Why and remedy of PIGEs hidden by a map held free at every grid angle (module docstring)."""
    said = ", ".join(hidden)
    where = "table" if axis in kern.WORKPIECE_ROTARY else "spindle"
    geometry = ""
    if len(points) == 2:
        a, b = (", ".join(f"{x:.4g}" for x in p) for p in points)
        geometry = (f"; the measured point sits at two places on the {where}, ({a}) and ({b}) mm: a rotation about the "
                    f"line through them moves neither, at every {axis} angle, and one that varies with {axis} as "
                    f"cos {axis} or sin {axis} is what {said} describe")
    return (f"{said} are the mean and first harmonic of {axis}'s radial and tilt motions (CONVENTIONS §10); with "
            f"{axis}'s map fitted, these setups leave those motions undetermined at every grid angle ({reason}), so "
            f"the PIGEs of {axis} are not determined either{geometry}",
            f"a setup with the measured point at a further place on the {where}, off the line through the others "
            f"(three points not on one line: the map test's plan proposes them), or identify without mapping {axis} "
            "(these files determine the PIGEs alone)")
