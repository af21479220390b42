#!/usr/bin/env python3
"""Benchmark of the Python package (not a timed test): what calling a Python model costs, and
iuq's Gaussian process against scikit-learn's, from Python.

1. Overhead per evaluation of a Python-callable model against the same model as a formula
   evaluated in Rust: ``iuq.sobol`` (one batch of N(d + 2) rows) and ``iuq.basis`` (one batch
   per stage), each run both ways with the same seed (the results are identical; checked).
2. ``iuq.GaussianProcess`` fit and predict (mean and std) against
   ``sklearn.gaussian_process.GaussianProcessRegressor`` on the same data, kernel
   (c·RBF_ARD + white noise), hyper-parameter bounds and number of optimiser restarts.

Prints medians over repeats and the ratios. Needs numpy and scikit-learn; run after
``pip install ./python``:

    python scripts/bench/python_overhead.py [--repeats 5] [--threads 1] [--quick]

``--threads`` (default 1) sets the threads of numpy's BLAS (OPENBLAS/OMP/MKL_NUM_THREADS) and
of iuq (RAYON_NUM_THREADS) before they load, so that both sides use the same number of cores.
On shared cores a multi-threaded OpenBLAS busy-waits: a 50-point scikit-learn fit took 18.6 s
with the default threads and 1.2 s with one thread on the 2-core machine of 2026-11-24.
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import sys
import time
import warnings


def _threads_from_argv(default: int = 1) -> int:
    for k, arg in enumerate(sys.argv):
        if arg == "--threads" and k + 1 < len(sys.argv):
            return int(sys.argv[k + 1])
        if arg.startswith("--threads="):
            return int(arg.split("=", 1)[1])
    return default


THREADS = _threads_from_argv()
for variable in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS", "RAYON_NUM_THREADS"):
    os.environ[variable] = str(THREADS)

import numpy as np  # noqa: E402  (after the thread settings)

import iuq  # noqa: E402

PI = 3.141592653589793
# Only + - * /: the formula and the numpy function give the same bits, so both runs do the
# same work and reach the same result.
FORMULA = "x1 + 2*x2*x3 + x1*x1*x2 - 0.5*x3*x3*x1"
LOG_LIKELIHOOD = "-0.5*(x1-0.3)*(x1-0.3)/0.01 - 0.5*(x2+0.2)*(x2+0.2)/0.04 - 0.5*x3*x3/0.09"


def model(x):
    x1, x2, x3 = x[:, 0], x[:, 1], x[:, 2]
    return x1 + 2 * x2 * x3 + x1 * x1 * x2 - 0.5 * x3 * x3 * x1


def log_likelihood(x):
    a, b, c = x[:, 0], x[:, 1], x[:, 2]
    return -0.5 * (a - 0.3) * (a - 0.3) / 0.01 - 0.5 * (b + 0.2) * (b + 0.2) / 0.04 - 0.5 * c * c / 0.09


def median_time(function, repeats):
    times = []
    result = None
    for _ in range(repeats):
        start = time.perf_counter()
        result = function()
        times.append(time.perf_counter() - start)
    return statistics.median(times), result


def overhead(repeats, quick):
    bounds = [(-1.0, 1.0)] * 3
    print("1. Python-callable model vs the same model as a Rust formula (medians of "
          f"{repeats} runs)")
    print(f"{'workload':<34} {'evaluations':>11} {'Rust formula':>13} {'Python callable':>16} "
          f"{'ratio':>7} {'overhead/eval':>14}")
    n_sobol = 2**12 if quick else 2**15
    cases = [
        (f"iuq.sobol, y = x1, n = {n_sobol}",
         lambda m: iuq.sobol(m, bounds, n=n_sobol, seed=0, outputs=["y"]),
         "x1", lambda x: x[:, 0].copy(), lambda r: r.evaluations),
        (f"iuq.sobol, n = {n_sobol} (1 batch)",
         lambda m: iuq.sobol(m, bounds, n=n_sobol, seed=0, outputs=["y"]),
         FORMULA, model, lambda r: r.evaluations),
    ]
    for samples in ((1000,) if quick else (1000, 10000)):
        cases.append((f"iuq.basis, N = {samples} (1 batch/stage)",
                      lambda m, s=samples: iuq.basis(m, bounds, samples=s, seed=0),
                      LOG_LIKELIHOOD, log_likelihood, lambda r: r.evaluations))
    for label, run, formula, function, evaluations in cases:
        t_rust, r_rust = median_time(lambda: run(formula), repeats)
        t_py, r_py = median_time(lambda: run(function), repeats)
        same = (np.array_equal(r_rust.S1, r_py.S1) if hasattr(r_rust, "S1")
                else np.array_equal(r_rust.samples, r_py.samples))
        assert same, f"{label}: the two runs differ"
        n = evaluations(r_py)
        print(f"{label:<34} {n:>11} {t_rust * 1e3:>10.1f} ms {t_py * 1e3:>13.1f} ms "
              f"{t_py / t_rust:>7.2f} {(t_py - t_rust) / n * 1e9:>11.0f} ns")
    print("   (overhead/eval = (Python − Rust) / evaluations: the batch's copy to numpy, the "
          "call, the check of the result and numpy's own arithmetic)")
    # What batching saves: the same numpy model called once per point, as a per-point
    # callback interface would call it.
    rows = iuq.design.sobol(20000, 3, seed=0, bounds=bounds)
    t_batch, _ = median_time(lambda: model(rows), repeats)
    t_points, _ = median_time(lambda: [model(rows[i:i + 1]) for i in range(rows.shape[0])], repeats)
    print(f"   the model alone on {rows.shape[0]} points: one batch {t_batch / rows.shape[0] * 1e9:.0f} ns/eval, "
          f"one call per point {t_points / rows.shape[0] * 1e9:.0f} ns/eval")


def gp_comparison(repeats, quick):
    from sklearn.gaussian_process import GaussianProcessRegressor
    from sklearn.gaussian_process.kernels import RBF, ConstantKernel, WhiteKernel

    print()
    print("2. iuq.GaussianProcess vs scikit-learn GaussianProcessRegressor (same data, kernel, "
          f"bounds, 10 restarts; medians of {repeats} runs)")
    print(f"{'n x d':<9} {'fit iuq':>9} {'fit sklearn':>12} {'ratio':>7} {'predict iuq':>12} "
          f"{'predict sklearn':>16} {'ratio':>7} {'LML iuq':>10} {'LML sklearn':>12}")
    rng = np.random.default_rng(0)
    sizes = [(50, 3), (200, 3)] if quick else [(50, 3), (200, 3), (400, 5)]
    n_predict = 10000
    for n, d in sizes:
        x = iuq.design.lhs(n, d, seed=1)
        y = np.sin(3 * x[:, 0]) + x[:, 1] ** 2 + 0.5 * x.sum(axis=1) + 0.01 * rng.standard_normal(n)
        z = (y - y.mean()) / y.std()
        xp = iuq.design.sobol(n_predict, d, seed=3)

        def fit_iuq():
            return iuq.GaussianProcess.fit(x, z, restarts=10, seed=0, scale_inputs=False,
                                           standardize_outputs=False)

        def fit_sklearn():
            kernel = (ConstantKernel(1.0, (1e-3, 1e3)) * RBF(np.ones(d), (1e-2, 1e3))
                      + WhiteKernel(1e-3, (1e-8, 1.0)))
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                return GaussianProcessRegressor(kernel=kernel, n_restarts_optimizer=10,
                                                random_state=0).fit(x, z)

        t_fit_iuq, ours = median_time(fit_iuq, repeats)
        t_fit_sk, theirs = median_time(fit_sklearn, repeats)
        t_pred_iuq, _ = median_time(lambda: ours.predict(xp, return_std=True), repeats)
        t_pred_sk, _ = median_time(lambda: theirs.predict(xp, return_std=True), repeats)
        print(f"{f'{n} x {d}':<9} {t_fit_iuq:>8.3f}s {t_fit_sk:>11.3f}s {t_fit_sk / t_fit_iuq:>7.1f} "
              f"{t_pred_iuq * 1e3:>9.1f} ms {t_pred_sk * 1e3:>13.1f} ms {t_pred_sk / t_pred_iuq:>7.1f} "
              f"{ours.log_marginal_likelihood:>10.3f} {theirs.log_marginal_likelihood_value_:>12.3f}")
    print(f"   (ratio = scikit-learn time / iuq time; predict: mean and std at {n_predict} points)")


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--repeats", type=int, default=5, help="runs per measurement (median)")
    parser.add_argument("--quick", action="store_true", help="smaller sizes (a smoke run)")
    parser.add_argument("--threads", type=int, default=1,
                        help="BLAS and iuq threads (read before numpy loads)")
    args = parser.parse_args()
    print(f"iuq {iuq.__version__}, numpy {np.__version__}, Python {platform.python_version()}, "
          f"{os.cpu_count()} CPUs, {THREADS} thread(s) for BLAS and iuq")
    overhead(args.repeats, args.quick)
    gp_comparison(max(1, args.repeats // 2 + 1), args.quick)


if __name__ == "__main__":
    main()
