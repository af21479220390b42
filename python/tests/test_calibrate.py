"""iuq.calibrate: the adaptive engine on a Python function, its store, interruption and ArviZ.

Exact posteriors come from a fine grid (two parameters, flat priors, no modelling error). The
accuracy asked of the calibrated posterior — every mean within 0.1 exact std, every std within
10 % — is the engine's own stopping rule (tolerance 0.1 posterior std on twice the surrogate's
typical error),
plus BASIS's Monte Carlo error at N = 8000 (about 0.02 std for a mean, 1.5 % for a std, from
ESS ≥ N/2); the fixed seeds make each check deterministic.
"""

from __future__ import annotations

import hashlib
import json
import os
import signal
import sqlite3
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

import iuq

X = np.linspace(0.5, 8.0, 10)
TRUTH = (2.0, 0.3)
NOISE = 0.05


def decay(theta):
    a, k = theta[:, 0:1], theta[:, 1:2]
    return a * np.exp(-k * X[None, :])


def observations():
    rng = np.random.default_rng(11)
    return TRUTH[0] * np.exp(-TRUTH[1] * X) + rng.normal(0, NOISE, X.size)


PRIORS = {"a": (0.5, 4.0), "k": (0.05, 0.8)}


def exact_moments(y, k_max=None):
    """Posterior means and stds of (a, k) on a 600 × 600 grid (flat priors; the model fails,
    i.e. has no posterior mass, above k_max)."""
    a = np.linspace(*PRIORS["a"], 600)
    k = np.linspace(*PRIORS["k"], 600)
    A, K = np.meshgrid(a, k, indexing="ij")
    pred = A[..., None] * np.exp(-K[..., None] * X)
    ll = -0.5 * np.sum((pred - y) ** 2, axis=-1) / NOISE**2
    if k_max is not None:
        ll = np.where(K > k_max, -np.inf, ll)
    w = np.exp(ll - ll.max())
    w /= w.sum()
    mean = np.array([np.sum(w * A), np.sum(w * K)])
    std = np.sqrt(np.array([np.sum(w * (A - mean[0]) ** 2), np.sum(w * (K - mean[1]) ** 2)]))
    return mean, std


@pytest.fixture(scope="module")
def calibrated(tmp_path_factory):
    y = observations()
    store = tmp_path_factory.mktemp("calibrate") / "store"
    result = iuq.calibrate(
        decay, PRIORS, y, np.full(X.size, NOISE), x=X, modelling_error=None,
        samples=8000, seed=3, store=store, progress=False,
    )
    return result, y


