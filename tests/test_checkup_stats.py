"""False alarms and detection of ``pige checkup``, measured on simulated machines (issue 42, "Done means").

The chart code the command runs (:func:`~pige_sym.verdict.checkup.reference.chart_state`,
:func:`~pige_sym.verdict.checkup.routine.judge`) judges histories in memory (:class:`checkup_sim.ChartSim`): a full
calibration, then check-ups whose estimates are drawn from the covariance of a real check-up fit of the virtual
machine (3 poses, 9 contacts, 17 degrees of freedom), with the held PIGEs at a real full calibration's errors.  One
history of real files (virtual machine → log → import → ``pige checkup``) checks that the draws are what the command
sees.

- **False alarms**: drift-free histories of 30 check-ups; every verdict that is not ``ok`` counts.  Stated rate 1 %
  per check-up.  Measured with the runs' scatter their measurement noise (the stated case) and with as much again
  of run-to-run scatter besides (re-clamping, temperature): the provisional limits of the first check-ups assume the
  first, docs/checkup.md gives both.
- **Detection**: ``n0`` drift-free check-ups, then one PIGE drifting by one standard error per run (its check-up
  standard error); detected when a check-up within the first five of the drift is not ``ok``.

The default suite runs small versions (fixed seeds: the same numbers every run); ``-m slow`` runs the issue's study
(200 histories × 30 check-ups; 200 drifts per PIGE) and prints the figures docs/checkup.md quotes.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from checkup_sim import (
    FREE,
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


@pytest.fixture(scope="module")
def design(tmp_path_factory: pytest.TempPathFactory) -> Design:
    folder = tmp_path_factory.mktemp("checkup_design")
    db = folder / "h.db"
    full = full_calibration(folder, db, "D1", TRUTH)
    program = checkup_program(folder, db, "D1")
    return design_from_files(full, checkup_file(program, TRUTH, 5, folder / "c.csv"))


def false_alarms(design: Design, histories: int, *, checkups: int = 30, extra: float = 0.0,
                 seed: int = 0) -> np.ndarray:
    """Alarms per check-up position over drift-free histories, shape=(checkups,)."""
    alarms = np.zeros(checkups, dtype=int)
    for h in range(histories):
        sim = ChartSim(design, np.random.default_rng([seed, h]), extra_scatter=extra)
        sim.calibrate(TRUTH, hourly(0))
        for i in range(checkups):
            alarms[i] += sim.checkup(TRUTH, hourly(i + 1)) != "ok"
    return alarms


def detections(design: Design, cases: int, n0: int, pige: str, *, seed: int = 1, rate: float = 1.0) -> np.ndarray:
    """Per case the drift run (1-5) that was flagged first, 0 when none of the five was."""
    found = np.zeros(cases, dtype=int)
    sigma = design.checkup_std[FREE.index(pige)]
    for c in range(cases):
        sim = ChartSim(design, np.random.default_rng([seed, n0, FREE.index(pige), c]))
        sim.calibrate(TRUTH, hourly(0))
        for i in range(n0):
            sim.checkup(TRUTH, hourly(i + 1))
        for k in range(1, 6):
            if sim.checkup(TRUTH | {pige: TRUTH[pige] + rate * sigma * k}, hourly(n0 + k)) != "ok":
                found[c] = k
                break
    return found


def calibrated_history(design, rng, scatter_um, calibrations, **kw):
    sim = ChartSim(design, rng, scatter_um=scatter_um, **kw)
    for i in range(calibrations):
        sim.calibrate(TRUTH, hourly(i, step_h=24.0 * 30))
    return sim


def test_a_machine_with_a_calibrated_history_and_run_to_run_scatter_is_not_called_drifted(design: Design) -> None:
    """Issue 49: 8-12 full calibrations of a machine whose axis lines move by 1-2x the probing noise from run to run
    (re-clamping, temperature), then 10 check-ups of the same still machine: the limits come from that history
    from the first check-up on, so the false alarms stay near the stated 1 % (the old provisional limits, from each
    run's own standard error, said DRIFTED in about 3 of 4)."""
    alarms = np.zeros(10, dtype=int)
    for h in range(30):
        rng = np.random.default_rng([49, h])
        sim = calibrated_history(design, rng, NOISE_UM * rng.uniform(1.0, 2.0), int(rng.integers(8, 13)))
        start = len(sim.runs)
        for i in range(10):
            alarms[i] += sim.checkup(TRUTH, hourly(start * 30 + i + 1)) != "ok"
    print(f"false alarms: {alarms.sum()} of 300 check-ups; per check-up {alarms.tolist()}")
    assert alarms.sum() <= 9, alarms  # 1 %: 3 expected; 9 is beyond the binomial's 99.9 % point


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
    ratio = values.std(axis=0, ddof=1) / design.checkup_std
    assert ((ratio > 0.55) & (ratio < 1.6)).all(), ratio
    assert np.abs(values.mean(axis=0) - [TRUTH[n] for n in FREE]).max() < 4 * design.checkup_std.max()


def test_false_alarms_of_a_drift_free_machine_stay_below_the_stated_rate(design: Design) -> None:
    alarms = false_alarms(design, 25)
    rate = alarms.sum() / alarms.size / 25
    print(f"false alarms: {alarms.sum()} of {25 * alarms.size} check-ups ({rate:.2%})")
    assert rate <= 0.015, alarms  # stated 1 %; 750 check-ups, binomial spread ~0.4 %


def test_a_drift_of_one_standard_error_per_run_is_flagged_within_five_runs(design: Design) -> None:
    found = detections(design, 30, 20, "EX0C")
    print(f"EX0C after 20 check-ups: flagged within 5 runs in {np.count_nonzero(found)} of 30, "
          f"first at run {np.bincount(found, minlength=6)[1:]}")
    assert np.count_nonzero(found) >= 26, found  # 90 %: 27 of 30 expected; the study (slow) measures it on 200


def test_without_history_the_same_drift_goes_unseen_until_the_tolerance(design: Design) -> None:
    """The chart needs its check-ups: after 5 the scatter has 4 degrees of freedom and the limits are wide (the
    power the docs state grows with the history); the test fails if the limits ignored the small sample."""
    found = detections(design, 20, 5, "EX0C")
    assert np.count_nonzero(found) <= 6, found


@pytest.mark.slow
def test_the_issue_s_study_200_histories_of_30_check_ups(design: Design) -> None:
    lines = []
    for extra, what in ((0.0, "scatter = measurement noise"), (1.0, "plus as much run-to-run scatter")):
        alarms = false_alarms(design, 200, extra=extra, seed=7)
        lines.append(f"false alarms, {what}: {alarms.sum()} of {200 * alarms.size} check-ups "
                     f"({alarms.sum() / 6000:.2%}); check-ups 1-5: {alarms[:5].sum() / 1000:.2%}, 6-30: "
                     f"{alarms[5:].sum() / 5000:.2%}")
        if extra == 0.0:
            assert alarms.sum() / 6000 <= 0.01, alarms
    for n0 in (10, 15, 20, 25):
        for name in FREE:
            found = detections(design, 200, n0, name, seed=8)
            lines.append(f"detection of {name} after {n0} check-ups: {np.count_nonzero(found) / 200:.1%} within 5 "
                         f"runs (first at run 1-5: {np.bincount(found, minlength=6)[1:].tolist()})")
            if n0 >= 20:
                assert np.count_nonzero(found) >= 180, (name, n0, found)
    print("\n".join(lines))
