#!/usr/bin/env python3
"""The adaptive engine against PyVBMC 1.5 and GPry 4.1, side by side, on problems with exact or
long-run reference posteriors (a benchmark, not a test: it prints our figures beside theirs).

    pip install ./python -r scripts/bench/requirements-engine.txt
    python3 scripts/bench/engine_vs_peers.py [--problems twoexp,banana,...] [--methods iuq,cli,pyvbmc,gpry]
    python3 scripts/bench/engine_vs_peers.py --iuq-bin target/release/iuq --out bench-out
    python3 scripts/bench/engine_vs_peers.py --methods cli --model-posterior --seed 2

Problems (synthetic data from known parameters, Gaussian noise, fixed seeds; the likelihood is
exactly N(y | f(θ), y_std²), which every method is given):

- twoexp: A·e^(−k1 t) + B·e^(−k2 t) at 20 times, 4 parameters with log-normal priors; the
  posterior is about 10⁻⁶ of the prior's volume;
- banana: outputs (a, b + a²) observed twice each, a with std 1 and b + a² with std 0.1: a curved
  2-parameter posterior;
- logistic: logistic growth at 12 times, 2 parameters; the model raises for r > 1.2 (part of the
  prior next to the posterior, r ≈ 0.8);
- oscillator200: A·e^(−γt)·cos(ωt + φ) at 200 times, 4 parameters;
- linear8: a linear model of 8 parameters (12 outputs, Gaussian prior): its posterior is Gaussian
  and known in closed form;
- decay: a·e^(−k t) at 10 times, 2 uniform parameters.

The reference: the closed form for linear8, quadrature on a grid for the 2-parameter problems
(banana, logistic, decay), otherwise emcee (64 walkers, 6,000 steps after 2,000 of burn-in,
thinned by 10) on the exact log-posterior. Reported per method: model calls, wall
time, seconds per adaptive round (iuq), C2ST against the reference (`c2st.py`: sbibm's 5-fold MLP
test, z-scored by the reference), the largest mean error in reference stds and the std ratios'
range. iuq runs with its defaults (`iuq.calibrate(model, priors, y, y_std, x=x)`, and `iuq
pipeline` on the same study with `[model] kind = "expression"` where the model is a formula);
PyVBMC and GPry on the same log-likelihood with their defaults, PyVBMC with the problem's box as
hard bounds and its central half as plausible bounds, GPry on the box (±4 prior stds for a
normal or log-normal prior).

With `--model-posterior` the CLI also runs `iuq pipeline --model-posterior` and adds a row
`cli+model`: the model's own posterior certified from the surrogate's, the largest mean error
and std ratios of its reported moments against the reference (beside the surrogate's on the
`cli` row; `paired` where they are paired with the surrogate's samples), its model calls counted on top of the surrogate's, and C2ST on a resample of its members by
weight (as many as there are members, so its noise is larger: about ±0.02 at 400 members).
`--seed` seeds every method (default 1).
"""

import argparse
import json
import math
import os
import signal
import subprocess
import sys
import tempfile
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from c2st import c2st, moment_errors  # noqa: E402


class Fails(Exception):
    """The model gives no answer at these parameters."""


def _data(f, truth, noise, seed):
    rng = np.random.default_rng(seed)
    clean = f(np.array([truth]))[0]
    std = np.full(clean.size, noise)
    return clean + rng.normal(0.0, std), std


def _twoexp():
    t = np.linspace(0.25, 10.0, 20)

    def f(th):
        return th[:, :1] * np.exp(-th[:, 1:2] * t) + th[:, 2:3] * np.exp(-th[:, 3:4] * t)

    y, s = _data(f, [2.0, 1.0, 1.0, 0.15], 0.01, 3)
    formula = [f"A*exp(-k1*{float(v)!r}) + B*exp(-k2*{float(v)!r})" for v in t]
    return dict(names=["A", "k1", "B", "k2"],
                priors={"A": {"log_normal": [0.5, 0.5]}, "k1": {"log_normal": [0.0, 0.5]},
                        "B": {"log_normal": [0.0, 0.5]}, "k2": {"log_normal": [-2.0, 0.5]}},
                f=f, x=t, y=y, y_std=s, formula=formula)


