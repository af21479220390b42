"""`iuq.ModelPosteriorSamples`: the model posterior's weighted members as the pipeline writes them
(`model-posterior/samples.csv`), and their systematic resample."""

from __future__ import annotations

import numpy as np
import pytest

import iuq
from iuq._model_posterior import read_model_posterior

COLUMNS = "weight,log_weight,raw_log_weight,ll_model,ll_surrogate,lp"


def members(weights, samples=None):
    weights = np.asarray(weights, dtype=float)
    n = len(weights)
    samples = np.arange(n, dtype=float)[:, None] if samples is None else np.asarray(samples, dtype=float)
    return iuq.ModelPosteriorSamples(
        names=["x"], samples=samples, weights=weights / weights.sum(),
        log_likelihood=np.zeros(n), log_prior=np.zeros(n),
    )


def test_systematic_resampling_draws_each_member_its_share_and_never_a_weightless_one():
    weights = np.array([0.0, 0.5, 0.0, 0.3, 0.2, 0.0])
    posterior = members(weights)
    for draws in (1, 6, 7, 100, 1001):
        for seed in range(5):
            chosen = posterior.resample(draws, seed)
            assert chosen.shape == (draws,)
            counts = np.bincount(chosen, minlength=weights.size)
            # Systematic resampling: ⌊draws·w⌋ or ⌈draws·w⌉ copies; none of a weight 0.
            assert np.all(counts >= np.floor(draws * weights)) and np.all(counts <= np.ceil(draws * weights))
            assert counts[weights == 0].sum() == 0
    assert np.all(members([1.0]).resample(5, 3) == 0)
    assert posterior.resample().shape == (weights.size,)
    assert posterior.resample(50, 7).tolist() == posterior.resample(50, 7).tolist()


def test_bad_draws_and_seeds_are_errors_naming_the_argument():
    posterior = members([1.0, 1.0])
    with pytest.raises(ValueError, match="^draws"):
        posterior.resample(0)
    with pytest.raises(TypeError, match="^draws"):
        posterior.resample(2.5)
    with pytest.raises(ValueError, match="^seed"):
        posterior.resample(2, -1)


def test_the_members_file_is_read_by_position_whatever_the_parameters_are_called(tmp_path):
    folder = tmp_path / "model-posterior"
    folder.mkdir()
    # Parameters named like the weight columns, a failed member (weight 0, −inf likelihood).
    (folder / "samples.csv").write_text(
        f"lp,weight,{COLUMNS}\n"
        "1.0,10.0,0.25,-1.386,0.1,-2.0,-2.1,-0.5\n"
        "2.0,20.0,0.75,-0.288,0.2,-1.0,-1.2,-0.5\n"
        "3.0,30.0,0,-inf,-inf,-inf,-1.5,-0.5\n"
    )
    posterior = read_model_posterior(tmp_path, {"certified": True})
    assert posterior.names == ["lp", "weight"]
    np.testing.assert_array_equal(posterior.samples, [[1, 10], [2, 20], [3, 30]])
    np.testing.assert_allclose(posterior.weights, [0.25, 0.75, 0.0])
    np.testing.assert_allclose(posterior.mean, [1.75, 17.5])
    assert posterior.log_likelihood[2] == -np.inf and np.all(posterior.log_prior == -0.5)
    assert read_model_posterior(tmp_path, None) is None
    (folder / "samples.csv").write_text("a,weight,lp\n1,1,0\n")
    with pytest.raises(ValueError, match="samples.csv"):
        read_model_posterior(tmp_path, {})
