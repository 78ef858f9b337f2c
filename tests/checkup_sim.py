"""Check-ups of simulated machines for the tests (tests/test_checkup*.py): real files, and histories in memory.

- **Real files** (:func:`full_calibration`, :func:`checkup_file`): pige's LinuxCNC probing programs run on the
  virtual machine of known PIGEs, imported, added to a history, as a user does it (``pige`` in this process).
- **Histories in memory** (:class:`ChartSim`): the chart of ``pige checkup`` (:func:`~pige_sym.verdict.checkup.
  reference.chart_state` and :func:`~pige_sym.verdict.checkup.routine.judge`, the code the command runs) fed with
  check-up estimates drawn from the covariance a real check-up fit has, held values with the errors a real full
  calibration has (drawn jointly with its free values, so the start of a segment carries the bias holding gives):
  thousands of check-ups in seconds for the false-alarm and detection studies.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from datetime import datetime, timedelta, timezone
from pathlib import Path
from typing import Any

import numpy as np

from pige_sym.cli.main import main
from pige_sym.identification.subset import SubsetFit
from pige_sym.verdict.checkup.judging import flags, fleet_series, judge
from pige_sym.verdict.checkup.reference import chart_state
from pige_sym.verdict.checkup.routine import CheckupOptions
from pige_sym.verdict.checkup.to_enter import checkup_changes
from pige_sym.verdict.history.store import RunRecord

MACHINE = "wC'A'bXYZ(C1)t"
SPHERE = ["--sphere", "100,20,60", "--sphere-radius", "12.7", "--stylus-radius", "1.5"]
KINS = ["--rtcp-off", "M429", "--rtcp-on", "M428", "--stylus-tool", "99", "--stylus-length", "120"]
#: The simulated machine: axis-line offsets of a few µm, tilts of tens of µrad (inside examples/tolerances.json).
TRUTH = {"EY0A": 3.0, "EZ0A": -2.0, "EB0A": 15.0, "EC0A": -12.0, "EX0C": 2.5, "EY0C": -1.5, "EA0C": 8.0, "EB0C": -6.0}
FREE = ["EY0A", "EZ0A", "EX0C", "EY0C"]
LOCATION = ["EY0A", "EZ0A", "EB0A", "EC0A", "EX0C", "EY0C", "EA0C", "EB0C"]
T0 = datetime(2026, 3, 2, 7, 0, tzinfo=timezone.utc)


def spec(pige: dict[str, float]) -> str:
    return ",".join(f"{k}={v!r}" for k, v in pige.items())


def pige(*args: str) -> int:
    """``pige ARGS`` in this process (its exit status)."""
    return main([str(a) for a in args])


def full_calibration(folder: Path, db: Path, machine_id: str, truth: dict[str, float], *, seed: int = 1,
                     when: datetime = T0, noise: float = 0.3, tolerances: Path | None = None) -> Path:
    """A full probing calibration (31-pose cone) of the virtual machine, added to the history."""
    folder.mkdir(parents=True, exist_ok=True)
    prog, log, csv = folder / "full.ngc", folder / "full.txt", folder / "full.csv"
    assert pige("program", "--instrument", "sphere-probe", "--dialect", "linuxcnc", "--machine", MACHINE, *SPHERE,
                *KINS, "--trajectory", "cone-frustum", "--out", prog, "--force") == 0
    assert pige("simulate", "--instrument", "sphere-probe", "--program", prog, "--pige", spec(truth), "--seed", seed,
                "--noise", noise, "--out", log, "--force") == 0
    assert pige("import-probe", log, "--format", "linuxcnc", "--program", prog, "--out", csv, "--force") == 0
    extra = ["--tolerances", tolerances] if tolerances is not None else []
    assert pige("history", "add", csv, "--machine-id", machine_id, "--db", db, "--date", when.isoformat(),
                "--method", "gauss-newton", *extra) == 0
    return csv


def checkup_program(folder: Path, db: Path, machine_id: str, dialect: str = "linuxcnc") -> Path:
    out = folder / f"checkup_{machine_id}.{'ngc' if dialect == 'linuxcnc' else 'nc'}"
    assert pige("program", "--checkup", "--machine-id", machine_id, "--db", db, "--dialect", dialect, "--out", out,
                "--force") == 0
    return out


def checkup_file(program: Path, truth: dict[str, float], seed: int, name: Path, noise: float = 0.3) -> Path:
    """The virtual machine's log of the check-up program, imported: ``name`` (.csv)."""
    log = name.with_suffix(".txt")
    assert pige("simulate", "--instrument", "sphere-probe", "--program", program, "--pige", spec(truth), "--seed",
                seed, "--noise", noise, "--out", log, "--force") == 0
    assert pige("import-probe", log, "--format", "linuxcnc", "--program", program, "--out", name, "--force") == 0
    return name


# ------------------------------------------------------------------------------------------- in memory


@dataclass
class Design:
    """What the draws copy from real fits: the full calibration's covariance (8 PIGEs) and a check-up fit's."""

    full_cov: np.ndarray  # (8, 8) in LOCATION order
    checkup_cov: np.ndarray  # (4, 4) in FREE order
    sensitivity: np.ndarray  # (4, 4): FREE by the held PIGEs in LOCATION order
    checkup_dof: int

    @property
    def checkup_std(self) -> np.ndarray:
        return np.sqrt(np.diag(self.checkup_cov))


