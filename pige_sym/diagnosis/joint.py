"""Diagnosis of several files of one machine: each file's own diagnosis, and whether the files agree.

A set of setups (R-test runs, probe imports, ballbar setups) is diagnosed in three parts:

1. **Each file alone.** R-test and probe files get the catalogue diagnosis of
   :mod:`~pige_sym.diagnosis.diagnose` (their rows are 3-D deviations).  A ballbar setup sees one
   projection per pose along a direction that turns with the pose: the catalogue's signatures are not
   built for it, so a ballbar file is checked for agreement only (said in its row, not silently).
2. **Do the files agree on one set of PIGEs?**  The joint model (shared PIGEs, a constant per relative
   ballbar file) is tested against separate models (each file its own PIGEs and constants) with an F test
   on the whitened residual sums (each file's rows divided by its own σ, as in the joint fit)::

       F = ((RSS_joint − Σ RSS_f) / (Σ rank_f − rank_joint)) / max(Σ RSS_f / Σ (n_f − rank_f), 1)

   Each σ is floored at ``SIGMA_FLOOR_UM`` for the test (noise-free simulations would otherwise make
   the first-order model's own 0.02 µm error at 50 µm / 100 µrad PIGEs "significant").
   A small p (below ``ALPHA``) means the machine did not hold one geometry over the setups (temperature,
   re-homing, a collision, a moved fixture) or an unmodelled effect projects differently in each setup.
3. **Which file?**  The same test with one file set apart at a time (its own PIGEs, the others shared),
   judged at ``ALPHA / files`` (Bonferroni), names the file that disagrees.

The final estimate is the joint PIGE fit; effects found in one file are reported with that file, and the
note says the joint estimate does not model them.
"""

from __future__ import annotations

import math
from collections.abc import Collection, Sequence
from dataclasses import dataclass, field
from typing import Any

from pige_sym.diagnosis.results import DiagnosisResult, Finding
from pige_sym.identification.joint import (
    Block,
    JointResult,
    common_machine,
    file_blocks,
    identify_joint,
    whitened_system,
)
from pige_sym.identification.result import IdentificationResult, json_float
from pige_sym.identification.spectrum import solve_scaled
from pige_sym.kernels import load_kernels
from pige_sym.measurements.ballbar import BallbarRun
from pige_sym.measurements.measurement import Measurement

ALPHA = 0.01  # false alarm of the agreement test (the per-file tests: ALPHA / files)
SIGMA_FLOOR_UM = 0.05  # below any R-test, probe or ballbar in use; the first-order model errs 0.02 um at 50 um PIGEs


@dataclass
class Agreement:
    """An F test of shared PIGEs against separate ones (module docstring)."""

    f_statistic: float
    dof: tuple[int, int]
    p_value: float

    def to_dict(self) -> dict[str, Any]:
        return {"f_statistic": json_float(self.f_statistic), "dof": list(self.dof), "p_value": json_float(self.p_value)}

    def text(self) -> str:
        return f"F = {self.f_statistic:.2f} on ({self.dof[0]}, {self.dof[1]}) dof, p = {self.p_value:.2g}"


@dataclass
class FileDiagnosis:
    """One file's part: its own findings (R-test, probe) and whether it agrees with the others."""

    label: str
    instrument: str
    rows: int
    sigma_um: float
    joint_rms_um: float
    findings: list[Finding]
    checked: str
    agreement: Agreement | None
    disagrees: bool

    def to_dict(self) -> dict[str, Any]:
        return {"file": self.label, "instrument": self.instrument, "rows": self.rows,
                "sigma_um": json_float(self.sigma_um), "joint_rms_um": json_float(self.joint_rms_um),
                "checked": self.checked, "findings": [f.to_dict() for f in self.findings],
                "agreement": None if self.agreement is None else self.agreement.to_dict(),
                "disagrees": self.disagrees}


