"""A picture of the cycle's operator messages in LinuxCNC's AXIS GUI (docs/linuxcnc-cycle.md §4), taken under Xvfb.

Not a test: ``.venv/bin/python tests/linuxcnc/axis_screenshot.py docs/linuxcnc-cycle-axis.png`` (about 3 minutes)
runs the shipped ``xyzac-trt`` simulation with the hidden true machine and the cycle installed (:mod:`cycle_setup`,
4 poses), with AXIS as its GUI on a virtual screen (``Xvfb``, started inside the run's namespaces, so nothing shows
on any screen of this computer).  The driver (:mod:`lcnc_driver`, started by the INI's ``[APPLICATIONS] APP``)
waits until AXIS answers ``axis-remote --ping``, loads the stylus, calls ``M451 P1`` from MDI, and leaves LinuxCNC's
error channel to AXIS, which shows the cycle's messages in its notification area as it does for an operator; then
it grabs the screen (``xwd``), closes AXIS (``axis-remote --quit``, which ends the run), and the picture is cut to
AXIS's window and written as a PNG (ImageMagick's ``convert``).

Needs ``Xvfb``, ``xwd`` and ``convert`` (apt: xvfb, x11-apps, imagemagick) besides what tests/linuxcnc needs; says
what is missing and exits 1 without them.
"""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import lcnc_harness
from cycle_setup import cycle_sim

#: the ops the driver's copy gains (lcnc_driver.EXTRA_OPS): wait for AXIS, take the picture and close AXIS
AXIS_OPS = '''

def _wait_axis(step):
    """Until AXIS answers axis-remote (it reads the error channel from then on), then ``settle`` seconds."""
    end = time.monotonic() + step.get("timeout", 120)
    while time.monotonic() < end:
        if subprocess.run(["axis-remote", "--ping"], capture_output=True).returncode == 0:
            time.sleep(step.get("settle", 3))
            return {}
        time.sleep(0.5)
    raise RuntimeError("AXIS did not answer axis-remote --ping")


def _shot(step):
    """``settle`` seconds for AXIS to show the messages, the screen into ``xwd``, then AXIS closed."""
    time.sleep(step.get("settle", 3))
    subprocess.run(["xwd", "-root", "-silent", "-out", step["xwd"]], check=True)
    subprocess.run(["axis-remote", "--quit"], check=False)
    return {}


EXTRA_OPS.update({"wait_axis": _wait_axis, "shot": _shot})
READ_ERRORS = False  # AXIS shows them
import atexit  # noqa: E402

atexit.register(subprocess.run, ["axis-remote", "--quit"], check=False)  # whatever happened: the run ends
'''
#: Xvfb inside the run's namespaces (its own network namespace: no other X client reaches it)
XVFB = "Xvfb :42 -screen 0 1100x900x24 -nolisten tcp >/dev/null 2>&1 &\nexport DISPLAY=:42\nsleep 2\n"


def missing() -> list[str]:
    return [tool for tool in ("Xvfb", "xwd", "convert") if shutil.which(tool) is None]


def axis_configuration(root: Path) -> tuple[object, Path]:
    """The cycle's simulation with AXIS as its GUI and the driver (with :data:`AXIS_OPS`) as an application."""
    cs = cycle_sim(root, "AC", poses=4)
    ini, driver = cs.sim.ini, cs.sim.cfg / "pige_driver.py"
    text = ini.read_text().replace(f"DISPLAY = {driver}", "DISPLAY = axis")
    text = text.replace("[APPLICATIONS]", f"[APPLICATIONS]\nDELAY = 2\nAPP = {driver}", 1)
    ini.write_text(text)
    code = driver.read_text()
    main_call = '\nif __name__ == "__main__":'
    assert main_call in code
    driver.write_text(code.replace(main_call, AXIS_OPS + main_call, 1))
    return cs, cs.sim.root / "axis.xwd"


def main(out: Path) -> int:
    if missing():
        print(f"needs {', '.join(missing())} (apt-get install xvfb x11-apps imagemagick)")
        return 1
    if lcnc_harness.unavailable():
        print(lcnc_harness.unavailable())
        return 1
    root = Path(tempfile.mkdtemp(prefix="pige_axis_"))
    cs, xwd = axis_configuration(root)
    lcnc_harness.WRAPPER = lcnc_harness.WRAPPER.replace("unset DISPLAY\n", XVFB)
    steps = [{"op": "wait_axis", "timeout": 120, "settle": 2}, {"op": "mdi", "lines": ["T9 M6", "G0 Z60"]},
             {"op": "mdi", "lines": ["M451 P1"], "timeout": 1200}, {"op": "shot", "xwd": str(xwd), "settle": 3}]
    run = lcnc_harness.run_sim(cs.sim, steps, timeout_s=1500, attempts=1)  # type: ignore[attr-defined]
    print(run.summary()[:1500])
    if not xwd.is_file():
        print(f"no picture taken; the run is in {root}")
        return 1
    # AXIS's window is at the top left of the black root window: -trim cuts the black
    subprocess.run(["convert", str(xwd), "-trim", "+repage", "-strip", "-colors", "64", str(out)], check=True)
    print(json.dumps({"wrote": str(out), "bytes": out.stat().st_size, "run": str(root)}))
    return 0


if __name__ == "__main__":
    sys.exit(main(Path(sys.argv[1]).resolve()))
