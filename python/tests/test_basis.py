"""iuq.basis: against `iuq basis` (bit for bit), the data form, and failing likelihoods."""

import json

import numpy as np
import pytest

import iuq
from conftest import read_csv

# Only +, -, *, /: numpy and iuq's formula evaluator give the same bits.
FORMULA = "-0.5*(x1-0.3)*(x1-0.3)/0.01 - 0.5*(x2+0.2)*(x2+0.2)/0.04"
BOUNDS = [(-1.0, 1.0), (-1.0, 1.0)]


def log_likelihood(x):
    a, b = x[:, 0], x[:, 1]
    return -0.5 * (a - 0.3) * (a - 0.3) / 0.01 - 0.5 * (b + 0.2) * (b + 0.2) / 0.04


def test_callable_and_formula_equal_the_cli_bit_for_bit(cli, tmp_path):
    study = tmp_path / "gauss.toml"
    study.write_text(
        'name = "gauss"\n[parameters]\nx1 = { uniform = [-1, 1] }\nx2 = { uniform = [-1, 1] }\n'
        f'[likelihood]\nlog_density = "{FORMULA}"\n'
    )
    out = tmp_path / "basis"
    summary = cli("basis", study, "--samples", 500, "--burn", 2, "--seed", 4, "--out", out)
    columns, table = read_csv(out / "samples.csv")
    assert columns[:2] == ["x1", "x2"]
    for model in (log_likelihood, FORMULA):
        ours = iuq.basis(model, BOUNDS, samples=500, burn=2, seed=4)
        assert np.array_equal(ours.samples, table[:, :2])
        assert np.array_equal(ours.log_likelihood, table[:, columns.index("ll")])
        assert ours.log_evidence == summary["log_evidence"]
        assert ours.n_stages == summary["stages"]
        assert ours.evaluations == summary["evaluations"]
        assert list(ours.mean) == [summary["mean"]["x1"], summary["mean"]["x2"]]
        assert list(ours.std) == [summary["std"]["x1"], summary["std"]["x2"]]
        assert list(ours.map) == [summary["map"]["x1"], summary["map"]["x2"]]
    stages = json.loads((out / "stages.json").read_text())
    assert len(ours.stages) == len(stages["stages"] if isinstance(stages, dict) else stages)


def test_the_posterior_and_evidence_of_a_gaussian():
    result = iuq.basis(log_likelihood, BOUNDS, samples=4000, seed=1)
    assert result.converged and result.stop_reason == "converged"
    assert result.samples.shape == (4000, 2) and result.names == ["x1", "x2"]
    # Monte Carlo error of a resampled population: a tenth of the posterior std
    assert np.all(np.abs(result.mean - [0.3, -0.2]) < 0.1 * np.array([0.1, 0.2]))
    assert result.std == pytest.approx([0.1, 0.2], rel=0.08)
    # Z = ∫ L π = (2π·0.1·0.2) / 4 (prior density 1/4; the likelihood's mass lies inside)
    assert result.log_evidence == pytest.approx(np.log(2 * np.pi * 0.1 * 0.2 / 4), abs=0.1)
    assert result.stages[0]["stage"] == 0 and result.stages[-1]["exponent"] == 1.0
    assert set(result.summary()) == {"x1", "x2"}


def test_the_likelihood_is_called_once_per_mcmc_step_with_the_whole_population():
    sizes = []

    def recording(x):
        sizes.append(x.shape[0])
        return log_likelihood(x)

    # The published fixed chains (burn = 0, l_max = 1): one batch per stage.
    result = iuq.basis(recording, BOUNDS, samples=300, seed=0, burn=0)
    assert len(sizes) == len(result.stages)
    assert sizes[0] == 300 and sum(sizes) == result.evaluations
    # The default mixing: one batch per MCMC step of every chain, as the stages report.
    sizes.clear()
    result = iuq.basis(recording, BOUNDS, samples=300, seed=0)
    assert len(sizes) == sum(s["batches"] for s in result.stages) > len(result.stages)
    assert all(s["burn_in"] >= 1 for s in result.stages[1:])
    assert sizes[0] == 300 and sum(sizes) == result.evaluations


def test_the_data_form_with_a_python_model_matches_least_squares():
    t = np.array([0.0, 1.0, 2.0, 3.0, 4.0])
    rng = np.random.default_rng(0)
    sigma = 0.1
    y = 1.0 + 0.5 * t + sigma * rng.standard_normal(t.size)

    def line(theta):
        return theta[:, :1] + theta[:, 1:2] * t[None, :]

    result = iuq.basis(model=line, data=y, data_std=np.full(t.size, sigma),
                       bounds={"a": (0, 2), "b": (0, 1)}, modelling_error=None,
                       computational_error="none", samples=3000, seed=2)
    design = np.column_stack([np.ones_like(t), t])
    exact_mean = np.linalg.solve(design.T @ design, design.T @ y)
    exact_sd = np.sqrt(np.diag(sigma**2 * np.linalg.inv(design.T @ design)))
    assert result.names == ["a", "b"]
    assert np.all(np.abs(result.mean - exact_mean) < 0.15 * exact_sd)
    assert result.std == pytest.approx(exact_sd, rel=0.1)


