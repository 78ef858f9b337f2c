"""Outputs that do not depend on the processor (issue 46): every combination pige prints is canonical.

Another processor or BLAS returns another basis of the same null space (any rotation within a cluster of equal
eigenvalues, any signs) from a normal matrix that differs in its last bits.  :func:`another_processor.another_processor`
plays that part in-process (its module docstring).  The commands must print the
same lines and write the same JSON: ``identify --projection x`` (the not-identifiable combinations of
docs/guide.md), ``plan --map`` (the motions a grid angle does not see, docs/maps.md) and ``diagnose`` (the
directions a candidate loses to the PIGEs).  On the code before issue 46 all three differ.

The property tests draw subspaces (random ones in mixed units, and small-integer ones with the ties and exact
ratios of a symmetric machine) and check that :func:`~pige_sym.identification.canonical.canonical_basis` gives the
same basis, to the bit, from the subspace computed with the parameters permuted, from a rotated basis and from a
normal matrix with 1e-12 relative noise, and that this basis is the row-echelon form: 1 on its pivots, 0 on the
other pivots, inside the subspace.
"""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from another_processor import another_processor
from pige_sym.cli.main import main

AC = "wC'A'bXYZ(C1)t"


@pytest.fixture(scope="module")
def run_csv(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """docs/guide.md's run.csv: a cone on the AC table with random PIGEs and a C angular error."""
    path = tmp_path_factory.mktemp("canonical") / "run.csv"
    assert main(["simulate", "--machine", AC, "--trajectory", "cone-frustum", "--pige", "random", "--seed", "1",
                 "--effect", "angular_error_C", "--out", str(path)]) == 0
    return path


def _printed(capsys: pytest.CaptureFixture[str], args: list[str], seed: int | None) -> str:
    capsys.readouterr()
    if seed is None:
        assert main(args) in (0, 1)
    else:
        with another_processor(seed):
            assert main(args) in (0, 1)
    return capsys.readouterr().out


@pytest.mark.parametrize("seed", [1, 2])
def test_identify_prints_and_writes_the_same_combinations_on_another_processor(
        run_csv: Path, capsys: pytest.CaptureFixture[str], seed: int) -> None:
    args = ["identify", str(run_csv), "--projection", "x"]
    here, there = _printed(capsys, args, None), _printed(capsys, args, seed)
    assert here == there  # the combinations, and the rank, dof and observability beside them
    assert "EX0C [um] - 12.5·EB0C [urad] is not identifiable" in here  # the ball 80 mm above the table: 1/0.08
    here_json = json.loads(_printed(capsys, [*args, "--json"], None))
    there_json = json.loads(_printed(capsys, [*args, "--json"], seed))
    assert here_json["unidentifiable"] == there_json["unidentifiable"]
    assert here_json.get("null_space") == there_json.get("null_space")
    assert {"EX0C": 1.0, "EB0C": -12.5} in here_json["null_space"]


def test_plan_map_says_the_same_unseen_motions_on_another_processor(capsys: pytest.CaptureFixture[str]) -> None:
    args = ["plan", "--instrument", "sphere-probe", "--machine", AC, "--sphere", "100,20,60", "--sphere-radius",
            "12.7", "--stylus-radius", "1.5", "--map", "C", "--map-step", "90", "--noise", "0.5"]
    here, there = _printed(capsys, args, None), _printed(capsys, args, 3)
    timing = re.compile(r"planned in [0-9.]+ s")
    assert timing.sub("", here) == timing.sub("", there)
    assert "see 3 of its 6 motions; not seen: EXC - 16.7·EBC - 1.67·EZC; " in here, here


def test_diagnose_names_the_same_removed_directions_on_another_processor(
        run_csv: Path, capsys: pytest.CaptureFixture[str]) -> None:
    here = _printed(capsys, ["diagnose", str(run_csv)], None)
    assert here == _printed(capsys, ["diagnose", str(run_csv)], 4)
    setup = [line for line in here.splitlines() if line.strip().startswith("setup_offset")]
    assert "dz_um is indistinguishable from -EZ0A [um]" in setup[0], setup


# --- the canonical basis itself ---------------------------------------------------------------------------------

def _subspace(seed: int, p: int, r: int, integer: bool) -> tuple[np.ndarray, np.ndarray]:
    """A design's normal matrix (P, P) whose null space has dimension r, and a basis of that null space (P, r)."""
    rng = np.random.default_rng(seed)
    null = rng.integers(-2, 3, size=(p, r)).astype(float) if integer else rng.standard_normal((p, r))
    while np.linalg.matrix_rank(null) < r:
        null[rng.integers(p), rng.integers(r)] += 1.0
    if not integer:
        null *= 10.0 ** rng.uniform(-2, 2, size=(p, 1))  # parameters in units far apart (µm, µrad, mm…)
    complement = np.eye(p) - null @ np.linalg.pinv(null)
    design = rng.standard_normal((3 * p, p)) @ complement
    design *= 10.0 ** rng.uniform(-1, 1, size=p) if not integer else 1.0
    return design.T @ design, null


def _texts(basis: Any, names: list[str]) -> list[str]:
    return [c.text() for c in basis.combinations(names)]


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 2**32 - 1), p=st.integers(2, 9), data=st.data(), integer=st.booleans())
def test_the_canonical_basis_is_the_same_from_any_basis_any_order_and_perturbed_sums(
        seed: int, p: int, data: st.DataObject, integer: bool) -> None:
    from pige_sym.identification.canonical import canonical_basis
    from pige_sym.identification.spectrum import scale_columns, solve_scaled

    r = data.draw(st.integers(1, p - 1), label="null dimension")
    normal, null = _subspace(seed, p, r, integer)
    names = [f"P{j}" for j in range(p)]
    sol = solve_scaled(normal, np.zeros(p), 0.0)
    assert sol.null_space.dimension == r
    expected = _texts(sol.null_space, names)
    rng = np.random.default_rng(seed + 1)
    noise = rng.standard_normal((p, p))
    perturbed = solve_scaled(normal * (1 + 1e-12 * (noise + noise.T) / 2), np.zeros(p), 0.0)
    assert _texts(perturbed.null_space, names) == expected
    assert np.array_equal(perturbed.null_space.coefficients, sol.null_space.coefficients)
    with another_processor(seed):  # another basis of it, from the same solve
        assert np.array_equal(solve_scaled(normal, np.zeros(p), 0.0).null_space.coefficients,
                              sol.null_space.coefficients)
    perm = rng.permutation(p)  # the parameters in another order: the same subspace, put back in order
    back = np.empty(p, dtype=int)
    back[perm] = np.arange(p)
    vectors, scale, gap = _raw_null(normal[np.ix_(perm, perm)])
    again = canonical_basis(vectors[back], scale[back], separation=gap)
    assert _texts(again, names) == expected
    assert np.array_equal(again.coefficients, sol.null_space.coefficients)
    # the row-echelon form: 1 on its pivots, 0 on the others, and inside the null space
    b = sol.null_space.coefficients
    assert np.array_equal(b[list(sol.null_space.pivots)], np.eye(r))
    scaled, scale, _ = scale_columns(normal)  # inside it up to the terms dropped (< 1e-3 each) and the rounding
    bs = b / scale[:, None]
    assert (np.linalg.norm(scaled @ bs, axis=0) <= 1e-2 * np.linalg.norm(bs, axis=0) * np.linalg.norm(scaled, 2)).all()


