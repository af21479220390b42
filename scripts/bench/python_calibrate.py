#!/usr/bin/env python3
"""Calibrating a Python function: iuq.calibrate against GPry 4.1's Runner on the same
log-likelihood, side by side, on Python models with known posteriors.

    python3 -m venv .venv-adaptive && .venv-adaptive/bin/pip install -r scripts/bench/requirements-adaptive.txt
    .venv-adaptive/bin/pip install ./python
    .venv-adaptive/bin/python scripts/bench/python_calibrate.py [--problems decay,logistic,oscillator] [--skip-gpry]
    .venv-adaptive/bin/python scripts/bench/python_calibrate.py --overhead   # round time at 100-500 runs

Problems (synthetic data from known parameters with Gaussian noise, fixed seeds; flat priors; no
modelling error, so that both methods calibrate the same likelihood):

- decay: y = a·exp(−k t) at 10 times, 2 parameters;
- logistic: a logistic growth integrated by explicit midpoint steps at 12 times, 2 parameters;
  the function raises for r > 1.2, part of the prior next to the posterior (r ≈ 0.8);
- oscillator: a damped oscillator A·exp(−γt)·cos(ωt) at 17 times, 3 parameters.

The exact posterior: `iuq.basis` on the exact log-likelihood with N = 50,000 (the failing region
as rejections). Accurate means every posterior mean within 0.1 exact std and every std within
10 %. Reported per method: model calls (rows evaluated), wall time, whether the final posterior
is accurate and its worst errors. For iuq also the wall time of each adaptive round (the
engine's work per round: GP fits, replicate BASIS samplings, surrogate error, acquisition) and
the bridge's cost per run (the initial design's stage time over its runs: forwarding each run to
the Python thread, the model, which is cheap here, and storing the result).
"""

import argparse
import math
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from gpry_reference import gpry_posterior, raised_initial_budget  # noqa: E402

PROBLEMS = {
    "decay": {
        "priors": {"a": (0.5, 4.0), "k": (0.05, 0.8)},
        "truth": [2.0, 0.3],
        "x": np.linspace(0.5, 8.0, 10),
        "noise": 0.05,
    },
    "logistic": {
        "priors": {"r": (0.1, 2.0), "K": (20.0, 100.0)},
        "truth": [0.8, 50.0],
        "x": np.linspace(1.0, 12.0, 12),
        "noise": 1.0,
        "fails": 1.2,
    },
    "oscillator": {
        "priors": {"A": (0.5, 2.0), "g": (0.05, 0.5), "w": (1.0, 3.0)},
        "truth": [1.2, 0.2, 2.0],
        "x": np.linspace(0.0, 8.0, 17),
        "noise": 0.05,
    },
}


class Fails(Exception):
    """The model gives no answer at these parameters."""


def simulate(problem, theta):
    """(n, d) parameter vectors → (n, m) outputs; raises where the model fails."""
    p = PROBLEMS[problem]
    x = p["x"]
    if problem == "decay":
        return theta[:, :1] * np.exp(-theta[:, 1:2] * x[None, :])
    if problem == "logistic":
        r, K = theta[:, 0], theta[:, 1]
        if np.any(r > p["fails"]):
            raise Fails(f"unstable for r > {p['fails']}")
        f = lambda N: r * N * (1 - N / K)  # noqa: E731
        N, t, out, dt = np.full_like(r, 2.0), 0.0, [], 0.05
        for target in x:
            while t < target - 1e-9:
                N = N + dt * f(N + 0.5 * dt * f(N))
                t += dt
            out.append(N)
        return np.array(out).T
    A, g, w = theta[:, 0:1], theta[:, 1:2], theta[:, 2:3]
    return A * np.exp(-g * x[None, :]) * np.cos(w * x[None, :])


def data(problem):
    p = PROBLEMS[problem]
    rng = np.random.default_rng(sum(map(ord, problem)))
    exact = simulate(problem, np.array([p["truth"]]))[0]
    return exact + rng.normal(0, p["noise"], exact.size)


def log_likelihood(problem, y, theta):
    """ln f(D | θ) of each row (−∞ where the model fails), in one vectorised call."""
    p = PROBLEMS[problem]
    theta = np.asarray(theta, dtype=np.float64)
    out = np.full(len(theta), -np.inf)
    ok = np.ones(len(theta), dtype=bool)
    if "fails" in p:
        ok = theta[:, 0] <= p["fails"]
    if ok.any():
        q = simulate(problem, theta[ok])
        out[ok] = -0.5 * np.sum(((y[None, :] - q) / p["noise"]) ** 2, axis=1)
    return out


def truth(problem, y):
    import iuq

    p = PROBLEMS[problem]
    post = iuq.basis(lambda t: log_likelihood(problem, y, t), p["priors"], samples=50000, seed=5)
    return post.mean, post.std


def judge(mean, std, exact):
    m0, s0 = exact
    dm = float(np.max(np.abs(np.asarray(mean) - m0) / s0))
    ds = float(np.max(np.abs(np.asarray(std) / s0 - 1)))
    return dm < 0.1 and ds < 0.1, dm, ds