@dataclass
class ChartSim:
    """One machine's history in memory, judged check-up by check-up by the command's own code (the chart, the
    scatter's posterior with the ``fleet``'s runs, the limits, the changes to enter)."""

    design: Design
    rng: np.random.Generator
    tolerance: float = 50.0
    extra_scatter: float = 0.0  # run-to-run scatter beyond the measurement noise, in units of the check-up std
    scatter_um: float = 0.0  # run-to-run std of each axis-line position [µm] (re-clamping, temperature), every run
    scatter_factor: dict[str, float] = field(default_factory=dict)  # per PIGE, times scatter_um (default 1)
    alpha: float = 0.01
    machine_id: str = "SIM"
    fleet: list[list[RunRecord]] = field(default_factory=list)
    runs: list[RunRecord] = field(default_factory=list)
    verdicts: list[str] = field(default_factory=list)
    results: list[Any] = field(default_factory=list)

    def moved(self, truth: dict[str, float]) -> dict[str, float]:
        """The machine at one run: its axis-line positions moved by the run-to-run scatter."""
        return {n: v + (self.scatter_um * self.scatter_factor.get(n, 1.0) * float(self.rng.standard_normal())
                        if n in FREE else 0.0) for n, v in truth.items()}

    def calibrate(self, truth: dict[str, float], when: datetime) -> None:
        truth = self.moved(truth)
        err = self.rng.multivariate_normal(np.zeros(8), self.design.full_cov)
        values = np.array([truth[n] for n in LOCATION]) + err
        std = np.sqrt(np.diag(self.design.full_cov))
        self.runs.append(_record(len(self.runs) + 1, when, "full", LOCATION, values, std, self.design.full_cov, 400,
                                 machine_id=self.machine_id))

    def checkup(self, truth: dict[str, float], when: datetime, corrected: bool = False) -> str:
        """Draw the check-up estimate of ``truth`` (the held values off by the last calibration's errors), judge it,
        store it; its verdict."""
        d = self.design
        truth = self.moved(truth)
        state = chart_state(self.runs, FREE, "sim", corrected=corrected, location=LOCATION)
        bias = -d.sensitivity @ np.array([state.held[n] - truth[n] for n in state.held])
        extra = self.rng.standard_normal(4) * self.extra_scatter * d.checkup_std
        x = np.array([truth[n] for n in FREE]) + bias + extra + self.rng.multivariate_normal(np.zeros(4),
                                                                                              d.checkup_cov)
        scale = np.sqrt(self.rng.chisquare(d.checkup_dof) / d.checkup_dof)
        own = d.checkup_cov * scale**2
        cov = own + d.sensitivity @ state.held_covariance @ d.sensitivity.T
        fit = SubsetFit(MACHINE, list(FREE), {n: "um" for n in FREE}, x, np.sqrt(np.diag(cov)), cov, state.held,
                        d.checkup_dof, 0.3, 27, sensitivity=d.sensitivity, fit_covariance=own)
        opts = CheckupOptions(alpha=self.alpha, corrected=corrected)
        t_now = (when - datetime.fromisoformat(state.origin)).total_seconds() / 3600.0
        items, verdict = judge(fit, state, dict.fromkeys(FREE, self.tolerance), opts, t_now,
                               fleet_series(self.fleet, LOCATION))
        changes = checkup_changes(fit, None, opts, state)
        info = {"signature": "sim", "after_correction": corrected, **flags(items), "to_enter": changes.entered}
        rec = _record(len(self.runs) + 1, when, "checkup", FREE, x, fit.std, fit.covariance, fit.dof, info, verdict,
                      machine_id=self.machine_id)
        self.runs.append(rec)
        self.verdicts.append(verdict)
        self.results.append((items, changes, state))
        return verdict


def _record(run_id: int, when: datetime, kind: str, names: list[str], values: np.ndarray, std: np.ndarray,
            cov: np.ndarray, dof: int, checkup: dict[str, Any] | None = None, verdict: str | None = None, *,
            machine_id: str = "SIM") -> RunRecord:
    return RunRecord(run_id, machine_id, f"run{run_id}", f"{run_id:064x}", when.isoformat(timespec="seconds"), "--date",
                     "", MACHINE, kind, list(names), {n: "um" for n in names}, np.asarray(values, dtype=float),
                     np.asarray(std, dtype=float), np.asarray(cov, dtype=float), dof, 0.3, [], verdict, None, kind,
                     SETUP if kind == "full" else None, checkup)


SETUP = {"instrument": "sphere-probe", "machine": MACHINE, "ball_mm": [100.0, 20.0, 60.0],
         "pivots_mm": {"A": [0.0, 0.0, 0.0], "C": [0.0, 0.0, 0.0]}}


def design_from_files(full_csv: Path, checkup_csv: Path) -> Design:
    """The covariances of a real full calibration and a real check-up fit of the simulated machine."""
    from pige_sym.identification.least_squares import identify
    from pige_sym.identification.subset import identify_subset
    from pige_sym.measurements.rtest import read_measurement

    full = identify(read_measurement(full_csv))
    idx = [full.parameters.index(n) for n in LOCATION]
    held = {n: TRUTH[n] for n in LOCATION if n not in FREE}
    fit = identify_subset(read_measurement(checkup_csv), FREE, held)
    assert fit.sensitivity is not None
    return Design(full.covariance[np.ix_(idx, idx)], fit.covariance, fit.sensitivity, fit.dof)


def hourly(i: int, step_h: float = 24.0) -> datetime:
    return T0 + timedelta(hours=step_h * i)
