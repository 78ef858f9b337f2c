"""``pige diagnose``: find what the PIGE model misses, name it, extend the model, measure the gain."""

from __future__ import annotations

import argparse
from typing import Any

from pige_sym.cli._setup import show_progress


def _check_plot_folder(args: argparse.Namespace, rotary_axes: tuple[str, ...]) -> None:
    """Before the long diagnosis: the plot folder must be a folder, and its PNGs are replaced only with --force."""
    from pathlib import Path

    from pige_sym.errors import InputError
    from pige_sym.files import check_output

    folder = Path(args.plots)
    if folder.exists() and not folder.is_dir():
        raise InputError(f"--plots {folder} is not a directory: give the folder the plots go into")
    names = ["residual_time", *(f"residual_{a}" for a in rotary_axes), "residual_rows", "residual_approach"]
    for name in names:
        check_output(folder / f"{name}.png", force=args.force, inputs=[args.file], what="--plots")


def _run_several(args: argparse.Namespace) -> int:
    """Several files (or a ballbar file): each file's own diagnosis and their agreement."""
    from pige_sym import api
    from pige_sym.cli._ballbar import plan_pointer
    from pige_sym.diagnosis.joint import format_joint_diagnosis
    from pige_sym.errors import InputError
    from pige_sym.files import to_json

    if args.plots:
        raise InputError("--plots draws the residuals of one R-test or probe file: diagnose that file alone")
    spec = _map_spec(args)
    result = api.diagnose_files(args.files, progress=show_progress(args.json), exclude=_mapped_effects(spec))
    gain = _map_gain(args, spec)
    if args.json:
        print(to_json(result.to_dict() | gain))
    else:
        print(format_joint_diagnosis(result) + plan_pointer(result.final, result.joint.files))
        _print_map_gain(args, spec, gain)
    return 0


def _map_spec(args: argparse.Namespace) -> Any:
    """``--map AXES [--map-step DEG] [--map-per-direction AXES]`` as a MapSpec (None without --map)."""
    from pige_sym.cli._maps import map_spec_option

    return map_spec_option(args, DIAGNOSE_MAP_STEP_DEG)


#: The default grid of ``pige diagnose --map`` [deg] (a coarse map answers "does a map explain the residual").
DIAGNOSE_MAP_STEP_DEG = 30.0


def _mapped_effects(spec: Any) -> list[str]:
    from pige_sym.diagnosis.map_gain import mapped_effects

    return mapped_effects(spec)


def _map_gain(args: argparse.Namespace, spec: Any) -> dict[str, object]:
    """``--map AXES``: the held-out gain of the error maps (:mod:`pige_sym.diagnosis.map_gain`), as JSON."""
    if spec is None:
        return {}
    from pige_sym.cli._maps import map_next_commands
    from pige_sym.diagnosis.map_gain import map_gain
    from pige_sym.measurements.sets import read_files

    items = read_files(args.files)
    gain = map_gain(items, spec)
    nxt = map_next_commands(args.files, items, spec, gain.explains())
    return {"map_gain": gain.to_dict() | {"sentences": gain.sentences(), "searched_without": _mapped_effects(spec),
                                          "next": nxt}}


def _print_map_gain(args: argparse.Namespace, spec: Any, gain: dict[str, Any]) -> None:
    if not gain:
        return
    doc = gain["map_gain"]
    print("\n" + "\n".join(doc["sentences"]))
    print(f"(the files' own diagnoses did not search {', '.join(doc['searched_without'])}: the maps hold every "
          "harmonic of those motions)")
    print("\n".join(doc["next"]))


def _run(args: argparse.Namespace) -> int:
    from pige_sym import api
    from pige_sym.diagnosis.residual_plots import residual_plots
    from pige_sym.files import to_json
    from pige_sym.identification.result import format_result
    from pige_sym.measurements.ballbar import is_ballbar_file

    if len(args.files) > 1 or is_ballbar_file(args.files[0]):
        return _run_several(args)
    args.file = args.files[0]
    spec = _map_spec(args)
    m = api.read(args.file)
    if args.plots:
        _check_plot_folder(args, m.rotary_axes)
    from pige_sym.diagnosis.diagnose import diagnose

    result = diagnose(m, progress=show_progress(args.json), exclude=_mapped_effects(spec))
    if args.plots:
        residual_plots(m, result, args.plots)
    gain = _map_gain(args, spec)
    if args.json:
        print(to_json(result.to_dict() | gain))
        return 0
    print(f"baseline PIGE fit: residual RMS {result.baseline_rms_um:.3f} um, held-out RMS "
          f"{result.baseline_heldout_rms_um:.3f} um, BIC {result.baseline_bic:.1f}")
    print(result.verdict())
    for c in result.clusters:
        print(f"note: {c}")
    if result.rejected:
        print("\nrejected candidates:")
        for r in result.rejected:
            print(f"  {r.effect}: {r.reason}")
    print("\nfinal estimates (with the accepted extensions):")
    print(format_result(result.final))
    if result.plots:
        print("\nplots: " + ", ".join(result.plots))
    _print_map_gain(args, spec, gain)
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "diagnose",
        help="what the PIGE model misses in R-test or probe files; do several files (ballbar setups too) agree?",
        description="Residual analysis, candidate extensions, identifiability, BIC/F-test/held-out gain. Several "
                    "files of one machine: each file's own diagnosis, an F test of whether they agree on one set "
                    "of PIGEs and which file does not, and the joint estimate.",
        epilog="examples:\n  pige diagnose run.csv --plots plots/\n  pige diagnose run.csv --json > diagnosis.json\n"
               "  pige diagnose radial_C.csv tangential_C.csv axial_C.csv rtest.csv   # do the setups agree?",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("files", nargs="+", metavar="FILE",
                   help="pige-rtest 1 measurement file (R-test or probe import); several files of one machine "
                        "(with pige-ballbar 1 setups) are diagnosed each alone and tested for agreement")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("--plots", metavar="DIR", help="write residual plots (PNG) into DIR")
    p.add_argument("--force", action="store_true", help="replace plots already in DIR")
    p.add_argument("--map", metavar="AXES", help="also fit the error maps of these axes (CONVENTIONS §10) and give "
                   "their held-out gain over the PIGEs alone, cross-validated by pose (docs/maps.md)")
    p.add_argument("--map-step", type=float, metavar="DEG", help="grid step of the maps [deg] (default 30)")
    p.add_argument("--map-per-direction", metavar="AXES",
                   help="map these axes' positioning error per approach direction, as pige identify does")
    p.set_defaults(handler=_run)
