"""Names of pige's LinuxCNC kinematics component and of its HAL pins (no SymPy: the runtime uses them too).

The emitter (:mod:`pige_sym.codegen.targets.linuxcnc`) creates exactly these pins, and
``pige compensate --controller linuxcnc`` prints ``setp`` lines for them from the kernels'
metadata (``ROTARY_AXES``, ``PARAMETERS``, ``UNITS``, ``TOOL_ROTARY``).

Pins (all ``in``), for a component ``<name>``:

* ``<name>.pivot-<axis>-x|y|z`` [mm]: nominal pivot of each rotary axis, machine frame at the
  reference pose (CONVENTIONS §2);
* ``<name>.tool-x|y|z`` [mm]: only with a tool-side rotary axis, the tool tip without tool length
  relative to the last head pivot at the reference pose (CONVENTIONS §4 ``tool_mm``);
* ``<name>.tool-offset`` [mm]: the tool length along the spindle (net ``motion.tooloffset.z``);
* ``<name>.sense-<axis>`` (s32): the commanded sense σ, θ = σ·θ_cmd (CONVENTIONS §9), +1 at load;
* ``<name>.<pige>`` in lower case: each location error [µm, µrad] and zero-position error [µrad]
  (``<name>.ex0c``, ``<name>.eb0a``, ``<name>.ec0c``).
"""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence

from pige_sym.codegen.machine_code import MachineStructure, parse_machine_code
from pige_sym.errors import InputError, UnsupportedMachineError

_VALID_NAME = re.compile(r"[a-z][a-z0-9_]{0,47}")
#: The realtime modules LinuxCNC ships (``halcompile --install`` of a component with one of these names would
#: replace LinuxCNC's own): the components ``src/hal/components/*.comp`` and ``src/hal/drivers/*.comp`` and the
#: modules ``src/Makefile`` builds (``obj-m`` / ``obj-$(CONFIG_…)``), in LinuxCNC 2.9.0~pre1 (commit f1270d6ed7,
#: as Debian ships it), v2.9.10 and master 5c41560ebbc3, read from the source.
LINUXCNC_MODULES = frozenset({
    "5axiskins", "abs", "abs_s32", "abs_s64", "and2", "anglejog", "axistest", "bin2gray", "biquad", "bitmerge",
    "bitslice", "bitwise", "bldc", "blend", "boss_plc", "carousel", "charge_pump", "clarke2", "clarke3", "clarkeinv",
    "classicladder_rt", "comp", "constant", "corexy_by_hal", "corexykins", "counter", "dbounce", "ddt", "deadzone",
    "debounce", "demux", "demux_generic", "differential", "div2", "edge", "encoder", "encoder_ratio", "enum",
    "eoffset_per_angle", "estop_latch", "feedcomp", "filter_kalman", "flipflop", "gantry", "gearchange",
    "genhexkins", "genserkins", "gray2bin", "hal_ax5214h", "hal_bb_gpio", "hal_evoreg", "hal_gm", "hal_gpio",
    "hal_lib", "hal_motenc", "hal_parport", "hal_pi_gpio", "hal_ppmc", "hal_skeleton", "hal_speaker", "hal_stg",
    "hal_tiro", "hal_vti", "histobins", "histobinstream", "hm2_7i43", "hm2_7i90", "hm2_eth", "hm2_modbus", "hm2_pci",
    "hm2_rpspi", "hm2_spi", "hm2_spix", "hm2_test", "homecomp", "homemod", "hostmot2", "hypot", "ilowpass", "integ",
    "invert", "joint_axis_mapper", "joyhandle", "knob2float", "laserpower", "latencybins", "latencybinstream", "lcd",
    "led_dim", "limit1", "limit2", "limit3", "limit_axis", "lincurve", "lineardeltakins", "logic", "lowpass", "lut5",
    "maj3", "match8", "matrix_kb", "matrixkins", "max31855", "maxkins", "mesa_7i65", "mesa_pktgyro_test",
    "mesa_uart", "message", "millturn", "minmax", "modmath", "momentary2nist", "motmod", "moveoff", "mult2",
    "multiclick", "multiswitch", "mux16", "mux2", "mux4", "mux8", "mux_generic", "near", "not", "offset", "ohmic",
    "oneshot", "opto_ac5", "or2", "orient", "output_buffer", "pci_8255", "pcl720", "pentakins", "pi500_vfd", "pid",
    "plasmac", "pluto_servo", "pluto_step", "pumakins", "pushmsg", "pwmgen", "radiobutton", "raster", "reset",
    "rosekins", "rotarydeltakins", "rotatekins", "rtapi", "safety_latch", "sample_hold", "sampler", "scale",
    "scaled_s32_sums", "scarakins", "scope_rt", "scorbot-kins", "select8", "serport", "setsserial", "siggen",
    "sim_axis_hardware", "sim_encoder", "sim_home_switch", "sim_matrix_kb", "sim_parport", "sim_spindle",
    "simple_tp", "sphereprobe", "spindle", "spindle_monitor", "stepgen", "steptest", "streamer", "sum2", "supply",
    "thc", "thcud", "thermistor", "threads", "threadtest", "three21kins", "time", "timedelay", "timedelta", "tof",
    "toggle", "toggle2nist", "ton", "tp", "tpcomp", "tpmod", "tripodkins", "tristate_bit", "tristate_float",
    "trivkins", "updown", "userkins", "watchdog", "wcomp", "weighted_sum", "wj200_vfd", "xhc_hb04_util", "xor2",
    "xyzab_tdr_kins", "xyzac-trt-kins", "xyzacb_trsrn", "xyzbc-trt-kins", "xyzbca_trsrn"
})


