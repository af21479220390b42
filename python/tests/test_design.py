"""iuq.design against `iuq design` (bit for bit) and scipy's plain Sobol' points."""

import numpy as np
import pytest

import iuq
from conftest import read_csv

CASES = [
    ("lhs", dict(n=20, dim=3, seed=7, method="maximin"), ["--method", "maximin"]),
    ("lhs", dict(n=15, dim=2, seed=3, method="optimized"), ["--method", "optimized"]),
    ("lhs", dict(n=9, dim=4, seed=11, method="random"), ["--method", "random"]),
    ("sobol", dict(n=64, dim=5, seed=2), []),
    ("saltelli", dict(n=16, dim=3, seed=5), []),
]


@pytest.mark.parametrize("kind,kwargs,flags", CASES)
def test_designs_equal_the_cli_bit_for_bit(cli, tmp_path, kind, kwargs, flags):
    out = tmp_path / "d.csv"
    cli("design", kind, "--n", kwargs["n"], "--dim", kwargs["dim"], "--seed", kwargs["seed"],
        *flags, "--out", out)
    columns, expected = read_csv(out)
    ours = getattr(iuq.design, kind)(**kwargs)
    assert columns == [f"x{k + 1}" for k in range(kwargs["dim"])]
    assert ours.dtype == np.float64 and ours.shape == expected.shape
    assert np.array_equal(ours, expected)


def test_bounds_scale_as_the_cli(cli, tmp_path):
    out = tmp_path / "d.csv"
    cli("design", "sobol", "--n", 32, "--dim", 2, "--seed", 4, "--bounds", "-3:1,10:300",
        "--out", out)
    _, expected = read_csv(out)
    ours = iuq.design.sobol(32, 2, seed=4, bounds=[(-3, 1), (10, 300)])
    assert np.array_equal(ours, expected)


def test_saltelli_has_n_times_d_plus_2_rows_and_seeds_matter():
    a = iuq.design.saltelli(8, 3, seed=1)
    assert a.shape == (8 * 5, 3)
    assert not np.array_equal(a, iuq.design.saltelli(8, 3, seed=2))
    assert np.array_equal(a, iuq.design.saltelli(8, 3, seed=1))


def test_unscrambled_sobol_equals_scipy():
    qmc = pytest.importorskip("scipy.stats.qmc")
    expected = qmc.Sobol(d=4, scramble=False).random(32)
    assert np.array_equal(iuq.design.sobol(32, 4, scramble=False), expected)


def test_latin_hypercube_has_one_point_per_stratum():
    x = iuq.design.lhs(10, 3, seed=0)
    for k in range(3):
        assert sorted(np.floor(x[:, k] * 10).astype(int)) == list(range(10))


@pytest.mark.parametrize(
    "call,match",
    [
        (lambda: iuq.design.lhs(0, 2), "^n: must be at least 1"),
        (lambda: iuq.design.sobol(4, 0), "^dim: must be at least 1"),
        (lambda: iuq.design.lhs(4, 2, method="best"), "^method: `best` is not one of"),
        (lambda: iuq.design.lhs(4, 2, seed=-1), "^seed: must be at least 0"),
        (lambda: iuq.design.saltelli(4, 2, bounds=[(0, 1)]), "^bounds: 1 ranges given for dim 2"),
        (lambda: iuq.design.sobol(4, 1, bounds=[(1, 0)]), "^bounds: range 0 must have finite lo < hi"),
    ],
)
def test_bad_input_is_a_value_error_naming_the_argument(call, match):
    with pytest.raises(ValueError, match=match):
        call()