def _raw_null(normal: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """The near-null span of a normal matrix as the solve finds it, before any canonical form: its eigenvectors
    in the scaled coordinates, the scale and the separation of its eigenvalues."""
    from pige_sym.identification.canonical import separation
    from pige_sym.identification.spectrum import scale_columns, scaled_spectrum

    scaled, scale, _ = scale_columns(normal)
    spec = scaled_spectrum(scaled)
    return spec.vectors[:, spec.near_null], scale, separation(spec.svals**2, spec.near_null)


def test_the_basis_is_the_row_echelon_form_in_parameter_units_whatever_the_units() -> None:
    from pige_sym.identification.canonical import canonical_basis

    span = np.array([[1.0, 0.0], [2.0, 1.0], [0.0, 3.0], [-1.0, 1.0]])  # x0 = a, x1 = 2a + b, x2 = 3b, x3 = b - a
    b = canonical_basis(span)
    assert b.pivots == (0, 1)
    assert b.coefficients.tolist() == [[1.0, 0.0], [0.0, 1.0], [-6.0, 3.0], [-3.0, 1.0]]
    # parameter 2 in units 1000 times smaller (µm for mm): its column norm 1000 times smaller, its scale 1000
    # times larger, the scaled problem the same: the same pivots, its coefficients 1000 times larger
    scale = np.array([1.0, 1.0, 1000.0, 1.0])
    micro = canonical_basis(span, scale)
    assert micro.pivots == (0, 1)
    assert micro.coefficients.tolist() == [[1.0, 0.0], [0.0, 1.0], [-6000.0, 3000.0], [-3.0, 1.0]]


def test_a_parameter_the_span_barely_touches_is_not_a_pivot_and_ties_go_in_order() -> None:
    from pige_sym.identification.canonical import canonical_basis

    tiny = canonical_basis(np.array([[0.01], [1.0], [-1.0]]))  # first parameter 1 % of the others: no pivot
    assert tiny.pivots == (1,) and tiny.coefficients[:, 0].tolist() == [0.01, 1.0, -1.0]
    dust = canonical_basis(np.array([[1e-4], [1.0], [-1.0]]))  # below 1e-3 of the largest: dropped
    assert dust.coefficients[:, 0].tolist() == [0.0, 1.0, -1.0]
    tie = canonical_basis(np.array([[1.0, 1.0], [1.0, -1.0], [0.0, 0.0]]))  # e0 and e1 span it: a tie, in order
    assert tie.pivots == (0, 1) and tie.coefficients.tolist() == [[1.0, 0.0], [0.0, 1.0], [0.0, 0.0]]


def test_coefficients_keep_only_the_digits_round_off_cannot_change() -> None:
    from pige_sym.identification.canonical import canonical_basis, rounded

    assert rounded(0.45512345678) == 0.455123 and rounded(-12.5000000001) == -12.5
    assert rounded(0.45512345678, delta=1e-8) == 0.4551  # round-off 1e-8: a digit is kept at 1e-4 of its unit
    assert rounded(1e-9, delta=1e-8) == 0.0
    span = np.array([[1.0], [0.45512345678]])
    assert canonical_basis(span).coefficients[1, 0] == 0.455123
    assert canonical_basis(span, separation=1e-4).coefficients[1, 0] == 0.455  # eigenvalues 1e-4 apart: 1e-8


def test_the_printer_writes_three_digits_without_ones_or_exponents() -> None:
    from pige_sym.identification.canonical import Combination, combination

    c = Combination((("EX0C", 1.0), ("EB0C", -12.5), ("EA0C", 0.000123456), ("EY0C", 12345.6)))
    assert c.text({"EX0C": "um", "EB0C": "urad"}) == \
        "EX0C [um] - 12.5·EB0C [urad] + 0.000123·EA0C + 12300·EY0C"
    assert Combination(()).text() == "0"
    assert combination(np.array([0.0, -1.0, 0.5, 1e-5]), ["a", "b", "c", "d"]).text() == "-b + 0.5·c"
    assert combination(np.array([0.3, -0.3]), ["a", "b"]).text() == "0.3·a - 0.3·b"  # a tie: in order


def test_the_identify_json_carries_the_basis_and_reads_back_as_a_parameter_file(
        run_csv: Path, capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    from pige_sym.identification.result import IdentificationResult
    from pige_sym.measurements.schema import read_params_file

    text = _printed(capsys, ["identify", str(run_csv), "--projection", "x", "--json"], None)
    doc = json.loads(text)
    assert doc["null_space"] == [{"EY0A": 1.0}, {"EZ0A": 1.0}, {"EX0C": 1.0, "EB0C": -12.5},
                                 {"EY0C": 1.0, "EA0C": 12.5}]
    assert [c.as_dict() for c in IdentificationResult.from_dict(doc).null_space] == doc["null_space"]
    full = json.loads(_printed(capsys, ["identify", str(run_csv), "--json"], None))
    assert full["null_space"] == []
    (tmp_path / "p.json").write_text(text)
    params = read_params_file(tmp_path / "p.json", machine=AC, allow_missing=True)
    assert "EY0A" in params.set_to_zero


def test_a_coefficient_at_a_rounding_tie_rounds_the_same_whichever_side_round_off_puts_it() -> None:
    """Exact dyadic data give exact ties (93/128 = 0.7265625 at 6 digits): round-off must not decide them."""
    from pige_sym.identification.canonical import rounded

    for tie, up in ((0.7265625, 0.726563), (-0.7265625, -0.726563), (123456.5, 123457.0), (2.5e-7, 2.5e-7)):
        assert {rounded(tie * (1 + e)) for e in (-1e-14, 0.0, 1e-14)} == {up}
    assert rounded(0.7265624) == 0.726562 and rounded(0.7265626) == 0.726563  # away from a tie: plain rounding
    assert rounded(0.7265625 + 1e-11, 2e-11) == rounded(0.7265625 - 1e-11, 2e-11) == 0.726563  # the given round-off
    assert rounded(0.7265625 - 1e-11) == 0.726562  # beyond the round-off of 0.73 (1e-12 of it): plain rounding
