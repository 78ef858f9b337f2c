"""Entering what pige prints into the shipped configurations: the correction, two ways (issue 31, item 4).

(a) **The stock trt pins.**  ``pige compensate --controller linuxcnc --current <today's pins>`` prints absolute
``setp <module>.<pin> <value>`` lines.  The shipped INIs set the offsets through signals
(``HALCMD = net :y-offset xyzac-trt-kins.y-offset`` … ``HALCMD = sets :y-offset 20``), where HAL refuses a
``setp`` of the pin (``pin 'xyzac-trt-kins.y-offset' is connected to a signal``): a shop edits the
``sets`` line instead, and the ``setp`` lines of the rotation points.  :func:`enter_trt_pins` does exactly that,
each edit matching the one line it expects.  The corrected axis lines (:func:`trt_lines`, from trtfuncs.c:
C through ``(x-rot-point, y-rot-point)``, A through ``(y-rot-point + y-offset, z-rot-point + z-offset)``, B
through ``(x-rot-point + x-offset, z-rot-point + z-offset)``) are what the next program is written for.

(b) **pige's kinematics.**  ``pige gen --target linuxcnc`` writes the component; ``pige compensate`` prints its
``setp`` lines (nominal pivots, senses, the identified PIGEs); :func:`kinematics_changes` loads it instead of
the stock module and enters those lines, nothing else.
"""

from __future__ import annotations

import re
from pathlib import Path

from lcnc_harness import IniChange
from loop_setup import Machine, pige
from stock_trt import stock_pins

TRT_MODULE = {"xyzac": "xyzac-trt-kins", "xyzbc": "xyzbc-trt-kins"}
ROT_POINTS = ("x-rot-point", "y-rot-point", "z-rot-point")


def printed_setp(text: str, module: str) -> dict[str, float]:
    """``{pin: value}`` of the ``setp <module>.<pin> <value>`` lines pige printed."""
    rx = re.compile(rf"^setp {re.escape(module)}\.(\S+)\s+(\S+)\s*$", flags=re.M)
    return {pin: float(value) for pin, value in rx.findall(text)}


def current_pins(kind: str) -> dict[str, float]:
    """Today's pins of the shipped configuration (its sets/setp lines)."""
    return dict.fromkeys(ROT_POINTS, 0.0) | stock_pins(kind)


def trt_correction(m: Machine, params: Path) -> tuple[str, dict[str, float]]:
    """What ``pige compensate --controller linuxcnc --current ...`` prints, and its trt ``setp`` values."""
    current = ",".join(f"{k}={v:g}" for k, v in current_pins(m.kind).items())
    text = pige("compensate", "--params", str(params), "--controller", "linuxcnc", "--current", current,
                cwd=params.parent)
    return text, printed_setp(text, TRT_MODULE[m.kind])


def enter_trt_pins(kind: str, pins: dict[str, float]) -> list[IniChange]:
    """The INI edits that enter ``pins``: the ``sets`` line of a netted pin, the ``setp`` line otherwise."""
    module = TRT_MODULE[kind]
    out = []
    for pin, value in pins.items():
        if pin in stock_pins(kind):
            out.append(IniChange(f"{module}.{pin} is netted to :{pin}: set the signal",
                                 rf"^(HALCMD = sets :{pin})\s+\S+\s*$", rf"\g<1> {value!r}"))
        elif pin in ROT_POINTS:
            out.append(IniChange(f"{module}.{pin}", rf"^(HALCMD = setp {module}\.{pin})\s+\S+\s*$",
                                 rf"\g<1> {value!r}"))
        else:
            raise AssertionError(f"pige printed a pin the shipped configuration does not set: {module}.{pin}")
    return out


def trt_lines(kind: str, pins: dict[str, float]) -> dict[str, tuple[float, float, float]]:
    """The axis lines the trt kinematics hold with ``pins`` (module docstring), as ``--pivot`` points."""
    p = current_pins(kind) | pins
    xr, yr, zr = (p[k] for k in ROT_POINTS)
    if kind == "xyzac":
        return {"A": (0.0, yr + p["y-offset"], zr + p["z-offset"]), "C": (xr, yr, zr)}
    return {"B": (xr + p["x-offset"], 0.0, zr + p["z-offset"]), "C": (xr, yr, zr)}


def pige_kinematics(m: Machine, params: Path, out: Path) -> tuple[str, str, list[str]]:
    """``pige gen --target linuxcnc``: (component name, its source, the ``setp`` lines compensate prints)."""
    from pige_sym.codegen.targets.linuxcnc_pins import default_name

    name = default_name(m.code)
    pige("gen", "--target", "linuxcnc", m.code, "--out", str(out), "--force", cwd=out.parent)
    text = pige("compensate", "--params", str(params), "--controller", "linuxcnc", cwd=params.parent)
    lines = [ln.strip() for ln in text.splitlines() if ln.startswith(f"setp {name}.")]
    return name, (out / f"{name}.comp").read_text(), lines


def kinematics_changes(kind: str, name: str, setp_lines: list[str]) -> list[IniChange]:
    """Load pige's component instead of the stock trt kinematics and enter its pins."""
    module = re.escape(TRT_MODULE[kind])
    entered = "\n".join(f"HALCMD = {ln}" for ln in setp_lines)
    return [
        IniChange("pige's kinematics", rf"^(KINEMATICS =) {module}( sparm=identityfirst)\s*$", rf"\1 {name}\2"),
        IniChange("its tool length", rf"^(HALCMD = net\s+:tool-offset\s+){module}\.tool-offset\s*$",
                  rf"\g<1>{name}.tool-offset"),
        IniChange("the stock offsets are not its pins", rf"^HALCMD = net\s+:[xyz]-offset\s+{module}\.\S+\s*$", None,
                  count=2),
        IniChange("their signals' values", r"^HALCMD = sets :[xyz]-offset\s+\S+\s*$", None, count=2),
        IniChange("nor the rotation points", rf"^HALCMD = setp {module}\.[xy]-rot-point\s+\S+\s*$", None, count=2),
        IniChange("pige's lines instead", rf"^HALCMD = setp {module}\.z-rot-point\s+\S+\s*$", entered),
    ]
