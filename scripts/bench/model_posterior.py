#!/usr/bin/env python3
"""Model runs to the model's own posterior (issue: the model posterior, certified): iuq's
importance stages from the surrogate's posterior against plain BASIS on the model and against
two-stage delayed-acceptance MCMC (tinyDA) with the same surrogate as its first stage.

Problems with exact posteriors (the cooling cup of examples/cooling, 2 parameters, 8 data):
  biased    one run per (θ, t), a surrogate trained on a one-shot design of 6 runs per time:
            its posterior is off by about a posterior std;
  failing   as biased, but the model fails for k > 0.305 (beside the posterior's mode), a
            20-run design (two thirds of it fail); the exact posterior is cut there;
  curve     one run per θ returning the whole curve (8 outputs), a 6-run design.
The exact posterior is BASIS on the closed form with N = 40,000 and 10 burn-in steps.

For each method the figure is the model evaluations (parameter vectors; for one run per (θ, t)
multiply by 8 for runs) needed to bring every posterior mean within 0.1 exact std and every std
within 10 %:
  (i)   iuq pipeline --model-posterior at S = 50, 100, 200, 400 members: the smallest S that
        holds, certified, for all 3 seeds; its evaluations (the reproducibility probe's
        included), plus the surrogate's design runs (beside);
  (ii)  iuq basis on the model, chains of one step without burn-in (the published study), and
        with burn = 10, N = 250 … 16,000: the smallest N that holds for all 3 seeds;
  (iii) tinyDA 0.9's delayed acceptance (subchain length 1) (Christen & Fox 2005): the surrogate (the pipeline's own
        GP bank rebuilt in scikit-learn) screens, the model confirms; adaptive Metropolis
        proposal, one chain from the surrogate posterior's MAP, 20 % burn-in dropped; iterations
        1,000 … 32,000: the smallest that
        holds for all 3 seeds; its model evaluations (confirmations) counted.
Targets: (i) at most 1/20 of (ii)'s evaluations and at most 1/3 of (iii)'s.

Usage: cargo build --release -p iuq && python3 scripts/bench/model_posterior.py [--quick]
       (needs numpy; tinyDA and ray for (iii): pip install -r scripts/bench/requirements-model-posterior.txt)
Environment: IUQ_BIN overrides the binary (default target/release/iuq).
"""
import argparse
import contextlib
import json
import os
import shutil
import subprocess
import sys
import tempfile
import warnings

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
IUQ = os.environ.get("IUQ_BIN", os.path.join(ROOT, "target", "release", "iuq"))
DATA = os.path.join(ROOT, "examples", "cooling", "cooling.csv")
TIMES = [0.5, 1, 2, 3, 4, 6, 8, 10]
CURVE = "20 + (T0 - 20) * exp(-k * {t})"
FAIL = " + 0 * sqrt(0.305 - k)"
PARAMETERS = ["k", "T0"]
PRIOR = {"k": (0.05, 0.8), "T0": (60.0, 100.0)}

PROBLEMS = {
    "biased": {"shape": "per_time", "design": 6, "fails": False},
    "failing": {"shape": "per_time", "design": 20, "fails": True},
    "curve": {"shape": "curve", "design": 6, "fails": False},
}


def iuq(*args, cwd=None):
    out = subprocess.run([IUQ, *map(str, args), "--json"], capture_output=True, text=True, cwd=cwd)
    if out.returncode != 0:
        sys.exit(f"iuq {' '.join(map(str, args))} failed: {out.stderr[-2000:]}")
    return json.loads(out.stdout)


def header(name):
    return (f'name = "{name}"\n[parameters]\nk = {{ uniform = [0.05, 0.8] }}\nT0 = {{ uniform = [60, 100] }}\n'
            f'[likelihood]\ndata = {{ file = "{DATA}", x = "t_min", y = "temperature_c", '
            f'y_err = "temperature_err_c" }}\nmodelling_error = false\n')


def exact_study(problem):
    fail = FAIL if PROBLEMS[problem]["fails"] else ""
    return header(f"exact-{problem}") + f'prediction = "{CURVE.format(t="x")}{fail}"\n'


def model_section(problem):
    p = PROBLEMS[problem]
    fail = FAIL if p["fails"] else ""
    if p["shape"] == "per_time":
        return f'[model]\nkind = "expression"\nabscissa = "t"\noutputs = {{ T = "{CURVE.format(t="t")}{fail}" }}\n'
    outputs = ", ".join(f'T{i} = "{CURVE.format(t=t)}{fail}"' for i, t in enumerate(TIMES))
    return f'[model]\nkind = "expression"\noutputs = {{ {outputs} }}\n'


def pipeline_study(problem, samples, seed):
    p = PROBLEMS[problem]
    return (header(f"mp-{problem}") + model_section(problem)
            + f'[surrogate]\ndesign = {{ kind = "lhs", n = {p["design"]}, seed = 1 }}\ntest = {{ kind = "sobol", n = 0 }}\n'
            + '[sampler]\nsamples = 4000\nburn = 10\nseed = 1\n'
            + f'[model_posterior]\nsamples = {samples}\nseed = {seed}\n')


