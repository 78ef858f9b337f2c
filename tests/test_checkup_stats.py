"""False alarms, detection and forecasts of ``pige checkup``, measured on simulated machines (issues 42 and 49).

The code the command runs (:func:`~pige_sym.verdict.checkup.reference.chart_state`,
:func:`~pige_sym.verdict.checkup.judging.judge`, :func:`~pige_sym.verdict.checkup.to_enter.checkup_changes`) judges
histories in memory (:class:`checkup_sim.ChartSim`): full calibrations and check-ups whose estimates are drawn from
the covariances of a real full calibration and a real check-up fit of the virtual machine (3 poses, 9 contacts), the
held PIGEs off by the full calibration's errors, the axis lines moving from run to run by ``scatter_um`` (re-clamping,
temperature: 1-2x the probing noise of 0.3 um, the issue's machines).  One history of real files checks that the
draws are what the command sees.

- **False alarms from the first check-up** (issue 49): 8-12 full calibrations, then 10 check-ups of the still
  machine; every verdict that is not ``ok`` counts.  Stated rate 1 % per check-up.
- **The fleet**: a new machine (one full calibration) in a history of 5 machines of its structure: its first
  check-up has learned limits, at the same rate.
- **Detection**: from the first check-up after 8 calibrations, one PIGE drifts by one run-to-run standard deviation
  (its check-up's total: scatter and standard error) per run; detected when one of the first five is not ``ok``.
- **Forecasts**: the same drifts towards a tolerance; at the first check-up that prints a forecast, does its 90 %
  interval hold the true crossing?

The default suite runs small versions (fixed seeds: the same numbers every run); ``-m slow`` runs the issue's studies
(200 histories or cases each) and prints the figures docs/checkup.md quotes.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from checkup_sim import (
    FREE,
    T0,
    TRUTH,
    ChartSim,
    Design,
    checkup_file,
    checkup_program,
    design_from_files,
    full_calibration,
    hourly,
)

#: The virtual machine's probing noise (contact scatter) [µm].
NOISE_UM = 0.3
#: Days between full calibrations in the simulated histories.
MONTH_H = 24.0 * 30


@pytest.fixture(scope="module")
def design(tmp_path_factory: pytest.TempPathFactory) -> Design:
    folder = tmp_path_factory.mktemp("checkup_design")
    db = folder / "h.db"
    full = full_calibration(folder, db, "D1", TRUTH)
    program = checkup_program(folder, db, "D1")
    return design_from_files(full, checkup_file(program, TRUTH, 5, folder / "c.csv"))


def calibrated(design: Design, rng: np.random.Generator, calibrations: int, scatter_um: float,
               **kw: object) -> ChartSim:
    """A machine with ``calibrations`` monthly full calibrations, moving by ``scatter_um`` from run to run."""
    sim = ChartSim(design, rng, scatter_um=scatter_um, **kw)  # type: ignore[arg-type]
    for i in range(calibrations):
        sim.calibrate(TRUTH, hourly(i, step_h=MONTH_H))
    return sim


def still_checkups(sim: ChartSim, count: int) -> np.ndarray:
    """``count`` daily check-ups of the still machine after its history: 1 where it was not ``ok``."""
    start = hourly(len(sim.runs), step_h=MONTH_H)
    return np.array([sim.checkup(TRUTH, start + (hourly(i + 1) - T0)) != "ok" for i in range(count)], dtype=int)


def false_alarms(design: Design, histories: int, *, seed: int, checkups: int = 10,
                 calibrations: tuple[int, int] = (8, 13), ratio: tuple[float, float] = (1.0, 2.0),
                 factor: dict[str, float] | None = None) -> np.ndarray:
    """Alarms per check-up position over drift-free histories, shape=(checkups,); ``factor``: a PIGE's scatter that
    many times the others'."""
    alarms = np.zeros(checkups, dtype=int)
    for h in range(histories):
        rng = np.random.default_rng([seed, h])
        sim = calibrated(design, rng, int(rng.integers(*calibrations)), NOISE_UM * rng.uniform(*ratio),
                         scatter_factor=dict(factor or {}))
        alarms += still_checkups(sim, checkups)
    return alarms


def fleet_false_alarms(design: Design, fleets: int, new: int, *, seed: int,
                       checkups: int = 10) -> tuple[np.ndarray, int, int]:
    """Per fleet of 5 machines (8-12 calibrations and 5 check-ups each, scatter 1-2x the noise), ``new`` new
    machines with one full calibration: (alarms per check-up position, first check-ups with learned limits, new
    machines)."""
    alarms, learned = np.zeros(checkups, dtype=int), 0
    for f in range(fleets):
        rng = np.random.default_rng([seed, f])
        fleet = []
        for k in range(5):
            sim = calibrated(design, rng, int(rng.integers(8, 13)), NOISE_UM * rng.uniform(1.0, 2.0),
                             machine_id=f"F{k}")
            still_checkups(sim, 5)
            fleet.append(sim.runs)
        for n in range(new):
            sim = calibrated(design, np.random.default_rng([seed, f, n]), 1, NOISE_UM * rng.uniform(1.0, 2.0),
                             machine_id="NEW", fleet=fleet)
            alarms += still_checkups(sim, checkups)
            items = sim.results[0][0]
            learned += all(i.limit is not None and not i.limit.provisional for i in items)
    return alarms, learned, fleets * new


