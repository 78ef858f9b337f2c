"""pige_sym: identify the position-independent geometric errors (PIGEs) of five-axis machines.

Data flows one way: machine code string → symbolic model (SymPy, :mod:`pige_sym.codegen.symbolic`)
→ generated NumPy kernels (:mod:`pige_sym.codegen.emit`, ``pige_sym/kernels/``) → runtime
(simulation, identification, diagnosis, compensation).  The runtime never imports SymPy.
"""

from typing import TYPE_CHECKING, Any

from pige_sym.constants import VERSION as __version__

if TYPE_CHECKING:
    from pige_sym.codegen.machine_code import MachineStructure, parse_machine_code
    from pige_sym.errors import PigeError
    from pige_sym.kernels import load_kernels

__all__ = ["PigeError", "MachineStructure", "load_kernels", "parse_machine_code", "__version__"]

_LAZY = {
    "PigeError": "pige_sym.errors",
    "MachineStructure": "pige_sym.codegen.machine_code",
    "parse_machine_code": "pige_sym.codegen.machine_code",
    "load_kernels": "pige_sym.kernels",
}


def __getattr__(name: str) -> Any:
    """The public names, imported on first use (``import pige_sym`` stays as cheap as the command line)."""
    if name in _LAZY:
        import importlib

        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'pige_sym' has no attribute {name!r}")