def test_the_data_form_equals_the_cli_bit_for_bit(cli, tmp_path):
    t = [0.0, 1.0, 2.0, 3.0]
    y = [1.05, 1.42, 2.07, 2.46]
    err = [0.1, 0.1, 0.2, 0.1]
    data = tmp_path / "line.csv"
    data.write_text("t,y,e\n" + "".join(f"{a!r},{b!r},{c!r}\n" for a, b, c in zip(t, y, err)))
    outputs = ", ".join(f'y{j} = "a + b*{tj!r}"' for j, tj in enumerate(t))
    study = tmp_path / "line.toml"
    study.write_text(
        'name = "line"\n[parameters]\na = { uniform = [0, 2] }\nb = { uniform = [0, 1] }\n'
        '[likelihood]\ndata = { file = "line.csv", x = "t", y = "y", y_err = "e" }\n'
        f'[model]\nkind = "expression"\noutputs = {{ {outputs} }}\n'
    )
    out = tmp_path / "basis"
    summary = cli("basis", study, "--samples", 400, "--seed", 6, "--out", out)
    columns, table = read_csv(out / "samples.csv")
    # Both default to the data's stds alone (no sigma_m).
    assert columns[:3] == ["a", "b", "ll"]
    times = np.array(t)

    def line(theta):
        return theta[:, :1] + theta[:, 1:2] * times[None, :]

    ours = iuq.basis(model=line, data=y, data_std=err, bounds={"a": (0, 2), "b": (0, 1)},
                     samples=400, seed=6)
    assert ours.names == ["a", "b"]
    assert np.array_equal(ours.samples, table[:, :2])
    assert ours.log_evidence == summary["log_evidence"]


def test_the_data_form_samples_the_modelling_error():
    t = np.linspace(0.5, 1.5, 6)
    y = 2.0 * t

    def model(theta):
        return theta[:, :1] * t[None, :], np.full((theta.shape[0], t.size), 0.01)

    result = iuq.basis(model=model, data=y, bounds=[(0, 4)], modelling_error=(0.001, 0.1),
                       computational_error="relative", samples=500, seed=0)
    assert result.names == ["x1", "sigma_m"]
    assert result.mean[0] == pytest.approx(2.0, abs=0.1)


def raises_beyond(x):
    if np.any(x[:, 0] > 0.8):
        raise FloatingPointError("no convergence for x1 > 0.8")
    return log_likelihood(x)


def test_an_exception_of_the_likelihood_is_raised_as_itself():
    with pytest.raises(FloatingPointError, match="no convergence for x1 > 0.8"):
        iuq.basis(raises_beyond, BOUNDS, samples=200, seed=0)


def test_with_on_error_fail_the_points_that_raise_are_rejected():
    result = iuq.basis(raises_beyond, BOUNDS, samples=400, seed=0, on_error="fail")
    assert result.converged and result.failures > 0
    (reason, count), = result.failure_reasons.items()
    assert "FloatingPointError: no convergence for x1 > 0.8" in reason
    assert np.all(result.samples[:, 0] <= 0.8)


@pytest.mark.parametrize(
    "kwargs,match",
    [
        (dict(samples=1), "^samples: must be at least 2"),
        (dict(proposal_scale=float("nan")), "^proposal_scale: must be finite"),
        (dict(bounds=None), "^bounds: give the parameter ranges"),
        (dict(log_likelihood="x1 +"), "^log_likelihood: "),
        (dict(log_likelihood=None, model=lambda x: x, data=[1.0, 2.0], data_std=[0.1, 0.1],
              computational_error="odd"), "^computational_error: `odd`"),
        (dict(log_likelihood=None, model=lambda x: x, data=[1.0, 2.0]),
         "^data_std: give the measurement stds, or a modelling_error"),
        (dict(burn=2**64 - 1), "^burn: must be at most 1048576"),
    ],
)
def test_bad_input_is_a_value_error_naming_the_argument(kwargs, match):
    args = dict(log_likelihood=log_likelihood, bounds=BOUNDS)
    args.update(kwargs)
    with pytest.raises(ValueError, match=match):
        iuq.basis(args.pop("log_likelihood"), args.pop("bounds"), **args)


def test_a_normal_prior_equals_the_cli(cli, tmp_path):
    study = tmp_path / "prior.toml"
    study.write_text(
        'name = "prior"\n[parameters]\nx1 = { normal = [0.2, 0.3] }\nx2 = { uniform = [-1, 1] }\n'
        f'[likelihood]\nlog_density = "{FORMULA}"\n'
    )
    out = tmp_path / "basis"
    summary = cli("basis", study, "--samples", 300, "--seed", 1, "--out", out)
    _, table = read_csv(out / "samples.csv")
    ours = iuq.basis(log_likelihood, [{"normal": [0.2, 0.3]}, (-1, 1)], samples=300, seed=1)
    assert np.array_equal(ours.samples, table[:, :2])
    assert ours.log_evidence == summary["log_evidence"]
