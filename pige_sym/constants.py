"""Defaults shared by every command and module (one place for each number).

Lengths in mm.  Changing a value here changes it for the CLI, the simulator, the
studies, the virtual device and the NC program writer alike.
"""

from __future__ import annotations

#: The package version (``pige --version``, reports); pyproject.toml carries the same number.
VERSION = "0.1.0"

#: Machine used when no ``--machine`` is given: an AC tilting table (ISO 10791 code).
DEFAULT_MACHINE = "wC'A'bXYZ(C1)t"

#: Machines whose kernels are tracked in ``generated/`` (shipped in the wheel as ``pige_sym.generated``) and are
#: checked by ``make check-generated``.  The Makefile reads this list from here.
SHIPPED_MACHINES: tuple[str, ...] = (
    "wC'A'bXYZ(C1)t",
    "wC'B'bXYZ(C1)t",
    "wbXYZCA(C1)t",
    "wC'bXYZB(C1)t",
)

#: The R-test's nominal noise per deviation component [µm]: what ``pige plan`` and ``pige simulate`` assume, and
#: what ``pige identify``'s model check judges an R-test file's residual against unless ``--noise`` states it.
RTEST_NOISE_UM = 0.25

#: Largest magnitude of a PIGE, an effect parameter or a map value [µm or µrad]: 10 mm or 10 mrad is far beyond a
#: machine that runs at all (every file reader refuses more).
MAX_PIGE = 1e4

#: Ball centre at the reference pose, workpiece frame [mm] (CONVENTIONS §4).
DEFAULT_BALL_MM: tuple[float, float, float] = (120.0, 0.0, 80.0)

# ---- choices of command-line options (defined here so that building the command line stays light)

#: Acquisition triggers: settle detection, program schedule, operator key.
TRIGGERS: tuple[str, ...] = ("stable", "schedule", "key")
#: Device protocols of ``pige acquire --protocol`` (adapters in pige_sym.acquisition.device).
DEVICE_PROTOCOLS: tuple[str, ...] = ("gauge", "rtest")
#: Faults the virtual R-test device can inject (pige rtest-sim --faults).
FAULT_KINDS: tuple[str, ...] = ("garbage", "checksum", "drop", "spike", "duplicate", "stall", "disconnect")
#: Identification methods and losses.
METHODS: tuple[str, ...] = ("gauss-newton", "double-differential")
LOSSES: tuple[str, ...] = ("linear", "soft_l1", "huber")
#: NC dialects (input and output of pige compensate / pige program).
DIALECTS: tuple[str, ...] = ("siemens", "fanuc", "linuxcnc")
#: Test-program schedule: move time and dwell per pose [s].
DEFAULT_MOVE_S = 5.0
DEFAULT_DWELL_S = 7.0
#: Largest change pige compensate may make to a word without refusing the program [mm], [deg].
DEFAULT_MAX_CHANGE_MM = 0.2
DEFAULT_MAX_CHANGE_DEG = 0.1
#: Travel of a rotary axis that does not turn fully (A, B) on which controller entries are judged, unless
#: ``pige compensate --travel`` gives it [deg, CONVENTIONS angle].  A full-turn C axis is judged on 0-360 deg.
DEFAULT_TILT_TRAVEL_DEG: tuple[float, float] = (-90.0, 90.0)
#: The dialects pige writes probing programs in (``--dialect``).
PROBE_DIALECTS = ("linuxcnc", "fanuc", "siemens", "heidenhain")
#: The touch-probe log layouts ``pige import-probe --format`` reads: the log each dialect's program writes.
PROBE_FORMATS = PROBE_DIALECTS