def accurate(mean, std, exact):
    return all(abs(mean[k] - exact[0][k]) <= 0.1 * exact[1][k] and abs(std[k] / exact[1][k] - 1) <= 0.1
               for k in PARAMETERS)


def exact_posterior(work, problem):
    path = os.path.join(work, f"exact-{problem}.toml")
    with open(path, "w") as f:
        f.write(exact_study(problem) + "[sampler]\nsamples = 40000\nburn = 10\nseed = 1\n")
    v = iuq("basis", path, "--out", os.path.join(work, f"exact-{problem}"))
    return v["mean"], v["std"]


def bench_iuq(work, problem, exact, sizes, seeds):
    for samples in sizes:
        results = []
        for seed in seeds:
            d = os.path.join(work, f"iuq-{problem}-{samples}-{seed}")
            os.makedirs(d, exist_ok=True)
            path = os.path.join(d, "study.toml")
            with open(path, "w") as f:
                f.write(pipeline_study(problem, samples, seed))
            v = iuq("pipeline", path, "--model-posterior", "--out", os.path.join(d, "out"))
            m = v["model_posterior"]
            # The probe's nudged evaluations are part of the method (they decide whether the
            # outputs repeat); an accurate but uncertified result does not count as reached.
            probe = (m.get("probe") or {}).get("model_evaluations", 0)
            results.append((accurate(m["mean"], m["std"], exact) and m["certified"],
                            m["model_evaluations"] + probe, m["certified"], v["runs"], m["pareto_k"]))
        if all(r[0] for r in results):
            return samples, max(r[1] for r in results), results[0][3], results
    return None, None, None, results


def bench_basis(work, problem, exact, burn, sizes, seeds):
    path = os.path.join(work, f"basis-{problem}.toml")
    with open(path, "w") as f:
        f.write(exact_study(problem))
    for n in sizes:
        runs = []
        for seed in seeds:
            v = iuq("basis", path, "--samples", n, "--burn", burn, "--seed", seed,
                    "--out", os.path.join(work, f"basis-{problem}-{burn}-{n}-{seed}"))
            runs.append((accurate(v["mean"], v["std"], exact), v["evaluations"]))
        if all(r[0] for r in runs):
            return n, max(r[1] for r in runs)
    return None, None


class SurrogateBank:
    """The pipeline's GP bank (gp-bank.json) in scikit-learn: fixed kernels, as iuq fitted them."""

    def __init__(self, path):
        from sklearn.gaussian_process import GaussianProcessRegressor
        from sklearn.gaussian_process.kernels import RBF, ConstantKernel, WhiteKernel

        with open(path) as f:
            bank = json.load(f)
        self.gps = []
        for g in bank["gps"]:
            h = g["hyperparameters"]
            lower = np.array(g["input_scaling"]["lower"])
            scale = np.array(g["input_scaling"]["range"])
            x = (np.array(g["training_inputs"]) - lower) / scale
            kernel = (ConstantKernel(h["signal_variance"], "fixed") * RBF(h["length_scales"], "fixed")
                      + WhiteKernel(h["noise_variance"], "fixed"))
            gp = GaussianProcessRegressor(kernel, alpha=g["jitter"], optimizer=None, normalize_y=True)
            gp.fit(x, np.array(g["training_outputs"]))
            self.gps.append((gp, lower, scale))

    def predict(self, theta):
        x = np.atleast_2d(theta)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            out = [gp.predict((x - lo) / sc, return_std=True) for gp, lo, sc in self.gps]
        return np.array([m[0] for m, _ in out]), np.array([s[0] for _, s in out])


