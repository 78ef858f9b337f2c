"""What to do next: the report's "next step", in every verdict state, computed from the result.

- no tolerances: judge the estimate (``pige check``);
- PASS: nothing to correct; keep the run in the machine's history to see drift;
- FAIL: correct the machine with the estimate the report used (``pige diagnose --json`` then ``pige compensate``),
  measure again, compare;
- UNDECIDED: which items are undecided and why, and what would decide them.  An item is undecided when
  ``|v| − k·u ≤ L < |v| + k·u``; it is decided by a standard uncertainty ``u ≤ u_req = | L − |v| | / k``.  The
  same test repeated with ``n`` poses scales ``u`` by ``√(n_now / n)`` (the normal matrix grows with the poses),
  so ``n = ⌈n_now · (u / u_req)²⌉`` poses of this test decide it; an orientation error (µrad) is also decided by a
  longer lever arm (a larger tilt range, a ball farther from the axis, a longer tool on a head), which ``pige
  plan`` searches.  The ``pige plan`` command is written out with the file's machine, ball or sphere, tool, noise
  and that number of poses (a probe plan: its time budget, 20 s per pose and 8 s per contact, ``pige plan``'s
  defaults).  An item without a value (not identifiable) needs a test that determines it.
- a diagnosis that failed: look at the file (its identification stands alone).

The history and the measured before/after pages get their own (:func:`history_next`, :func:`compare_next`).

Every command printed runs as printed (issue 50): the user's own file names, quoted for the shell; a correction
without the report's ``--program`` gives the controller-neutral corrected axis lines (``--controller table``).  What
the report cannot know — a measurement not made yet, a tolerance file not given, the name of the machine in a history
— is said in words, never as a placeholder inside a command.
"""

from __future__ import annotations

import math
import shlex
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from pige_sym.report.data import MeasurementReport, ReportData
from pige_sym.report.html_blocks import esc
from pige_sym.verdict.check import CheckItem

#: pige plan's probe schedule (its --pose-time and --contact-time defaults) [s].
PROBE_POSE_S, PROBE_CONTACT_S = 20.0, 8.0


@dataclass
class NextStep:
    """What to do next: one sentence, the reasons per item, the commands in order."""

    what: str
    commands: list[str] = field(default_factory=list)
    reasons: list[str] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        return {"what": self.what, "reasons": self.reasons, "commands": self.commands}


def next_html(step: NextStep) -> str:
    """The step as HTML: the sentence, the reasons as a list, each command on its own line."""
    reasons = ("<ul>" + "".join(f"<li>{esc(r)}</li>" for r in step.reasons) + "</ul>") if step.reasons else ""
    return f'<span data-next-step="1">{esc(step.what)}</span>{reasons}{commands_html(step.commands)}'


def commands_html(commands: list[str]) -> str:
    """Each command on its own line, as the reports print follow-up commands (``<code class="cmd">``)."""
    return "".join(f'<br><code class="cmd">{esc(c)}</code>' for c in commands)


def shell_word(text: str) -> str:
    """``text`` as one shell word a user can read: a machine code in double quotes (``"wC'A'bXYZ(C1)t"``, as the
    docs write it) when that is safe, else :func:`shlex.quote`."""
    if shlex.quote(text) == text or any(c in text for c in '"$`\\!'):
        return shlex.quote(text)
    return f'"{text}"'


def _vec(values: Any) -> str:
    return ",".join(f"{float(x):g}" for x in values)


def _decide(item: CheckItem, k: float, poses: int, instrument: str) -> tuple[str, int | None]:
    """Why one item is undecided and how many poses of this test would decide it (None: no number of poses)."""
    if item.value is None or item.std is None:
        return (f"{item.name} has no value: this test cannot determine it (pige plan names one that does)", None)
    need = abs(item.limit - abs(item.value)) / k
    if need <= 0:
        return (f"{item.name} = {item.value:.3g} {item.unit} lies on its limit {item.limit:g}: no measurement "
                "decides it; correct the machine first", None)
    n = math.ceil(poses * (item.std / need) ** 2)
    lever = ("; or a longer lever arm: a larger tilt range, a " + ("sphere" if instrument == "sphere-probe" else
                                                                   "ball") + " farther from the axis, a longer tool"
             if item.unit == "urad" else "")
    return (f"{item.name} = {item.value:.3g} ± {item.std:.2g} {item.unit} against its limit {item.limit:g}: "
            f"|v| ± {k:g}u straddles it; deciding needs u ≤ {need:.2g} {item.unit} ({item.std / need:.2g}× "
            f"smaller): {n} poses of this test instead of {poses} (u falls as 1/√poses){lever}", n)