def _banana():
    def f(th):
        a, b = th[:, 0], th[:, 1]
        return np.stack([a, b + a * a, a, b + a * a], axis=1)

    # a is known to ±0.7, b + a² to ±0.07: b ≈ y₂ − a², a banana over a's range.
    rng = np.random.default_rng(5)
    s = np.array([1.0, 0.1, 1.0, 0.1])
    y = f(np.array([[0.5, -0.2]]))[0] + rng.normal(0.0, s)
    return dict(names=["a", "b"], priors={"a": (-4.0, 4.0), "b": (-10.0, 4.0)}, f=f,
                x=np.arange(4.0), y=y, y_std=s, formula=["a", "b + a*a", "a", "b + a*a"])


def _logistic():
    t = np.linspace(1.0, 12.0, 12)

    def f(th):
        r, K = th[:, 0], th[:, 1]
        if np.any(r > 1.2):
            raise Fails("unstable for r > 1.2")
        N0 = 2.0
        return K[:, None] / (1.0 + (K[:, None] / N0 - 1.0) * np.exp(-r[:, None] * t))

    y, s = _data(f, [0.8, 50.0], 1.0, 7)
    return dict(names=["r", "K"], priors={"r": (0.1, 2.0), "K": (20.0, 100.0)}, f=f, x=t, y=y,
                y_std=s, formula=None, fails=lambda th: th[:, 0] > 1.2)


def _oscillator200():
    t = np.linspace(0.0, 10.0, 200)

    def f(th):
        A, g, w, p = (th[:, k:k + 1] for k in range(4))
        return A * np.exp(-g * t) * np.cos(w * t + p)

    y, s = _data(f, [1.2, 0.2, 2.0, 0.3], 0.1, 11)
    formula = [f"A*exp(-g*{float(v)!r})*cos(w*{float(v)!r} + p)" for v in t]
    return dict(names=["A", "g", "w", "p"],
                priors={"A": (0.5, 2.0), "g": (0.05, 0.5), "w": (1.0, 3.0), "p": (-1.0, 1.0)},
                f=f, x=t, y=y, y_std=s, formula=formula)


def _linear8():
    rng = np.random.default_rng(13)
    X = rng.normal(size=(12, 8))

    def f(th):
        # Summed left to right, as the CLI's formula below is evaluated: both see the same model
        # outputs to the last bit (`th @ X.T` differs there, and the adaptive path with it).
        out = np.empty((len(th), 12))
        for j in range(12):
            total = X[j, 0] * th[:, 0]
            for k in range(1, 8):
                total = total + X[j, k] * th[:, k]
            out[:, j] = total
        return out

    y, s = _data(f, list(rng.normal(0.0, 1.0, 8)), 0.5, 17)
    names = [f"c{k}" for k in range(8)]
    formula = [" + ".join(f"({float(X[j, k])!r})*c{k}" for k in range(8)) for j in range(12)]
    # Exact posterior: prior N(0, I), likelihood N(y | Xθ, s²I).
    precision = np.eye(8) + X.T @ X / 0.25
    cov = np.linalg.inv(precision)
    mean = cov @ (X.T @ y / 0.25)
    return dict(names=names, priors={n: {"normal": [0.0, 1.0]} for n in names}, f=f,
                x=np.arange(12.0), y=y, y_std=s, formula=formula, exact=(mean, cov))


def _decay():
    t = np.linspace(0.5, 8.0, 10)

    def f(th):
        return th[:, :1] * np.exp(-th[:, 1:2] * t)

    y, s = _data(f, [2.0, 0.3], 0.05, 19)
    return dict(names=["a", "k"], priors={"a": (0.5, 4.0), "k": (0.05, 0.8)}, f=f, x=t, y=y,
                y_std=s, formula=[f"a*exp(-k*{float(v)!r})" for v in t])


PROBLEMS = {"twoexp": _twoexp, "banana": _banana, "logistic": _logistic,
            "oscillator200": _oscillator200, "linear8": _linear8, "decay": _decay}


