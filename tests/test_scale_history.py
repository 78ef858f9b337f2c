"""A long history costs in proportion to its runs (issue 47, item 4): `pige history show`, `pige report --history`.

Counted, not timed (the times are in benchmarks/bench_scale_history.py):

- the comparisons of consecutive runs are computed together (:func:`~pige_sym.verdict.history.changes.
  compare_consecutive`) and give what :func:`compare_runs` of each pair gave before — the oracle here is that
  function as it was written, pair by pair;
- the check-up plot and the trend plot draw a fixed number of artists and at most 17 date labels, whatever the number
  of runs (each run drew its own error bar, limit and tolerance lines, and the trend plot one date per run: a history
  of 1,000 runs took minutes to draw).
"""

from __future__ import annotations

import math
from datetime import datetime, timedelta, timezone
from typing import Any

import numpy as np
import pytest

from pige_sym.verdict.history.changes import ALPHA, TEST, Change, Comparison, compare_consecutive, compare_runs
from pige_sym.verdict.history.records import RunRecord

AC = "wC'A'bXYZ(C1)t"
LOCATION = ["EY0A", "EZ0A", "EB0A", "EC0A", "EX0C", "EY0C", "EA0C", "EB0C"]
FREE = ["EY0A", "EZ0A", "EX0C", "EY0C"]
T0 = datetime(2026, 1, 5, 7, 0, tzinfo=timezone.utc)


# ------------------------------------------------------------------ the oracle: compare_runs as it was, pair by pair

def _welch_as_written(va: float, vb: float, na: int, nb: int) -> float:
    num = (va + vb) ** 2
    den = (va**2 / max(na, 1) if va > 0 else 0.0) + (vb**2 / max(nb, 1) if vb > 0 else 0.0)
    return num / den if den > 0 else float(max(na + nb, 1))


def _joint_as_written(d: np.ndarray, cov: np.ndarray) -> tuple[float, int]:
    s = np.sqrt(np.diag(cov))
    scaled = cov / np.outer(s, s)
    w, v = np.linalg.eigh(scaled)
    keep = w > 1e-10 * max(float(w.max()), 1e-300)
    proj = v[:, keep].T @ (d / s)
    return float((proj**2 / w[keep]).sum()), int(keep.sum())


def _effect_ids(run: Any) -> list[str] | None:
    effects = getattr(run, "effects", None)
    if effects is None:
        return None
    return sorted(str(f.get("effect")) for f in effects if f.get("effect") != "outliers")


