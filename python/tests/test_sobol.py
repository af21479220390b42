"""iuq.sobol: against `iuq sobol` (bit for bit), SALib on Ishigami, and failing models."""

import numpy as np
import pytest

import iuq

PI = 3.141592653589793
BOUNDS = [(-PI, PI)] * 3


def ishigami(x):
    return np.sin(x[:, 0]) + 7.0 * np.sin(x[:, 1]) ** 2 + 0.1 * x[:, 2] ** 4 * np.sin(x[:, 0])


# Only + and *: numpy and iuq's formula evaluator give the same bits.
FORMULA = "x1 + 2*x2*x3 + x1*x1*x2"


def polynomial(x):
    return x[:, 0] + 2 * x[:, 1] * x[:, 2] + x[:, 0] * x[:, 0] * x[:, 1]


def study(tmp_path, formula=FORMULA):
    path = tmp_path / "poly.toml"
    path.write_text(
        'name = "poly"\n[parameters]\n'
        'x1 = { uniform = [-1, 2] }\nx2 = { uniform = [0, 1] }\nx3 = { uniform = [-2, 3] }\n'
        f'[model]\nkind = "expression"\noutputs = {{ f = "{formula}" }}\n'
    )
    return path


POLY_BOUNDS = {"x1": (-1, 2), "x2": (0, 1), "x3": (-2, 3)}


@pytest.mark.parametrize("replicates", [None, 4])
def test_callable_and_formula_equal_the_cli_bit_for_bit(cli, tmp_path, replicates):
    extra = [] if replicates is None else ["--replicates", replicates]
    expected = cli("sobol", study(tmp_path), "--n", 256, "--seed", 3, *extra)["outputs"]["f"]
    for model in (polynomial, {"f": FORMULA}):
        ours = iuq.sobol(model, POLY_BOUNDS, n=256, seed=3, outputs=["f"], replicates=replicates)
        for key in ("S1", "ST", "S1_conf", "ST_conf"):
            assert list(getattr(ours, key)) == [expected[key][k] for k in ("x1", "x2", "x3")], key
        assert ours.variance[0] == expected["variance"]
        assert ours.evaluations == 256 * 5 * (replicates or 1)


def test_ishigami_agrees_with_salib_within_the_intervals():
    salib_sample = pytest.importorskip("SALib.sample.sobol")
    salib_analyze = pytest.importorskip("SALib.analyze.sobol")
    problem = {"num_vars": 3, "names": ["x1", "x2", "x3"], "bounds": [[-PI, PI]] * 3}
    ours = iuq.sobol(ishigami, problem, n=4096, seed=1)
    assert ours.names == ["x1", "x2", "x3"] and ours.S1.shape == (3,)
    x = salib_sample.sample(problem, 4096, calc_second_order=False, seed=1)
    theirs = salib_analyze.analyze(problem, ishigami(x), calc_second_order=False, seed=1)
    for key in ("S1", "ST"):
        gap = np.abs(getattr(ours, key) - theirs[key])
        assert np.all(gap <= getattr(ours, key + "_conf") + theirs[key + "_conf"]), key
    # and both against the analytic indices (a = 7, b = 0.1)
    exact_s1 = np.array([0.3139, 0.4424, 0.0])
    exact_st = np.array([0.5576, 0.4424, 0.2437])
    assert np.all(np.abs(ours.S1 - exact_s1) <= ours.S1_conf + 5e-4)
    assert np.all(np.abs(ours.ST - exact_st) <= ours.ST_conf + 5e-4)
    lower, upper = ours.S1_interval[..., 0], ours.S1_interval[..., 1]
    assert np.all(lower < ours.S1) and np.all(ours.S1 < upper)


def test_several_outputs_give_one_row_each():
    result = iuq.sobol(lambda x: np.column_stack([x[:, 0], x[:, 1] + 0.01 * x[:, 0]]),
                       [(0, 1), (0, 1)], n=512, seed=0)
    assert result.outputs == ["y1", "y2"]
    assert result.S1.shape == (2, 2) and result.ST_interval.shape == (2, 2, 2)
    assert result.S1[0, 0] == pytest.approx(1.0, abs=0.02)
    assert result.S1[1, 1] == pytest.approx(1.0, abs=0.02)


def test_the_model_is_called_once_per_design_with_the_whole_batch():
    shapes = []

    def model(x):
        shapes.append(x.shape)
        return x.sum(axis=1)

    iuq.sobol(model, [(0, 1)] * 4, n=64, seed=0, outputs=1)
    assert shapes == [(64 * 6, 4)]


def raises_beyond_2(x):
    if np.any(x[:, 0] > 2.0):
        raise ArithmeticError("x1 beyond 2: the solver diverges")
    return ishigami(x)


