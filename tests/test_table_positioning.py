"""The positioning tables of SINUMERIK (``$AA_ENC_COMP``) and ISG (``kw.ssfk``): each controller's interpolation,
rebuilt here from its manual, applied to the printed table, puts a true axis on its commanded angle.

- **SINUMERIK** (K3 Compensations 6FC5397-1BP40-3BA1, pp. 237–242; 808D Function Manual 01/2017, p. 109): the
  value at a position is interpolated linearly between the points ``MIN + N·STEP``; below ``MIN`` the first value,
  above ``MAX`` the last; with the modulo function the table repeats with period ``MAX − MIN``.  "A positive
  compensation value causes the machine axis to move in the negative direction": the axis is driven to
  ``commanded − value``.
- **ISG** (Beckhoff TF5200 kw.ssfk pages): the values are position errors ``actual − programmed`` on the points
  ``kw_startpos + i·interval`` in the list's unit, linearly interpolated, the end values outside, ``pos`` while
  moving in the positive direction and ``neg`` in the negative one; the CNC changes the setpoint to cancel the
  error: the axis is driven to ``commanded − value``.

The true axis is written from CONVENTIONS §9–§10 as in tests/test_table_linuxcnc_comp.py: commanded (its drive at)
m, it stands at σ·m + E + φ^d(σ·m).  FANUC's and HEIDENHAIN's tables and ISG's volumetric tables are refused with
the reason (their pages do not settle the sign, the unit or the model): no value in their output.
"""

from __future__ import annotations

import math
import re

import numpy as np
import pytest
from test_table_linuxcnc_comp import RAD, params_with, random_axis, true_angle

from pige_sym.compensation.controllers import ControllerOptions, get_controller
from pige_sym.compensation.controllers.tables.isg_ssfk import render_lines as ssfk_lines
from pige_sym.compensation.controllers.tables.siemens_lec import render_lines as lec_lines
from pige_sym.errors import InputError


def siemens_tables(text: str) -> dict[str, dict]:
    """The ``$AA_ENC_COMP`` program, read back: per machine axis its values and table parameters."""
    out: dict[str, dict] = {}
    for name, n, v in re.findall(r"^\$AA_ENC_COMP\[0,(\d+),(\w+)\]=(\S+)$", text, flags=re.M):
        out.setdefault(n, {"values": {}})["values"][int(name)] = float(v)
    for key, axis, v in re.findall(r"^\$AA_ENC_COMP_(STEP|MIN|MAX|IS_MODULO)\[0,(\w+)\]=(\S+)$", text, flags=re.M):
        out[axis][key] = float(v)
    assert "%_N_AX_EEC_INI\nCHANDATA(1)\n" in text and text.rstrip().endswith("M17")
    return out


