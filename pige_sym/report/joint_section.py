"""The report's joint section: several files of one machine identified and diagnosed together.

``pige report`` gives every R-test run and probe import its own section (it can be identified,
diagnosed and compensated alone).  A ballbar setup cannot: one projection per pose determines only some
combinations of the PIGEs.  So, for each machine of the report with a ballbar file (with ``--joint``: also
with two R-test/probe files or more), the report adds a joint section (computed by
:func:`pige_sym.report.gather.gather_joints`, rendered here):

- the agreement test of :func:`pige_sym.diagnosis.joint.diagnose_joint` (one set of PIGEs for all files,
  and which file disagrees), in plain words first;
- each file's part: instrument, rows, its own σ, the RMS of its joint residual, its free constant
  (``zero: relative`` ballbar files), its own diagnosis (ballbar: agreement only) and its test against the
  others;
- the effects a set of ballbar setups shows jointly (:mod:`pige_sym.diagnosis.joint_effects`);
- the joint PIGE estimate with standard errors, what the set cannot determine named and given no value;
  with ``--tolerances`` the verdict of the joint estimate (``pige check F1 F2 …``); with truth sidecars
  that agree on the PIGEs (``pige simulate``), the true values and the errors in standard errors.

The section leads the page when the report has no single file that stands alone (ballbar files only).
"""

from __future__ import annotations

import math

import numpy as np

from pige_sym.diagnosis.joint import JointDiagnosis
from pige_sym.report.data import JointReport
from pige_sym.report.html_blocks import esc, kvs, num, path_html, table, units
from pige_sym.report.html_verdict import check_table_html
from pige_sym.report.next_step import CORRECT_WORDS, NextStep, commands_html, correct_commands, shell_word
from pige_sym.report.words import count, value_std


def _agreement_sentence(d: JointDiagnosis) -> tuple[str, str]:
    """(agree, disagree or none; plain sentence) of the agreement test.  Shown as a plain line, never as a
    badge: it says whether the files are consistent, not whether the machine is in tolerance (the verdict)."""
    status, a = d.agreement_status, d.agreement
    if a is None:
        if len(d.files) == 1:
            return "none", "one file: nothing to compare it with"
        return "none", ("the files see different combinations of the PIGEs, so their agreement cannot be tested; "
                        "a setup that repeats one would check it")
    if status == "disagree":
        bad = [f.label for f in d.files if f.disagrees]
        who = f" — the file that disagrees: {', '.join(bad)}" if bad else " — no single file stands out"
        return "disagree", (f"the files do not agree on one set of PIGEs (F test p = {a.p_value:.2g}){who}; the "
                            "machine changed between the setups or an effect the model misses shows differently in "
                            "each: do not use the joint estimate")
    return "agree", (f"the files agree on one set of PIGEs (F test p = {a.p_value:.2g}): they can be identified "
                     "together")


def _agreement_line(d: JointDiagnosis) -> str:
    """The agreement as a plain line (no badge: the verdict is the only badge)."""
    kind, sentence = _agreement_sentence(d)
    text = esc(sentence[0].upper() + sentence[1:]) + "."
    return f'<span data-agreement="{esc(kind)}"' + (' class="bad">' if kind == "disagree" else ">") + text + "</span>"


def _seen_jointly(d: JointDiagnosis) -> str:
    """The effects the setups show together, or what was searched and not found."""
    if d.effects:
        return "; ".join(f.title() + ": " + ", ".join(f"{p} = {value_std(v, f.std[p])} {units(f.units[p])}"
                                                      for p, v in f.params.items()) for f in d.effects)
    if d.searched:
        return (f"nothing beyond the PIGEs: none of the {len(d.searched)} catalogue effects searched on the joint "
                "rows of the setups is accepted")
    return "nothing searched jointly (the joint search is for sets of ballbar setups)"


