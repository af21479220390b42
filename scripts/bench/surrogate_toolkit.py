#!/usr/bin/env python3
"""Side-by-side benchmark of the surrogate toolkit against its Python references.

Runs our kernels (through the `iuq` release binary, timed in-process) and the references
(scikit-learn, SALib, scipy, pyDOE) on the same data in the same script, and prints each pair of
timings with the ratio. Timings are medians of repeats; the machine is noisy, so read ratios.

Usage: cargo build --release -p iuq && python3 scripts/bench/surrogate_toolkit.py [--quick]
"""
import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
IUQ = os.environ.get("IUQ_BIN", os.path.join(ROOT, "target", "release", "iuq"))


def iuq(*args):
    out = subprocess.run([IUQ, *map(str, args), "--json"], capture_output=True, text=True)
    if out.returncode != 0:
        sys.exit(f"iuq {' '.join(map(str, args))} failed: {out.stderr}")
    return json.loads(out.stdout)


def median_time(fn, repeats):
    times = []
    result = None
    for _ in range(repeats):
        start = time.perf_counter()
        result = fn()
        times.append(time.perf_counter() - start)
    return float(np.median(times)), result


def row(name, ours, reference, target=None, extra=""):
    ratio = reference / ours if ours > 0 else float("inf")
    goal = f" (target ≥ {target}×)" if target else ""
    print(f"{name:<34} iuq {ours:9.4f} s   reference {reference:9.4f} s   ratio {ratio:7.1f}×{goal}{extra}")
    return ratio


def smooth_function(x):
    return np.sin(2 * np.pi * x[:, 0]) + x[:, 1] ** 2 + 0.5 * x[:, 2] + 0.01 * np.sin(37 * np.arange(len(x)))