def siemens_value(t: dict, pos: float) -> float:
    """K3 pp. 237, 240 and the modulo function (808D p. 109), written here."""
    vals = np.array([t["values"][k] for k in sorted(t["values"])])
    lo, hi, step = t["MIN"], t["MAX"], t["STEP"]
    assert np.isclose(lo + step * (vals.size - 1), hi)
    if t["IS_MODULO"]:
        pos = lo + (pos - lo) % (hi - lo)
    elif pos <= lo:
        return float(vals[0])
    elif pos >= hi:
        return float(vals[-1])
    k = min(int((pos - lo) // step), vals.size - 2)
    f = (pos - lo - k * step) / step
    return float((1 - f) * vals[k] + f * vals[k + 1])


@pytest.mark.parametrize("sigma", [1, -1])
def test_the_siemens_lec_table_puts_the_axis_where_it_was_commanded(sigma: int) -> None:
    rng = np.random.default_rng(20 + sigma)
    built = {ax: random_axis(rng, ax, per_direction=False) for ax in ("A", "C")}
    params = params_with({ax: b[0] for ax, b in built.items()}, {"A": sigma, "C": sigma}, {"EA0A": -12.0})
    text = "\n".join(lec_lines(params, {"A": "A1", "C": "C1"}))
    tables = siemens_tables(text)
    assert tables["C1"]["IS_MODULO"] == 1 and tables["C1"]["MIN"] == 0 and tables["C1"]["MAX"] == 360
    assert tables["A1"]["IS_MODULO"] == 0
    for ax, name in (("A", "A1"), ("C", "C1")):
        maps, plus, _ = built[ax]
        grid, full = maps.grid.angles_deg, maps.grid.full_turn
        zero = -12.0 if ax == "A" else 0.0
        commands = np.concatenate([rng.uniform(-800, 800, 200) if full else rng.uniform(-80, 80, 200),
                                   sigma * (grid + 15.0)])
        # the table holds the map alone: E is the swivel data record's offset angle (tests/test_map_advice.py)
        worst = max(abs(true_angle(cmd - siemens_value(tables[name], cmd), sigma, grid, plus, plus, full, 1, zero)
                        - sigma * cmd - zero * 1e-6 / RAD) for cmd in commands)
        before = max(abs(true_angle(cmd, sigma, grid, plus, plus, full, 1, zero) - sigma * cmd) for cmd in commands)
        assert worst * RAD * 1e6 < 0.1 < 20 < before * RAD * 1e6


def test_siemens_enters_the_mean_of_a_map_per_direction_and_needs_the_machine_axis_name() -> None:
    rng = np.random.default_rng(3)
    params = params_with({"C": random_axis(rng, "C", per_direction=True)[0]}, {"C": -1})
    assert any("--machine-axis C=<name>" in ln for ln in lec_lines(params, None))
    assert not any(ln.startswith("$AA_ENC_COMP") for ln in lec_lines(params, None))
    text = "\n".join(lec_lines(params, {"C": "C1"}))
    assert "the reversal is NOT" in text
    opts = ControllerOptions(machine_axes={"C": "C1"})
    with pytest.raises(InputError, match="not equidistant"):
        from pige_sym.model.error_motions import AxisMaps, MapGrid

        odd = params_with({"C": AxisMaps(MapGrid("C", np.array([0.0, 30.0, 90.0]), True), {"ECC": np.ones(3)})}, {})
        lec_lines(odd, opts.machine_axes)


def isg_tables(lines: list[str]) -> dict[str, dict]:
    """The kw.ssfk list bodies, read back per axis (the notes start with '#')."""
    out: dict[str, dict] = {}
    axis = None
    for ln in lines:
        head = re.match(r"^# (\w+): list body", ln)
        if head:
            axis = head.group(1)
            out[axis] = {"pos": {}, "neg": {}}
            continue
        if ln.startswith("#") or axis is None:
            continue
        key, value = ln.split()
        row = re.match(r"kw\.ssfk\.table\[(\d+)\]\.(pos|neg)$", key)
        if row:
            out[axis][row.group(2)][int(row.group(1))] = int(value)
        else:
            out[axis][key.removeprefix("kw.ssfk.")] = int(value)
    return out


def isg_value(t: dict, pos_units: float, velocity: float) -> float:
    """TF5200 kw.ssfk: linear between kw_startpos + i·interval, the end values outside, pos/neg by direction."""
    table = t["pos" if velocity > 0 else "neg"]
    vals = np.array([table[i] for i in range(t["kw_nr_max"])], dtype=float)
    x = (pos_units - t["kw_startpos"]) / t["interval"]
    if x <= 0:
        return float(vals[0])
    if x >= vals.size - 1:
        return float(vals[-1])
    k = int(math.floor(x))
    return float((1 - (x - k)) * vals[k] + (x - k) * vals[k + 1])


@pytest.mark.parametrize("sigma", [1, -1])
def test_the_isg_kw_ssfk_list_puts_the_axis_where_it_was_commanded(sigma: int) -> None:
    rng = np.random.default_rng(30 + sigma)
    unit = 1e-4  # deg
    built = {ax: random_axis(rng, ax, per_direction=True) for ax in ("A", "C")}
    params = params_with({ax: b[0] for ax, b in built.items()}, {"A": sigma, "C": sigma})
    tables = isg_tables(ssfk_lines(params, unit))
    assert set(tables) == {"A", "C"} and tables["C"]["bilateral"] == 1 and tables["C"]["unit"] == 1
    for ax in ("A", "C"):
        maps, plus, minus = built[ax]
        grid, full = maps.grid.angles_deg, maps.grid.full_turn
        commands = np.concatenate([rng.uniform(-900, 900, 150) if full else rng.uniform(-80, 80, 150),
                                   sigma * (grid + 15.0)])
        worst = before = 0.0
        for cmd in commands:
            for velocity in (1.0, -1.0):
                theta_dir = int(np.sign(sigma * velocity))
                drive = cmd - isg_value(tables[ax], cmd / unit, velocity) * unit
                worst = max(worst, abs(true_angle(drive, sigma, grid, plus, minus, full, theta_dir) - sigma * cmd))
                before = max(before, abs(true_angle(cmd, sigma, grid, plus, minus, full, theta_dir) - sigma * cmd))
        assert worst * RAD * 1e6 < 1.0 < 20 < before * RAD * 1e6  # within the list's rounding (1 unit = 1.75 urad)


def test_isg_refuses_a_rotary_list_without_its_unit() -> None:
    rng = np.random.default_rng(5)
    params = params_with({"C": random_axis(rng, "C", per_direction=True)[0]}, {"C": -1})
    lines = ssfk_lines(params, None)
    assert any("--isg-unit-deg" in ln and "not settled" in ln for ln in lines)
    assert not any(ln.startswith("kw.") for ln in lines)
    with pytest.raises(InputError, match="whole number"):
        ssfk_lines(params, 7e-4)


@pytest.mark.parametrize(("style", "word"), [("fanuc", "NO VALUE"), ("heidenhain", "NO TABLE"), ("isg", "NOT written")])
def test_the_tables_whose_pages_do_not_settle_them_are_refused(style: str, word: str) -> None:
    rng = np.random.default_rng(6)
    params = params_with({ax: random_axis(rng, ax, per_direction=True)[0] for ax in ("A", "C")}, {"A": -1, "C": -1},
                         {n: 1.0 for n in ("EX0C", "EY0C", "EA0C", "EB0C", "EY0A", "EZ0A", "EB0A", "EC0A")})
    if style == "heidenhain":
        params.axis_sense = {}
    module = get_controller(style)
    text = module.render(params, ControllerOptions(heidenhain_trans="position"))
    refused = [ln for ln in text.splitlines() if word in ln]
    assert refused and all("settle" in ln or "define" in ln for ln in refused)
    assert module.map_motions(params) == ([] if style != "isg" else ["A:EAA+", "A:EAA-", "C:ECC+", "C:ECC-"])
