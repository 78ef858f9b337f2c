"""Hash of a kernel module's inputs, computable without SymPy.

The hash covers the canonical machine code and the source text of the parser,
the symbolic model and the emitter, so a kernel written by an older generator
is recognised as stale.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

from pige_sym.codegen.machine_code import MachineStructure

GENERATOR_SOURCES = ("machine_code.py", "symbolic.py", "decompose.py", "templates.py", "emit.py", "kernel_helpers.py")


def current_hash(structure: MachineStructure) -> str:
    """SHA-256 (first 16 hex digits) of the canonical code and the generator sources."""
    h = hashlib.sha256()
    h.update(structure.canonical.encode())
    here = Path(__file__).parent
    for name in GENERATOR_SOURCES:
        h.update((here / name).read_bytes().replace(b"\r\n", b"\n"))
    return h.hexdigest()[:16]