def check_machine(structure: MachineStructure) -> None:
    """Refuse, with the reason, a machine LinuxCNC's joints cannot hold this way.

    Raises
    ------
    UnsupportedMachineError
    """
    linear = [a.name for a in structure.linear_axes]
    rotary = [a.name for a in structure.rotary_axes]
    if sorted(linear) != ["X", "Y", "Z"]:
        raise UnsupportedMachineError(f"machine {structure.canonical!r}: the LinuxCNC component needs exactly the "
                                      f"linear axes X, Y, Z (has {', '.join(linear)})")
    if any(len(r) != 1 for r in rotary) or len(set(rotary)) != len(rotary):
        raise UnsupportedMachineError(f"machine {structure.canonical!r}: LinuxCNC has one A, B and C coordinate; "
                                      f"rotary axes {', '.join(rotary)} cannot be mapped")
    if structure.spindle is not None and structure.spindle[0] != "C":
        raise UnsupportedMachineError(f"machine {structure.canonical!r}: LinuxCNC applies the tool length along Z "
                                      f"(motion.tooloffset.z) but the spindle {structure.spindle} is not along Z")


def default_name(code: str | MachineStructure) -> str:
    """``pige_xyz<rotary letters>_<trt|head|mixed>``, e.g. ``pige_xyzac_trt``, ``pige_xyzbc_mixed``."""
    structure = parse_machine_code(code) if isinstance(code, str) else code
    sides = {a.side for a in structure.rotary_axes}
    kind = "trt" if sides == {"workpiece"} else "head" if sides == {"tool"} else "mixed"
    return "pige_xyz" + "".join(a.name.lower() for a in structure.rotary_axes) + "_" + kind


def check_name(name: str) -> str:
    """A component name halcompile and HAL accept (lower case letters, digits, ``_``), not one of
    :data:`LINUXCNC_MODULES`; returns it.

    Raises
    ------
    InputError
    """
    if not _VALID_NAME.fullmatch(name):
        raise InputError(f"--name {name!r}: a LinuxCNC component name is a lower-case letter followed by up to 47 "
                         "lower-case letters, digits or '_' (it is the .comp file name and a C identifier)")
    if name in LINUXCNC_MODULES:
        raise InputError(f"--name {name}: LinuxCNC ships a module of that name, and halcompile --install would "
                         "replace it; choose a name of your own (default pige_xyz<rotary>_<trt|head|mixed>)")
    return name


def pin_names(name: str, rotary_axes: Sequence[str], parameters: Sequence[str], units: Mapping[str, str],
              tool_rotary: bool) -> dict[str, str]:
    """HAL pin → what it holds [unit], in the order the component creates them.

    Parameters
    ----------
    name : str
        Component name (the pin prefix).
    rotary_axes : sequence of str
        The kernels' ``ROTARY_AXES``.
    parameters : sequence of str
        The kernels' ``PARAMETERS`` (location errors, then zero-position errors).
    units : mapping
        The kernels' ``UNITS`` (``"um"`` or ``"urad"`` per parameter).
    tool_rotary : bool
        Whether a tool-side rotary axis exists (then the ``tool-x|y|z`` pins exist).
    """
    pins: dict[str, str] = {}
    for axis in rotary_axes:
        for c in "xyz":
            pins[f"{name}.pivot-{axis.lower()}-{c}"] = f"nominal pivot of {axis}, machine {c.upper()} [mm]"
    if tool_rotary:
        for c in "xyz":
            pins[f"{name}.tool-{c}"] = (f"tool tip without tool length, relative to the last head pivot, "
                                        f"{c.upper()} at the reference pose [mm]")
    pins[f"{name}.tool-offset"] = "tool length along the spindle [mm]; net motion.tooloffset.z to it"
    for axis in rotary_axes:
        pins[f"{name}.sense-{axis.lower()}"] = f"commanded sense of {axis} (s32): +1 CONVENTIONS, -1 reversed"
    for p in parameters:
        zero = p[1:2] == p[3:4]
        pins[error_pin(name, p)] = f"{p} [{units[p]}]" + (" zero-position error" if zero else "")
    return pins


def error_pin(name: str, parameter: str) -> str:
    """The pin of one PIGE or zero-position error, e.g. ``pige_xyzac_trt.ex0c``."""
    return f"{name}.{parameter.lower()}"