def compare_runs_as_written(a: Any, b: Any, *, alpha: float = ALPHA, from_run: int | None = None,
                            to_run: int | None = None) -> Comparison:
    """pige_sym.verdict.history.changes.compare_runs before issue 47 (one pair at a time)."""
    from scipy.special import fdtrc, stdtr

    names = list(a.parameters) + [p for p in b.parameters if p not in a.parameters]
    tested: list[str] = []
    for p in names:
        if p in a.parameters and p in b.parameters:
            i, j = a.parameters.index(p), b.parameters.index(p)
            if all(math.isfinite(float(x)) and float(x) >= 0 for x in (a.covariance[i, i], b.covariance[j, j])) \
                    and math.isfinite(float(a.values[i])) and math.isfinite(float(b.values[j])) \
                    and a.covariance[i, i] + b.covariance[j, j] > 0:
                tested.append(p)
    ia = [a.parameters.index(p) for p in tested]
    ib = [b.parameters.index(p) for p in tested]
    d = np.asarray(b.values, dtype=float)[ib] - np.asarray(a.values, dtype=float)[ia]
    cov = np.asarray(a.covariance, dtype=float)[np.ix_(ia, ia)] + np.asarray(b.covariance, dtype=float)[np.ix_(ib, ib)]
    nu = (int(a.dof), int(b.dof))
    stat, rank, p_joint = None, 0, None
    if tested:
        stat, rank = _joint_as_written(d, cov)
        p_joint = float(fdtrc(max(rank, 1), max(min(nu), 1), stat / max(rank, 1)))
    joint = p_joint is not None and p_joint <= alpha
    out = Comparison(from_run, to_run, TEST, alpha, len(tested), rank, stat, nu, p_joint, joint)
    effects_a, effects_b = _effect_ids(a), _effect_ids(b)
    if effects_a is not None and effects_b is not None and effects_a != effects_b:
        out.notes.append(f"the runs were fitted with different effects ({', '.join(effects_a) or 'none'} vs "
                         f"{', '.join(effects_b) or 'none'}): a PIGE change may partly reflect the model")
    m = max(len(tested), 1)
    for p in names:
        unit = a.units.get(p) or b.units.get(p, "")
        if p not in tested:
            why = "not determined in both runs" if p in a.parameters and p in b.parameters else \
                "estimated in one run only (different model)"
            out.changes.append(Change(p, unit, from_run, to_run, None, None, None, None, None, why))
            continue
        k = tested.index(p)
        va, vb = float(a.covariance[ia[k], ia[k]]), float(b.covariance[ib[k], ib[k]])
        std = math.sqrt(va + vb)
        z = float(d[k]) / std
        p_val = float(2 * stdtr(_welch_as_written(va, vb, nu[0], nu[1]), -abs(z)))
        sig = joint and p_val <= alpha / m
        out.changes.append(Change(p, unit, from_run, to_run, float(d[k]), std, z, p_val, sig,
                                  "" if sig or not joint else "within noise at the Bonferroni level"))
    return out


# ------------------------------------------------------------------------------------------------------ the runs

def _run(i: int, names: list[str], rng: np.random.Generator, *, kind: str = "full",
         checkup: dict[str, Any] | None = None, effects: list[dict[str, Any]] | None = None) -> RunRecord:
    p = len(names)
    a = rng.normal(size=(p, p)) * rng.uniform(0.05, 2.0, size=p)
    cov = a @ a.T / p + np.diag(rng.uniform(0.0, 0.05, size=p))
    values = rng.normal(scale=5.0, size=p)
    shape = rng.random()
    if shape < 0.1:  # undetermined parameter
        values[rng.integers(p)] = np.nan
    elif shape < 0.15:  # a parameter held exactly (no variance)
        k = rng.integers(p)
        cov[k, :] = cov[:, k] = 0.0
    elif shape < 0.2:  # a rank-one (singular) change covariance
        u = rng.normal(size=p)
        cov = np.outer(u, u)
    std = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    when = (T0 + timedelta(days=i)).isoformat(timespec="seconds")
    return RunRecord(i + 1, "M", f"run{i}.csv", f"{i:064x}", when, "--date", when, AC, "gauss-newton", list(names),
                     {n: "urad" if n[1] in "ABC" else "um" for n in names}, values, std, cov,
                     int(rng.integers(0, 40)), 0.3, effects or [], "pass", None, kind, None, checkup)


def _history(n: int, seed: int) -> list[RunRecord]:
    """Full calibrations (8 PIGEs, sometimes with an effect) and check-ups (4), sometimes another parameter set."""
    rng = np.random.default_rng(seed)
    runs = []
    for i in range(n):
        u = rng.random()
        if u < 0.2:
            effects = [{"effect": "backlash_C"}] if rng.random() < 0.5 else []
            runs.append(_run(i, LOCATION, rng, effects=effects))
        elif u < 0.3:
            runs.append(_run(i, ["EX0C", "EY0C", "EA0A"], rng))  # a parameter only this run has
        else:
            runs.append(_run(i, FREE, rng, kind="checkup"))
    return runs


