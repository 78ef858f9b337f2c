"""pige_sym: identify the position-independent geometric errors (PIGEs) of five-axis machines.

Data flows one way: machine code string → symbolic model (SymPy, :mod:`pige_sym.codegen.symbolic`)
→ generated NumPy kernels (:mod:`pige_sym.codegen.emit`, ``pige_sym/kernels/``) → runtime
(simulation, identification, diagnosis, compensation).  The runtime never imports SymPy.
"""

from pige_sym.codegen.machine_code import MachineStructure, parse_machine_code
from pige_sym.errors import PigeError
from pige_sym.kernels import load_kernels

__all__ = ["PigeError", "MachineStructure", "load_kernels", "parse_machine_code"]
__version__ = "0.1.0"