def log_prior(problem, th):
    """ln π(θ) for (n, d) θ; −∞ outside the support."""
    total = np.zeros(len(th))
    for k, name in enumerate(problem["names"]):
        p, v = problem["priors"][name], th[:, k]
        if isinstance(p, tuple):
            inside = (v >= p[0]) & (v <= p[1])
            total += np.where(inside, -math.log(p[1] - p[0]), -np.inf)
        elif "normal" in p:
            m, sd = p["normal"]
            total += -0.5 * ((v - m) / sd) ** 2 - math.log(sd * math.sqrt(2 * math.pi))
        else:
            m, sd = p["log_normal"]
            with np.errstate(divide="ignore", invalid="ignore"):
                lv = np.log(v)
                total += np.where(v > 0, -0.5 * ((lv - m) / sd) ** 2 - lv - math.log(sd * math.sqrt(2 * math.pi)),
                                  -np.inf)
    return total


def log_likelihood(problem, th):
    """ln N(y | f(θ), y_std²) for (n, d) θ; −∞ where the model fails."""
    th = np.atleast_2d(th)
    out = np.full(len(th), -np.inf)
    ok = np.ones(len(th), bool) if "fails" not in problem else ~problem["fails"](th)
    if ok.any():
        q = problem["f"](th[ok])
        r = (problem["y"] - q) / problem["y_std"]
        out[ok] = -0.5 * np.sum(r * r, axis=1) - np.sum(np.log(problem["y_std"] * math.sqrt(2 * math.pi)))
    return out


def box(problem):
    """Hard bounds for the peers: the uniform range, or ±4 prior stds (in log space for log-normal)."""
    lo, hi = [], []
    for name in problem["names"]:
        p = problem["priors"][name]
        if isinstance(p, tuple):
            a, b = p
        elif "normal" in p:
            m, sd = p["normal"]
            a, b = m - 4 * sd, m + 4 * sd
        else:
            m, sd = p["log_normal"]
            a, b = math.exp(m - 4 * sd), math.exp(m + 4 * sd)
        lo.append(a)
        hi.append(b)
    return np.array(lo), np.array(hi)


def grid_reference(problem, rng, size=20000, n=2001):
    """A sample of a 2-parameter posterior from quadrature: the log-posterior on an n × n grid of
    the prior's box, then on an n × n grid of the box where the first grid's density exceeds
    1e-14 of its largest (widened by two cells), cells drawn by their mass and a point uniform in
    the cell. Exact up to the grid's resolution (a thin curved posterior, such as the banana's
    b ≈ y − a² ± 0.07, keeps tens of cells across its width), where a long emcee run of the
    banana came out with b's std 6 % narrow."""
    lo, hi = box(problem)
    for _ in range(2):
        axes = [np.linspace(lo[k], hi[k], n) for k in range(2)]
        a, b = np.meshgrid(*axes, indexing="ij")
        th = np.column_stack([a.ravel(), b.ravel()])
        lp = log_prior(problem, th)
        ll = np.full(len(th), -np.inf)
        inside = np.isfinite(lp)
        ll[inside] = log_likelihood(problem, th[inside])
        logp = (lp + ll).reshape(n, n)
        keep = logp > logp.max() + math.log(1e-14)
        cell = [(hi[k] - lo[k]) / (n - 1) for k in range(2)]
        rows, cols = np.nonzero(keep)
        lo = [max(lo[0], axes[0][rows.min()] - 2 * cell[0]), max(lo[1], axes[1][cols.min()] - 2 * cell[1])]
        hi = [min(hi[0], axes[0][rows.max()] + 2 * cell[0]), min(hi[1], axes[1][cols.max()] + 2 * cell[1])]
    w = np.exp(logp.ravel() - logp.max())
    pick = rng.choice(len(w), size, p=w / w.sum())
    return th[pick] + (rng.random((size, 2)) - 0.5) * np.array(cell)