@dataclass
class JointDiagnosis:
    """Diagnosis of a set of files of one machine."""

    machine: str
    joint: JointResult
    files: list[FileDiagnosis]
    agreement: Agreement | None
    notes: list[str] = field(default_factory=list)
    effects: list[Finding] = field(default_factory=list)  # seen jointly in a set of ballbar setups
    extended: JointResult | None = None  # the joint fit with those effects
    searched: list[str] = field(default_factory=list)  # the effects searched jointly (a set of ballbar setups)

    @property
    def final(self) -> IdentificationResult:
        """The joint PIGE estimate (with the effects found jointly, when there are)."""
        return self.joint.result if self.extended is None else self.extended.result

    @property
    def findings(self) -> list[Finding]:
        """Every file's findings (each also listed under its file) and the effects found jointly."""
        return [f for fd in self.files for f in fd.findings] + self.effects

    def to_dict(self) -> dict[str, Any]:
        final = self.final.to_dict()
        return {"machine": self.machine, "method": "joint-diagnosis",
                "agreement": None if self.agreement is None else self.agreement.to_dict(),
                "files": [f.to_dict() for f in self.files], "notes": self.notes,
                "effects": [f.to_dict() for f in self.effects], "effects_searched": self.searched,
                "joint_effects": self.joint_effects_text(),
                "pige": final["pige"], "std": final["std"], "covariance": final["covariance"], "units": final["units"],
                "unidentifiable": final["unidentifiable"], "null_space": final["null_space"],
                "rank": final["rank"], "condition": final["condition"],
                "rms_um": final["rms_um"], "ball_mm": final["ball_mm"], "pivots_mm": final["pivots_mm"],
                "tool_mm": final["tool_mm"]}

    @property
    def agreement_status(self) -> str:
        """``untestable`` (one file, or no combination measured twice), ``disagree`` (p < ALPHA) or ``agree``."""
        if self.agreement is None:
            return "untestable"
        return "disagree" if self.agreement.p_value < ALPHA else "agree"

    def verdict(self) -> str:
        lines = []
        if self.agreement is None:
            lines.append("One file: nothing to compare it with." if len(self.files) == 1 else
                         "The files see different combinations of the PIGEs (no combination is measured twice): "
                         "their agreement cannot be tested; add a setup that repeats one to check it.")
        elif self.agreement.p_value < ALPHA:
            bad = [f.label for f in self.files if f.disagrees]
            who = f"; the file that disagrees: {', '.join(bad)}" if bad else "; no single file stands out"
            lines.append(f"The files do NOT agree on one set of PIGEs ({self.agreement.text()}){who}. The machine "
                         "changed between the setups (temperature, re-homing, a moved fixture) or an effect the "
                         "model misses projects differently in each: the joint estimate is not to be trusted.")
        else:
            lines.append(f"The files agree on one set of PIGEs ({self.agreement.text()}).")
        groups: dict[str, list[str]] = {}  # files with the same own result: one line, not one each
        for fd in self.files:
            found = ", ".join(f.title() for f in fd.findings) or "nothing beyond the PIGEs"
            alone = fd.checked.startswith("agreement only")  # a ballbar file: no diagnosis of its own
            groups.setdefault(fd.checked + ("; effects searched jointly (next line)" if alone and
                                            self.searched else "" if alone else f": {found}"), []).append(fd.label)
        for what, labels in groups.items():
            who = labels[0] if len(labels) == 1 else f"{len(labels)} files ({', '.join(labels)})"
            lines.append(f"- {who}: {what}")
        joint = self.joint_effects_text()
        if joint:
            lines.append(joint)
        return "\n".join(lines)

    def joint_effects_text(self) -> str:
        """What the joint search of a set of ballbar setups found, in one sentence ("" when none was made)."""
        if self.effects:
            return ("Seen jointly in the ballbar setups: " + ", ".join(f.title() for f in self.effects)
                    + " (the PIGEs below are estimated with them).")
        if not self.searched:
            return ""
        return (f"Searched jointly over the {len(self.files)} setups: none of the {len(self.searched)} catalogue "
                "effects (angular positioning errors, wobbles and radial run-outs of the swept axes, squareness) "
                "improves the joint fit enough to be accepted: the PIGEs alone explain the setups (joint residual "
                f"RMS {self.final.rms_um:.3g} um).")


