"""benchmarks/RESULTS.md names the processor and the load of its run (issue 46): the header lines run.py writes."""

from __future__ import annotations

import importlib.util
import os
import re
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _run_module():
    spec = importlib.util.spec_from_file_location("bench_run", ROOT / "benchmarks" / "run.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # its dataclasses look their module up
    spec.loader.exec_module(module)
    return module


def test_the_header_names_the_processor_and_the_load_before_and_after() -> None:
    run = _run_module()
    before = run.load_average()
    lines = run.machine_info(before, "9.00, 8.00, 7.00")
    text = "\n".join(lines)
    cpuinfo = Path("/proc/cpuinfo")
    if cpuinfo.is_file():
        name = next((ln.split(":", 1)[1].strip() for ln in cpuinfo.read_text().splitlines()
                     if ln.startswith("model name")), None)
        if name:
            assert f"- CPU: {name}" in text
    if hasattr(os, "getloadavg"):
        assert re.fullmatch(r"\d+\.\d\d, \d+\.\d\d, \d+\.\d\d", before), before
    load = next(ln for ln in lines if ln.startswith("- load average"))
    assert f"start of the run: {before};" in load and "end: 9.00, 8.00, 7.00" in load


@pytest.mark.skipif(not Path("/proc/cpuinfo").is_file(), reason="reads /proc/cpuinfo")
def test_the_processor_line_carries_vendor_and_family_when_the_kernel_gives_them() -> None:
    fields = dict(ln.split(":", 1) for ln in Path("/proc/cpuinfo").read_text().splitlines() if ":" in ln)
    fields = {k.strip(): v.strip() for k, v in fields.items()}
    cpu = _run_module().cpu_model()
    if "vendor_id" in fields:
        assert fields["vendor_id"] in cpu
    if "cpu family" in fields:
        assert f"family {fields['cpu family']}" in cpu