def bench_gp(work, repeats):
    from sklearn.gaussian_process import GaussianProcessRegressor
    from sklearn.gaussian_process.kernels import RBF, ConstantKernel, WhiteKernel

    rng = np.random.default_rng(1)
    x = rng.random((500, 3))
    y = smooth_function(x)
    train = os.path.join(work, "train.csv")
    np.savetxt(train, np.column_stack([x, y]), delimiter=",", header="x1,x2,x3,y", comments="")
    gp_file = os.path.join(work, "gp.json")
    ours = [iuq("gp", "fit", "--data", train, "--inputs", "x1,x2,x3", "--output", "y",
                "--restarts", 10, "--seed", r, "--out", gp_file) for r in range(repeats)]
    ours_seconds = float(np.median([o["seconds"] for o in ours]))
    ours_lml = ours[-1]["log_marginal_likelihood"]

    def sklearn_fit():
        kernel = ConstantKernel(1.0, (1e-2, 1e2)) * RBF([0.5] * 3, (1e-2, 1e2)) + WhiteKernel(1e-3, (1e-10, 1.0))
        return GaussianProcessRegressor(kernel, n_restarts_optimizer=10, normalize_y=True,
                                        random_state=0).fit(x, y)

    sk_seconds, sk = median_time(sklearn_fit, max(1, repeats // 2))
    sk_lml = sk.log_marginal_likelihood_value_
    row("GP fit n=500 d=3, 10 restarts", ours_seconds, sk_seconds, 20,
        f"   LML iuq {ours_lml:.4f} vs sklearn {sk_lml:.4f}")

    points = rng.random((100_000, 3))
    pts_file = os.path.join(work, "points.csv")
    np.savetxt(pts_file, points, delimiter=",", header="x1,x2,x3", comments="")
    pred = iuq("bench", "gp-predict", "--model", gp_file, "--points", pts_file, "--repeats", repeats)
    sk_mean_s, _ = median_time(lambda: sk.predict(points), repeats)
    sk_std_s, _ = median_time(lambda: sk.predict(points, return_std=True), max(1, repeats // 2))
    row("GP predict 100k, mean only", pred["seconds_mean_median"], sk_mean_s, 50)
    row("GP predict 100k, mean + std", pred["seconds_median"], sk_std_s, 50)


def bench_sobol(repeats):
    from SALib.analyze import sobol as sobol_analyze
    from SALib.sample import sobol as sobol_sample

    study = os.path.join(ROOT, "examples", "ishigami.toml")
    n = 2 ** 14
    ours = [iuq("sobol", study, "--n", n, "--seed", r) for r in range(repeats)]
    ours_seconds = float(np.median([o["seconds"] for o in ours]))
    problem = {"num_vars": 3, "names": ["x1", "x2", "x3"], "bounds": [[-np.pi, np.pi]] * 3}

    def salib():
        x = sobol_sample.sample(problem, n, calc_second_order=False, seed=1)
        y = np.sin(x[:, 0]) + 7 * np.sin(x[:, 1]) ** 2 + 0.1 * x[:, 2] ** 4 * np.sin(x[:, 0])
        return sobol_analyze.analyze(problem, y, calc_second_order=False, num_resamples=100, seed=1)

    sa_seconds, sa = median_time(salib, repeats)
    exact = np.array([0.313905191147811, 0.442411144790041, 0.0])
    ours_s1 = np.array([ours[-1]["outputs"]["f"]["S1"][k] for k in ("x1", "x2", "x3")])
    row("Sobol' indices N=2^14 (Ishigami)", ours_seconds, sa_seconds, None,
        f"   |S1 err| iuq {np.abs(ours_s1 - exact).max():.4f} SALib {np.abs(sa['S1'] - exact).max():.4f}")


def bench_kde(work, repeats):
    from scipy.stats import gaussian_kde

    rng = np.random.default_rng(0)
    x = rng.multivariate_normal([0, 0], [[1, 0.6], [0.6, 2]], size=10_000)
    pts = os.path.join(work, "kde.csv")
    grid_file = os.path.join(work, "kde_grid.csv")
    np.savetxt(pts, x, delimiter=",", header="a,b", comments="")
    ours = iuq("bench", "kde", "--points", pts, "--grid", 100, "--repeats", repeats, "--out", grid_file)
    grid = np.loadtxt(grid_file, delimiter=",", skiprows=1)

    def scipy_kde():
        return gaussian_kde(x.T)(grid[:, :2].T)

    sp_seconds, density = median_time(scipy_kde, max(1, repeats // 2))
    err = np.max(np.abs(density - grid[:, 2]) / density.max())
    row("2-D KDE 10k points, 100×100 grid", ours["seconds_median"], sp_seconds, 10,
        f"   max |diff|/max = {err:.1e}")


def bench_lhs(work, repeats):
    try:
        from pydoe import lhs  # pyDOE >= 1.6
    except ImportError:
        from pyDOE import lhs

    out = os.path.join(work, "lhs.csv")
    ours = [iuq("design", "lhs", "--n", 500, "--dim", 3, "--method", "optimized", "--seed", r, "--out", out)
            for r in range(repeats)]
    seconds = float(np.median([o["seconds"] for o in ours]))
    distance = float(np.median([o["min_distance"] for o in ours]))

    def min_distance(p):
        d = np.sqrt(((p[:, None, :] - p[None, :, :]) ** 2).sum(-1))
        return d[np.triu_indices(len(p), 1)].min()

    py_seconds, design = median_time(lambda: lhs(3, samples=500, criterion="maximin", seed=0), repeats)
    py100_seconds, design100 = median_time(
        lambda: lhs(3, samples=500, criterion="maximin", iterations=100, seed=0), 1)
    print(f"{'LHS n=500 d=3 (quality, not speed)':<34} iuq ESE {seconds:.3f} s, min distance {distance:.4f} "
          f"(target ≥ 0.06 in < 1 s); pyDOE maximin {min_distance(design):.4f} in {py_seconds:.3f} s, "
          f"100 tries {min_distance(design100):.4f} in {py100_seconds:.2f} s")


def main():
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--quick", action="store_true", help="fewer repeats")
    args = parser.parse_args()
    repeats = 3 if args.quick else 5
    if not os.path.exists(IUQ):
        sys.exit(f"{IUQ} not found: run `cargo build --release -p iuq` first")
    print(f"threads: {os.cpu_count()}; medians of {repeats} repeats; ratio = reference / iuq")
    with tempfile.TemporaryDirectory() as work:
        bench_gp(work, repeats)
        bench_sobol(repeats)
        bench_kde(work, repeats)
        bench_lhs(work, repeats)


if __name__ == "__main__":
    main()