def _rss_rank(blocks: Sequence[Block], sigmas: Sequence[float]) -> tuple[float, int, int]:
    """Whitened residual sum, rank and observations of one shared model over ``blocks``."""
    a, y = whitened_system(blocks, sigmas)
    sol = solve_scaled(a.T @ a, a.T @ y, float(y @ y))
    return float(sol.rss), int(sol.rank), int(y.size)


def _f_test(shared: tuple[float, int, int], parts: list[tuple[float, int, int]]) -> Agreement | None:
    """Shared model against the separate ``parts`` (each its own parameters)."""
    from scipy.special import fdtrc

    rss_sep = sum(p[0] for p in parts)
    dof_sep = shared[2] - sum(p[1] for p in parts)
    dof_num = sum(p[1] for p in parts) - shared[1]
    if dof_num <= 0 or dof_sep <= 0:
        return None
    # whitened by their own σ the separate fits give rss_sep / dof_sep = 1; below the σ floor less: then 1
    f_stat = max(shared[0] - rss_sep, 0.0) / dof_num / max(rss_sep / dof_sep, 1.0)
    return Agreement(f_stat, (dof_num, dof_sep), float(fdtrc(dof_num, dof_sep, f_stat)))


def _attribute(blocks: Sequence[Block], sigmas: Sequence[float], alone: list[tuple[float, int, int]]
               ) -> tuple[list[Agreement | None], set[int]]:
    """Per-file tests (one file apart, the others shared) and the files that disagree.

    Backward elimination: the most significant file below ``ALPHA / active files`` is flagged and
    left out, and the rest are tested again, so one moved file does not drag the files that share
    its combinations along.  Each file keeps the test of the last round it took part in.
    """
    active = list(range(len(blocks)))
    tests: list[Agreement | None] = [None] * len(blocks)
    flagged: set[int] = set()
    while len(active) > 2:
        shared = _rss_rank([blocks[i] for i in active], [sigmas[i] for i in active])
        for i in active:
            rest = [j for j in active if j != i]
            tests[i] = _f_test(shared, [alone[i], _rss_rank([blocks[j] for j in rest], [sigmas[j] for j in rest])])
        worst = min(active, key=lambda i: math.inf if tests[i] is None else tests[i].p_value)  # type: ignore[union-attr]
        test = tests[worst]
        if test is None or test.p_value >= ALPHA / len(active):
            break
        flagged.add(worst)
        active.remove(worst)
    return tests, flagged


def _pooled_sigmas(blocks: Sequence[Block]) -> list[float]:
    """σ per file for the tests: pooled over the files of one instrument, floored at ``SIGMA_FLOOR_UM``."""
    pooled: dict[str, tuple[float, int]] = {}
    for b in blocks:
        rss, rank, n = _rss_rank([b], [1.0])
        old = pooled.get(b.instrument, (0.0, 0))
        pooled[b.instrument] = (old[0] + rss, old[1] + n - rank)
    return [max(math.sqrt(pooled[b.instrument][0] / max(pooled[b.instrument][1], 1)), SIGMA_FLOOR_UM)
            for b in blocks]


def _own_findings(item: Measurement | BallbarRun, progress: bool, known: DiagnosisResult | None,
                  exclude: Collection[str] = ()) -> tuple[list[Finding], str, list[str]]:
    if isinstance(item, BallbarRun):
        return [], "agreement only (one projection per pose: the catalogue needs 3-D rows)", []
    from pige_sym.diagnosis.diagnose import diagnose

    diag = known if known is not None else diagnose(item, progress=progress, exclude=exclude)
    return diag.findings, "catalogue diagnosis", diag.clusters


