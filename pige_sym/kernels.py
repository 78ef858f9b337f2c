"""Runtime access to the generated NumPy kernels (no SymPy unless generating).

Kernel modules live in ``generated/`` at the repository root (override with the
environment variable ``PIGE_GENERATED_DIR``), one per machine, named after the
canonical machine code (``kin_wCpApbXYZ_C1_t.py`` for ``wC'A'bXYZ(C1)t``).
:func:`load_kernels` imports one, generating it first if it is absent or stale
(its input hash differs from the current generator's); generation needs SymPy
and is announced on stderr.
"""

from __future__ import annotations

import importlib.util
import os
import re
import sys
from pathlib import Path
from types import ModuleType
from typing import Any

from .errors import KernelError
from .machine_code import MachineStructure, parse_machine_code

_CACHE: dict[str, ModuleType] = {}
DEFAULT_MACHINE = "wC'A'bXYZ(C1)t"
#: Machines whose kernels ship in generated/ and are checked by `make check-generated`.
SHIPPED_MACHINES = ("wC'A'bXYZ(C1)t", "wC'B'bXYZ(C1)t", "wbXYZCA(C1)t", "wC'bXYZB(C1)t")


def generated_dir() -> Path:
    """Directory holding the generated kernel modules."""
    env = os.environ.get("PIGE_GENERATED_DIR")
    if env:
        return Path(env)
    return Path(__file__).resolve().parent.parent / "generated"


def kernel_path(code: str | MachineStructure) -> Path:
    """Path of the generated module for a machine code."""
    structure = parse_machine_code(code) if isinstance(code, str) else code
    return generated_dir() / f"{structure.module_name}.py"


_HASH_RE = re.compile(r"^# input hash\s*:\s*([0-9a-f]+)", re.MULTILINE)


def _file_hash(path: Path) -> str | None:
    head = path.read_text(encoding="utf-8")[:4000]
    m = _HASH_RE.search(head)
    return m.group(1) if m else None


def load_kernels(code: str | MachineStructure, *, regenerate_stale: bool = True) -> Any:
    """Import the generated kernel module of a machine, generating it if needed.

    Parameters
    ----------
    code : str or MachineStructure
        Machine structure code, e.g. ``"wC'A'bXYZ(C1)t"``.
    regenerate_stale : bool
        Regenerate when the module was produced by a different generator version.

    Returns
    -------
    module
        Exposes ``MACHINE_CODE``, ``ROTARY_AXES``, ``PARAMETERS``, ``UNITS``,
        ``deviation``, ``jacobian``, ``basis``, ``coefficients`` and the nominal
        kinematics (see :mod:`pige_sym.emit`).
    """
    structure = parse_machine_code(code) if isinstance(code, str) else code
    key = structure.canonical
    if key in _CACHE:
        return _CACHE[key]
    path = kernel_path(structure)
    need = not path.exists()
    if not need and regenerate_stale:
        from .emit_hash import current_hash

        need = _file_hash(path) != current_hash(structure)
    if need:
        print(
            f"pige: generating kernels for {key} into {path.parent} (first use; `make gen` does this ahead)",
            file=sys.stderr,
        )
        try:
            from .emit import write_module
        except ImportError as exc:  # pragma: no cover - sympy missing
            raise KernelError(f"kernels for {key} are missing and SymPy is not installed to generate them") from exc
        write_module(structure, path.parent)
    spec = importlib.util.spec_from_file_location(f"pige_generated.{structure.module_name}", path)
    if spec is None or spec.loader is None:
        raise KernelError(f"cannot import generated kernels from {path}")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    if module.MACHINE_CODE != key:
        raise KernelError(f"{path} holds kernels for {module.MACHINE_CODE!r}, not {key!r}: run make gen")
    _CACHE[key] = module
    return module