def answer_joint_html(i: int, jr: JointReport) -> str:
    """The first-screen answer of a joint section: machine, files, agreement, verdict, largest PIGE."""
    d = jr.diagnosis
    if jr.check is None:
        verdict = ('<span data-verdict="none" class="badge none">not judged</span> <small>no tolerances given '
                   "(give pige report your tolerance file with --tolerances)</small>")
    else:
        odd = [f"{it.name} {it.status}" for it in jr.check.items if it.status != "pass"]
        verdict = (f'<span data-verdict="{esc(jr.check.verdict)}" class="badge {esc(jr.check.verdict)}">'
                   f"{esc(jr.check.verdict.upper())}</span> <small>"
                   + esc(", ".join(odd) if odd else f"all {len(jr.check.items)} items pass") + "</small>")
    res = d.final
    piges = [n for n in res.parameters if "." not in n]  # effect parameters are named <effect>.<parameter>
    known = [n for n, v in zip(res.parameters, res.values, strict=True) if n in piges and math.isfinite(float(v))]
    facts = [("machine", f"<code>{esc(jr.machine)}</code>"),
             ("files", esc(f"{count(len(jr.paths), 'file')} identified jointly: ")
              + ", ".join(f'<span class="file">{path_html(p.name)}</span>' for p in jr.paths)),
             ("verdict (joint estimate)", verdict),
             ("do the files agree?", _agreement_line(d) + " <small>(a consistency check of the setups, not the "
                                     "verdict)</small>"),
             ("seen jointly", esc(_seen_jointly(d))),
             ("determined", esc(f"{len(known)} of {len(piges)} PIGEs"
                                + (f"; not determined by these setups: {', '.join(res.unidentifiable)}"
                                   if res.unidentifiable else ""))),
             ("next step", _step_html(_next_step(jr)))]
    return (f'<div class="answer" id="answer-j{i + 1}"><div class="facts">{kvs(facts)}</div>'
            f'<div class="used"><p class="cap">PIGEs of the joint estimate</p>{_pige_table(jr, compact=True)}'
            "</div></div>")


def _next_step(jr: JointReport) -> NextStep:
    """What to do with this result: one sentence and the commands, each runnable as printed."""
    d, res = jr.diagnosis, jr.diagnosis.final
    undetermined = [n for n, v in zip(res.parameters, res.values, strict=True) if not math.isfinite(float(v))]
    if d.agreement_status == "disagree":
        return NextStep("measure the disagreeing setup again (after the machine has settled), or find what changed "
                        "between the setups; do not compensate with this estimate")
    if undetermined:
        return NextStep("add setups: this names the smallest set that determines every PIGE:",
                        [f"pige plan --instrument ballbar --machine {shell_word(jr.machine)}"])
    if jr.check is not None and jr.check.verdict == "pass":
        return NextStep("in tolerance: nothing to correct; keep the run (pige history add) to see drift later")
    if jr.check is not None and jr.check.verdict == "undecided":
        return _undecided_step(jr)
    return NextStep(f"correct the machine with the joint estimate{CORRECT_WORDS}; then measure again:",
                    correct_commands([str(p) for p in jr.paths], "diagnosis"))


def _step_html(step: NextStep) -> str:
    """The sentence, then each command on its own line (as the files' next step shows them)."""
    return esc(step.what) + commands_html(step.commands)


def _undecided_step(jr: JointReport) -> NextStep:
    """An undecided joint verdict: per item the standard uncertainty that decides it, how many times the points
    per setup reach it (u falls as 1/√points), and the ballbar plan whose worst std is that target."""
    assert jr.check is not None
    und = [i for i in jr.check.items if i.status == "undecided"]
    parts, needs = [], []
    for i in und:
        if i.value is None or i.std is None:
            parts.append(f"{i.name} has no value (no setup here determines it)")
            continue
        need = abs(i.limit - abs(i.value)) / jr.check.k
        needs.append(need)
        parts.append(f"{i.name} needs u ≤ {need:.2g} {i.unit} (now {i.std:.2g}): "
                     + (f"{(i.std / need) ** 2:.2g}× the points per setup" if need > 0 else "it lies on its limit"))
    sigma = float(np.median([f.sigma_um for f in jr.diagnosis.files]))
    target = f" --target {min(needs):.2g}" if needs and min(needs) > 0 else ""
    return NextStep(f"undecided: {'; '.join(parts)} (u falls as 1/√points), or setups that see it better:",
                    [f"pige plan --instrument ballbar --machine {shell_word(jr.machine)} --noise {sigma:.2g}{target} "
                     "--out setups.json"])


def _files_table(jr: JointReport) -> str:
    """Each file's part of the final joint fit: with effects seen jointly, σ, residual and constant are those
    of the fit with the effects (σ re-estimated with them), the fit whose estimate the section shows."""
    d = jr.diagnosis
    final = d.joint if d.extended is None else d.extended
    head = ["file", "instrument", "rows", "own σ [µm]", "joint residual RMS [µm]", "constant [µm]",
            "own diagnosis", "against the others"]
    rows, classes = [], []
    for fd, fs in zip(d.files, final.files, strict=True):
        const = "—" if fs.constant_um is None else f"{num(fs.constant_um)} ± {num(fs.constant_std_um, '.2g')}"
        found = ", ".join(f.effect for f in fd.findings) or "nothing beyond the PIGEs"
        own = f"{fd.checked}: {found}" if not fd.checked.startswith("agreement only") else "agreement only"
        if fd.agreement is None:
            test = "—"
        else:
            test = f"{'DISAGREES' if fd.disagrees else 'agrees'} (p = {fd.agreement.p_value:.2g})"
        rows.append([f'<code class="path">{path_html(fd.label)}</code>', esc(fd.instrument), esc(fd.rows),
                     num(fs.sigma_um, ".3g"), num(fs.rms_um, ".3g"), const, esc(own), esc(test)])
        classes.append("unid" if fd.disagrees else "")
    return table(head, rows, row_classes=classes, num_cols=[2, 3, 4, 5])


