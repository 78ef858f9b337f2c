"""Which ballbar setups? Rank single setups and pick the smallest set that determines every PIGE.

Candidates (:func:`candidate_setups`): radial, tangential and axial setups of the rotary table's axis with
the tilt axis at 0 and at ``tilt_deg``, and of the tilt axis, each a ``zero: relative`` file (one free
constant).  The predicted covariance of a set is ``σ²(Σ_f A_fᵀA_f)⁺`` over the PIGEs and the constants
(:func:`pige_sym.identification.joint.ballbar_block`, the same rows the identification uses), with the
ballbar noise σ; a set *determines* the PIGEs when every one of them has a finite variance inflation (no
weight in a near-null direction).  :func:`plan_setups` searches every set of up to ``max_setups`` setups
and returns the smallest whose worst predicted standard error is within ``target`` (then the best of that
size).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field

import numpy as np

from pige_sym.errors import InputError
from pige_sym.identification.joint import Block, ballbar_block
from pige_sym.identification.spectrum import solve_scaled
from pige_sym.kernels import load_kernels
from pige_sym.measurements.ballbar import SETUPS
from pige_sym.simulation.ballbar import BallbarSetup, ballbar_setup, simulate_ballbar


@dataclass
class SetupSet:
    """A set of setups and what it determines: rank, worst predicted std [µm or µrad], what it cannot see."""

    labels: list[str]
    rank: int
    determined: int
    n_parameters: int
    worst_std: float
    std: dict[str, float]
    undetermined: list[str]
    setups: list[BallbarSetup] = field(default_factory=list)

    def program_commands(self, machine: str) -> list[str]:
        """The ``pige program --instrument ballbar`` command of each setup, in order."""
        out = []
        for s in self.setups:
            held = [f" --tilt {v:g}" for a, v in zip(s.rotary_axes, s.angles_deg[0], strict=True)
                    if a != s.axis and s.axis[0] == "C" and v != 0]
            out.append(f"pige program --instrument ballbar --machine \"{machine}\" --setup {s.kind} --axis {s.axis}"
                       + "".join(held) + f" --dialect siemens --out {s.kind}_{s.axis}"
                       + "".join(h.replace(" --tilt ", "") for h in held) + ".mpf")
        return out


def candidate_setups(machine: str, tilt_deg: float = -45.0) -> list[BallbarSetup]:
    """The candidate setups of a table machine (module docstring)."""
    kern = load_kernels(machine)
    table = next((a for a in kern.ROTARY_AXES if a[0] == "C"), None)
    tilt = next((a for a in kern.ROTARY_AXES if a != table), None)
    if table is None or tilt is None or kern.TOOL_ROTARY:
        raise InputError(f"{kern.MACHINE_CODE}: ballbar setups are planned for a C table on a tilt axis")
    out = []
    for kind in SETUPS:
        out.append(ballbar_setup(machine, kind, table, tilt_deg=0.0))
        out.append(ballbar_setup(machine, kind, table, tilt_deg=tilt_deg))
        out.append(ballbar_setup(machine, kind, tilt))
    return out


def setup_label(s: BallbarSetup) -> str:
    held = [f"{a}={v:g}" for a, v in zip(s.rotary_axes, s.angles_deg[0], strict=True) if a != s.axis]
    return f"{s.kind} {s.axis}" + (f" ({', '.join(held)})" if s.axis[0] == "C" else "")


def _block(machine: str, setup: BallbarSetup) -> Block:
    """The identification's rows of one setup on the nominal machine, without noise (its design matrix)."""
    return ballbar_block(simulate_ballbar(machine, setup, pige={}, noise_um=0.0), setup_label(setup), False)


def evaluate(machine: str, setups: list[BallbarSetup], noise_um: float = 1.0,
             blocks: list[Block] | None = None) -> SetupSet:
    """Rank and predicted standard errors of a set of setups (module docstring); ``blocks``: their rows
    (:func:`_block`, one per setup, in order) when already computed."""
    kern = load_kernels(machine)
    names = list(kern.LOCATION_PARAMETERS)
    if blocks is None:
        blocks = [_block(machine, s) for s in setups]
    q = len(blocks)
    rows = []
    for i, b in enumerate(blocks):
        nuis = np.zeros((b.data.size, q))
        nuis[:, i] = 1.0
        rows.append(np.hstack([b.design, nuis]))
    a = np.vstack(rows)
    sol = solve_scaled(a.T @ a, np.zeros(a.shape[1]), 0.0)
    p = len(names)
    ok = np.isfinite(sol.vif[:p])
    std = {n: float(np.sqrt(sol.cov_unit[j, j]) * noise_um) if ok[j] else float("inf") for j, n in enumerate(names)}
    all_names = names + [f"zero[{b.label}]" for b in blocks]
    units = dict(kern.UNITS) | {n: "um" for n in all_names[p:]}
    combos = [c.text(units) for c in sol.null_space.combinations(all_names)]
    rank = sol.rank - int(np.isfinite(sol.vif[p:]).sum())
    return SetupSet([b.label for b in blocks], rank, int(ok.sum()), p, max(std.values()), std, combos, list(setups))


def plan_setups(machine: str, *, target: float, noise_um: float = 1.0, max_setups: int = 6,
                tilt_deg: float = -45.0) -> tuple[SetupSet | None, list[SetupSet]]:
    """The smallest set of setups whose worst predicted std is within ``target``, and the best of each size."""
    cands = candidate_setups(machine, tilt_deg)
    rows = [_block(machine, s) for s in cands]  # each candidate's rows once, not once per set that holds it
    best_by_size: list[SetupSet] = []
    for size in range(1, max_setups + 1):
        sets = [evaluate(machine, [cands[i] for i in c], noise_um, [rows[i] for i in c])
                for c in itertools.combinations(range(len(cands)), size)]
        best = min(sets, key=lambda s: (-s.determined, -s.rank, s.worst_std))
        best_by_size.append(best)
        if best.determined == best.n_parameters and best.worst_std <= target:
            return best, best_by_size
    return None, best_by_size


def format_setups(machine: str, sets: list[SetupSet], chosen: SetupSet | None, *, target: float | None,
                  noise_um: float) -> str:
    """Text of a ranking (single setups) or a plan (best set per size, the chosen one)."""
    lines = [f"ballbar setups for {machine}, noise {noise_um:g} um per reading (zero: relative, one constant each)",
             "", f"{'rank':>6}{'determined':>12}{'worst std':>11}  setups"]
    for s in sets:
        worst = f"{s.worst_std:.3g}" if np.isfinite(s.worst_std) else "—"
        lines.append(f"{s.rank:>4}/{s.n_parameters}{s.determined:>10}/{s.n_parameters}{worst:>11}  "
                     + " + ".join(s.labels))
    if target is not None:
        lines.append("")
        if chosen is None:
            lines.append(f"no set of up to {len(sets)} setups reaches a worst std of {target:g}: the best is above")
        else:
            lines.append(f"chosen: {' + '.join(chosen.labels)} (worst std {chosen.worst_std:.3g} <= {target:g}; "
                         "fewer setups cannot determine every PIGE within the target)")
    for s in sets[:3] if target is None else []:
        if s.undetermined:
            lines.append(f"{' + '.join(s.labels)} cannot see: " + "; ".join(s.undetermined[:4]))
    return "\n".join(lines)