def _plan_command(rep: MeasurementReport, poses: int) -> str | None:
    """``pige plan`` for this file's machine, set-up and noise, with ``poses`` poses (a probe: their budget); None for
    a probe file that does not state its sphere's and stylus' radii (the command needs them)."""
    m = rep.measurement
    tool = f" --tool {_vec(m.tool_mm)}" if m.tool_mm is not None else ""
    if m.metadata.get("instrument") == "sphere-probe":
        radii = (m.metadata.get("sphere_radius_mm"), m.metadata.get("stylus_radius_mm"))
        if None in radii:
            return None
        contacts = m.optional.get("n_samples")
        per_pose = PROBE_POSE_S + PROBE_CONTACT_S * (float(contacts.mean()) if contacts is not None else 5.0)
        return (f"pige plan --instrument sphere-probe --machine {shell_word(rep.machine)} --sphere "
                f"{_vec(m.ball_mm)} --sphere-radius {radii[0]} --stylus-radius {radii[1]} --noise "
                f"{float(m.metadata.get('contact_sigma_um', 0.5)):.2g}{tool} --budget {math.ceil(poses * per_pose)}")
    pivots = "".join(f" --pivot {a}={_vec(v)}" for a, v in m.pivots_mm.items() if any(float(x) for x in v))
    return (f"pige plan --machine {shell_word(rep.machine)} --points {poses} --noise {rep.primary.sigma_um:.2g} "
            f"--ball {_vec(m.ball_mm)}{tool}{pivots} --out plan.csv   # and --limits AXIS=lo:hi: your machine's "
            "travel")


#: What the correction commands leave to the user, in words (a command pige prints runs as printed).
CORRECT_WORDS = ("; for your controller's own entries use --controller siemens, heidenhain, fanuc, linuxcnc or isg "
                 "instead of table, for a part program give its path before --params")
MEASURE_AGAIN = "then measure the same test again and compare the two files (pige compare, this file first)"


def correct_commands(files: list[str], method: str, program: Any = None) -> list[str]:
    """The fit of ``files`` that compensation uses (``method``: ``diagnosis`` or an identification method) and the
    compensation from it: of ``program`` when the report has one, else the controller-neutral corrected axis lines
    (``--controller table``); every file name the user's, every command runnable as printed."""
    names = " ".join(shlex.quote(str(f)) for f in files)
    if method == "diagnosis":
        fit, params = f"pige diagnose {names} --json > diagnosis.json", "diagnosis.json"
    else:
        fit, params = f"pige identify {names} --method {method} --json > identify.json", "identify.json"
    if program is None:
        return [fit, f"pige compensate --params {params} --controller table"]
    out = program.with_name(f"{program.stem}_comp{program.suffix}")
    return [fit, f"pige compensate {shlex.quote(str(program))} --params {params} --out {shlex.quote(str(out))}"]


def _correct(rep: MeasurementReport, data: ReportData) -> list[str]:
    """Commands that correct the machine with the estimate the report used."""
    return correct_commands([str(rep.path)], rep.primary_method, data.program)


def _correct_words(data: ReportData) -> str:
    return CORRECT_WORDS if data.program is None else ""


def measurement_next(rep: MeasurementReport, data: ReportData) -> NextStep:
    """The next step of one R-test or probe file (module docstring); in a report that fits the files' error maps
    together, the maps' answer is the next step of every file."""
    if data.maps is not None:
        return NextStep("these files are fitted together with their error maps: the maps' answer at the top of the "
                        "page says what to do next", list(data.maps.next_commands))
    q = shlex.quote(str(rep.path))
    if rep.diagnosis is None:
        return NextStep("The diagnosis failed on these data: look at the file (its Measured deviations) before "
                        "using the PIGE-only fit; a file the PIGE model explains gives a diagnosis.",
                        [f"pige identify {q}"])
    chk = rep.check
    if chk is None:
        return NextStep("Judge the estimate against your tolerances (pige check this file with --tolerances and your "
                        "tolerance file; its format: pige check --help), then correct the machine if it is out"
                        f"{_correct_words(data)}:", _correct(rep, data))
    if chk.verdict == "pass":
        return NextStep("In tolerance: nothing to correct. Keep the run in the machine's history (pige history add "
                        "this file with --machine-id, the name you give the machine, and --tolerances "
                        f"{chk.tolerances}), to see a change in the next one.")
    poses = rep.measurement.n_rows - 1
    decided = [_decide(i, chk.k, poses, str(rep.measurement.metadata.get("instrument", "rtest")))
               for i in chk.items if i.status == "undecided"]
    reasons = [r for r, _ in decided]
    if chk.verdict == "fail":
        bad = ", ".join(i.name for i in chk.items if i.status == "fail")
        program = (f" (the test program corrected with it is already written: {rep.compensated_program})"
                   if rep.compensated_program is not None else "")
        also = f" Undecided as well: {', '.join(r.split(' ')[0] for r in reasons)} (why below)." if reasons else ""
        return NextStep(f"Out of tolerance ({bad}): correct the machine with the estimate this report used"
                        f"{program}{_correct_words(data)}; {MEASURE_AGAIN}.{also}", _correct(rep, data), reasons)
    counts = [n for _, n in decided if n is not None]
    plan = _plan_command(rep, max(counts)) if counts else _plan_command(rep, poses)
    names = [i.name for i in chk.items if i.status == "undecided"]
    them = "it" if len(names) == 1 else "them"
    if plan is None:
        return NextStep(f"Undecided: {', '.join(names)} cannot be called in or out of tolerance with this uncertainty. "
                        f"pige plan --instrument sphere-probe names a test that decides {them}, given the sphere's "
                        "and the stylus' radii (this file does not state them).", [], reasons)
    return NextStep(f"Undecided: {', '.join(names)} cannot be called in or out of tolerance with this uncertainty. "
                    f"A test that decides {them}:", [plan], reasons)


