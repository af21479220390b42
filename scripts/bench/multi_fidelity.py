#!/usr/bin/env python3
"""Two fidelities against one, side by side (a benchmark, not a test): `iuq.calibrate` with a
cheap model (`low_fidelity=`, at declared cost ratios 10, 100 and 1,000), with the expensive
model alone, and with the cheap model alone (its bias), on pairs whose expensive posterior is
known.

    pip install ./python -r scripts/bench/requirements-engine.txt
    python3 scripts/bench/multi_fidelity.py [--pairs ode,trend,failure,curve] [--ratios 10,100,1000]
    python3 scripts/bench/multi_fidelity.py --json bench-out/multi_fidelity.json

Pairs (synthetic data from known parameters with Gaussian noise, fixed seeds; the likelihood
N(y | f(θ), y_std²)):

- ode: logistic growth y' = r·y·(1 − y/K), y(0) = 0.1, observed at 12 times; expensive: RK4
  with 400 steps; cheap: explicit Euler with 12 steps (a coarse solver of the same ODE);
- trend: A·e^(−kt) + 0.3·sin(kt) at 10 times, one run per time; cheap: A·e^(−kt)·(1 + 0.03t),
  whose trend in t is wrong;
- failure: the same decay as `trend` but the expensive model fails (a non-finite value) for
  k > 0.7 and the cheap one, A·e^(−kt), for A > 8 (different failure regions);
- curve: a damped oscillation A·e^(−γt)·cos(ωt) at 60 times (one run returns the curve); cheap:
  ω off by 1 % (a long curve whose cheap shape drifts).

Reference: a 500 × 500 grid over the box for the 2-parameter pairs, emcee (32 walkers, 4,000
steps after 1,000, thinned by 5) for the 3-parameter curve. Reported per method: expensive runs,
cheap runs, total cost in expensive runs (expensive + cheap / ratio), C2ST against the reference
(`c2st.py`), the largest mean error in reference stds and the std ratios' range, wall time.
"""

import argparse
import json
import math
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from c2st import c2st, moment_errors  # noqa: E402

import iuq  # noqa: E402


def _logistic_rk4(r, k, t, steps):
    y = np.full(r.shape, 0.1)
    h = t[-1] / steps
    out = np.empty((r.size, t.size))
    targets = list(t)
    time_now, j = 0.0, 0
    f = lambda y: r * y * (1 - y / k)  # noqa: E731
    for _ in range(steps + 1):
        while j < len(targets) and targets[j] <= time_now + 1e-12:
            out[:, j] = y
            j += 1
        k1 = f(y)
        k2 = f(y + 0.5 * h * k1)
        k3 = f(y + 0.5 * h * k2)
        k4 = f(y + h * k3)
        y = y + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        time_now += h
    return out


def _logistic_euler(r, k, t, steps):
    y = np.full(r.shape, 0.1)
    h = t[-1] / steps
    grid = np.linspace(0, t[-1], steps + 1)
    path = [y]
    for _ in range(steps):
        y = y + h * r * y * (1 - y / k)
        path.append(y)
    path = np.array(path).T
    return np.array([np.interp(t, grid, p) for p in path])


def pair_ode():
    t = np.linspace(1.0, 12.0, 12)
    fine = lambda th: _logistic_rk4(th[:, 0], th[:, 1], t, 400)  # noqa: E731
    coarse = lambda th: _logistic_euler(th[:, 0], th[:, 1], t, 12)  # noqa: E731
    return dict(name="ode", box=[(0.2, 1.5), (0.5, 3.0)], names=["r", "K"], x=t, truth=[0.7, 2.0],
                noise=0.02, high=fine, low=coarse, per_point=False)


def pair_trend(fail=False):
    t = np.arange(10.0)

    # A failing run is a non-finite value of its row (a batch of runs is one call).
    def high(theta, x):
        y = theta[:, 0] * np.exp(-theta[:, 1] * x) + 0.3 * np.sin(theta[:, 1] * x)
        return np.where(theta[:, 1] > 0.7, np.nan, y) if fail else y

    def low(theta, x):
        if fail:
            y = theta[:, 0] * np.exp(-theta[:, 1] * x)
            return np.where(theta[:, 0] > 8.0, np.nan, y)
        return theta[:, 0] * np.exp(-theta[:, 1] * x) * (1 + 0.03 * x)

    return dict(name="failure" if fail else "trend", box=[(1.0, 10.0), (0.05, 1.0)], names=["A", "k"],
                x=t, truth=[5.0, 0.3], noise=0.05, high=high, low=low, per_point=True)


def pair_curve():
    t = np.linspace(0.1, 6.0, 60)

    def osc(th, scale):
        return th[:, :1] * np.exp(-th[:, 1:2] * t) * np.cos(scale * th[:, 2:3] * t)

    return dict(name="curve", box=[(0.5, 3.0), (0.05, 0.8), (1.0, 3.0)], names=["A", "gamma", "omega"],
                x=t, truth=[1.5, 0.3, 2.0], noise=0.05, high=lambda th: osc(th, 1.0),
                low=lambda th: osc(th, 1.01), per_point=False)


PAIRS = {"ode": pair_ode, "trend": pair_trend, "failure": lambda: pair_trend(fail=True), "curve": pair_curve}


