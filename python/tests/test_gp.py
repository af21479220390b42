"""iuq.GaussianProcess against `iuq gp` (files and numbers bit for bit) and scikit-learn."""

import json

import numpy as np
import pytest

import iuq
from conftest import read_csv, write_csv


def data(n=30, seed=3):
    x = iuq.design.lhs(n, 2, seed=seed, bounds=[(0.0, 2.0), (-1.0, 1.0)])
    y = np.sin(3.0 * x[:, 0]) + x[:, 1] ** 2 + 0.3 * x[:, 0] * x[:, 1]
    return x, y


def test_fit_save_predict_q2_equal_the_cli(cli, tmp_path):
    x, y = data()
    train = tmp_path / "train.csv"
    write_csv(train, ["a", "b", "f"], np.column_stack([x, y]))
    cli_file = tmp_path / "cli.json"
    cli("gp", "fit", "--data", train, "--inputs", "a,b", "--output", "f", "--restarts", 4,
        "--seed", 9, "--out", cli_file)
    gp = iuq.GaussianProcess.fit(x, y, restarts=4, seed=9, input_names=["a", "b"], output_name="f")
    py_file = tmp_path / "py.json"
    gp.save(py_file)
    assert py_file.read_bytes() == cli_file.read_bytes()

    xt, yt = data(n=25, seed=8)
    points = tmp_path / "points.csv"
    write_csv(points, ["a", "b", "f"], np.column_stack([xt, yt]))
    predicted = tmp_path / "pred.csv"
    cli("gp", "predict", "--model", cli_file, "--points", points, "--out", predicted)
    columns, table = read_csv(predicted)
    mean, std = gp.predict(xt, return_std=True)
    assert np.array_equal(mean, table[:, columns.index("mean")])
    assert np.array_equal(std, table[:, columns.index("std")])
    _, std_noise = gp.predict(xt, return_std=True, include_noise=True)
    assert np.array_equal(std_noise, table[:, columns.index("std_with_noise")])
    assert np.array_equal(gp.predict(xt), mean)

    validated = cli("gp", "validate", "--model", cli_file, "--data", points)
    assert gp.q2(xt, yt) == validated["q2"]
    assert 0.9 < gp.q2(xt, yt) <= 1.0

    loaded = iuq.GaussianProcess.load(cli_file)
    assert loaded.input_names == ["a", "b"] and loaded.output_name == "f"
    assert np.array_equal(loaded.predict(xt), mean)
    assert loaded.log_marginal_likelihood == gp.log_marginal_likelihood


def test_the_saved_file_is_a_gp_bank_of_one_output(tmp_path):
    x, y = data()
    gp = iuq.GaussianProcess.fit(x, y, restarts=2, seed=1, input_names=["a", "b"], output_name="f")
    gp.save(tmp_path / "bank.json")
    bank = json.loads((tmp_path / "bank.json").read_text())
    assert bank["format"] == "iuq-gp-bank" and bank["version"] == 1
    assert bank["input_names"] == ["a", "b"] and bank["output_names"] == ["f"]
    # A bank of two outputs (the pipeline's gp-bank.json) is not one GP.
    bank["output_names"] = ["f", "g"]
    bank["gps"] = bank["gps"] * 2
    (tmp_path / "two.json").write_text(json.dumps(bank))
    with pytest.raises(ValueError, match="^path: .*two.json: a GP bank of 2 outputs"):
        iuq.GaussianProcess.load(tmp_path / "two.json")


def test_fit_summary_equals_the_cli_json(cli, tmp_path):
    x, y = data()
    train = tmp_path / "train.csv"
    write_csv(train, ["x1", "x2", "y"], np.column_stack([x, y]))
    summary = cli("gp", "fit", "--data", train, "--inputs", "x1,x2", "--output", "y",
                  "--out", tmp_path / "g.json")
    gp = iuq.GaussianProcess.fit(x, y)
    assert gp.log_marginal_likelihood == summary["log_marginal_likelihood"]
    assert list(gp.length_scales) == summary["length_scales"]
    assert gp.noise_variance == summary["noise_variance"]
    assert gp.loo_q2 == summary["loo_q2"]