def checkup_next(run: Any, database: str | None = None, run_number: int = 0, full: Any = None) -> NextStep:
    """The next step of a machine whose last run is a check-up: the one ``pige checkup`` printed
    (:func:`pige_sym.verdict.checkup.routine.next_step`, stored with the run).  For a check-up stored before it was,
    or stored with the placeholder command pige printed then (``pige checkup NEXT.csv …``, ``pige history add
    FULL.csv …``: files that do not exist), the same function on what was stored, with this history's
    ``database`` and the controller options its program differs from the ``full`` calibration's run by (the stored
    record is left as it is)."""
    from pige_sym.verdict.checkup.routine import NextRun, controller_options, next_step

    info = run.checkup or {}
    stored = info.get("next_step")
    if not (isinstance(stored, list) and len(stored) == 2 and all(isinstance(x, str) for x in stored)) or any(
            old in stored[1] for old in ("NEXT.csv", "FULL.csv")):
        setup = getattr(run, "setup", None)
        probe = setup.get("probe") if isinstance(setup, dict) else None
        dialect = ((probe or {}).get("program") or {}).get("dialect") if isinstance(probe, dict) else None
        full_setup = getattr(full, "setup", None)
        options = controller_options(probe, full_setup.get("probe") if isinstance(full_setup, dict) else None)
        stored = next_step(str(run.verdict), [str(x) for x in info.get("notes", [])], info.get("to_enter"),
                           run.machine_id, NextRun(database, dialect, run_number, options))
    return NextStep(f"{stored[0][:1].upper()}{stored[0][1:]}.", [stored[1]] if stored[1] else [])


def history_next(data: ReportData) -> NextStep:
    """The next step of a machine's history: the last check-up's (as ``pige checkup`` printed it); else act on a
    change or on the last verdict, else measure as planned.  A run yet to be measured is named in words: a command
    printed runs as printed."""
    h = data.history
    assert h is not None
    if h.runs[-1].kind == "checkup" and h.check is None:
        full = next((r for r in reversed(h.runs) if r.kind == "full"), None)
        return checkup_next(h.runs[-1], h.database, len(h.runs), full)
    changed = [c.parameter for comp in h.comparisons[-1:] for c in comp.changes if c.significant]
    verdict = h.check.verdict if h.check is not None else (h.runs[-1].verdict or "none")
    add = f"add it to this history (pige history add, --machine-id {shlex.quote(h.machine_id)})"
    if verdict == "fail":
        files = h.runs[-1].file_name.split("; ")
        if not all(Path(f).is_file() for f in files):
            return NextStep(f"The last run is out of tolerance: correct the machine from it (its file, added as "
                            f"{'; '.join(files)}, is not there any more: pige diagnose it where it is now --json, then "
                            f"pige compensate --params with that output); then measure again and {add}.")
        return NextStep(f"The last run is out of tolerance: correct the machine from it{CORRECT_WORDS}; then measure "
                        f"again and {add}.", correct_commands(files, "diagnosis"))
    if changed:
        return NextStep(f"{', '.join(changed)} changed in the last run: measure again to confirm before acting (a "
                        f"real change repeats), and {add}.")
    if verdict == "none":
        return NextStep("Nothing changed significantly; judge the last run against your tolerances (pige report "
                        f"--history {shlex.quote(h.machine_id)} with --tolerances and your tolerance file).")
    state = " and the last run is in tolerance" if verdict == "pass" else f"; the last run is {verdict}"
    return NextStep(f"Nothing changed significantly{state}: measure again as planned, and {add}.")


def compare_next(data: ReportData) -> NextStep:
    """The next step of a measured before/after."""
    c = data.comparison
    assert c is not None
    after = shlex.quote(c.after)
    if c.improvement > 0:
        return NextStep(f"The correction removed {c.improvement:.0%} of the RMS deviation: judge what is left "
                        "against your tolerances (pige check the after file with --tolerances and your tolerance "
                        "file), or see what is left, by cause:", [f"pige diagnose {after}"])
    return NextStep("The deviation did not shrink: find out why before correcting again (what is left, by cause).",
                    [f"pige diagnose {after}"])
