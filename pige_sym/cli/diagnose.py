"""``pige diagnose``: find what the PIGE model misses, name it, extend the model, measure the gain."""

from __future__ import annotations

import argparse

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
    result = api.diagnose_files(args.files, progress=show_progress(args.json))
    gain = _map_gain(args)
    if args.json:
        print(to_json(result.to_dict() | gain))
    else:
        print(format_joint_diagnosis(result) + plan_pointer(result.final, result.joint.files))
        _print_map_gain(gain)
    return 0


def _map_gain(args: argparse.Namespace) -> dict[str, object]:
    """``--map AXES``: the held-out gain of the error maps (:mod:`pige_sym.diagnosis.map_gain`), as JSON."""
    if args.map is None:
        if args.map_step is not None:
            from pige_sym.errors import InputError

            raise InputError("--map-step goes with --map AXES")
        return {}
    from pige_sym.cli._maps import axes_option, map_step
    from pige_sym.diagnosis.map_gain import map_gain
    from pige_sym.identification.maps import MapSpec
    from pige_sym.measurements.sets import read_files

    axes = axes_option(args.map, "--map")
    step = map_step(30.0 if args.map_step is None else args.map_step, axes)
    gain = map_gain(read_files(args.files), MapSpec(axes, step))
    return {"map_gain": gain.to_dict() | {"sentences": gain.sentences()}}


def _print_map_gain(gain: dict[str, object]) -> None:
    if gain:
        print("\n" + "\n".join(gain["map_gain"]["sentences"]))  # type: ignore[index]


def _run(args: argparse.Namespace) -> int:
    from pige_sym import api
    from pige_sym.diagnosis.residual_plots import residual_plots
    from pige_sym.files import to_json
    from pige_sym.identification.result import format_result
    from pige_sym.measurements.ballbar import is_ballbar_file

    if len(args.files) > 1 or is_ballbar_file(args.files[0]):
        return _run_several(args)
    args.file = args.files[0]
    m = api.read(args.file)
    if args.plots:
        _check_plot_folder(args, m.rotary_axes)
    result = api.diagnose(m, progress=show_progress(args.json))
    if args.plots:
        residual_plots(m, result, args.plots)
    gain = _map_gain(args)
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
    _print_map_gain(gain)
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
    p.set_defaults(handler=_run)