def bench_tinyda(work, problem, exact, sizes, seeds):
    try:
        import tinyDA as tda
        from scipy.stats import uniform
    except ImportError as e:
        return None, None, f"tinyDA not installed ({e})"
    with open(DATA) as f:
        lines = [line for line in f if line.strip() and not line.startswith("#")]
    data = np.array([[float(v) for v in line.split(",")] for line in lines[1:]])
    t, y, sd = data[:, 0], data[:, 1], data[:, 2]
    # The surrogate of the iuq run at the largest S (its design and GP bank are the same at every S).
    gp_file = None
    for root, _, files in os.walk(work):
        if "gp-bank.json" in files and f"iuq-{problem}-" in root:
            gp_file = os.path.join(root, "gp-bank.json")
            break
    if gp_file is None:
        return None, None, "no GP bank"
    bank = SurrogateBank(gp_file)
    # The chain starts where the surrogate's posterior has its MAP, as iuq's method starts from
    # the surrogate's posterior (not from the exact posterior, which a user does not have).
    with open(os.path.join(os.path.dirname(gp_file), "basis-gp", "summary.json")) as f:
        surrogate_map_by_name = json.load(f)["map"]
    surrogate_map = np.array([surrogate_map_by_name[p] for p in PARAMETERS])
    fails = PROBLEMS[problem]["fails"]

    class Fine:
        evaluations = 0

        def __call__(self, theta):
            Fine.evaluations += 1
            k, t0 = theta
            if fails and k > 0.305:
                return np.full(len(t), np.nan)
            return 20 + (t0 - 20) * np.exp(-k * t)

    def coarse(theta):
        mean, std = bank.predict(theta)
        return np.concatenate([mean, std])

    class FineLikelihood:
        def loglike(self, out):
            if not np.all(np.isfinite(out)):
                return -np.inf
            return -0.5 * np.sum(((out - y) / sd) ** 2)

    class CoarseLikelihood:
        def loglike(self, out):
            mean, std = out[:len(t)], out[len(t):]
            var = sd ** 2 + std ** 2
            return -0.5 * np.sum((mean - y) ** 2 / var + np.log(var))

    class Prior:
        def logpdf(self, x):
            inside = all(PRIOR[p][0] <= v <= PRIOR[p][1] for p, v in zip(PARAMETERS, x))
            return 0.0 if inside else -np.inf

        def rvs(self, size=None):
            return np.array([uniform(PRIOR[p][0], PRIOR[p][1] - PRIOR[p][0]).rvs() for p in PARAMETERS])

    for n in sizes:
        ok, evaluations = [], []
        for seed in seeds:
            np.random.seed(seed)
            Fine.evaluations = 0
            posteriors = [tda.Posterior(Prior(), CoarseLikelihood(), coarse),
                          tda.Posterior(Prior(), FineLikelihood(), Fine())]
            proposal = tda.AdaptiveMetropolis(C0=np.diag([0.01 ** 2, 1.0 ** 2]), adaptive=True)
            start = surrogate_map
            with warnings.catch_warnings(), open(os.devnull, "w") as quiet, \
                    contextlib.redirect_stderr(quiet):
                warnings.simplefilter("ignore")
                chain = tda.sample(posteriors, proposal, iterations=n, n_chains=1, initial_parameters=start,
                                   subchain_length=1, force_sequential=True, store_coarse_chain=False)
            fine = chain["chain_fine_0"]
            samples = np.array([link.parameters for link in fine])[n // 5:]
            mean = dict(zip(PARAMETERS, samples.mean(axis=0)))
            std = dict(zip(PARAMETERS, samples.std(axis=0)))
            ok.append(accurate(mean, std, exact))
            evaluations.append(Fine.evaluations)
        if all(ok):
            return n, max(evaluations), ""
    return None, None, "not reached"


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="one seed per setting")
    parser.add_argument("--problems", default=",".join(PROBLEMS))
    parser.add_argument("--work", default=None)
    parser.add_argument("--only-iuq", action="store_true",
                        help="iuq's figure only (after a change to the model posterior; the references "
                             "do not depend on it)")
    args = parser.parse_args()
    if not os.path.exists(IUQ):
        sys.exit(f"{IUQ} not found: run `cargo build --release -p iuq` first")
    seeds = [1] if args.quick else [1, 2, 3]
    work = args.work or tempfile.mkdtemp(prefix="iuq-model-posterior-")
    os.makedirs(work, exist_ok=True)
    rows = []
    for problem in args.problems.split(","):
        exact = exact_posterior(work, problem)
        s, ev, design, detail = bench_iuq(work, problem, exact, [50, 100, 200, 400], seeds)
        if args.only_iuq:
            b0 = b10 = (None, None)
            da = (None, None, "not run (--only-iuq)")
        else:
            b0 = bench_basis(work, problem, exact, 0, [250, 500, 1000, 2000, 4000, 8000, 16000], seeds)
            b10 = bench_basis(work, problem, exact, 10, [250, 500, 1000, 2000, 4000, 8000], seeds)
            da = bench_tinyda(work, problem, exact, [1000, 2000, 4000, 8000, 16000, 32000], seeds)
        rows.append((problem, s, ev, design, b0, b10, da, detail))
        print(f"{problem}: iuq S = {s} ({ev} evaluations + {design} design runs); "
              f"BASIS burn 0 N = {b0[0]} ({b0[1]}); burn 10 N = {b10[0]} ({b10[1]}); "
              f"tinyDA {da[0]} iterations ({da[1]} model evaluations) {da[2]}; "
              f"iuq detail (accurate, evaluations, certified, runs, k̂) {detail}", flush=True)
    print()
    print("model evaluations to every mean within 0.1 std and every std within 10 % of the exact posterior"
          f" ({len(seeds)} seed{'s' if len(seeds) > 1 else ''} each)")
    print(f"{'problem':<10}{'iuq reweight':>14}{'(+ design)':>12}{'BASIS burn 0':>14}{'ratio':>8}"
          f"{'BASIS burn 10':>15}{'ratio':>8}{'tinyDA':>10}{'ratio':>8}")
    for problem, s, ev, design, b0, b10, da, _ in rows:
        def ratio(other):
            return f"{other / ev:.0f}×" if ev and other else "–"
        print(f"{problem:<10}{ev or '–':>14}{design or '–':>12}{b0[1] or '–':>14}{ratio(b0[1]):>8}"
              f"{b10[1] or '–':>15}{ratio(b10[1]):>8}{da[1] or '–':>10}{ratio(da[1]):>8}")
    if args.work is None:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
