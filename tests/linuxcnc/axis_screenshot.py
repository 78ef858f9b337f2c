"""A picture of the cycle's messages in LinuxCNC's AXIS GUI (docs/linuxcnc-cycle.md), taken under Xvfb.

Not a test: ``python tests/linuxcnc/axis_screenshot.py OUT.png`` runs the shipped ``xyzac-trt`` simulation with the
cycle installed (:mod:`cycle_setup`, 4 poses) and AXIS as its GUI on a virtual screen (Xvfb, started inside the
run's namespaces), lets the driver (:mod:`lcnc_driver`, started by the INI's ``[APPLICATIONS] APP``) load the stylus
and call ``M451 P1``, then grabs the screen (``xwd``, ImageMagick's ``convert``) and closes AXIS.  Needs ``Xvfb``,
``xwd`` (apt: xvfb, x11-apps) and ``convert``.
"""

from __future__ import annotations

import json
import shutil
import sys
import tempfile
from pathlib import Path

import lcnc_harness
from cycle_setup import cycle_sim

SHOT = """
import os, subprocess, time
def shot(step):
    time.sleep(step.get("settle", 3))
    subprocess.run(["xwd", "-root", "-silent", "-out", step["xwd"]], check=True)
    subprocess.run(["axis-remote", "--quit"], check=False)
    return {}
"""


def main(out: Path) -> int:
    if not (shutil.which("Xvfb") and shutil.which("xwd") and shutil.which("convert")):
        print("needs Xvfb, xwd and convert (apt-get install xvfb x11-apps imagemagick)")
        return 1
    root = Path(tempfile.mkdtemp(prefix="pige_axis_"))
    cs = cycle_sim(root, "AC", poses=4)
    ini = cs.sim.ini
    driver = cs.sim.cfg / "pige_driver.py"
    text = ini.read_text().replace(f"DISPLAY = {driver}", "DISPLAY = axis")
    text = text.replace("[APPLICATIONS]", f"[APPLICATIONS]\nDELAY = 5\nAPP = {driver}", 1)
    ini.write_text(text)
    code = driver.read_text()
    # the GUI reads the error channel's messages: the driver leaves them to it
    code = code.replace("m = self.err.poll()", "m = None")
    driver.write_text(code.replace("def run(job: dict) -> dict:", SHOT + "\n\ndef run(job: dict) -> dict:", 1)
                      .replace('res = getattr(drv, "idle_step" if', 'res = shot(step) if step["op"] == "shot" else '
                               'getattr(drv, "idle_step" if'))
    xwd = cs.sim.root / "axis.xwd"
    lcnc_harness.WRAPPER = lcnc_harness.WRAPPER.replace(
        "unset DISPLAY\n", "Xvfb :42 -screen 0 1280x900x24 -nolisten tcp >/dev/null 2>&1 &\nexport DISPLAY=:42\n"
        "sleep 2\n")
    steps = [{"op": "mdi", "lines": ["T9 M6", "G0 Z60"]}, {"op": "mdi", "lines": ["M451 P1"], "timeout": 1200},
             {"op": "shot", "xwd": str(xwd), "settle": 2}]
    run = lcnc_harness.run_sim(cs.sim, steps, timeout_s=700, attempts=1)
    print(run.summary()[:2000])
    if not xwd.is_file():
        return 1
    import subprocess

    subprocess.run(["convert", str(xwd), str(out)], check=True)
    print(json.dumps({"wrote": str(out)}))
    return 0


if __name__ == "__main__":
    sys.exit(main(Path(sys.argv[1]).resolve()))