def reference(problem, seed=1):
    """The reference posterior sample: the closed form, quadrature for 2 parameters, or a long
    emcee run."""
    rng = np.random.default_rng(seed)
    if "exact" in problem:
        mean, cov = problem["exact"]
        return rng.multivariate_normal(mean, cov, size=20000)
    if len(problem["names"]) == 2:
        return grid_reference(problem, rng)
    import emcee

    d = len(problem["names"])

    def log_post(th):
        return log_prior(problem, th) + np.where(np.isfinite(log_prior(problem, th)), log_likelihood(problem, th), -np.inf)

    # Start around the best of 20,000 prior-box draws.
    lo, hi = box(problem)
    draws = lo + (hi - lo) * rng.random((20000, d))
    best = draws[np.argmax(log_post(draws))]
    walkers = 64
    start = best + 1e-3 * (hi - lo) * rng.normal(size=(walkers, d))
    start = np.clip(start, lo, hi)
    sampler = emcee.EnsembleSampler(walkers, d, log_post, vectorize=True)
    # emcee draws from numpy's global state unless given its own: seeded, the reference is the
    # same on every run.
    sampler.random_state = np.random.RandomState(seed).get_state()
    sampler.run_mcmc(start, 8000, progress=False)
    return sampler.get_chain(discard=2000, thin=10, flat=True)


def score(samples, ref):
    mean_error, std_ratio = moment_errors(samples, ref)
    return dict(c2st=c2st(samples, ref), mean_error=float(mean_error.max()),
                std_ratio=(float(std_ratio.min()), float(std_ratio.max())))


def run_iuq(problem, seed=1):
    import iuq

    calls = [0]

    def model(th):
        calls[0] += len(th)
        return problem["f"](th)

    started = time.time()
    result = iuq.calibrate(model, problem["priors"], problem["y"], problem["y_std"], x=problem["x"], seed=seed,
                           progress=False)
    wall = time.time() - started
    rounds = [r["seconds"] for r in result.rounds]
    return dict(calls=calls[0], wall=wall, rounds=rounds, converged=result.converged,
                samples=result.samples[:, :len(problem["names"])],
                evaluations=[r.get("surrogate_evaluations", 0) for r in result.rounds])


def _toml_prior(p):
    if isinstance(p, tuple):
        return f"{{ uniform = [{p[0]!r}, {p[1]!r}] }}"
    (kind, args), = p.items()
    return f"{{ {kind} = [{', '.join(repr(float(a)) for a in args)}] }}"


def write_study(problem, workdir, name, surrogate, sampler):
    """The problem as an `iuq pipeline` study in `workdir` (its data in data.csv, the model as
    expressions, one output per data row), with the `[surrogate]` and `[sampler]` lines given;
    returns the study file's path."""
    os.makedirs(workdir, exist_ok=True)
    with open(os.path.join(workdir, "data.csv"), "w") as f:
        f.write("x,y,y_err\n")
        for a, b, c in zip(problem["x"], problem["y"], problem["y_std"]):
            f.write(f"{float(a)!r},{float(b)!r},{float(c)!r}\n")
    outputs = ", ".join(f'y{j} = "{e}"' for j, e in enumerate(problem["formula"]))
    lines = [f'name = "{name}"', "[parameters]"]
    lines += [f"{n} = {_toml_prior(problem['priors'][n])}" for n in problem["names"]]
    lines += ["[likelihood]", 'data = { file = "data.csv", x = "x", y = "y", y_err = "y_err" }',
              "[model]", 'kind = "expression"', f"outputs = {{ {outputs} }}",
              "[surrogate]", *surrogate, "[sampler]", *sampler]
    study = os.path.join(workdir, "study.toml")
    with open(study, "w") as f:
        f.write("\n".join(lines) + "\n")
    return study


