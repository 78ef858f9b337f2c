"""Start-up cost: commands import only what they use (the ratios themselves are in `make bench`)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

HEAVY = ("scipy", "matplotlib", "sympy", "serial", "tqdm", "sqlalchemy")

_PROBE = """
import json, sys, io, contextlib
from pige_sym.cli.main import main
buf = io.StringIO()
with contextlib.redirect_stdout(buf):
    try:
        status = main(sys.argv[1:])
    except SystemExit as exc:
        status = exc.code
loaded = sorted({m.split('.')[0] if not m.startswith('scipy.') else '.'.join(m.split('.')[:2])
                 for m in sys.modules})
print(json.dumps({"status": status, "modules": loaded}))
"""


def _modules_after(args: list[str], cwd: Path) -> set[str]:
    proc = subprocess.run([sys.executable, "-c", _PROBE, *args], cwd=cwd, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    data = json.loads(proc.stdout.strip().splitlines()[-1])
    assert data["status"] in (0, None), data
    return set(data["modules"])


def test_help_imports_nothing_heavy(tmp_path: Path) -> None:
    loaded = _modules_after(["--help"], tmp_path)
    assert not {m for m in loaded if m.split(".")[0] in HEAVY}, sorted(loaded)
    assert "numpy" not in loaded  # the parser's choices come from pige_sym.constants, not the modules using them


@pytest.fixture(scope="module")
def measurement(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from pige_sym.measurements.rtest_writer import write_measurement
    from pige_sym.model.trajectories import make_trajectory
    from pige_sym.simulation.simulator import random_pige, simulate

    machine = "wC'A'bXYZ(C1)t"
    sim = simulate(machine, make_trajectory(machine, "cone-frustum"), pige=random_pige(machine, 1), seed=1)
    return write_measurement(sim.measurement, tmp_path_factory.mktemp("startup") / "run.csv")


def test_identify_needs_no_optimizer_statistics_plots_or_serial(measurement: Path) -> None:
    loaded = _modules_after(["identify", str(measurement)], measurement.parent)
    unwanted = {"matplotlib", "sympy", "serial", "tqdm", "sqlalchemy", "scipy.optimize", "scipy.stats"}
    assert not (loaded & unwanted), sorted(loaded & unwanted)


def test_diagnose_needs_no_plots_symbolic_or_serial(measurement: Path) -> None:
    loaded = _modules_after(["diagnose", str(measurement)], measurement.parent)
    assert not (loaded & {"matplotlib", "sympy", "serial", "sqlalchemy"}), sorted(loaded)
