"""``pige gen``: derive the error model with SymPy and write the NumPy kernels of machine codes."""

from __future__ import annotations

import argparse
from pathlib import Path


def _run(args: argparse.Namespace) -> int:
    from pige_sym.codegen.emit import render_module, same_code, write_module
    from pige_sym.codegen.machine_code import parse_machine_code
    from pige_sym.kernels import cache_dir, shipped_dir

    if args.out:
        out_dir = Path(args.out)
    elif args.shipped or args.check:
        out_dir = shipped_dir()
    else:
        out_dir = cache_dir()
    from pige_sym.constants import SHIPPED_MACHINES
    from pige_sym.errors import InputError

    codes = list(args.codes) + (list(SHIPPED_MACHINES) if args.all_shipped else [])
    if not codes:
        raise InputError("give at least one machine code, or --all-shipped")
    structures = [parse_machine_code(c) for c in codes]
    status = 0
    for st in structures:
        path = out_dir / f"{st.module_name}.py"
        if not args.check:
            print(f"wrote {write_module(st, out_dir)}")
            continue
        if not path.exists():
            print(f"MISSING {path} (machine {st.canonical}): run make gen-all and commit the result")
            status = 1
        elif not same_code(path.read_text(encoding="utf-8"), render_module(st)):
            print(f"DIFFERS {path} (machine {st.canonical}): run make gen-all and commit the result")
            status = 1
        else:
            print(f"ok      {path}")
    return status


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``pige gen``."""
    p = sub.add_parser(
        "gen",
        help="generate NumPy kernels for machine codes",
        description=(
            "Derive the error model with SymPy and write a NumPy kernel module per machine code. "
            "Kernels go to the user cache (PIGE_KERNEL_DIR overrides it), where pige finds them; "
            "--shipped writes the package's own kernels (developers, make gen-all)."
        ),
        epilog="example:\n  pige gen \"wC'B'bXYZ(C1)t\"\n  pige gen --check --all-shipped",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("codes", nargs="*", metavar="CODE", help="ISO 10791 machine structure code")
    p.add_argument("--all-shipped", action="store_true", help="every machine whose kernels ship with the package")
    where = p.add_mutually_exclusive_group()
    where.add_argument("--out", help="output directory (default: the user kernel cache)")
    where.add_argument("--shipped", action="store_true", help="write into the package's shipped kernels")
    p.add_argument(
        "--check", action="store_true",
        help="regenerate in memory and fail on any code difference (the SymPy version line is not compared)",
    )
    p.set_defaults(handler=_run)
