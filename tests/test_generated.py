"""``generated/``, as the design asked: the kernels live there in a checkout, pige finds them there, and a
script imports one with nothing but NumPy (the README's script runs as written)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from pige_sym.codegen.machine_code import parse_machine_code
from pige_sym.constants import SHIPPED_MACHINES
from pige_sym.kernels import generated_dir, in_checkout, kernel_path

ROOT = Path(__file__).resolve().parents[1]


def _readme_block(heading: str, lang: str) -> str:
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    section = text[text.index(heading):]
    start = section.index(f"```{lang}\n") + len(lang) + 4
    return section[start:section.index("```", start)]


def test_the_tracked_kernels_are_in_generated_and_pige_uses_them() -> None:
    assert in_checkout() and generated_dir() == ROOT / "generated"
    for code in SHIPPED_MACHINES:
        st = parse_machine_code(code)
        assert (ROOT / "generated" / f"{st.module_name}.py").is_file()
        assert kernel_path(code) == ROOT / "generated" / f"{st.module_name}.py"
    assert not (ROOT / "pige_sym" / "kernels" / "shipped").exists()


def test_the_readme_script_runs_with_numpy_alone() -> None:
    """SymPy and pige_sym are made unimportable: the generated module needs neither."""
    script = "import sys; sys.modules['sympy'] = None; sys.modules['pige_sym'] = None\n" + \
        _readme_block("### Generated kernels", "python")
    out = subprocess.run([sys.executable, "-c", script], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    lines = out.stdout.splitlines()
    assert lines[0].startswith("('EY0A', 'EZ0A', 'EB0A', 'EC0A', 'EX0C', 'EY0C', 'EA0C', 'EB0C', 'EA0A', 'EC0C')")
    assert lines[1] == "um urad"
    assert "-10." in out.stdout and "-8.66" in out.stdout and "-5." in out.stdout


def test_make_gen_writes_into_generated_in_a_checkout(tmp_path, monkeypatch) -> None:
    """``pige gen`` (what make gen runs) writes a shipped machine's module in place: no second copy in the cache."""
    from pige_sym.cli.main import main

    monkeypatch.setenv("PIGE_KERNEL_DIR", str(tmp_path / "cache"))
    path = ROOT / "generated" / f"{parse_machine_code(SHIPPED_MACHINES[0]).module_name}.py"
    before = path.read_bytes()
    assert main(["gen", SHIPPED_MACHINES[0]]) == 0
    after = path.read_bytes()
    # the code is the same (only the SymPy version line may differ); nothing went to the cache
    assert [ln for ln in before.splitlines() if not ln.startswith(b"# sympy")] == \
        [ln for ln in after.splitlines() if not ln.startswith(b"# sympy")]
    assert not (tmp_path / "cache").exists()
    path.write_bytes(before)
