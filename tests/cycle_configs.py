"""LinuxCNC configurations for the cycle's unit tests (no LinuxCNC needed): written the way the shipped trt sims
are (LinuxCNC 2.9's ``sim/axis/vismach/5axis/table-rotary-tilting``: right-aligned keys, the M428/M429 switchkins
remaps and their NGC procedures, the offsets netted to signals and set with ``sets``, the rotation points with
``setp``), plus a configuration that loads pige's kinematics component."""

from __future__ import annotations

from pathlib import Path

SWITCH_SUB = """;M{code} by remap: kinstype=={kinstype}
o<{code}remap>sub
  #<kinstype> = {kinstype}
  #<SWITCHKINS_PIN> = 3
   M68  E#<SWITCHKINS_PIN> Q#<kinstype>
   M66  E0 L0
o<{code}remap>endsub
"""

STOCK_INI = """[EMC]
VERSION = 1.1
MACHINE = sim-{kind}-trt-kins (switchkins)

[DISPLAY]
             DISPLAY = axis
     POSITION_OFFSET = RELATIVE

[RS274NGC]
SUBROUTINE_PATH = ./remap_subs
   HAL_PIN_VARS = 1
          REMAP = M428  modalgroup=10  ngc=428remap
          REMAP = M429  modalgroup=10  ngc=429remap
 PARAMETER_FILE = {kind}.var

[KINS]
#NOTE: switchkins-type == 0 is identity kins
KINEMATICS = {kind}-trt-kins sparm=identityfirst
    JOINTS = 5

[HAL]
          HALUI = halui
        HALFILE = LIB:basic_sim.tcl
HALCMD = net :kinstype-select <= motion.analog-out-03 => motion.switchkins-type
HALCMD = net  :tool-offset  motion.tooloffset.z
HALCMD = net  :tool-offset  {kind}-trt-kins.tool-offset
HALCMD = net  :{off}-offset     {kind}-trt-kins.{off}-offset
HALCMD = net  :z-offset     {kind}-trt-kins.z-offset
HALCMD = sets :{off}-offset     {offv}
HALCMD = sets :z-offset     {zoff}

# not currently supported by the gui:
HALCMD = setp {kind}-trt-kins.x-rot-point 0
HALCMD = setp {kind}-trt-kins.y-rot-point 0
HALCMD = setp {kind}-trt-kins.z-rot-point 0

[TRAJ]
                COORDINATES = XYZ{tilt}C
               LINEAR_UNITS = mm
              ANGULAR_UNITS = deg
"""


def write_stock(folder: Path, kind: str = "xyzac") -> Path:
    """A stock trt configuration (module docstring) in ``folder``; its INI."""
    folder.mkdir(parents=True, exist_ok=True)
    tilt, off, offv, zoff = ("A", "y", 20, 10) if kind == "xyzac" else ("B", "x", -20, -15)
    ini = folder / f"{kind}-trt.ini"
    ini.write_text(STOCK_INI.format(kind=kind, tilt=tilt, off=off, offv=offv, zoff=zoff))
    subs = folder / "remap_subs"
    subs.mkdir(exist_ok=True)
    for code, kinstype in (("428", 1), ("429", 0)):
        (subs / f"{code}remap.ngc").write_text(SWITCH_SUB.format(code=code, kinstype=kinstype))
    (folder / f"{kind}-trt.tbl").write_text("T9 P9 Z30 D10\n")
    return ini


def write_pige_component(folder: Path) -> Path:
    """The same machine with pige's kinematics component (its PIGE pins set in a HAL file beside the INI)."""
    ini = write_stock(folder)
    text = ini.read_text().replace("KINEMATICS = xyzac-trt-kins sparm=identityfirst",
                                   "KINEMATICS = pige_xyzac_trt sparm=identityfirst")
    text = "\n".join(ln for ln in text.splitlines() if "trt-kins." not in ln or "tool-offset" in ln)
    text = text.replace("xyzac-trt-kins.tool-offset", "pige_xyzac_trt.tool-offset")
    text = text.replace("        HALFILE = LIB:basic_sim.tcl",
                        "        HALFILE = LIB:basic_sim.tcl\n        HALFILE = kins.hal")
    text = text.replace("HALCMD = sets :y-offset     20\nHALCMD = sets :z-offset     10\n", "")
    ini.write_text(text + "\n")
    lines = ["setp pige_xyzac_trt.sense-a -1", "setp pige_xyzac_trt.sense-c -1", "setp pige_xyzac_trt.pivot-a-y 20",
             "setp pige_xyzac_trt.pivot-a-z 10", "setp pige_xyzac_trt.pivot-a-x 0"]
    lines += [f"setp pige_xyzac_trt.pivot-c-{c} 0" for c in "xyz"]
    lines += [f"setp pige_xyzac_trt.{n} {v}" for n, v in
              (("ey0a", 1.5), ("ez0a", -2), ("eb0a", 0), ("ec0a", 0), ("ex0c", 3.25), ("ey0c", 0), ("ea0c", 0),
               ("eb0c", 0))]
    (folder / "kins.hal").write_text("# pige's component\n" + "\n".join(lines) + "\n")
    return ini


def install_args(ini: Path, *extra: str) -> list[str]:
    """``pige cycle install`` of the AC machine's cycle (the loop's sphere and stylus)."""
    return ["cycle", "install", str(ini), "--sphere", "20,10,15", "--sphere-radius", "6.35", "--stylus-radius", "1.5",
            "--stylus-tool", "9", "--stylus-length", "30", *extra]


def tree(folder: Path) -> dict[str, bytes]:
    """Every file under ``folder`` with its bytes."""
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}