def test_our_log_marginal_likelihood_is_no_worse_than_scikit_learns():
    gaussian_process = pytest.importorskip("sklearn.gaussian_process")
    kernels = pytest.importorskip("sklearn.gaussian_process.kernels")
    x, y = data(n=40, seed=1)
    # measurement noise keeps both optima inside the bounds (a noise-free fit sits on the
    # noise bound, where the optimisers stop on their own tolerances)
    y = y + 0.05 * np.random.default_rng(5).standard_normal(y.size)
    # Both fit the same data on the same scale: unit-cube inputs, standardised outputs, the
    # same kernel (c·RBF_ARD + white noise) and the same hyper-parameter bounds.
    u = (x - np.array([0.0, -1.0])) / 2.0
    z = (y - y.mean()) / y.std()
    ours = iuq.GaussianProcess.fit(u, z, restarts=10, seed=0, scale_inputs=False,
                                   standardize_outputs=False)
    kernel = (
        kernels.ConstantKernel(1.0, (1e-3, 1e3)) * kernels.RBF([1.0, 1.0], (1e-2, 1e3))
        + kernels.WhiteKernel(1e-3, (1e-8, 1.0))
    )
    theirs = gaussian_process.GaussianProcessRegressor(
        kernel=kernel, n_restarts_optimizer=10, random_state=0
    ).fit(u, z)
    # Same definition of the likelihood: scikit-learn's value at our optimum is ours.
    theta = np.log([ours.signal_variance, *ours.length_scales, ours.noise_variance])
    assert theirs.log_marginal_likelihood(theta) == pytest.approx(
        ours.log_marginal_likelihood, rel=1e-6, abs=1e-6
    )
    # the optimisers agree to ~1e-10 here; 1e-8 leaves room for their stopping tolerances only
    assert ours.log_marginal_likelihood >= theirs.log_marginal_likelihood_value_ - 1e-8
    mean = ours.predict(u)
    assert np.max(np.abs(mean - theirs.predict(u))) < 1e-2


def test_bad_input_names_the_argument(tmp_path):
    x, y = data()
    with pytest.raises(ValueError, match="^y: 29 values for 30 rows of X"):
        iuq.GaussianProcess.fit(x, y[:-1])
    with pytest.raises(ValueError, match="^kernel: `rbf` is not one of"):
        iuq.GaussianProcess.fit(x, y, kernel="rbf")
    with pytest.raises(ValueError, match="^restarts: must be at most 10000"):
        iuq.GaussianProcess.fit(x, y, restarts=2**63)
    gp = iuq.GaussianProcess.fit(x, y, restarts=0)
    with pytest.raises(ValueError, match="^X: expected 2 columns"):
        gp.predict(np.zeros((3, 3)))
    with pytest.raises(ValueError, match="^X: holds non-finite values"):
        gp.predict([[np.nan, 0.0]])
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"format": "other", "version": 1, "inputs": [], "output": "y", "gp": {}}))
    with pytest.raises(ValueError, match="^path: .*bad.json: not a GP file"):
        iuq.GaussianProcess.load(bad)
    gp.save(bad)
    saved = json.loads(bad.read_text())
    saved["version"] = 2
    bad.write_text(json.dumps(saved))
    with pytest.raises(ValueError, match="^path: .*bad.json: not a GP file: .*format `iuq-gp-bank` version 2 is not"):
        iuq.GaussianProcess.load(bad)
    with pytest.raises(ValueError, match="^path: .*cannot read"):
        iuq.GaussianProcess.load(tmp_path / "missing.json")


def test_the_gil_is_released_while_rust_fits():
    import threading
    import time

    x = iuq.design.lhs(300, 4, seed=2)
    y = np.sin(4 * x[:, 0]) + x[:, 1] * x[:, 2] + x[:, 3]
    window = {}

    def fit():
        window["start"] = time.perf_counter()
        iuq.GaussianProcess.fit(x, y, restarts=10, seed=0)
        window["end"] = time.perf_counter()

    worker = threading.Thread(target=fit)
    ticks = []
    worker.start()
    while worker.is_alive():
        ticks.append(time.perf_counter())
        time.sleep(0.001)
    worker.join()
    start, end = window["start"], window["end"]
    assert end - start > 0.1, "the fit is too short to tell"
    # With the GIL held during the fit the main thread could not tick inside the window (20 ms
    # margins: 4 switch intervals of 5 ms).
    inside = [t for t in ticks if start + 0.02 < t < end - 0.02]
    assert len(inside) >= 5
