"""The check-up's reading of a history (issue 49): segments, the scatter's data, the values in force, what a check-up
measures; the hierarchical prior against its oracle; the stored flag of a correction entered before a full
calibration (schema 3).

Histories are built from run records (:func:`checkup_sim._record`) as ``pige history add`` and ``pige checkup``
store them; the oracles are written here.
"""

from __future__ import annotations

import math
from datetime import datetime, timedelta, timezone

import numpy as np
import pytest
from checkup_sim import FREE, LOCATION, SETUP, _record

from pige_sym.verdict.checkup.reference import chart_state, measures_machine, segments_of, series_of
from pige_sym.verdict.checkup.scatter import Series, posteriors

T = datetime(2026, 1, 1, tzinfo=timezone.utc)
COV = np.diag(np.full(8, 0.01))


def full(k: int, values: np.ndarray, *, corrected: bool = False, setup: dict | None = None) -> object:
    rec = _record(k, T + timedelta(days=k), "full", LOCATION, values, np.full(8, 0.1), COV, 400)
    rec.setup = dict(SETUP if setup is None else setup)
    rec.after_correction = corrected
    return rec


def checkup(k: int, values: list[float], *, corrected: bool = False, to_enter: dict | None = None) -> object:
    info = {"signature": "s", "after_correction": corrected, "in_control": dict.fromkeys(FREE, True),
            "outside": dict.fromkeys(FREE, False), "flagged": dict.fromkeys(FREE, False), "to_enter": to_enter}
    return _record(k, T + timedelta(days=k), "checkup", FREE, np.array(values), np.full(4, 0.2),
                   np.diag(np.full(4, 0.04)), 17, info, "ok")


def test_only_an_entered_correction_starts_a_segment() -> None:
    """Consecutive full calibrations share a segment (their scatter is learned); ``--corrected`` on a full
    calibration or a check-up starts one."""
    v = np.zeros(8)
    runs = [full(1, v), full(2, v + 0.3), full(3, v - 0.2), full(4, v, corrected=True), checkup(5, [0.1] * 4),
            checkup(6, [0.0] * 4, corrected=True)]
    assert segments_of(runs) == [0, 0, 0, 1, 1, 2]
    series = series_of(runs, ["EX0C"])["EX0C"]
    assert series.dof == 2 + 1 + 0 and series.kinds == ["full"] * 4 + ["checkup"] * 2


def test_the_newest_check_ups_are_marked_recent_and_left_out_when_the_rest_is_worth_enough() -> None:
    runs = [full(1, np.zeros(8)), full(2, np.zeros(8))] + [checkup(3 + i, [0.0] * 4) for i in range(7)]
    s = series_of(runs, ["EX0C"], lag=5)["EX0C"]
    assert s.recent.tolist() == [False] * 4 + [True] * 5 and s.settled().values.size == 4


@pytest.mark.parametrize("kind", ["identity", "rtest"])
def test_what_a_check_up_measures_decides_what_a_correction_does(kind: str) -> None:
    """Identity probing measures the machine itself: a correction entered moves the values in force, not the level
    the next check-up starts from, and the held values are the calibration's.  An R-test measures what the
    controller leaves: the correction moves the level by what was entered (and the calibration's, once entered,
    the held values)."""
    setup = SETUP if kind == "identity" else SETUP | {"instrument": "rtest", "probe": None}
    v = np.array([3.0, -2.0, 15.0, -12.0, 2.5, -1.5, 8.0, -6.0])  # LOCATION order
    runs = [full(1, v, setup=setup), checkup(2, [3.0, -2.0, 5.5, -1.5], to_enter={"EX0C": 3.0})]
    from pige_sym.measurements.run_setup import RunSetup

    assert measures_machine(RunSetup.from_dict(setup)) == (kind == "identity")
    state = chart_state(runs, FREE, "s", corrected=True, location=LOCATION)
    start = state.runs["EX0C"][0][0]
    held = state.held["EB0A"]
    if kind == "identity":  # the calibration's correction in force (weighed: well determined, as estimated)
        assert state.absolute and start == pytest.approx(5.5)
        assert state.in_force["EX0C"] == pytest.approx(2.5 + 3.0, abs=0.01) and state.level["EX0C"] == state.in_force[
            "EX0C"]
        assert held == pytest.approx(15.0)
    else:  # nothing entered after the calibration: the controller holds the check-up's correction only
        assert not state.absolute and start == pytest.approx(5.5 - 3.0)
        assert state.in_force["EX0C"] == pytest.approx(3.0) and state.level["EX0C"] == 0.0
        assert held == pytest.approx(15.0)
    runs[1].checkup["after_correction"] = True  # the calibration's correction entered before the check-up
    state = chart_state(runs, FREE, "s", corrected=True, location=LOCATION)
    assert state.held["EB0A"] == pytest.approx(15.0 if kind == "identity" else 0.0, abs=0.01)


def test_the_hierarchical_posterior_against_direct_integration() -> None:
    """The posterior of one unit's τ² against a direct numerical integration of the hierarchical model over
    (ν₀, s₀², the other units' τ²) on the same grids: the scaled-inverse-χ² density written here, each unit's
    restricted likelihood from scipy's normal density."""
    from scipy.stats import invgamma, multivariate_normal

    from pige_sym.verdict.checkup import scatter

    rng = np.random.default_rng(8)
    units = [Series("M", f"P{k}", rng.normal(size=6) * s, np.full(6, 0.04), np.zeros(6, int))
             for k, s in enumerate((0.5, 0.6, 0.45))]
    post = posteriors(units[:1], units)["P0"]
    tau2 = post.tau2
    scales = tau2[np.arange(2 * scatter.SCALE_EVERY, tau2.size - 2 * scatter.SCALE_EVERY, scatter.SCALE_EVERY)]

    def loglik(u: Series) -> np.ndarray:
        out = []
        for t in tau2:
            v = t + u.variances
            w = 1 / v
            mu = (w @ u.values) / w.sum()
            out.append(multivariate_normal(np.full(v.size, mu), np.diag(v)).logpdf(u.values) - 0.5 * np.log(w.sum()))
        return np.array(out)

    like = [np.exp(loglik(u) - loglik(u).max()) for u in units]
    total = np.zeros(tau2.size)
    for nu in scatter.PRIOR_DOF:
        for s2 in scales:
            prior = invgamma(nu / 2, scale=nu * s2 / 2).pdf(tau2) * tau2  # density in log τ²
            prior /= prior.sum()
            others = np.prod([prior @ lk for lk in like[1:]])
            total += others * prior
    oracle = total * like[0]
    oracle /= oracle.sum()
    assert np.abs(np.cumsum(oracle) - np.cumsum(post.weights)).max() < 1e-6
    assert math.isclose(post.median, math.sqrt(tau2[np.searchsorted(np.cumsum(oracle), 0.5)]))


def test_a_run_s_correction_flag_is_stored_and_read_strictly() -> None:
    """Schema 3's ``runs.after_correction``: 0 or 1, else refused naming the column (a row of an older file: 0)."""
    from test_history_decode import row

    from pige_sym.errors import SchemaRefusal
    from pige_sym.verdict.history.decode import decode_run

    assert decode_run(row()).after_correction is False
    assert decode_run(row(after_correction=1)).after_correction is True
    for bad in (2, 1.0, "1", None, True):
        with pytest.raises(SchemaRefusal, match="after_correction: expected 0 or 1"):
            decode_run(row(after_correction=bad))
