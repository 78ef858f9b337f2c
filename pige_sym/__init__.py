"""pige_sym: identify the position-independent geometric errors (PIGEs) of five-axis machines.

Data flows one way: machine code string → symbolic model (SymPy, :mod:`pige_sym.symbolic`)
→ generated NumPy kernels (:mod:`pige_sym.emit`, ``generated/``) → runtime
(simulation, identification, diagnosis, compensation).  The runtime never imports SymPy.
"""

from .errors import PigeError
from .kernels import load_kernels
from .machine_code import MachineStructure, parse_machine_code

__all__ = ["PigeError", "MachineStructure", "load_kernels", "parse_machine_code"]
__version__ = "0.1.0"