def test_an_exception_of_the_model_is_raised_as_itself():
    with pytest.raises(ArithmeticError, match="x1 beyond 2: the solver diverges"):
        iuq.sobol(raises_beyond_2, BOUNDS, n=128, seed=0, outputs=1)


def test_with_on_error_fail_the_points_that_raise_are_failed_points():
    result = iuq.sobol(raises_beyond_2, BOUNDS, n=256, seed=0, outputs=1, on_error="fail")
    assert result.failed_evaluations > 0
    assert result.dropped_groups > 0
    (reason, count), = result.failure_reasons.items()
    assert "ArithmeticError: x1 beyond 2: the solver diverges" in reason
    assert count == result.failed_evaluations
    assert np.all(np.isfinite(result.S1))


def test_non_finite_outputs_are_failed_points():
    def model(x):
        y = x[:, 0] + x[:, 1]
        y[x[:, 0] > 0.9] = np.nan
        return y

    result = iuq.sobol(model, [(0, 1), (0, 1)], n=256, seed=0, outputs=1)
    assert result.failed_evaluations > 0


def test_a_result_of_the_wrong_shape_is_a_value_error():
    with pytest.raises(ValueError, match=r"model: returned an array of shape \[3\]"):
        iuq.sobol(lambda x: np.zeros(3), [(0, 1), (0, 1)], n=8, seed=0, outputs=1)


@pytest.mark.parametrize(
    "kwargs,match",
    [
        (dict(bounds=[(0, 1), (2, 1)]), r"^bounds: range 1 must have finite lo < hi"),
        (dict(n=1), "^n: must be at least 2"),
        (dict(confidence=1.5), "^confidence: 1.5 must lie strictly between 0 and 1"),
        (dict(on_error="ignore"), "^on_error: `ignore` is not one of"),
        (dict(model="x1 +"), "^model: output `y`"),
        (dict(bounds={"num_vars": 2, "names": ["a", "b"], "bounds": [[0, 1], [0, 1]],
                      "dists": ["triang", "unif"]}), r"^bounds: dists\[0\] = 'triang' is not supported"),
        (dict(bounds=[{"normal": [0, -1]}, (0, 1)]), "^bounds: .*x1.*scale -1 must be positive"),
        (dict(bounds=[{"gamma": [1, 1]}, (0, 1)]), "^bounds: prior 0: `gamma` is not one of"),
        # Counts that would overflow or exhaust memory are errors, not a PanicException.
        (dict(resamples=2**63), "^resamples: must be at most 1048576"),
    ],
)
def test_bad_input_is_a_value_error_naming_the_argument(kwargs, match):
    args = dict(model="x1 + x2", bounds=[(0, 1), (0, 1)], n=8)
    args.update(kwargs)
    with pytest.raises(ValueError, match=match):
        iuq.sobol(args.pop("model"), args.pop("bounds"), **args)


def test_priors_other_than_uniform_equal_the_cli(cli, tmp_path):
    path = tmp_path / "priors.toml"
    path.write_text(
        'name = "priors"\n[parameters]\n'
        'x1 = { normal = [1, 0.5] }\nx2 = { log_normal = [0, 0.3] }\n'
        'x3 = { truncated_normal = [0, 1, -1, 2] }\n'
        f'[model]\nkind = "expression"\noutputs = {{ f = "{FORMULA}" }}\n'
    )
    expected = cli("sobol", path, "--n", 128, "--seed", 2)["outputs"]["f"]
    bounds = {"x1": {"normal": [1, 0.5]}, "x2": {"log_normal": [0, 0.3]},
              "x3": {"truncated_normal": [0, 1, -1, 2]}}
    ours = iuq.sobol(polynomial, bounds, n=128, seed=2, outputs=["f"])
    assert list(ours.S1) == [expected["S1"][k] for k in ("x1", "x2", "x3")]
    assert list(ours.ST) == [expected["ST"][k] for k in ("x1", "x2", "x3")]


def test_salib_normal_inputs_give_the_analytic_indices_of_a_linear_model():
    # y = x1 + 2 x2 with x1 ~ N(0, 1), x2 ~ N(0, 0.5): V = 1 + 1, S1 = ST = (0.5, 0.5)
    problem = {"num_vars": 2, "names": ["a", "b"], "bounds": [[0, 1], [0, 0.5]],
               "dists": ["norm", "norm"]}
    result = iuq.sobol(lambda x: x[:, 0] + 2 * x[:, 1], problem, n=4096, seed=0)
    assert result.names == ["a", "b"]
    assert np.all(np.abs(result.S1 - 0.5) <= result.S1_conf)
    assert np.all(np.abs(result.ST - 0.5) <= result.ST_conf)