def run_iuq(problem, y):
    import iuq

    p = PROBLEMS[problem]
    calls = [0]

    def model(theta):
        calls[0] += len(theta)
        return simulate(problem, theta)

    started = time.time()
    r = iuq.calibrate(
        model, p["priors"], y, np.full(y.size, p["noise"]), x=p["x"], modelling_error=None,
        samples=20000, seed=1, progress=False, sensitivity=0,
    )
    seconds = time.time() - started
    stages = {s["stage"]: s["seconds"] for s in r.raw["stage_seconds"]}
    # The initial design's stage: its runs forwarded, evaluated (a cheap model here) and stored.
    bridge = stages.get("initial and test runs", float("nan")) / max(6, len(p["priors"]) + 2)
    return calls[0], r.mean, r.std, seconds, [round(x["seconds"], 1) for x in r.rounds], bridge, r.converged


def run_gpry(problem, y, options=None):
    """GPry on the problem's exact log-likelihood: (calls, mean, std, seconds)."""
    p = PROBLEMS[problem]
    names = list(p["priors"])

    def ll(theta):
        return float(log_likelihood(problem, y, np.asarray([theta]))[0])

    return gpry_posterior(ll, names, [p["priors"][n] for n in names], seed=1, options=options)


def overhead(sizes):
    """iuq's own time per adaptive round with n runs already made (the decay problem, an
    initial design of n runs, one round): the round's wall time (GP fits on n runs, the
    replicate BASIS samplings, the surrogate error, the acquisition) and the bridge per run."""
    import iuq

    p = PROBLEMS["decay"]
    y = data("decay")
    print("\n| runs | round 1 (s) | initial design stage per run (ms) |")
    print("|---|---|---|")
    for n in sizes:
        r = iuq.calibrate(
            lambda t: simulate("decay", t), p["priors"], y, np.full(y.size, p["noise"]), x=p["x"],
            modelling_error=None, initial_runs=n, max_runs=n + 2, samples=2000, seed=1,
            progress=False, sensitivity=0,
        )
        stages = {s["stage"]: s["seconds"] for s in r.raw["stage_seconds"]}
        first = r.rounds[0]["seconds"] if r.rounds else float("nan")
        print(f"| {n} | {first:.2f} | {1000 * stages['initial and test runs'] / n:.2f} |", flush=True)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--problems", default=",".join(PROBLEMS))
    parser.add_argument("--skip-gpry", action="store_true")
    parser.add_argument("--overhead", action="store_true", help="only the round time at 100, 250 and 500 runs")
    args = parser.parse_args()
    if args.overhead:
        overhead([100, 250, 500])
        return
    rows = []
    for problem in args.problems.split(","):
        y = data(problem)
        exact = truth(problem, y)
        print(f"\n{problem}: exact mean {np.round(exact[0], 4)}, std {np.round(exact[1], 4)}", flush=True)
        calls, mean, std, seconds, rounds, bridge, converged = run_iuq(problem, y)
        ok, dm, ds = judge(mean, std, exact)
        print(f"  iuq.calibrate: {calls} calls, accurate {ok} (mean {dm:.3f} std, std {100 * ds:.1f} %), "
              f"{seconds:.0f} s, rounds {rounds} s, bridge {1000 * bridge:.1f} ms per run, converged {converged}", flush=True)
        rows.append((problem, "iuq.calibrate", calls, ok, dm, ds, seconds,
                     f"median round {np.median(rounds):.1f} s; bridge {1000 * bridge:.1f} ms/run"))
        if not args.skip_gpry:
            try:
                calls, mean, std, seconds = run_gpry(problem, y)
                ok, dm, ds = judge(mean, std, exact)
                rows.append((problem, "GPry Runner", calls, ok, dm, ds, seconds, "default settings"))
                print(f"  GPry: {calls} calls, accurate {ok} (mean {dm:.3f} std, std {100 * ds:.1f} %), {seconds:.0f} s", flush=True)
            except Exception as e:  # report, do not hide
                rows.append((problem, "GPry Runner", "failed", False, math.nan, math.nan, math.nan, repr(e)[:100]))
                print(f"  GPry failed: {e!r}", flush=True)
                options = raised_initial_budget(e, len(PROBLEMS[problem]["priors"]))
                if options is not None:
                    max_initial = options["max_initial"]
                    try:
                        calls, mean, std, seconds = run_gpry(problem, y, options)
                        ok, dm, ds = judge(mean, std, exact)
                        rows.append((problem, f"GPry, max_initial = {max_initial}", calls, ok, dm, ds, seconds, ""))
                        print(f"  GPry (max_initial {max_initial}): {calls} calls, accurate {ok} (mean {dm:.3f} std, std {100 * ds:.1f} %), {seconds:.0f} s", flush=True)
                    except Exception as e2:  # report, do not hide
                        rows.append((problem, "GPry, max_initial raised", "failed", False, math.nan, math.nan, math.nan, repr(e2)[:100]))
                        print(f"  GPry (max_initial raised) failed: {e2!r}", flush=True)
    print("\n| problem | method | model calls | accurate | worst mean error (stds) | worst std error | wall time (s) | note |")
    print("|---|---|---|---|---|---|---|---|")
    for problem, method, calls, ok, dm, ds, seconds, note in rows:
        print(f"| {problem} | {method} | {calls} | {'yes' if ok else 'no'} | {dm:.3f} | {100 * ds:.1f} % | {seconds:.0f} | {note} |")


if __name__ == "__main__":
    main()