def test_a_python_model_is_calibrated_to_its_exact_posterior(calibrated):
    result, y = calibrated
    mean, std = exact_moments(y)
    assert result.names == ["a", "k"]
    assert result.converged, result.stop_reason
    assert np.all(np.abs(result.mean - mean) < 0.1 * std), (result.mean, mean, std)
    assert np.all(np.abs(result.std / std - 1) < 0.1), (result.std, std)
    # Every run is in the store, with its parameters and outputs.
    assert result.model_runs == len(result.runs) and result.model_runs < 40
    first = result.runs[0]
    assert first["status"] == "succeeded"
    np.testing.assert_allclose(first["outputs"], decay(np.array([[first["a"], first["k"]]]))[0], rtol=1e-12)
    assert result.store.is_file() and (result.out / "report.html").is_file()
    # Rounds far from settled sample the exploring population (4 replicates of 2000 / 4), the
    # others the full one (4 × 2000), and a round samples more than that only once the
    # surrogate's error, counted twice (`surrogate_error_multiple`), is below the tolerance.
    full = 4 * 2000
    assert result.rounds[0]["samples"] == full // 4, result.rounds
    for before, after in zip(result.rounds, result.rounds[1:]):
        if 2 * before["surrogate_error"] >= 0.1:
            assert after["samples"] in (full // 4, full), result.rounds


def test_with_data_stds_only_the_defaults_give_the_exact_posterior():
    # No modelling error unless asked, the surrogate's variance added as it is: the posterior of
    # N(y | model, y_std²), the grid's, within the tolerances of the module's header.
    y = observations()
    result = iuq.calibrate(decay, PRIORS, y, np.full(X.size, NOISE), x=X, seed=5, progress=False)
    mean, std = exact_moments(y)
    assert result.names == ["a", "k"]
    assert result.converged, result.stop_reason
    assert np.all(np.abs(result.mean - mean) < 0.1 * std), (result.mean, mean, std)
    assert np.all(np.abs(result.std / std - 1) < 0.1), (result.std, std)


def test_without_data_stds_a_modelling_error_is_required():
    with pytest.raises(ValueError, match="^y_std: give the measurement stds, or a modelling_error"):
        iuq.calibrate(decay, PRIORS, observations(), x=X, progress=False)


def test_called_again_on_its_store_it_reuses_every_run_and_reports_progress(calibrated):
    from iuq._calibrate import _describe

    result, y = calibrated
    calls = []
    lines = []

    def counted(theta):
        calls.append(len(theta))
        return decay(theta)

    # The store knows the model by its description (by default the function's name and a digest
    # of its source): the same description reuses the runs.
    again = iuq.calibrate(
        counted, PRIORS, y, np.full(X.size, NOISE), x=X, modelling_error=None, samples=8000,
        seed=3, store=result.store.parent.parent, progress=lines.append,
        description=_describe(decay, None),
    )
    assert not calls
    assert again.model_runs == result.model_runs
    np.testing.assert_array_equal(again.samples, result.samples)
    assert any(line.startswith("pipeline: adaptive round") for line in lines), lines[:5]
    assert any(line.startswith("basis: ") for line in lines)


def test_a_raising_model_keeps_the_posterior_out_of_its_failing_region(tmp_path):
    y = observations()
    # The model raises for k > 0.34, three posterior stds above the mean (k ≈ 0.307 ± 0.012):
    # 0.3 % of the exact posterior's mass lies there.
    k_max = 0.34

    def fragile(theta):
        if np.any(theta[:, 1] > k_max):
            raise ValueError(f"no steady state for k > {k_max}")
        return decay(theta)

    result = iuq.calibrate(
        fragile, PRIORS, y, np.full(X.size, NOISE), x=X, modelling_error=None,
        samples=8000, seed=3, store=tmp_path / "s", progress=False,
    )
    failed = [r for r in result.runs if r["status"] == "failed"]
    assert failed and all("no steady state" in r["reason"] for r in failed)
    assert all(r["k"] > k_max for r in failed)
    assert result.converged, result.stop_reason
    # The classifier may leave an unsure band of at most 2 % of the posterior unresolved
    # (the engine's BOUNDARY_SHARE).
    assert np.mean(result.samples[:, 1] > k_max) <= 0.02
    mean, std = exact_moments(y, k_max)
    assert np.all(np.abs(result.mean - mean) < 0.1 * std), (result.mean, mean, std)
    assert np.all(np.abs(result.std / std - 1) < 0.1), (result.std, std)


def test_a_model_run_once_per_point_is_calibrated(tmp_path):
    y = observations()
    seen = []

    def at(theta, x):
        seen.append((theta.shape, x.shape))
        return theta[:, 0] * np.exp(-theta[:, 1] * x)

    result = iuq.calibrate(
        at, PRIORS, y, np.full(X.size, NOISE), x=X, per_point=True, modelling_error=None,
        samples=8000, seed=3, store=tmp_path / "s", progress=False,
    )
    assert all(t[1] == 2 and xs == (t[0],) for t, xs in seen)
    assert {round(r["x"], 12) for r in result.runs} == {round(v, 12) for v in X}
    assert result.converged, result.stop_reason
    # One GP per data point: the engine stops when the surrogate's error could move a moment by
    # 0.1 posterior std at its 68 % quantile; 2.5 times that bounds it at 99 %.
    mean, std = exact_moments(y)
    assert np.all(np.abs(result.mean - mean) < 0.25 * std), (result.mean, mean, std)
    assert np.all(np.abs(result.std / std - 1) < 0.1), (result.std, std)


def test_the_posterior_check_and_the_model_posterior_run_the_function(tmp_path):
    y = observations()
    result = iuq.calibrate(
        decay, PRIORS, y, np.full(X.size, NOISE), x=X, modelling_error=None, samples=4000,
        seed=3, store=tmp_path / "s", progress=False, posterior_check=5, model_posterior=True,
    )
    check = result.raw["posterior_check"]
    assert len(check) == X.size and all(point["passed"] for point in check)
    posterior = result.model_posterior
    assert posterior["certified"] and posterior["pareto_k"] < 0.7
    # Importance-weighted model runs: with an effective sample size n_eff the Monte Carlo error
    # of a mean is std/sqrt(n_eff), of a std about std/sqrt(2 n_eff); 3.5 of those.
    n_eff = posterior["effective_sample_size"]
    assert n_eff > 100
    mean, std = exact_moments(y)
    for k, name in enumerate(("a", "k")):
        assert abs(posterior["mean"][name] - mean[k]) < 3.5 * std[k] / np.sqrt(n_eff)
        assert abs(posterior["std"][name] / std[k] - 1) < 3.5 / np.sqrt(2 * n_eff)
    # The store holds the engine's runs, the check's (the MAP and 5 samples of the surrogate's
    # posterior) and the model posterior's. The check's samples and the model posterior's
    # members are both drawn from the surrogate posterior's population, so a check run may be a
    # member's run: with m of the population's N members run, each sample is one with
    # probability m/N.
    assert result.model_runs == len(result.runs)
    members_run = posterior["member_sizing"][-1]["samples"]
    shared_at_most = int(np.ceil(5 * members_run / 4000 + 3 * np.sqrt(5 * members_run / 4000)))
    extra = result.model_runs - result.surrogate_runs - posterior["model_runs"]
    assert 5 - shared_at_most <= extra <= 6, (extra, members_run)
    assert result.surrogate_runs < 30
    # The weighted members as arrays; in ArviZ they are one chain resampled systematically,
    # whose mean differs from the weighted mean by less than a multinomial resample's 3
    # standard errors (3·std/√n; systematic resampling's are smaller).
    members = result.model_posterior_samples
    assert members is not None and members.names == ["a", "k"]
    n = len(members.weights)
    data = result.to_arviz(source="model")
    assert data.posterior.sizes["draw"] == n and data.posterior.sizes["chain"] == 1
    assert data.posterior.attrs["pareto_k"] == posterior["pareto_k"]
    assert data.posterior.attrs["certified"] == 1
    assert list(data.observed_data["y"].values) == list(y)
    for k, name in enumerate(members.names):
        if posterior["paired"]:
            # The summary pairs the members with the surrogate's samples: the two means differ
            # by the members' plain mean's error against the population's (std/√n), 4 of those.
            assert abs(members.mean[k] - posterior["mean"][name]) < 4 * members.std[k] / np.sqrt(n), name
        else:
            assert members.mean[k] == pytest.approx(posterior["mean"][name], rel=1e-12)
        drawn = float(data.posterior[name].mean())
        assert abs(drawn - members.mean[k]) < 3 * members.std[k] / np.sqrt(n), name
    assert np.isfinite(data.sample_stats["lp"].values).all()
    with pytest.raises(ValueError, match="source"):
        result.to_arviz(source="models")


def chaotic_decay(theta):
    """The decay curve plus an irregular term of std NOISE that any change of θ redraws (a
    hash of its bits seeds it), as a chaotic simulator's."""
    out = decay(theta)
    for i, row in enumerate(np.atleast_2d(theta)):
        seed = int.from_bytes(hashlib.sha256(np.ascontiguousarray(row).tobytes()).digest()[:8], "little")
        out[i] += np.random.default_rng(seed).normal(0, NOISE, out.shape[1])
    return out


def test_model_posterior_options_reach_the_method_for_a_chaotic_function(tmp_path):
    y = observations()
    result = iuq.calibrate(
        chaotic_decay, PRIORS, y, np.full(X.size, NOISE), x=X, modelling_error=None, max_runs=40,
        samples=2000, sensitivity=0, seed=3, store=tmp_path / "s", progress=False,
        model_posterior={"samples": 60, "replicates": 3, "max_samples": 60},
    )
    posterior = result.model_posterior
    # The probe saw outputs that do not repeat, so the likelihood is noisy: one importance step,
    # each member's curve (one call, one run group) measured 3 times, less the probe's 4 runs;
    # a second batch where the first showed the surrogate's posterior off (then both are one
    # mixture sample).
    assert posterior["probe"]["irregular"] is True
    assert posterior["pseudo_marginal"] is True and posterior["replicates"] == 3
    assert posterior["proposal_mismatch"]["permutations"] == 999
    batches = 1 + len(posterior["corrections"])
    assert all(c["moment_matched"] for c in posterior["corrections"])
    assert posterior["samples"] == 60 * batches and len(posterior["stages"]) == 1
    assert posterior["replicate_runs"] == 60 * batches * 2 - 4
    # An empty dict is the defaults; a bad key or value is a ValueError naming it.
    with pytest.raises(ValueError, match="model_posterior.replicatez"):
        iuq.calibrate(
            decay, PRIORS, y, np.full(X.size, NOISE), x=X, modelling_error=None, max_runs=20,
            sensitivity=0, seed=3, store=tmp_path / "t", progress=False,
            model_posterior={"replicatez": 2},
        )
    with pytest.raises(ValueError, match="model_posterior.samples"):
        iuq.calibrate(
            decay, PRIORS, y, np.full(X.size, NOISE), x=X, modelling_error=None, max_runs=20,
            sensitivity=0, seed=3, store=tmp_path / "u", progress=False,
            model_posterior={"samples": [1, 2]},
        )


def test_with_on_error_raise_the_exception_stops_the_call_as_itself(tmp_path):
    class SolverDiverged(RuntimeError):
        pass

    def fragile(theta):
        if np.any(theta[:, 1] > 0.5):
            raise SolverDiverged("diverged at step 17")
        return decay(theta)

    with pytest.raises(SolverDiverged, match="diverged at step 17"):
        iuq.calibrate(
            fragile, PRIORS, observations(), np.full(X.size, NOISE), x=X, modelling_error=None,
            seed=3, store=tmp_path / "s", progress=False, on_error="raise", batch_size=1,
        )
    # The runs finished before the exception are stored, none as failed.
    con = sqlite3.connect(tmp_path / "s" / "calibration.campaign" / "campaign.sqlite")
    try:
        counts = dict(con.execute("select status, count(*) from runs group by status").fetchall())
    finally:
        con.close()
    assert counts.get("failed", 0) == 0 and counts.get("succeeded", 0) >= 1, counts


def test_non_finite_outputs_are_failed_runs_with_their_reason(tmp_path):
    def gappy(theta):
        out = decay(theta)
        out[theta[:, 1] > 0.5] = np.nan
        return out

    result = iuq.calibrate(
        gappy, PRIORS, observations(), np.full(X.size, NOISE), x=X, modelling_error=None,
        samples=4000, seed=3, store=tmp_path / "s", progress=False,
    )
    failed = [r for r in result.runs if r["status"] == "failed"]
    assert failed and all(r["k"] > 0.5 and "non-finite" in r["reason"] for r in failed)
    assert np.all(result.samples[:, 1] < 0.5)


SCRIPT = textwrap.dedent(
    """
    import json, sys, time
    import numpy as np
    import iuq
    X = np.linspace(0.5, 8.0, 10)
    log = open(sys.argv[2], "a")
    def model(theta):
        for row in theta:
            log.write(json.dumps([float(v) for v in row]) + "\\n")
            log.flush()
        time.sleep(float(sys.argv[3]))
        return theta[:, 0:1] * np.exp(-theta[:, 1:2] * X[None, :])
    rng = np.random.default_rng(11)
    y = 2.0 * np.exp(-0.3 * X) + rng.normal(0, 0.05, X.size)
    r = iuq.calibrate(model, {"a": (0.5, 4.0), "k": (0.05, 0.8)}, y, np.full(X.size, 0.05), x=X,
                      modelling_error=None, samples=2000, seed=3, store=sys.argv[1], progress=False,
                      batch_size=1, description="decay")
    print(json.dumps({"mean": r.mean.tolist(), "std": r.std.tolist(), "runs": r.model_runs}))
    """
)


def _logged(path: Path) -> list:
    if not path.exists():
        return []
    return [tuple(json.loads(line)) for line in path.read_text().splitlines() if line.strip()]


def _succeeded(store: Path) -> set:
    con = sqlite3.connect(f"file:{store}?mode=ro", uri=True)
    try:
        return {tuple(json.loads(p)) for (p,) in con.execute("select parameters from runs where status = 'succeeded'")}
    finally:
        con.close()


def test_killed_and_called_again_it_repeats_no_finished_run_and_gives_the_same_result(tmp_path):
    script = tmp_path / "calibrate_decay.py"
    script.write_text(SCRIPT)
    store, log = tmp_path / "killed", tmp_path / "killed.log"
    process = subprocess.Popen([sys.executable, str(script), str(store), str(log), "0.05"])
    deadline = time.time() + 120
    while len(_logged(log)) < 7 and process.poll() is None and time.time() < deadline:
        time.sleep(0.02)
    assert process.poll() is None, "the calibration ended before it could be killed"
    process.send_signal(signal.SIGKILL)
    process.wait()
    database = store / "calibration.campaign" / "campaign.sqlite"
    finished = _succeeded(database)
    assert len(finished) >= 6
    before = len(_logged(log))
    again = subprocess.run([sys.executable, str(script), str(store), str(log), "0"], capture_output=True, text=True, timeout=600)
    assert again.returncode == 0, again.stderr[-3000:]
    repeated = set(_logged(log)[before:]) & finished
    assert not repeated, f"{len(repeated)} finished runs evaluated again"
    uninterrupted = subprocess.run(
        [sys.executable, str(script), str(tmp_path / "whole"), str(tmp_path / "whole.log"), "0"],
        capture_output=True, text=True, timeout=600,
    )
    assert uninterrupted.returncode == 0, uninterrupted.stderr[-3000:]
    assert json.loads(again.stdout.splitlines()[-1]) == json.loads(uninterrupted.stdout.splitlines()[-1])


def _default_sigint() -> None:
    """In the child before exec: SIGINT back to its default, as from a terminal. A shell that
    starts the tests as a background job without job control (`nohup .ci/run &` from a script)
    hands its children SIGINT ignored, and Python then installs no KeyboardInterrupt handler."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def _interrupt_within_a_second(process, store: Path, timeout: float) -> dict:
    """Send SIGINT to `process`; check that it raised KeyboardInterrupt within a second and left
    its store intact; the store's run counts by status."""
    sent = time.time()
    process.send_signal(signal.SIGINT)
    _, stderr = process.communicate(timeout=timeout)
    elapsed = time.time() - sent
    assert "KeyboardInterrupt" in stderr, stderr[-2000:]
    assert elapsed < 1.0, f"took {elapsed:.2f} s to stop"
    con = sqlite3.connect(store / "calibration.campaign" / "campaign.sqlite")
    try:
        assert con.execute("pragma integrity_check").fetchone()[0] == "ok"
        return dict(con.execute("select status, count(*) from runs group by status").fetchall())
    finally:
        con.close()


def test_ctrl_c_interrupts_within_a_second_and_leaves_the_store_consistent(tmp_path):
    script = tmp_path / "calibrate_decay.py"
    script.write_text(SCRIPT)
    store, log = tmp_path / "store", tmp_path / "run.log"
    # A model call takes 2 s: the interrupt arrives inside the user's function.
    process = subprocess.Popen(
        [sys.executable, str(script), str(store), str(log), "2"],
        stderr=subprocess.PIPE, text=True, preexec_fn=_default_sigint,
    )
    deadline = time.time() + 120
    while len(_logged(log)) < 3 and process.poll() is None and time.time() < deadline:
        time.sleep(0.02)
    assert process.poll() is None
    counts = _interrupt_within_a_second(process, store, timeout=30)
    # Two runs finished (2 s each) before the interrupt; the third was under way: not a
    # failure, it runs again next time.
    assert counts.get("succeeded", 0) == 2 and counts.get("failed", 0) == 0, counts


ENGINE_SCRIPT = textwrap.dedent(
    """
    import json, sys
    import numpy as np
    import iuq
    X = np.linspace(0.5, 8.0, 40)
    def model(theta):
        with open(sys.argv[2], "a") as log:
            log.write(f"{len(theta)}\\n")
        return theta[:, 0:1] * np.exp(-theta[:, 1:2] * X[None, :])
    rng = np.random.default_rng(11)
    y = 2.0 * np.exp(-0.3 * X) + rng.normal(0, 0.05, X.size)
    iuq.calibrate(model, {"a": (0.5, 4.0), "k": (0.05, 0.8)}, y, np.full(X.size, 0.05), x=X,
                  modelling_error=None, initial_runs=400, seed=3, store=sys.argv[1],
                  progress=False, sensitivity=0)
    """
)


def test_ctrl_c_interrupts_the_engine_within_a_second(tmp_path):
    # 400 initial runs of a cheap 40-point curve, then the engine's work on them: 40 GP fits on
    # 400 runs, several seconds without a check of the pipeline's (without the grace, the
    # KeyboardInterrupt waited for them: 5-7 s here). The interrupt arrives there.
    script = tmp_path / "calibrate_engine.py"
    script.write_text(ENGINE_SCRIPT)
    store, log = tmp_path / "store", tmp_path / "calls.log"
    process = subprocess.Popen(
        [sys.executable, str(script), str(store), str(log)],
        stderr=subprocess.PIPE, text=True, preexec_fn=_default_sigint,
    )
    deadline = time.time() + 300
    while sum(map(int, log.read_text().split())) < 400 if log.exists() else True:
        assert process.poll() is None and time.time() < deadline, "the initial runs did not finish"
        time.sleep(0.02)
    time.sleep(0.5)
    assert process.poll() is None
    counts = _interrupt_within_a_second(process, store, timeout=120)
    assert counts.get("succeeded", 0) == 400, counts


def test_to_arviz_round_trips_through_arviz_summary(calibrated):
    az = pytest.importorskip("arviz")
    result, y = calibrated
    data = result.to_arviz()
    summary = az.summary(data, round_to="none", kind="stats")
    for k, name in enumerate(result.names):
        assert summary.loc[name, "mean"] == pytest.approx(result.mean[k], rel=1e-12)
        assert summary.loc[name, "sd"] == pytest.approx(result.samples[:, k].std(ddof=1), rel=1e-9)
    np.testing.assert_array_equal(data.observed_data["y"].values, y)
    predictive = data.posterior_predictive["y"].values
    assert predictive.shape == (1, 1000, X.size)
    # The posterior predictive is centred on the data within its spread.
    centre = predictive.mean(axis=(0, 1))
    assert np.all(np.abs(centre - y) < 3 * predictive.std(axis=(0, 1)))
    assert "<table>" in result._repr_html_()
    assert result.to_pandas().shape == result.samples.shape
    assert result.model_posterior_samples is None
    with pytest.raises(ValueError, match="model_posterior=True"):
        result.to_arviz(source="model")


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"y_std": [0.1] * 9 + [0.0]}, "y_std"),
        ({"parameters": {"x": (0, 1)}}, "parameters"),
        ({"on_error": "ignore"}, "on_error"),
        ({"tolerance": 0.0}, "tolerance"),
        ({"surrogate_error_multiple": -1.0}, "surrogate_error_multiple"),
        ({"modelling_error": (0.1, 0.01)}, "modelling_error"),
        ({"y_std": [0.1] * 3}, "y_std"),
    ],
)
def test_bad_input_is_a_value_error_naming_the_argument(tmp_path, kwargs, match):
    args = {"parameters": PRIORS, "y_std": np.full(X.size, NOISE)}
    args.update(kwargs)
    with pytest.raises(ValueError, match=match):
        iuq.calibrate(decay, args.pop("parameters"), observations(), store=tmp_path / "s", progress=False, **args)


def test_a_callable_study_is_refused_by_the_command_line(cli, tmp_path):
    iuq_bin = os.environ.get("IUQ_BIN") or str(Path(__file__).resolve().parents[2] / "target" / "debug" / "iuq")
    (tmp_path / "data.csv").write_text("x,y,e\n0,1,0.1\n1,2,0.1\n")
    (tmp_path / "s.toml").write_text(
        'name = "s"\n[parameters]\na = { uniform = [0, 1] }\n[likelihood]\n'
        'data = { file = "data.csv", x = "x", y = "y", y_err = "e" }\n[model]\nkind = "callable"\n'
        '[surrogate]\ndesign = { kind = "lhs", n = 4 }\n'
    )
    done = subprocess.run([iuq_bin, "pipeline", str(tmp_path / "s.toml")], capture_output=True, text=True)
    assert done.returncode == 2
    assert "model.kind" in done.stderr and "iuq.calibrate" in done.stderr