def detections(design: Design, cases: int, *, seed: int, calibrations: int = 8) -> np.ndarray:
    """Per case (the drifting PIGE in turn) the drift run (1-5) flagged first, 0 when none of the five was."""
    found = np.zeros(cases, dtype=int)
    for c in range(cases):
        rng = np.random.default_rng([seed, calibrations, c])
        scatter = NOISE_UM * rng.uniform(1.0, 2.0)
        sim = calibrated(design, rng, calibrations, scatter)
        name = FREE[c % len(FREE)]
        sd = np.hypot(scatter, sim.design.checkup_std[FREE.index(name)])
        start = hourly(len(sim.runs), step_h=MONTH_H)
        for k in range(1, 6):
            when = start + (hourly(k) - T0)
            if sim.checkup(TRUTH | {name: TRUTH[name] + sd * k}, when) != "ok":
                found[c] = k
                break
    return found


def forecasts(design: Design, cases: int, *, seed: int) -> tuple[int, int, int, int]:
    """Drifts of 0.5-2 sd per run from the first check-up after 8-12 calibrations, the tolerance (on the error the
    values in force leave: the last calibration's values) reached about 8-20 runs ahead: (first forecasts whose 90 %
    interval holds the true crossing, first forecasts, forecasts of the still PIGEs, check-ups)."""
    hits = shown = false = checks = 0
    for c in range(cases):
        rng = np.random.default_rng([seed, c])
        scatter = NOISE_UM * rng.uniform(1.0, 2.0)
        sim = calibrated(design, rng, int(rng.integers(8, 13)), scatter)
        name = FREE[c % len(FREE)]
        rate = rng.uniform(0.5, 2.0) * np.hypot(scatter, sim.design.checkup_std[FREE.index(name)])
        sim.tolerance = rate * rng.uniform(8.0, 20.0)
        start = hourly(len(sim.runs), step_h=MONTH_H)
        origin = (start - T0).total_seconds() / 3600.0
        for k in range(1, 30):
            sim.checkup(TRUTH | {name: TRUTH[name] + rate * k}, start + (hourly(k) - T0))
            checks += 1
            items = {i.name: i for i in sim.results[-1][0]}
            false += sum(i.trend is not None and i.trend.leaves_at is not None for n, i in items.items() if n != name)
            tr = items[name].trend
            if tr is not None and tr.leaves_at is not None:
                level = sim.results[-1][2].level[name]  # the values in force: the error left is x - level
                crossing = origin + 24.0 * (sim.tolerance + level - TRUTH[name]) / rate
                low = -np.inf if tr.reached else tr.leaves_low
                high = np.inf if tr.leaves_high is None else tr.leaves_high
                hits += bool(low <= crossing <= high)
                shown += 1
                break
    return hits, shown, false, checks


def test_the_draws_are_what_the_command_sees(design: Design, tmp_path: Path) -> None:
    """Real check-ups of the drift-free virtual machine spread like the draws: their run-to-run std per PIGE is the
    check-up fit's predicted std (12 files: within a factor 0.55-1.6, the chi-square range of 11 dof at 99 %)."""
    db = tmp_path / "h.db"
    full_calibration(tmp_path, db, "R1", TRUTH, seed=11)
    program = checkup_program(tmp_path, db, "R1")
    from pige_sym.identification.subset import identify_subset
    from pige_sym.measurements.rtest import read_measurement

    held = {n: TRUTH[n] for n in TRUTH if n not in FREE}
    values = np.array([identify_subset(read_measurement(checkup_file(program, TRUTH, 100 + i, tmp_path / f"c{i}.csv")),
                                       FREE, held).values for i in range(12)])
    ratio = values.std(axis=0, ddof=1) / np.sqrt(np.diag(design.checkup_cov))
    assert ((ratio > 0.55) & (ratio < 1.6)).all(), ratio
    assert np.abs(values.mean(axis=0) - [TRUTH[n] for n in FREE]).max() < 4 * design.checkup_std.max()


def test_a_machine_with_a_calibrated_history_and_run_to_run_scatter_is_not_called_drifted(design: Design) -> None:
    """Issue 49: 8-12 full calibrations of a machine whose axis lines move by 1-2x the probing noise from run to run
    (re-clamping, temperature), then 10 check-ups of the same still machine: the limits come from that history
    from the first check-up on, so the false alarms stay near the stated 1 % (the old provisional limits, from each
    run's own standard error, said DRIFTED in 91 of the first 150)."""
    alarms = false_alarms(design, 30, seed=49)
    print(f"false alarms: {alarms.sum()} of 300 check-ups; per check-up {alarms.tolist()}")
    assert alarms.sum() <= 9, alarms  # 1 %: 3 expected; 9 is beyond the binomial's 99.9 % point


