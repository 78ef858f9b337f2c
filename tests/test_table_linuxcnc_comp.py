"""LinuxCNC ``[JOINT_n]COMP_FILE``: what LinuxCNC does with the file, rebuilt here from its source, corrects the axis.

LinuxCNC 2.9.0~pre1 (f1270d6ed7), written here without pige's code: ``usrmotLoadComp`` (usrmotintf.cc) reads
``%lf %lf %lf`` per line and stops at the first line that is not three numbers, type 0 turns values into trims
``nominal − value``, type 1 takes them as trims; ``EMCMOT_SET_JOINT_COMP`` (command.c) refuses more than 256 entries
and nominals that do not increase, and takes the slope to the next entry (none after the last, and the first trim
below the first nominal, motion.c); ``compute_screw_comp`` (control.c) interpolates the forward column while the
joint's velocity is positive, the reverse one while it is negative; ``motor_pos_cmd = pos_cmd + trim``.

The true axis is written from CONVENTIONS §9–§10: commanded the motor angle m, it stands at θ = σ·m + E + φ^d(σ·m),
φ^d the map of the direction of approach (linear interpolation between grid angles, wrapping on a full turn).
With the printed file, every commanded angle (between grid angles, many turns away, both senses, both
directions) puts the axis where it was commanded, to second order; without it, the map's error is left.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from pige_sym.cli.main import main
from pige_sym.compensation.controllers.tables.linuxcnc_comp import comp_table, comp_tables
from pige_sym.compensation.controllers.tables.positioning import positioning_maps
from pige_sym.compensation.parameters import CompensationParameters
from pige_sym.errors import InputError
from pige_sym.model.error_motions import AxisMaps, ErrorMaps, MapGrid

AC = "wC'A'bXYZ(C1)t"
RAD = math.pi / 180.0


def params_with(maps: dict[str, AxisMaps], sense: dict[str, int], values: dict[str, float] | None = None
                ) -> CompensationParameters:
    return CompensationParameters(AC, dict(values or {}), {}, None, {}, "test", [], axis_sense=sense,
                                  error_maps=ErrorMaps(maps))


def linuxcnc_load(text: str, comp_type: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """usrmotLoadComp + EMCMOT_SET_JOINT_COMP: (nominal, forward trim, reverse trim)."""
    rows = []
    for line in text.splitlines():
        parts = line.split()
        try:
            nums = [float(x) for x in parts[:3]]
        except ValueError:
            break
        if len(nums) != 3:
            break
        nom, fwd, rev = nums
        rows.append((nom, nom - fwd, nom - rev) if comp_type == 0 else (nom, fwd, rev))
    table = np.array(rows)
    assert len(rows) <= 256, "joint: too many compensation entries"
    assert (np.diff(table[:, 0]) > 0).all(), "joint: compensation values must increase"
    return table[:, 0], table[:, 1], table[:, 2]


def linuxcnc_trim(table: tuple[np.ndarray, np.ndarray, np.ndarray], pos: float, velocity: float) -> float:
    """compute_screw_comp at a commanded joint position moving with ``velocity`` (never 0 here)."""
    nom, fwd, rev = table
    trims = fwd if velocity > 0 else rev
    if pos < nom[0]:
        return float(trims[0])
    k = int(np.searchsorted(nom, pos, side="right")) - 1
    if k >= len(nom) - 1:
        return float(trims[-1])
    slope = (trims[k + 1] - trims[k]) / (nom[k + 1] - nom[k])
    return float(trims[k] + slope * (pos - nom[k]))


def true_hat(grid: np.ndarray, values: np.ndarray, full_turn: bool, theta: float) -> float:
    """CONVENTIONS §10's linear interpolation, written here."""
    if full_turn:
        nodes, vals = np.append(grid, grid[0] + 360.0), np.append(values, values[0])
        t = grid[0] + (theta - grid[0]) % 360.0
    else:
        nodes, vals, t = grid, values, min(max(theta, grid[0]), grid[-1])
    return float(np.interp(t, nodes, vals))


def true_angle(motor_deg: float, sigma: int, grid: np.ndarray, plus: np.ndarray, minus: np.ndarray, full: bool,
               theta_direction: int, zero_urad: float = 0.0) -> float:
    """θ [deg] the true axis stands at when its motor is at ``motor_deg`` (module docstring)."""
    phi = true_hat(grid, plus if theta_direction > 0 else minus, full, sigma * motor_deg)
    return sigma * motor_deg + (zero_urad + phi) * 1e-6 / RAD


def random_axis(rng: np.random.Generator, axis: str, per_direction: bool) -> tuple[AxisMaps, np.ndarray, np.ndarray]:
    full = axis == "C"
    grid = np.arange(12) * 30.0 if full else np.arange(0.0, 61.0, 10.0)
    plus = rng.normal(scale=40.0, size=grid.size)
    minus = plus - 25.0 - rng.normal(scale=5.0, size=grid.size) if per_direction else plus
    phi = "ECC" if axis == "C" else "EAA"
    values = {phi + "+": plus, phi + "-": minus} if per_direction else {phi: plus}
    return AxisMaps(MapGrid(axis, grid, full), values), plus, minus