def _pige_table(jr: JointReport, *, compact: bool = False) -> str:
    """The joint estimate (PIGEs, then the effects' parameters); ``compact``: value ± std, unit and verdict
    (the first screen), else value, std, unit and, with truth sidecars, the true value and the error in σ."""
    res = jr.diagnosis.final
    items = {it.name: it for it in jr.check.items} if jr.check is not None else {}
    if compact:
        head = ["parameter", "value ± std", "unit"] + (["status"] if items else [])
    else:
        head = ["parameter", "value", "std", "unit"] + (["true", "error / std"] if jr.truth is not None else [])
    rows, classes = [], []
    for name, v, s in zip(res.parameters, res.values, res.std, strict=True):
        bad = not math.isfinite(float(v))
        unit = esc(units(res.units.get(name, "")))
        if compact:
            shown = esc(name).replace(".", ".<wbr>")  # angular_error_C.<wbr>cos_urad wraps at its dot
            row = [f"<b>{shown}</b>", "not determined" if bad else esc(value_std(float(v), float(s))), unit]
            if items:
                st = items[name].status if name in items else "—"
                row.append(f'<span class="st {esc(st)}">{esc(st)}</span>')
        else:
            row = [f"<b>{esc(name)}</b>", "not determined" if bad else num(float(v)), "—" if bad else num(float(s)),
                   unit]
            if jr.truth is not None:
                t = jr.truth.get(name)
                z = None if bad or t is None or not float(s) > 0 else (float(v) - t) / float(s)
                row += [num(t), num(z, "+.2f")]
        rows.append(row)
        classes.append("unid" if bad else "")
    nums = [1] if compact else [1, 2] + ([4, 5] if jr.truth is not None else [])
    return table(head, rows, row_classes=classes, num_cols=nums)


def joint_html(i: int, jr: JointReport, figures: str = "") -> str:
    """The joint section (module docstring); ``figures`` is its figures' HTML."""
    d = jr.diagnosis
    parts = [f'<section data-section="joint" id="joint-{i + 1}">',
             f"<h2>Joint identification — {count(len(jr.paths), 'file')} of <code>{esc(jr.machine)}</code></h2>",
             f"<p>Agreement of the files (a consistency check, not the verdict): {_agreement_line(d)}</p>",
             "<p>Every file's rows are divided by its own noise σ and fitted with one set of PIGEs (a free "
             "constant per relative ballbar file, whose zero is unknown). A ballbar file is one projection per "
             "pose, along the bar: it is checked for agreement only; R-test and probe files also get their own "
             "catalogue diagnosis."
             + (" With effects seen jointly, each file's σ, residual and constant below are those of the fit with "
                "the effects (σ estimated again with them)." if d.extended is not None else "") + "</p>",
             "<h3>The files</h3>", _files_table(jr), figures]
    if jr.check is not None:
        parts += ["<h3>Conformance of the joint estimate</h3>", check_table_html(jr.check)]
    if d.effects:
        parts += ["<h3>Effects seen jointly in the ballbar setups</h3>",
                  "<p>The catalogue searched on the joint rows of the setups (docs/ballbar.md); the PIGEs below are "
                  "estimated with these effects.</p><ul>"
                  + "".join(f"<li>{esc(f.sentence())}" + "".join(f"<br><small>{esc(a)}</small>" for a in f.alternatives)
                            + "</li>" for f in d.effects) + "</ul>"]
    parts += ["<h3>Joint estimate</h3>", _pige_table(jr)]
    res = d.final
    parts.append(f"<p><small>Rank {res.rank}/{len(res.parameters)}, joint residual RMS {num(res.rms_um, '.3g')} "
                 "µm. A combination no file measures gets no value.</small></p>")
    parts += [f'<p class="note">{esc(n)}</p>' for n in d.notes]
    parts.append("</section>")
    return "\n".join(parts)