def test_a_machine_calibrated_once_without_scatter_is_not_called_drifted(design: Design) -> None:
    """One full calibration, no run-to-run scatter beyond the noise, 20 check-ups (provisional limits for the first,
    then learned from the machine's own check-ups)."""
    alarms = false_alarms(design, 10, seed=5, checkups=20, calibrations=(1, 2), ratio=(0.0, 0.0))
    print(f"false alarms: {alarms.sum()} of 200 check-ups; per check-up {alarms.tolist()}")
    assert alarms.sum() <= 7, alarms  # 1 %: 2 expected


def test_a_new_machine_of_a_fleet_has_learned_limits_from_its_first_check_up(design: Design) -> None:
    alarms, learned, machines = fleet_false_alarms(design, 2, 3, seed=50, checkups=5)
    print(f"fleet: first check-ups with learned limits {learned} of {machines}; false alarms {alarms.sum()} of "
          f"{machines * 5}")
    assert learned == machines and alarms.sum() <= 2, (learned, alarms)


def test_a_drift_of_one_standard_deviation_per_run_is_flagged_within_five_runs(design: Design) -> None:
    found = detections(design, 40, seed=51)
    print(f"after 8 calibrations: flagged within 5 runs in {np.count_nonzero(found)} of 40, first at run "
          f"{np.bincount(found, minlength=6)[1:].tolist()}")
    assert np.count_nonzero(found) >= 33, found  # 90 %: 36 expected; the study (slow) measures it on 200


def test_the_first_forecast_printed_holds_the_true_crossing(design: Design) -> None:
    hits, shown, false, checks = forecasts(design, 24, seed=52)
    print(f"first forecasts holding the true crossing: {hits} of {shown}; forecasts of still PIGEs {false} in "
          f"{checks} check-ups")
    assert shown >= 20 and hits >= 0.75 * shown and false <= 0.01 * 3 * checks + 2, (hits, shown, false)


@pytest.mark.slow
def test_the_issue_s_studies(design: Design) -> None:
    """Issue 49's figures (docs/checkup.md): false alarms from the first check-up, the fleet, detection, forecasts."""
    lines = []
    alarms = false_alarms(design, 200, seed=7)
    lines.append(f"false alarms, 200 histories of 8-12 calibrations (scatter 1-2x the noise), 10 check-ups each: "
                 f"{alarms.sum()} of 2000 ({alarms.sum() / 2000:.2%}); check-ups 1-5: {alarms[:5].sum()} of 1000 "
                 f"({alarms[:5].sum() / 1000:.2%}), 6-10: {alarms[5:].sum()} of 1000 ({alarms[5:].sum() / 1000:.2%})")
    assert alarms.sum() <= 20 and alarms[:5].sum() <= 15 and alarms[5:].sum() <= 15, alarms
    fleet, learned, machines = fleet_false_alarms(design, 40, 5, seed=8)
    lines.append(f"fleet: 200 new machines (1 calibration) in histories of 5 machines of their structure: first "
                 f"check-ups with learned limits {learned} of {machines}; false alarms {fleet.sum()} of "
                 f"{machines * 10} ({fleet.sum() / machines / 10:.2%}); check-ups 1-5: {fleet[:5].sum()}, "
                 f"6-10: {fleet[5:].sum()}")
    assert learned == machines and fleet.sum() <= 20, (learned, fleet)
    for calibrations in (8, 12):
        found = detections(design, 200, seed=9, calibrations=calibrations)
        per = [np.count_nonzero(found[k::4]) / 50 for k in range(4)]
        lines.append(f"detection after {calibrations} calibrations: {np.count_nonzero(found) / 200:.1%} within 5 runs "
                     f"(per PIGE {', '.join(f'{n} {p:.0%}' for n, p in zip(FREE, per, strict=True))}; first at run "
                     f"1-5: {np.bincount(found, minlength=6)[1:].tolist()})")
        assert np.count_nonzero(found) >= 180, (calibrations, found)
    for factor in (2.5, 4.0):  # one PIGE scattering more than the others: the shared prior shrinks it towards them
        odd = false_alarms(design, 200, seed=11, factor={"EZ0A": factor})
        lines.append(f"false alarms, EZ0A's scatter {factor:g}x the others': {odd.sum()} of 2000 "
                     f"({odd.sum() / 2000:.2%}); check-ups 1-5: {odd[:5].sum() / 1000:.2%}, 6-10: "
                     f"{odd[5:].sum() / 1000:.2%}")
        assert odd.sum() <= 30, (factor, odd)
    hits, shown, false, checks = forecasts(design, 200, seed=10)
    lines.append(f"forecasts: the first printed holds the true crossing in {hits} of {shown} ({hits / shown:.1%}); "
                 f"forecasts of still PIGEs {false} in {checks} check-ups x 3 PIGEs")
    assert hits >= 0.85 * shown, (hits, shown)
    print("\n".join(lines))