def _same(got: Comparison, expected: Comparison) -> None:
    def close(x: Any, y: Any) -> bool:
        if x is None or y is None or isinstance(x, (str, bool)):
            return x == y
        return math.isclose(x, y, rel_tol=1e-9, abs_tol=1e-12) or (math.isnan(x) and math.isnan(y))

    for key in ("from_run", "to_run", "test", "alpha", "n_tested", "rank", "dof", "significant", "notes"):
        assert getattr(got, key) == getattr(expected, key), key
    assert close(got.statistic, expected.statistic) and close(got.p_value, expected.p_value)
    assert [c.parameter for c in got.changes] == [c.parameter for c in expected.changes]
    for c, e in zip(got.changes, expected.changes, strict=True):
        assert (c.unit, c.from_run, c.to_run, c.significant, c.reason) == (e.unit, e.from_run, e.to_run,
                                                                            e.significant, e.reason)
        for key in ("change", "std", "z", "p_value"):
            assert close(getattr(c, key), getattr(e, key)), (c, e)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_consecutive_comparisons_are_compare_runs_of_each_pair(seed: int) -> None:
    runs = _history(300, seed)
    got = compare_consecutive(runs, alpha=0.05)
    expected = [compare_runs_as_written(a, b, alpha=0.05, from_run=a.id, to_run=b.id)
                for a, b in zip(runs, runs[1:], strict=False)]
    assert len(got) == len(expected) == 299
    assert sum(c.significant for c in expected) > 10, "the oracle must see changes too"
    for g, e in zip(got, expected, strict=True):
        _same(g, e)
    for a, b in zip(runs[:40], runs[1:41], strict=False):  # the one-pair entry is the same code
        _same(compare_runs(a, b, from_run=a.id, to_run=b.id), compare_runs_as_written(a, b, from_run=a.id,
                                                                                       to_run=b.id))


def test_a_history_without_a_pair_compares_nothing() -> None:
    assert compare_consecutive([]) == [] and compare_consecutive(_history(1, 0)) == []


# ------------------------------------------------------------------------------------------------------ the plots

def _checkup_info(rng: np.random.Generator, after_correction: bool) -> dict[str, Any]:
    items = []
    for name in FREE:
        status = ["pass", "pass", "fail"][int(rng.integers(3))]
        items.append({"name": name, "value": 1.0, "std": 0.1, "status": status, "tolerance": 5.0,
                      "limit": {"centre": 0.1, "half_width": 0.6, "outside": bool(rng.random() < 0.3)},
                      "trend": {"rate_per_h": 0.001, "significant": False}})
    return {"items": items, "after_correction": after_correction}


def _report_history(n: int) -> Any:
    from pige_sym.report.data import HistoryData, ReportData

    rng = np.random.default_rng(n)
    runs = []
    for i in range(n):
        if i % 10 == 0:
            runs.append(_run(i, LOCATION, rng))
        else:
            runs.append(_run(i, FREE, rng, kind="checkup", checkup=_checkup_info(rng, i % 7 == 3)))
    runs[-1] = _run(n - 1, FREE, rng, kind="checkup", checkup=_checkup_info(rng, False))
    history = HistoryData("M", "sqlite:///h.db", runs, compare_consecutive(runs), {n: 10.0 for n in LOCATION})
    return ReportData(measurements=[], history=history)


def _artists(fig: Any) -> list[int]:
    return [len(ax.lines) + len(ax.collections) + len(ax.containers) + len(ax.patches) for ax in fig.axes]


def test_the_history_plots_draw_a_fixed_number_of_artists_whatever_the_runs() -> None:
    import matplotlib.pyplot as plt

    from pige_sym.report.checkup_section import checkup_figure
    from pige_sym.report.figures import trend_figure

    counts = {}
    for n in (30, 300):
        data = _report_history(n)
        check, trend = checkup_figure(data), trend_figure(data.history)
        labels = [len([t for t in ax.get_xticklabels() if t.get_text()]) for ax in trend.axes if ax.get_visible()]
        counts[n] = (_artists(check), _artists(trend), max(labels))
        plt.close(check)
        plt.close(trend)
    assert counts[30][:2] == counts[300][:2], counts
    assert counts[30][2] <= 17 and counts[300][2] <= 17, counts