def run_cli(problem, binary, workdir, seed=1, model_posterior=False, adaptive="{}"):
    if problem["formula"] is None:
        return None
    # The CLI's adaptive defaults are iuq.calibrate's (max(6, d + 2) initial runs, batch 2,
    # max_runs 300).
    study = write_study(problem, workdir, "bench", [f"adaptive = {adaptive}"], [f"seed = {seed}"])
    if model_posterior:
        with open(study, "a") as f:
            f.write(f"[model_posterior]\nseed = {seed}\n")
    started = time.time()
    command = [binary, "pipeline", study, "--out", os.path.join(workdir, "out"), "--json"]
    done = subprocess.run(command + (["--model-posterior"] if model_posterior else []),
                          capture_output=True, text=True, timeout=1800)
    wall = time.time() - started
    if done.returncode != 0:
        return dict(error=done.stderr.strip().splitlines()[-1:])
    summary = json.loads(done.stdout)
    d = len(problem["names"])
    samples = np.loadtxt(os.path.join(workdir, "out", "basis-gp", "samples.csv"), delimiter=",", skiprows=1)
    with open(os.path.join(workdir, "out", "adaptive", "rounds.json")) as f:
        rounds = json.load(f)
    rounds = rounds if isinstance(rounds, list) else rounds["rounds"]
    m = summary.get("model_posterior")
    # `runs` counts the surrogate's runs; the model posterior's are in its own `model_runs`.
    row = dict(calls=summary.get("runs"), wall=wall,
               rounds=[r["seconds"] for r in rounds], converged=summary.get("converged"), samples=samples[:, :d])
    if m:
        members = np.loadtxt(os.path.join(workdir, "out", "model-posterior", "samples.csv"), delimiter=",",
                             skiprows=1)
        theta, w = members[:, :d], members[:, d]
        w = w / w.sum()
        # Systematic resampling by weight: as many equally weighted samples as members.
        u = (np.random.default_rng(seed).random() + np.arange(len(w))) / len(w)
        resampled = theta[np.minimum(np.searchsorted(np.cumsum(w), u), len(w) - 1)]
        # The estimate's moments as the summary reports them (a paired estimate's where `paired`).
        names = problem["names"]
        row["model_posterior"] = dict(calls=m.get("model_runs"), certified=m.get("certified"), theta=theta, weights=w,
                                      resampled=resampled, paired=m.get("paired", False),
                                      mean=np.array([m["mean"][n] for n in names]),
                                      std=np.array([m["std"][n] for n in names]),
                                      max_mcse=max(m["mcse_mean"][n] / m["std"][n] for n in names))
    return row


def weighted_score(resampled, ref, m, s):
    """The estimate's largest mean error (reference stds) and std ratios from its reported
    moments `m`, `s`, and C2ST on the resample of its weighted members."""
    mean, std = ref.mean(axis=0), ref.std(axis=0)
    ratio = s / std
    return dict(c2st=c2st(resampled, ref), mean_error=float((np.abs(m - mean) / std).max()),
                std_ratio=(float(ratio.min()), float(ratio.max())))


def run_pyvbmc(problem, seed=1):
    from pyvbmc import VBMC

    calls = [0]
    lo, hi = box(problem)

    def log_joint(th):
        calls[0] += 1
        th = np.atleast_2d(th)
        lp = log_prior(problem, th)[0]
        if not np.isfinite(lp):
            return -np.inf
        ll = log_likelihood(problem, th)[0]
        # PyVBMC needs finite values: a failing model is a very low log-density.
        return lp + ll if np.isfinite(ll) else lp - 1e4

    np.random.seed(seed)
    plb, pub = lo + 0.25 * (hi - lo), hi - 0.25 * (hi - lo)
    x0 = 0.5 * (plb + pub)
    started = time.time()
    vbmc = VBMC(log_joint, x0[None, :], lo[None, :], hi[None, :], plb[None, :], pub[None, :],
                options={"display": "off"})
    vp, _ = vbmc.optimize()
    wall = time.time() - started
    samples, _ = vp.sample(20000)
    return dict(calls=calls[0], wall=wall, samples=samples, converged=True)


