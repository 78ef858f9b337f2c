"""Defaults shared by every command and module (one place for each number).

Lengths in mm.  Changing a value here changes it for the CLI, the simulator, the
studies, the virtual device and the NC program writer alike.
"""

from __future__ import annotations

#: Machine used when no ``--machine`` is given: an AC tilting table (ISO 10791 code).
DEFAULT_MACHINE = "wC'A'bXYZ(C1)t"

#: Machines whose kernels ship inside the package (``pige_sym/kernels/shipped``) and are
#: checked by ``make check-generated``.  The Makefile reads this list from here.
SHIPPED_MACHINES: tuple[str, ...] = (
    "wC'A'bXYZ(C1)t",
    "wC'B'bXYZ(C1)t",
    "wbXYZCA(C1)t",
    "wC'bXYZB(C1)t",
)

#: Ball centre at the reference pose, workpiece frame [mm] (CONVENTIONS §4).
DEFAULT_BALL_MM: tuple[float, float, float] = (120.0, 0.0, 80.0)