@pytest.mark.parametrize("sigma", [1, -1])
@pytest.mark.parametrize("per_direction", [True, False])
def test_the_comp_file_puts_the_axis_where_it_was_commanded(sigma: int, per_direction: bool) -> None:
    rng = np.random.default_rng(5 + sigma + 2 * per_direction)
    built = {ax: random_axis(rng, ax, per_direction) for ax in ("A", "C")}
    params = params_with({ax: b[0] for ax, b in built.items()}, {"A": sigma, "C": sigma}, {"EA0A": 17.0})
    tables = {t.axis: t for t in comp_tables(params)}
    assert set(tables) == {"A", "C"} and tables["A"].joint == 3 and tables["C"].joint == 4
    for ax, (maps, plus, minus) in built.items():
        text = tables[ax].text()
        assert all(len(line.split()) == 3 for line in text.splitlines())  # no header, no comment
        table = linuxcnc_load(text, comp_type=1)
        grid, full = maps.grid.angles_deg, maps.grid.full_turn
        zero = 17.0 if ax == "A" else 0.0
        lo, hi = (table[0][0], table[0][-1]) if full else (-80.0, 80.0)
        commands = np.concatenate([rng.uniform(lo, hi, 150), sigma * (grid + 15.0), [lo, hi]])
        worst_after = worst_before = 0.0
        for cmd in commands:
            for velocity in (1.0, -1.0):
                theta_dir = int(np.sign(sigma * velocity))
                motor = cmd + linuxcnc_trim(table, cmd, velocity)
                after = true_angle(motor, sigma, grid, plus, minus, full, theta_dir, zero) - sigma * cmd
                before = true_angle(cmd, sigma, grid, plus, minus, full, theta_dir, zero) - sigma * cmd
                worst_after, worst_before = max(worst_after, abs(after)), max(worst_before, abs(before))
        # second order: the map is evaluated at the motor angle, |trim| away: |trim| · max slope of the map
        largest = (np.abs(np.concatenate([plus, minus])).max() + zero) * 1e-6
        slope = np.abs(np.diff(np.stack([plus, minus]), axis=1)).max() * 1e-6 / (np.diff(grid).min() * RAD)
        assert worst_after * RAD < 1.01 * largest * slope
        assert worst_after * RAD * 1e6 < 0.1 < 20.0 < worst_before * RAD * 1e6  # the map's error without the file


def test_a_full_turn_covers_whole_turns_in_256_entries_and_a_tilt_its_grid() -> None:
    rng = np.random.default_rng(1)
    params = params_with({ax: random_axis(rng, ax, True)[0] for ax in ("A", "C")}, {"A": -1, "C": -1})
    tables = {t.axis: t for t in comp_tables(params)}
    c, a = tables["C"], tables["A"]
    assert c.nominal_deg[0] == -3600.0 and c.nominal_deg[-1] == 3600.0 and c.nominal_deg.size == 241
    assert np.allclose(a.nominal_deg, -np.arange(60.0, -1.0, -10.0))  # sigma -1: commanded -60..0
    assert "keep [JOINT_4]MIN_LIMIT/MAX_LIMIT inside" in " ".join(c.notes)
    fine = params_with({"C": AxisMaps(MapGrid("C", np.arange(360) * 1.0, True), {"ECC": np.zeros(360)})}, {})
    with pytest.raises(InputError, match="at most 256 per joint"):
        comp_table(AC, positioning_maps(fine)["C"])
    with pytest.raises(InputError, match="at most 256"):
        comp_table(AC, positioning_maps(params)["C"], (-4000.0, 4000.0))


def test_a_grid_angle_without_value_enters_zero_and_says_so() -> None:
    grid = np.arange(12) * 30.0
    values = np.linspace(-20, 20, 12)
    values[3] = np.nan
    params = params_with({"C": AxisMaps(MapGrid("C", grid, True), {"ECC": values})}, {})
    (table,) = comp_tables(params)
    assert any("no value at theta = 90 deg: entered as 0" in n for n in table.notes)
    assert table.forward_deg[np.isclose(table.nominal_deg, 90.0)][0] == 0.0


@pytest.fixture
def maps_file(tmp_path):
    """A parameter file with per-direction positioning maps, as pige identify --map --json writes it."""
    import json

    grid = list(np.arange(12) * 30.0)
    rng = np.random.default_rng(4)
    doc = {"machine": AC, "pige": {"EX0C": 1.0, "EY0C": -2.0, "EA0C": 3.0, "EB0C": 0.0, "EY0A": 1.0,
                                          "EZ0A": 0.5, "EB0A": 4.0, "EC0A": -1.0},
           "units": {}, "ball_mm": [20.0, 10.0, 15.0], "axis_sense": {"A": -1, "C": -1},
           "error_motions": {"C": {"angle_deg": grid, "full_turn": True,
                                   "ECC+": {"value": list(rng.normal(size=12) * 30), "std": [1.0] * 12,
                                            "unit": "urad", "kind": "positioning"},
                                   "ECC-": {"value": list(rng.normal(size=12) * 30), "std": [1.0] * 12,
                                            "unit": "urad", "kind": "positioning"}}}}
    path = tmp_path / "maps.json"
    path.write_text(json.dumps(doc))
    return path


def test_compensate_writes_the_files_and_prints_the_ini_lines(maps_file, tmp_path, capsys) -> None:
    out = tmp_path / "comp"
    out.mkdir()
    args = ["compensate", "--params", str(maps_file), "--controller", "linuxcnc", "--comp-dir", str(out)]
    assert main(args) == 0, capsys.readouterr().err
    text = capsys.readouterr().out
    assert "[JOINT_4]\nCOMP_FILE = pige_joint4_c.comp\nCOMP_FILE_TYPE = 1" in text
    assert f"wrote {out / 'pige_joint4_c.comp'} (241 lines: compensation file pige_joint4_c.comp)" in text
    table = linuxcnc_load((out / "pige_joint4_c.comp").read_text(), comp_type=1)
    assert table[0].size == 241
    assert main(args) == 2  # never over a file without --force
    assert "--force" in capsys.readouterr().err
    assert main([*args, "--force"]) == 0
    assert main(["compensate", "--params", str(maps_file), "--controller", "siemens", "--comp-dir", str(out)]) == 2
    assert "--controller linuxcnc" in capsys.readouterr().err
