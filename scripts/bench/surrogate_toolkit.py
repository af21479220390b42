#!/usr/bin/env python3
"""Side-by-side benchmark of the surrogate toolkit against its Python references.

Runs our kernels (through the `iuq` release binary, timed in-process) and the references
(scikit-learn, SALib, scipy, pyDOE) on the same data in the same script, and prints each pair of
timings with the ratio. Timings are medians of repeats; the machine is noisy, so read ratios.

Usage: cargo build --release -p iuq && python3 scripts/bench/surrogate_toolkit.py [--quick]
       [--record] [--compare]

The performance record: `--record` appends this run's figures (date, commit, CPU, vector
extension the kernels dispatch to, kernel, iuq's and the reference's seconds, ratio) to
docs/benchmarks.csv; `--compare` sets each kernel's time beside the last recorded one on the same
CPU and vector extension and flags any kernel more than 1.5× slower (exit status 1). Times from
different machines are never compared. The record is for developers, not a timed test.
"""
import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
import warnings

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


RECORD = os.path.join(ROOT, "docs", "benchmarks.csv")
RECORD_COLUMNS = ["date", "commit", "cpu", "vector", "kernel", "iuq_seconds", "reference_seconds", "ratio"]
SLOWER = 1.5
RESULTS = []


def row(name, ours, reference, target=None, extra=""):
    ratio = reference / ours if ours > 0 else float("inf")
    RESULTS.append((name, ours, reference, ratio))
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


def bench_gp_bank(work, repeats):
    """The GP bank at the red-cell studies' size inside one BASIS stage: 8 GPs (one per shear
    stress) of 136 runs in 3 parameters, mean and std at 10,000 samples; iuq's figure is the sum
    of the 8 GPs' in-process medians, the reference's that of scikit-learn's predict."""
    from sklearn.gaussian_process import GaussianProcessRegressor
    from sklearn.gaussian_process.kernels import RBF, ConstantKernel, WhiteKernel

    rng = np.random.default_rng(2)
    points = rng.random((10_000, 3))
    pts_file = os.path.join(work, "bank_points.csv")
    np.savetxt(pts_file, points, delimiter=",", header="x1,x2,x3", comments="")
    ours_std = ours_mean = sk_std = sk_mean = 0.0
    for g in range(8):
        x = rng.random((136, 3))
        y = np.tanh((1 + g) * x[:, 0]) * (1 - 0.3 * x[:, 1]) + 0.1 * x[:, 2] ** 2
        train = os.path.join(work, f"bank{g}.csv")
        np.savetxt(train, np.column_stack([x, y]), delimiter=",", header="x1,x2,x3,y", comments="")
        gp_file = os.path.join(work, f"bank{g}.json")
        iuq("gp", "fit", "--data", train, "--inputs", "x1,x2,x3", "--output", "y", "--restarts", 2,
            "--seed", 0, "--out", gp_file)
        pred = iuq("bench", "gp-predict", "--model", gp_file, "--points", pts_file, "--repeats", 5 * repeats)
        ours_std += pred["seconds_median"]
        ours_mean += pred["seconds_mean_median"]
        kernel = ConstantKernel(1.0, (1e-2, 1e2)) * RBF([0.5] * 3, (1e-2, 1e2)) + WhiteKernel(1e-3, (1e-10, 1.0))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            sk = GaussianProcessRegressor(kernel, normalize_y=True, random_state=0).fit(x, y)
        sk_mean += median_time(lambda: sk.predict(points), 5 * repeats)[0]
        sk_std += median_time(lambda: sk.predict(points, return_std=True), 5 * repeats)[0]
    row("GP bank 8x136, 10k points, mean", ours_mean, sk_mean)
    row("GP bank 8x136, 10k points, mean+std", ours_std, sk_std)


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


def machine():
    """The CPU's model name and the widest vector extension iuq's kernels dispatch to."""
    cpu, flags = "unknown", set()
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name") and cpu == "unknown":
                    cpu = line.split(":", 1)[1].strip()
                elif line.startswith("flags"):
                    flags = set(line.split(":", 1)[1].split())
    except OSError:
        pass
    if {"avx512f", "avx2", "fma"} <= flags:
        vector = "avx512"
    elif {"avx2", "fma"} <= flags:
        vector = "avx2"
    else:
        vector = "baseline"
    return cpu, vector


def commit():
    out = subprocess.run(["git", "-C", ROOT, "rev-parse", "--short", "HEAD"], capture_output=True, text=True)
    dirty = subprocess.run(["git", "-C", ROOT, "status", "--porcelain", "--untracked-files=no"],
                           capture_output=True, text=True).stdout.strip()
    return (out.stdout.strip() or "unknown") + ("+dirty" if dirty else "")


def read_record():
    import csv
    if not os.path.exists(RECORD):
        return []
    with open(RECORD, newline="") as f:
        return list(csv.DictReader(f))


def compare_with_record(cpu, vector):
    """Flag kernels more than SLOWER× slower than the last recorded run on this CPU."""
    last = {}
    for r in read_record():
        if r["cpu"] == cpu and r["vector"] == vector:
            last[r["kernel"]] = r
    slower = []
    print(f"\ncompared with {os.path.relpath(RECORD, ROOT)} (same CPU, {vector}):")
    for name, ours, _, _ in RESULTS:
        r = last.get(name)
        if r is None:
            print(f"  {name:<34} no earlier record")
            continue
        before = float(r["iuq_seconds"])
        factor = ours / before if before > 0 else float("inf")
        flag = "  SLOWER" if factor > SLOWER else ""
        print(f"  {name:<34} {before:9.4f} s ({r['commit']}, {r['date']}) -> {ours:9.4f} s  ×{factor:.2f}{flag}")
        if factor > SLOWER:
            slower.append(name)
    return slower


def append_record(cpu, vector):
    import csv
    import datetime
    new = not os.path.exists(RECORD)
    date = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d")
    sha = commit()
    with open(RECORD, "a", newline="") as f:
        w = csv.writer(f)
        if new:
            w.writerow(RECORD_COLUMNS)
        for name, ours, reference, ratio in RESULTS:
            w.writerow([date, sha, cpu, vector, name, f"{ours:.6g}", f"{reference:.6g}", f"{ratio:.3g}"])
    print(f"recorded {len(RESULTS)} kernels in {os.path.relpath(RECORD, ROOT)} at {sha}")


def main():
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--quick", action="store_true", help="fewer repeats")
    parser.add_argument("--record", action="store_true", help="append the figures to docs/benchmarks.csv")
    parser.add_argument("--compare", action="store_true",
                        help=f"flag kernels more than {SLOWER}x slower than the last record on this CPU (exit 1)")
    args = parser.parse_args()
    repeats = 3 if args.quick else 5
    if not os.path.exists(IUQ):
        sys.exit(f"{IUQ} not found: run `cargo build --release -p iuq` first")
    print(f"threads: {os.cpu_count()}; medians of {repeats} repeats; ratio = reference / iuq")
    with tempfile.TemporaryDirectory() as work:
        bench_gp(work, repeats)
        bench_gp_bank(work, repeats)
        bench_sobol(repeats)
        bench_kde(work, repeats)
        bench_lhs(work, repeats)
    cpu, vector = machine()
    slower = compare_with_record(cpu, vector) if args.compare else []
    if args.record:
        append_record(cpu, vector)
    if slower:
        sys.exit(f"more than {SLOWER}x slower than recorded: {', '.join(slower)}")


if __name__ == "__main__":
    main()
