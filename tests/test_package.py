"""The package as users install it: a wheel in a fresh environment, run from elsewhere.

The wheel is built from a copy of the tracked sources, installed into a new virtual
environment (dependencies borrowed from the test's own environment through a path
entry, so no network is needed), and ``pige`` is run from an unrelated directory with
its cache and data directories redirected to the test's temporary folder.  Nothing may
be written into the installed package.
"""

from __future__ import annotations

import os
import shutil
import site
import subprocess
import sys
import sysconfig
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
NON_SHIPPED = "wA'C'bXYZ(C1)t"


def _tracked_copy(dest: Path) -> Path:
    try:
        files = subprocess.run(["git", "ls-files"], cwd=REPO, capture_output=True, text=True, check=True).stdout
    except (OSError, subprocess.CalledProcessError):
        pytest.skip("not a git checkout: cannot tell the tracked sources")
    for name in files.splitlines():
        src = REPO / name
        if src.is_file():
            (dest / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(src, dest / name)
    return dest


def _snapshot(root: Path) -> dict[str, tuple[int, int]]:
    return {str(p.relative_to(root)): (p.stat().st_size, p.stat().st_mtime_ns) for p in root.rglob("*") if p.is_file()}


@pytest.fixture(scope="module")
def installed(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    base = tmp_path_factory.mktemp("wheel")
    src = _tracked_copy(base / "src")
    dist = base / "dist"
    build = subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q", "-w", str(dist), str(src)],
        capture_output=True, text=True, timeout=300,
    )
    if build.returncode != 0:
        pytest.fail("building the wheel failed:\n" + build.stdout + build.stderr)
    (wheel,) = dist.glob("pige_sym-*.whl")
    venv = base / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True, timeout=120)
    py = venv / "bin" / "python"
    purelib = Path(subprocess.run(
        [str(py), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
        capture_output=True, text=True, check=True,
    ).stdout.strip())
    # dependencies (numpy, scipy, sympy, ...) from this environment, appended after the venv's own packages
    deps = [p for p in [*site.getsitepackages(), sysconfig.get_paths()["purelib"]] if Path(p).is_dir()]
    (purelib / "_borrowed_dependencies.pth").write_text("\n".join(dict.fromkeys(deps)) + "\n")
    install = subprocess.run(
        [sys.executable, "-m", "pip", "--python", str(py), "install", "--no-deps", "-q", str(wheel)],
        capture_output=True, text=True, timeout=300,
    )
    if install.returncode != 0:
        pytest.fail("installing the wheel failed:\n" + install.stdout + install.stderr)
    return {"venv": venv, "package": purelib / "pige_sym", "wheel": wheel, "home": base / "home"}


def _pige(installed: dict[str, Path], cwd: Path, *args: str) -> subprocess.CompletedProcess[str]:
    home = installed["home"]
    env = {k: v for k, v in os.environ.items() if not k.startswith(("PIGE_", "PYTHON", "VIRTUAL_ENV"))}
    env.update({
        "HOME": str(home), "XDG_CACHE_HOME": str(home / "cache"), "XDG_DATA_HOME": str(home / "data"),
        "PYTHONDONTWRITEBYTECODE": "1", "MPLBACKEND": "Agg",
    })
    if os.environ.get("PYTHONPYCACHEPREFIX"):  # the suite's bytecode folder (make test): never the installation,
        env.pop("PYTHONDONTWRITEBYTECODE")  # and the libraries' bytecode is there already
        env["PYTHONPYCACHEPREFIX"] = os.environ["PYTHONPYCACHEPREFIX"]
    cwd.mkdir(parents=True, exist_ok=True)
    return subprocess.run(
        [str(installed["venv"] / "bin" / "pige"), *args], cwd=cwd, env=env, capture_output=True, text=True, timeout=300
    )


def test_wheel_ships_subpackages_and_kernels(installed: dict[str, Path]) -> None:
    import zipfile

    names = zipfile.ZipFile(installed["wheel"]).namelist()
    for part in ("pige_sym/cli/main.py", "pige_sym/codegen/emit.py", "pige_sym/acquisition/engine.py",
                 "pige_sym/nc/program.py", "pige_sym/report/__init__.py",
                 "pige_sym/generated/kin_wCpApbXYZ_C1_t.py"):
        assert part in names, part


def test_installed_pige_runs_anywhere_and_writes_nothing_into_the_installation(
    installed: dict[str, Path], tmp_path: Path
) -> None:
    package = installed["package"]
    before = _snapshot(package)
    version = _pige(installed, tmp_path, "--version")
    assert version.returncode == 0 and version.stdout.startswith("pige "), version.stderr
    for code, name in (("wC'A'bXYZ(C1)t", "shipped"), (NON_SHIPPED, "generated")):
        work = tmp_path / name
        sim = _pige(installed, work, "simulate", "--machine", code, "--pige", "random", "--seed", "3",
                    "--out", "run.csv")
        assert sim.returncode == 0, sim.stderr
        ident = _pige(installed, work, "identify", "run.csv", "--json")
        assert ident.returncode == 0, ident.stderr
        assert '"machine"' in ident.stdout
    cached = list((installed["home"] / "cache").rglob("kin_*.py"))
    assert [p.name for p in cached] == ["kin_wApCpbXYZ_C1_t.py"], cached  # only the non-shipped machine
    assert _snapshot(package) == before, "pige wrote into its installation"
