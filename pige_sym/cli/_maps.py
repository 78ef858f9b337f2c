"""Options of a map test (``pige plan --map``, ``pige program --instrument sphere-probe --map``): the grid, the
ranges and the setups (:mod:`pige_sym.planning.map_setups`)."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from pige_sym.cli._setup import finite_option, parse_vec3
from pige_sym.errors import InputError


def add_map_arguments(p: argparse.ArgumentParser) -> None:
    """The map options shared by ``plan`` and ``program``."""
    g = p.add_argument_group("error maps of the rotary axes (CONVENTIONS §10; docs/maps.md)")
    g.add_argument("--map", metavar="AXES", help="plan (or write) the test of these axes' error maps, e.g. C,A")
    g.add_argument("--map-step", type=float, default=15.0, metavar="DEG", help="grid step [deg] (default %(default)s)")
    g.add_argument("--map-per-direction", metavar="AXES",
                   help="map these axes' positioning error per approach direction: every angle met from both sides")
    g.add_argument("--map-range", action="append", metavar="AXIS=lo:hi",
                   help="range of an axis that does not turn fully [deg] (default 0:90 on a table, -45:45 on a head)")
    g.add_argument("--map-point", action="append", metavar="x,y,z",
                   help="measured point of a setup on the workpiece side [mm]: sphere centre, R-test ball or table "
                        "ball (repeatable, one per setup; default: the given one turned by 120 and 240 deg)")
    g.add_argument("--map-tool", action="append", metavar="x,y,z",
                   help="stylus (ball) centre from the last tool-side pivot of a setup [mm] (repeatable; default: "
                        "--tool, one --map-extension longer, one --map-offset across)")
    g.add_argument("--map-extension", type=float, default=100.0, metavar="MM",
                   help="head axes: the proposed longer tool [mm] (default %(default)s)")
    g.add_argument("--map-offset", type=float, default=50.0, metavar="MM",
                   help="head axes: the proposed offset stylus across the spindle axis [mm] (default %(default)s)")
    g.add_argument("--map-setups", type=int, metavar="N",
                   help="use exactly N setups (default: the fewest that determine every value)")


def axes_option(text: str | None, what: str) -> tuple[str, ...]:
    """``C,A`` as ("C", "A") (None: ``()``); an empty list, an empty item or an axis given twice is refused."""
    from pige_sym.options import parse_names

    return parse_names(text, what, "C,A")


def map_axes(args: argparse.Namespace, kern: Any = None) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """``--map`` and ``--map-per-direction`` (every ``pige`` command that maps): the axes, each a rotary axis of the
    machine when its kernels ``kern`` are given, an axis per direction mapped too.

    Raises
    ------
    InputError
    """
    axes = axes_option(args.map, "--map")
    per_direction = axes_option(getattr(args, "map_per_direction", None), "--map-per-direction")
    bad = [a for a in axes + per_direction if kern is not None and a not in kern.ROTARY_AXES]
    if bad:
        raise InputError(f"--map {','.join(bad)}: give rotary axes of {kern.MACHINE_CODE} "
                         f"({', '.join(kern.ROTARY_AXES)})")
    extra = [a for a in per_direction if a not in axes]
    if extra:
        raise InputError(f"--map-per-direction {','.join(extra)}: map the axis too "
                         f"(--map {','.join(axes + tuple(extra))})")
    return axes, per_direction


def map_step(step: float | None, axes: tuple[str, ...]) -> float:
    """``--map-step`` (default 15) checked for every mapped axis by the one check of identify, plan and program
    (:func:`~pige_sym.model.error_motions.check_map_step`)."""
    from pige_sym.identification.maps import DEFAULT_MAP_STEP_DEG
    from pige_sym.model.error_motions import check_map_step

    value = DEFAULT_MAP_STEP_DEG if step is None else step
    for axis in axes or (None,):
        check_map_step(value, axis)
    return float(value)


def map_request(args: argparse.Namespace, kern: Any, instrument: str, *, point: Any, tool: Any = None,
                probe: Any = None, pivots: Any = None, noise_um: float, pose_s: float,
                contact_s: float = 0.0) -> Any:
    """The :class:`~pige_sym.planning.map_setups.MapTestRequest` of the options."""
    import numpy as np

    from pige_sym.identification.maps import MapSpec
    from pige_sym.planning.map_setups import MapTestRequest, map_ranges

    axes, per_direction = map_axes(args, kern)
    if args.map_setups is not None and args.map_setups < 1:
        raise InputError(f"--map-setups {args.map_setups}: give 1 or more")
    points = tuple(np.array(parse_vec3(x, "--map-point")) for x in args.map_point or [])
    tools = tuple(np.array(parse_vec3(x, "--map-tool")) for x in args.map_tool or [])
    return MapTestRequest(
        kern.MACHINE_CODE, instrument, MapSpec(axes, map_step(args.map_step, axes), per_direction),
        map_ranges(kern, args.map_range), np.asarray(point, dtype=float),
        None if tool is None else np.asarray(tool, dtype=float), noise_um, points, tools,
        finite_option(args.map_extension, "--map-extension", positive=True),
        finite_option(args.map_offset, "--map-offset", positive=True), probe,
        {a: np.asarray(v, dtype=float) for a, v in (pivots or {}).items()}, pose_s, contact_s, args.map_setups,
        _target(args))


def _target(args: argparse.Namespace) -> float | None:
    """``--target``: a positive finite std [µm or µrad], or None."""
    target = getattr(args, "target", None)
    return None if target is None else finite_option(target, "--target", positive=True)


def numbered(out: str, count: int) -> list[Path]:
    """``map.ngc`` → ``map_1.ngc`` … ``map_<count>.ngc``: one program per setup."""
    path = Path(out)
    return [path.with_name(f"{path.stem}_{i}{path.suffix}") for i in range(1, count + 1)]


def map_options_text(args: argparse.Namespace, setups: int) -> str:
    """The map options as given, for the next command (``pige program``) to write the same setups."""
    parts = [f"--map {args.map}", f"--map-step {args.map_step:g}", f"--map-setups {setups}"]
    if args.map_per_direction:
        parts.append(f"--map-per-direction {args.map_per_direction}")
    parts += [f"--map-range {r}" for r in args.map_range or []]
    parts += [f"--map-point {x}" for x in args.map_point or []]
    parts += [f"--map-tool {x}" for x in args.map_tool or []]
    if args.map_extension != 100.0:
        parts.append(f"--map-extension {args.map_extension:g}")
    if args.map_offset != 50.0:
        parts.append(f"--map-offset {args.map_offset:g}")
    return " ".join(parts)


def identify_map_options(spec: Any) -> str:
    """``--map C,A --map-step 30 [--map-per-direction C]``: the options ``pige identify`` fits ``spec`` with."""
    out = f"--map {','.join(spec.axes)} --map-step {spec.step_deg:g}"
    return out + (f" --map-per-direction {','.join(spec.per_direction)}" if spec.per_direction else "")


def map_next_commands(paths: list[str], items: list[tuple[str, Any]], spec: Any, explains: bool) -> list[str]:
    """What to run next after ``pige diagnose --map`` (:func:`pige_sym.report.map_section.next_commands`, the same
    commands the map report gives), with the sentence before them."""
    from pige_sym.report.map_section import next_commands

    commands = next_commands([(str(p), x) for p, (_, x) in zip(paths, items, strict=True)], spec, explains)
    said = ("the maps explain what the PIGEs miss; write them as a parameter file and correct with them" if explains
            else "the maps do not explain enough to be worth entering; write the PIGEs as a parameter file and "
            "correct with them")
    return [f"next: {said} (the second command corrects an NC program too: give it the program and --out):",
            *(f"  {c}" for c in commands)]


def map_spec_option(args: argparse.Namespace, default_step_deg: float) -> Any:
    """``--map AXES [--map-step DEG] [--map-per-direction AXES]`` of a command that fits maps from files (diagnose,
    report) as a MapSpec, None without ``--map`` (the axes and the step checked as identify, plan and program
    check them: :func:`map_axes`, :func:`map_step`)."""
    from pige_sym.identification.maps import MapSpec

    if args.map is None:
        if args.map_step is not None:
            raise InputError("--map-step goes with --map AXES")
        if getattr(args, "map_per_direction", None):
            raise InputError("--map-per-direction goes with --map AXES")
        return None
    axes, per_direction = map_axes(args)
    return MapSpec(axes, map_step(default_step_deg if args.map_step is None else args.map_step, axes), per_direction)