def evaluate(pair, f, theta):
    """f at the rows of theta, a (n, m) array (NaN where the model fails)."""
    if pair["per_point"]:
        return np.array([f(np.repeat(th[None, :], pair["x"].size, 0), pair["x"]) for th in theta])
    return f(theta)


def data(pair, seed=7):
    rng = np.random.default_rng(seed)
    y = evaluate(pair, pair["high"], np.array([pair["truth"]]))[0]
    return y + pair["noise"] * rng.standard_normal(y.size)


def log_likelihood(pair, y, theta):
    pred = evaluate(pair, pair["high"], theta)
    ll = -0.5 * (((y - pred) / pair["noise"]) ** 2).sum(-1)
    return np.where(np.isfinite(ll), ll, -np.inf)


def reference(pair, y, seed=1):
    rng = np.random.default_rng(seed)
    box = np.array(pair["box"])
    if len(box) == 2:
        n = 500
        a = box[0, 0] + (box[0, 1] - box[0, 0]) * (np.arange(n) + 0.5) / n
        b = box[1, 0] + (box[1, 1] - box[1, 0]) * (np.arange(n) + 0.5) / n
        aa, bb = np.meshgrid(a, b, indexing="ij")
        grid = np.column_stack([aa.ravel(), bb.ravel()])
        ll = np.concatenate([log_likelihood(pair, y, chunk) for chunk in np.array_split(grid, 50)])
        w = np.exp(ll - ll.max())
        w /= w.sum()
        idx = rng.choice(w.size, 20000, p=w)
        cell = (box[:, 1] - box[:, 0]) / n
        return grid[idx] + rng.uniform(-0.5, 0.5, (idx.size, 2)) * cell
    import emcee

    def log_post(th):
        if np.any(th < box[:, 0]) or np.any(th > box[:, 1]):
            return -np.inf
        return float(log_likelihood(pair, y, th[None, :])[0])

    walkers = 32
    start = np.array(pair["truth"]) + 1e-3 * rng.standard_normal((walkers, len(box)))
    sampler = emcee.EnsembleSampler(walkers, len(box), log_post)
    # emcee draws from numpy's global state unless given its own: seeded, the reference is the
    # same on every run.
    sampler.random_state = np.random.RandomState(seed).get_state()
    sampler.run_mcmc(start, 5000, progress=False)
    return sampler.get_chain(discard=1000, thin=5, flat=True)


def run(pair, y, model, low=None, ratio=None, seed=1):
    priors = {n: b for n, b in zip(pair["names"], pair["box"])}
    kwargs = dict(x=pair["x"], per_point=pair["per_point"], sensitivity=0, seed=seed, progress=False)
    if low is not None:
        kwargs.update(low_fidelity=low, cost_ratio=ratio)
    with tempfile.TemporaryDirectory() as store:
        started = time.perf_counter()
        result = iuq.calibrate(model, priors, y, np.full(y.size, pair["noise"]), store=store, **kwargs)
        wall = time.perf_counter() - started
        cheap_runs = 0
        cheap_store = Path(store) / "calibration.campaign" / "low-fidelity" / "campaign.sqlite"
        if cheap_store.is_file():
            import sqlite3

            with sqlite3.connect(cheap_store) as db:
                cheap_runs = db.execute("SELECT COUNT(*) FROM runs").fetchone()[0]
    return result, cheap_runs, wall


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--pairs", default=",".join(PAIRS))
    parser.add_argument("--ratios", default="10,100,1000")
    parser.add_argument("--json", default=None, help="also write the table as JSON here (after every row)")
    args = parser.parse_args()
    ratios = [float(r) for r in args.ratios.split(",")]
    rows = []
    header = f"{'pair':8} {'method':22} {'expensive':>9} {'cheap':>6} {'cost':>8} {'c2st':>6} {'mean err':>8} {'stds':>12} {'wall s':>7}"
    print(header)
    for name in args.pairs.split(","):
        pair = PAIRS[name]()
        y = data(pair)
        ref = reference(pair, y)
        cases = [("expensive alone", pair["high"], None, None), ("cheap alone (bias)", pair["low"], None, None)]
        cases += [(f"two fidelities r={r:g}", pair["high"], pair["low"], r) for r in ratios]
        for label, model, low, ratio in cases:
            result, cheap_runs, wall = run(pair, y, model, low, ratio)
            accuracy = c2st(result.samples, ref)
            mean_error, std_ratio = moment_errors(result.samples, ref)
            expensive_runs = 0 if label.startswith("cheap") else result.model_runs
            cost = expensive_runs + (cheap_runs / ratio if ratio else 0.0)
            if label.startswith("cheap"):
                cheap_runs, cost = result.model_runs, math.nan
            row = dict(pair=name, method=label, expensive_runs=expensive_runs, cheap_runs=cheap_runs,
                       cost=cost, c2st=accuracy, mean_error=float(np.max(mean_error)),
                       std_ratio=[float(np.min(std_ratio)), float(np.max(std_ratio))], wall=wall,
                       converged=result.converged)
            rows.append(row)
            print(f"{name:8} {label:22} {expensive_runs:9d} {cheap_runs:6d} {cost:8.1f} {accuracy:6.3f} "
                  f"{row['mean_error']:8.3f} {row['std_ratio'][0]:5.3f}–{row['std_ratio'][1]:5.3f} {wall:7.1f}",
                  flush=True)
            if args.json:
                Path(args.json).parent.mkdir(parents=True, exist_ok=True)
                Path(args.json).write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
