"""Runtime access to the generated NumPy kernels (no SymPy unless generating).

Where kernel modules live, one per machine, named after the canonical machine code
(``kin_wCpApbXYZ_C1_t.py`` for ``wC'A'bXYZ(C1)t``):

- the generated folder (:func:`generated_dir`): in a checkout the top-level ``generated/``, which
  holds the machines of :data:`~pige_sym.constants.SHIPPED_MACHINES` (tracked) and whatever
  ``make gen MACHINE=...`` / ``pige gen`` wrote; in an installed package ``pige_sym/generated``,
  the shipped machines the wheel carries, never written at run time;
- the user cache directory (``$PIGE_KERNEL_DIR``, else the platform's cache directory,
  e.g. ``~/.cache/pige_sym/kernels`` on Linux): kernels generated with SymPy on first use of a
  machine found in neither place, announced on stderr.

:func:`load_kernels` looks in that order and regenerates (into the cache, never into the
installation) a module whose generator fingerprint differs from the current generator's.
"""

from __future__ import annotations

import importlib.util
import os
import re
import sys
from pathlib import Path
from typing import cast

from pige_sym.codegen.machine_code import MachineStructure, parse_machine_code
from pige_sym.constants import DEFAULT_MACHINE, SHIPPED_MACHINES
from pige_sym.errors import KernelError
from pige_sym.kernels.protocol import KernelModule

__all__ = [
    "DEFAULT_MACHINE",
    "SHIPPED_MACHINES",
    "KernelModule",
    "cache_dir",
    "kernel_path",
    "load_kernels",
    "generated_dir",
    "in_checkout",
]

_CACHE: dict[str, KernelModule] = {}
_HASH_RE = re.compile(r"^# input hash\s*:\s*([0-9a-f]+)", re.MULTILINE)


def in_checkout() -> bool:
    """True when pige_sym runs from a source checkout (``pyproject.toml`` and ``generated/`` beside the package)."""
    root = Path(__file__).resolve().parents[2]
    return (root / "pyproject.toml").is_file() and (root / "generated" / "__init__.py").is_file()


def generated_dir() -> Path:
    """The generated folder: the checkout's top-level ``generated/``, else the installed ``pige_sym/generated``."""
    if in_checkout():
        return Path(__file__).resolve().parents[2] / "generated"
    return Path(__file__).resolve().parents[1] / "generated"


def cache_dir() -> Path:
    """Directory for kernels generated at run time (``$PIGE_KERNEL_DIR`` or the user cache)."""
    env = os.environ.get("PIGE_KERNEL_DIR")
    if env:
        return Path(env)
    from platformdirs import user_cache_dir

    return Path(user_cache_dir("pige_sym")) / "kernels"


def _file_hash(path: Path) -> str | None:
    with path.open(encoding="utf-8") as fh:
        head = fh.read(4000)
    m = _HASH_RE.search(head)
    return m.group(1) if m else None


def _locate(structure: MachineStructure) -> tuple[Path, bool]:
    """Where the machine's kernels are (generated folder if current, else the cache) and whether they are current."""
    from pige_sym.codegen.fingerprint import current_hash

    fingerprint = current_hash(structure)
    generated = generated_dir() / f"{structure.module_name}.py"
    if generated.is_file() and _file_hash(generated) == fingerprint:
        return generated, True
    cached = cache_dir() / f"{structure.module_name}.py"
    return cached, cached.is_file() and _file_hash(cached) == fingerprint


def kernel_path(code: str | MachineStructure) -> Path:
    """Path of the current kernel module of a machine: in the generated folder if current, else in the cache.

    The returned file may not exist yet; :func:`load_kernels` generates it there.
    """
    structure = parse_machine_code(code) if isinstance(code, str) else code
    return _locate(structure)[0]


def _generate(structure: MachineStructure, path: Path) -> None:
    print(
        f"pige: generating kernels for {structure.canonical} into {path.parent} (first use; `pige gen` does it ahead)",
        file=sys.stderr,
    )
    try:
        from pige_sym.codegen.emit import write_module
    except ImportError as exc:  # pragma: no cover - sympy missing
        raise KernelError(
            f"kernels for {structure.canonical} are missing and SymPy is not installed to generate them"
        ) from exc
    write_module(structure, path.parent)


def load_kernels(code: str | MachineStructure) -> KernelModule:
    """Import the kernel module of a machine, generating it into the cache if needed.

    Parameters
    ----------
    code : str or MachineStructure
        Machine structure code, e.g. ``"wC'A'bXYZ(C1)t"``.

    Returns
    -------
    KernelModule
        The generated module (see :class:`~pige_sym.kernels.protocol.KernelModule`).
    """
    if isinstance(code, str) and code in _CACHE:  # the exact spelling already loaded: no parse
        return _CACHE[code]
    structure = parse_machine_code(code) if isinstance(code, str) else code
    key = structure.canonical
    if key in _CACHE:
        if isinstance(code, str):
            _CACHE[code] = _CACHE[key]
        return _CACHE[key]
    path, current = _locate(structure)
    if not current:
        _generate(structure, path)
    spec = importlib.util.spec_from_file_location(f"pige_generated.{structure.module_name}", path)
    if spec is None or spec.loader is None:
        raise KernelError(f"cannot import generated kernels from {path}")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    kernels = cast(KernelModule, module)
    if kernels.MACHINE_CODE != key:
        raise KernelError(f"{path} holds kernels for {kernels.MACHINE_CODE!r}, not {key!r}: run pige gen")
    _CACHE[key] = kernels
    if isinstance(code, str):
        _CACHE[code] = kernels
    return kernels