def run_gpry(problem, seed=1):
    from gpry_reference import raised_initial_budget  # noqa: F401
    from gpry import Runner

    calls = [0]
    lo, hi = box(problem)
    names = problem["names"]

    def counted(theta):
        calls[0] += 1
        th = np.array([theta])
        return float(log_prior(problem, th)[0] + log_likelihood(problem, th)[0])

    namespace = {"_f": counted}
    exec(f"def loglike({', '.join(names)}):\n    return _f([{', '.join(names)}])", namespace)
    started = time.time()
    try:
        runner = Runner(namespace["loglike"], bounds=[[a, b] for a, b in zip(lo, hi)], params=list(names),
                        seed=seed, verbose=0)
        runner.run()
        runner.generate_mc_sample()
    except Exception as e:  # noqa: BLE001 (a peer's failure is a result)
        return dict(error=str(e)[:80], calls=calls[0])
    wall = time.time() - started
    s = runner.last_mc_samples()
    X, w = s["X"], s["w"]
    if w is not None:
        rng = np.random.default_rng(seed)
        X = X[rng.choice(len(X), 20000, p=w / w.sum())]
    return dict(calls=calls[0], wall=wall, samples=X, converged=True)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--problems", default=",".join(PROBLEMS))
    parser.add_argument("--methods", default="iuq,cli,pyvbmc,gpry")
    parser.add_argument("--iuq-bin", default="target/release/iuq")
    parser.add_argument("--out", default=None, help="work directory of the CLI runs (default: a temporary one)")
    parser.add_argument("--json", default=None, help="also write the table as JSON here (after every row)")
    parser.add_argument("--max-seconds", type=int, default=900, help="a method's time limit per problem")
    parser.add_argument("--seed", type=int, default=1, help="the seed of every method (default 1)")
    parser.add_argument("--adaptive", default="{}",
                        help="the CLI study's `adaptive` table (default `{}`: the defaults)")
    parser.add_argument("--model-posterior", action="store_true",
                        help="the CLI also certifies the model's own posterior (a `cli+model` row)")
    args = parser.parse_args()

    def too_long(*_):
        raise TimeoutError(f"over {args.max_seconds} s")

    signal.signal(signal.SIGALRM, too_long)
    work = args.out or tempfile.mkdtemp(prefix="iuq-bench-")
    rows = []
    for name in args.problems.split(","):
        problem = PROBLEMS[name]()
        ref = reference(problem)
        for method in args.methods.split(","):
            signal.alarm(args.max_seconds)
            try:
                if method == "iuq":
                    r = run_iuq(problem, args.seed)
                elif method == "cli":
                    r = run_cli(problem, args.iuq_bin, os.path.join(work, name), args.seed, args.model_posterior, args.adaptive)
                elif method == "pyvbmc":
                    r = run_pyvbmc(problem, args.seed)
                else:
                    r = run_gpry(problem, args.seed)
            except Exception as e:  # noqa: BLE001
                r = dict(error=f"{type(e).__name__}: {str(e)[:80]}")
            finally:
                signal.alarm(0)
            if r is None:
                continue
            model = r.pop("model_posterior", None)
            row = dict(problem=name, method=method, **{k: v for k, v in r.items() if k != "samples"})
            if "samples" in r:
                row.update(score(r["samples"], ref))
            rows.append(row)
            report(row, args.json, rows)
            if model is not None:
                row = dict(problem=name, method="cli+model", calls=model["calls"], certified=model["certified"],
                           max_mcse=model["max_mcse"], paired=model["paired"],
                           **weighted_score(model["resampled"], ref, model["mean"], model["std"]))
                rows.append(row)
                report(row, args.json, rows)


def report(row, json_path, rows):
    """Print one row of the table (and write the table so far as JSON)."""
    if json_path:
        with open(json_path, "w") as f:
            json.dump(rows, f, indent=1, default=float)
    rounds = row.get("rounds") or []
    name, method = row["problem"], row["method"]
    extra = (f"  certified {row['certified']}, paired {row['paired']}, max MCSE {row['max_mcse']:.3f} sd"
             if "certified" in row else "")
    print(f"{name:14s} {method:9s} calls {row.get('calls', '-')!s:>5}  wall {row.get('wall', float('nan')):7.1f} s  "
          f"rounds {len(rounds):2d} (median {np.median(rounds) if rounds else float('nan'):5.2f} s, max "
          f"{max(rounds) if rounds else float('nan'):5.2f} s)  c2st {row.get('c2st', float('nan')):.3f}  "
          f"mean err {row.get('mean_error', float('nan')):.3f} sd  std ratio "
          f"{row.get('std_ratio', (float('nan'),) * 2)[0]:.3f}–{row.get('std_ratio', (float('nan'),) * 2)[1]:.3f}"
          + extra + (f"  ERROR {row['error']}" if "error" in row else ""), flush=True)


if __name__ == "__main__":
    main()