def diagnose_joint(items: Sequence[tuple[str, Measurement | BallbarRun]], *, progress: bool = False,
                   diagnoses: Sequence[DiagnosisResult | None] | None = None,
                   exclude: Collection[str] = ()) -> JointDiagnosis:
    """Diagnose several files of one machine (module docstring).

    Parameters
    ----------
    items : sequence of (label, Measurement or BallbarRun)
    progress : bool
        Progress bars of the per-file diagnoses on stderr.
    diagnoses : sequence of DiagnosisResult or None, optional
        Each file's own diagnosis when already made (``pige report``); None: made here.
    exclude : collection of str
        Catalogue ids the per-file diagnoses leave out (``pige diagnose --map``: the mapped axes' error motions).

    Returns
    -------
    JointDiagnosis
    """
    machine = common_machine(items)
    joint = identify_joint(items)
    blocks = file_blocks(items)
    sigmas = _pooled_sigmas(blocks)
    shared = _rss_rank(blocks, sigmas)
    alone = [_rss_rank([b], [s]) for b, s in zip(blocks, sigmas, strict=True)]
    overall = _f_test(shared, alone) if len(blocks) > 1 else None
    tests, flagged = _attribute(blocks, sigmas, alone)
    files, notes = [], []
    for i, ((label, item), b, summary) in enumerate(zip(items, blocks, joint.files, strict=True)):
        known = None if diagnoses is None else diagnoses[i]
        findings, checked, clusters = _own_findings(item, progress, known, exclude)
        notes += [f"{label}: {c}" for c in clusters]
        files.append(FileDiagnosis(label, b.instrument, b.data.size, sigmas[i], summary.rms_um, findings, checked,
                                   tests[i], i in flagged))
    effects, extended = _ballbar_effects(machine, items, blocks, [f.sigma_um for f in joint.files])
    searched = _searched(items)
    if effects and overall is not None and overall.p_value < ALPHA:
        notes.append("the agreement test compares PIGE-only models: an effect the setups see differently can "
                     "make them disagree; judge it with the effects found")
    if any(fd.findings for fd in files):
        notes.append("the joint estimate holds the PIGEs only: an effect found in one file is not modelled in it "
                     "(compensate from that file's own diagnosis, or remove the cause and measure again)")
    if overall is not None and len(blocks) == 2 and overall.p_value < ALPHA:
        notes.append("with two files the test cannot say which one moved")
    if not math.isfinite(joint.result.rms_um):
        notes.append("the joint fit has no residual")
    return JointDiagnosis(machine, joint, files, overall, notes, effects, extended, searched)


def _searched(items: Sequence[tuple[str, Measurement | BallbarRun]]) -> list[str]:
    """The effects the joint search tries on a set of ballbar setups (none for other sets)."""
    runs = [x for _, x in items if isinstance(x, BallbarRun)]
    if len(runs) != len(items):
        return []
    from pige_sym.diagnosis.joint_effects import candidates

    return [spec.id + "".join(f" {k}={v:g}" for k, v in spec.options.items()) for spec in candidates(runs)]


def _ballbar_effects(machine: str, items: Sequence[tuple[str, Measurement | BallbarRun]], blocks: list[Block],
                     sigmas: list[float]) -> tuple[list[Finding], JointResult | None]:
    """The catalogue effects a set of ballbar setups shows jointly (none for other sets); ``sigmas``: each
    file's σ from its own fit (as the joint identification weighed it)."""
    runs = [(label, x) for label, x in items if isinstance(x, BallbarRun)]
    if len(runs) != len(items):
        return [], None
    from pige_sym.diagnosis.joint_effects import diagnose_ballbar_set

    names = list(load_kernels(machine).LOCATION_PARAMETERS)
    return diagnose_ballbar_set(machine, runs, blocks, sigmas, names, SIGMA_FLOOR_UM)


def format_joint_diagnosis(d: JointDiagnosis) -> str:
    """Text printed by ``pige diagnose F1 F2 ...``."""
    from pige_sym.identification.joint import format_files
    from pige_sym.identification.result import format_result

    lines = [d.verdict()]
    for fd in d.files:
        if fd.agreement is not None:
            mark = "DISAGREES" if fd.disagrees else "agrees"
            lines.append(f"  {fd.label} against the others: {fd.agreement.text()} ({mark}, "
                         f"alpha {ALPHA / len(d.files):.2g})")
        for f in fd.findings:
            lines.append(f"  {fd.label}: {f.sentence()}")
    lines += [f"  jointly: {f.sentence()}" for f in d.effects]
    lines += [f"note: {n}" for n in d.notes]
    final = d.joint if d.extended is None else d.extended  # each file's σ and residual in the fit shown
    what = "PIGEs" if d.extended is None else "PIGEs and the effects seen jointly; σ per file estimated with them"
    lines += ["", f"joint estimate ({what}):", format_result(d.final), format_files(final.files)]
    return "\n".join(lines)

