"""The cycle's map test inside LinuxCNC 2.9 (issue 48: "with pige's component all 8 PIGEs are entered, and the maps
when a map test was run"): ``M451 P3 Q1..Q3``, ``M451 P2``, on the shipped ``xyzac-trt`` simulation with pige's
kinematics component and a true machine with hidden PIGEs and error maps (:mod:`cycle_map_setup`).

One simulation: install with ``--map C,A --map-step 45``; the driver, as the operator, moves the true sphere to each
setup's place and calls ``M451 P3 Q<k>``; the true tool point at 36 work points between the grid angles (TCP MDI
moves); ``M451 P2``; the pins; the same moves; then LinuxCNC started again.  What is checked:

- after each setup but the last the message names where the next sphere goes (the setups' places) and the code to
  call; after the last, the verdict and a proposal with the 8 PIGE pins and the map pins of both axes;
- ``M451 P2`` enters them: the map pins live (node counts 8 and 3, the grid) and in ``values.hal`` in the safe
  order, the PIGE pins too; after a restart of LinuxCNC the same values in force;
- the true tool-point error at the held-out work points drops at least 20 times (its largest value), and its
  largest value lies below the bound the noise sets: the proposal's own predicted error after the entry over the
  axes' travel at its 95 % point (the identification's covariance, with each setup's noise).
"""

from __future__ import annotations

import json
import re
from typing import Any

import numpy as np
import pytest
from cycle_map_setup import (
    HELD_OUT,
    ON_GRID,
    CycleMapSim,
    cycle_map_sim,
    held_out_errors,
    map_pins,
    run_map_cycle,
)
from lcnc_harness import RunResult
from map_loop import SETUPS

from conftest import need_started

pytestmark = pytest.mark.linuxcnc


@pytest.fixture(scope="module")
def map_cycle(lcnc: None, tmp_path_factory: pytest.TempPathFactory) -> tuple[CycleMapSim, RunResult, RunResult]:
    cs = cycle_map_sim(tmp_path_factory.mktemp("cycle_maps"))
    run, restart = run_map_cycle(cs)
    return cs, run, restart


def _steps(run: RunResult) -> list[dict[str, Any]]:
    need_started(run)
    assert run.result.get("ok"), run.summary()
    return list(run.result["steps"])


def _labelled(run: RunResult, label: str) -> dict[str, Any]:
    return next(s for s in _steps(run) if s.get("label") == label)


def _messages(step: dict[str, Any]) -> list[str]:
    return [m[1] for m in step["messages"] if m[0] != "error"]


def test_each_setup_names_the_next_sphere_and_the_last_proposes_pige_and_maps(map_cycle) -> None:
    cs, run, _ = map_cycle
    times = []
    for k in range(1, len(SETUPS) + 1):
        step = _labelled(run, f"M451 P3 Q{k}")
        times.append(step["sim_s"])
        lines = _messages(step)
        print(f"M451 P3 Q{k}: {step['sim_s']:.0f} s of machine time, {step['wall_s']:.0f} s wall:\n  "
              + "\n  ".join(lines))
        if k < len(SETUPS):
            where = ", ".join(f"{v:.4g}" for v in SETUPS[k])
            assert any(f"X, Y, Z = {where} mm" in ln and f"M451 P3 Q{k + 1}" in ln for ln in lines), lines
        else:
            assert lines[0].startswith("PIGE M451 P3 map test: FAIL"), lines
            text = " ".join(lines)
            assert any(ln.startswith("proposal: ") for ln in lines), lines
            assert re.search(r"C map: \d+ values .*A map: \d+ values", text) and "M451 P2 within" in text, lines
    proposal = json.loads(next(p for p in cs.runs() if p.name.endswith("M451-enter")).joinpath(
        "proposal.entered.json").read_text())
    pins = {e["pin"] for e in proposal["entries"]}
    assert {f"{cs.name}.{n.lower()}" for n in ("EY0A", "EZ0A", "EB0A", "EC0A", "EX0C", "EY0C", "EA0C", "EB0C")} <= pins
    assert {f"{cs.name}.map-c-nodes", f"{cs.name}.map-a-nodes", f"{cs.name}.exc-07", f"{cs.name}.eaa-02"} <= pins
    print(f"machine time per setup {', '.join(f'{t:.0f}' for t in times)} s")


def test_the_entry_puts_the_maps_live_in_values_hal_and_after_a_restart(map_cycle) -> None:
    cs, run, restart = map_cycle
    reads = [s for s in _steps(run) if s["op"] == "read"]
    before, after = reads[0]["readings"][0], reads[1]["readings"][0]
    n = cs.name
    assert before[f"{n}.map-c-nodes"] == 0 and before[f"{n}.map-a-nodes"] == 0
    assert after[f"{n}.map-c-nodes"] == 8 and after[f"{n}.map-a-nodes"] == 3
    assert after[f"{n}.map-c-step"] == 45 and after[f"{n}.map-a-step"] == 45 and after[f"{n}.map-c-full-turn"]
    assert any(abs(after[f"{n}.ecc-{k:02d}"]) > 1.0 for k in range(8)), after
    text = cs.values_file.read_text()
    for pin in map_pins(cs):
        assert f"setp {pin} " in text
    assert text.index(f"{n}.map-c-nodes 0") < text.index(f"{n}.exc-00") < text.index(f"{n}.map-c-nodes 8")
    need_started(restart)
    assert restart.result.get("ok"), restart.summary()
    again = restart.result["steps"][0]["readings"][0]
    assert again == pytest.approx(after, abs=1e-9), {k: (v, again[k]) for k, v in after.items() if v != again[k]}


def _held_out(map_cycle) -> tuple[np.ndarray, np.ndarray, dict[str, Any]]:
    """The true tool point's errors at the held-out work points before and after the entry [µm], and the concluding
    run's prediction."""
    cs, run, _ = map_cycle
    before = held_out_errors(_labelled(run, "before"))
    after = held_out_errors(_labelled(run, "after"))
    concluded = next(p for p in cs.runs() if (p / "result.json").is_file() and "M451-map" in p.name)
    predicted = json.loads((concluded / "result.json").read_text())["predicted_um"]
    grid = {w: held_out_errors(_labelled(run, w), ON_GRID) for w in ("before", "after")}
    rms = {k: float(np.sqrt(np.mean(v ** 2))) for k, v in (("before", before), ("after", after))}
    print(f"held-out TCP moves ({before.size} work points 6 mm around the first sphere, between the grid angles): "
          f"true tool point off the target before the entry max {before.max():.2f} um (RMS {rms['before']:.2f}), "
          f"after max {after.max():.3f} um (RMS {rms['after']:.3f}); predicted after over {predicted['over']}: "
          f"{predicted['after']['expected']:.2f} um (95 % <= {predicted['after']['p95']:.2f}); on the grid angles "
          f"{ON_GRID}: before max {grid['before'].max():.2f} um, after max {grid['after'].max():.3f} um; after, per "
          "held-out angle: " + ", ".join(f"{a}: {v:.2f}" for a, v in zip(
              HELD_OUT, after.reshape(len(HELD_OUT), -1).max(axis=1), strict=True)))
    return before, after, predicted


def test_the_true_tool_point_between_the_grid_angles_drops_twenty_times(map_cycle) -> None:
    before, after, _ = _held_out(map_cycle)
    assert before.max() >= 20.0 * after.max()


def test_the_true_tool_point_between_the_grid_angles_lies_below_the_noise_bound(map_cycle) -> None:
    _, after, predicted = _held_out(map_cycle)
    assert after.max() < float(predicted["after"]["p95"])
