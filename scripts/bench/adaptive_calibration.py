#!/usr/bin/env python3
"""How many model runs a calibration needs: iuq's adaptive engine against a one-shot maximin
Latin hypercube of growing size and against GPry, side by side, on problems with known
posteriors.

    python3 -m venv .venv-adaptive && .venv-adaptive/bin/pip install -r scripts/bench/requirements-adaptive.txt
    cargo build --release -p iuq
    .venv-adaptive/bin/python scripts/bench/adaptive_calibration.py [--problems cooling,logistic,oscillator] [--skip-gpry] [--skip-lhs] [--skip-adaptive]

Each problem is a model y(θ, x) evaluated at the data's abscissae in one run (the "curve" shape:
one run per parameter vector returns every data point as one array, `output.array`), with
synthetic data made here from known parameters and Gaussian noise (fixed seeds). The sweep: 2
(cooling, failing over part of the prior), 3 (logistic, oscillator), 4 (exp2, failing for
k2 > 2), 6 (exp3: three exponentials, a sharply curved posterior, 24 outputs), 8 and 10
(truncated Fourier series) parameters, and a 240-point curve (longcurve, 4 parameters). The
truth is BASIS on the exact curve (`iuq basis` with `likelihood.prediction`, N = 50,000, the
default adaptive mixing); the methods' final posteriors use N = 20,000. A posterior is
*accurate* when every parameter's mean lies within 0.1 posterior std of the truth's and its std
within 10 % of the truth's. Reported per method: the model runs it made and whether its
posterior is accurate.

- iuq adaptive: `iuq pipeline` with `[surrogate] adaptive = { batch = 2 }` after an initial
  maximin LHS of 6 runs, the model a command (one process per run); runs = every run the
  pipeline made; also the runs after which a round's posterior
  (N = 2,000) first met the accuracy criterion, and the wall time. For curves of 20 points or
  more, again with `reduced_basis = true` (GPs on principal components).
- one-shot LHS: `iuq pipeline` without `adaptive`, design n = 8, 16, …, 256; the smallest n
  whose posterior is accurate.
- GPry (El Gammal et al. 2023; `pip install gpry`): its Runner with the true log-likelihood, its
  default acquisition (LogExp), batches and convergence criterion, then its MC sample of the
  surrogate posterior; runs = truth evaluations. A model failure is a log-likelihood of −∞,
  which GPry's classifier learns.

The cooling problem's model fails (exits non-zero) for k > 0.4, next to the posterior
(k ≈ 0.31).
"""

import argparse
import json
import math
import os
import random
import shutil
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(Path(__file__).resolve().parent))
from gpry_reference import gpry_posterior, raised_initial_budget  # noqa: E402
# Extra keys of `[surrogate] adaptive` (e.g. ", log_likelihood_tolerance = 0.05"), for experiments.
ADAPTIVE_EXTRA = os.environ.get("IUQ_BENCH_ADAPTIVE_EXTRA", "")
# The adaptive study's initial maximin LHS (then batches of 2 per round).
INITIAL_RUNS = 6
# The binary measured ($IUQ_BENCH_BIN, e.g. a copy that a rebuild cannot change mid-run).
IUQ = Path(os.environ.get("IUQ_BENCH_BIN", ROOT / "target" / "release" / "iuq"))

PROBLEMS = {
    "cooling": {
        "parameters": {"k": (0.05, 0.8), "T0": (60.0, 100.0)},
        "truth": {"k": 0.3, "T0": 88.0},
        "x": [0.5, 1, 2, 3, 4, 6, 8, 10],
        "noise": 0.8,
        "formula": "20 + (T0 - 20) * exp(-k * x)",
        "fails": "k > 0.4",
    },
    "logistic": {
        "parameters": {"K": (5.0, 15.0), "r": (0.2, 2.0), "t0": (2.0, 8.0)},
        "truth": {"K": 10.0, "r": 0.8, "t0": 5.0},
        "x": [float(t) for t in range(0, 11)],
        "noise": 0.3,
        "formula": "K / (1 + exp(-r * (x - t0)))",
        "fails": None,
    },
    "oscillator": {
        "parameters": {"A": (0.5, 2.0), "g": (0.05, 0.5), "w": (1.0, 3.0)},
        "truth": {"A": 1.2, "g": 0.2, "w": 2.0},
        "x": [0.5 * i for i in range(0, 17)],
        "noise": 0.05,
        "formula": "A * exp(-g * x) * cos(w * x)",
        "fails": None,
    },
    # Four parameters; the model fails for k2 > 2 (the posterior lies at k2 ≈ 1.5).
    "exp2": {
        "parameters": {"A1": (0.2, 4.0), "k1": (0.02, 0.5), "A2": (0.2, 4.0), "k2": (0.6, 3.0)},
        "truth": {"A1": 1.0, "k1": 0.15, "A2": 2.0, "k2": 1.5},
        "x": [0.25 * i for i in range(1, 21)],
        "noise": 0.02,
        "formula": "A1 * exp(-k1 * x) + A2 * exp(-k2 * x)",
        "fails": "k2 > 2.0",
    },
    # Six parameters, a sharply curved posterior (amplitudes and rates trade off), 24 outputs.
    "exp3": {
        "parameters": {
            "A1": (0.2, 4.0), "k1": (0.02, 0.3), "A2": (0.2, 4.0),
            "k2": (0.3, 1.2), "A3": (0.2, 4.0), "k3": (1.2, 5.0),
        },
        "truth": {"A1": 1.0, "k1": 0.1, "A2": 2.0, "k2": 0.6, "A3": 1.5, "k3": 2.5},
        "x": [0.25 * i for i in range(1, 25)],
        "noise": 0.01,
        "formula": "A1 * exp(-k1 * x) + A2 * exp(-k2 * x) + A3 * exp(-k3 * x)",
        "fails": None,
    },
    # Eight and ten parameters: truncated Fourier series with a trend (Gaussian posteriors).
    "fourier8": {
        "parameters": {n: (v - 2.0, v + 2.0) for n, v in
                       {"a0": 1.0, "a1": 0.5, "b1": -0.8, "a2": 0.3, "b2": 0.6, "a3": -0.4, "b3": 0.2, "c": 0.1}.items()},
        "truth": {"a0": 1.0, "a1": 0.5, "b1": -0.8, "a2": 0.3, "b2": 0.6, "a3": -0.4, "b3": 0.2, "c": 0.1},
        "x": [0.3 * i for i in range(0, 20)],
        "noise": 0.1,
        "formula": "a0 + a1 * cos(x) + b1 * sin(x) + a2 * cos(2 * x) + b2 * sin(2 * x) + a3 * cos(3 * x) + b3 * sin(3 * x) + c * x",
        "fails": None,
    },
    "fourier10": {
        "parameters": {n: (v - 2.0, v + 2.0) for n, v in
                       {"a0": 1.0, "a1": 0.5, "b1": -0.8, "a2": 0.3, "b2": 0.6, "a3": -0.4, "b3": 0.2,
                        "a4": 0.25, "b4": -0.3, "c": 0.1}.items()},
        "truth": {"a0": 1.0, "a1": 0.5, "b1": -0.8, "a2": 0.3, "b2": 0.6, "a3": -0.4, "b3": 0.2,
                  "a4": 0.25, "b4": -0.3, "c": 0.1},
        "x": [0.25 * i for i in range(0, 24)],
        "noise": 0.1,
        "formula": "a0 + a1 * cos(x) + b1 * sin(x) + a2 * cos(2 * x) + b2 * sin(2 * x) + a3 * cos(3 * x) + b3 * sin(3 * x) + a4 * cos(4 * x) + b4 * sin(4 * x) + c * x",
        "fails": None,
    },
    # A long curve: 240 points of a growth-and-decay profile, four parameters.
    "longcurve": {
        "parameters": {"A": (0.5, 2.0), "r": (0.5, 3.0), "t0": (1.0, 5.0), "g": (0.02, 0.3)},
        "truth": {"A": 1.2, "r": 1.5, "t0": 3.0, "g": 0.1},
        "x": [0.05 * i for i in range(0, 240)],
        "noise": 0.05,
        "formula": "A / (1 + exp(-r * (x - t0))) * exp(-g * x)",
        "fails": None,
    },
}


def curve(problem, theta):
    """The model's outputs at every abscissa; None where the model fails."""
    p = PROBLEMS[problem]
    v = dict(zip(p["parameters"], theta))
    if p["fails"] is not None and eval(p["fails"], {}, dict(v)):
        return None
    code = compile(p["formula"].replace("^", "**"), problem, "eval")
    scope = {"exp": math.exp, "cos": math.cos, "sin": math.sin, "sqrt": math.sqrt}
    return [eval(code, scope, dict(v, x=x)) for x in p["x"]]


def run_model(problem):
    """The command model: params.json in, result.json out (exit 3 where the model fails)."""
    with open("params.json", encoding="utf-8") as f:
        params = json.load(f)
    theta = [float(params[name]) for name in PROBLEMS[problem]["parameters"]]
    y = curve(problem, theta)
    if y is None:
        print(f"the model gives no answer at {params}", file=sys.stderr)
        return 3
    with open("result.json", "w", encoding="utf-8") as f:
        json.dump({"y": y}, f)
    return 0


def data(problem):
    p = PROBLEMS[problem]
    rng = random.Random(sum(map(ord, problem)) + 7)
    exact = curve(problem, list(p["truth"].values())) or []
    return [(x, y + rng.gauss(0, p["noise"])) for x, y in zip(p["x"], exact)]


# Curves of at least this many points are also run with `[surrogate] reduced_basis`.
REDUCED_BASIS_MIN_POINTS = 20


def study_text(problem, name, design_n, adaptive, seed=1, reduced_basis=False):
    p = PROBLEMS[problem]
    lines = [f'name = "{name}"', "[parameters]"]
    lines += [f"{k} = {{ uniform = [{lo}, {hi}] }}" for k, (lo, hi) in p["parameters"].items()]
    lines += [
        "[likelihood]",
        'data = { file = "data.csv", x = "x", y = "y", y_err = "y_err" }',
        "modelling_error = false",
        "[model]",
        'kind = "command"',
        f'command = ["{sys.executable}", "{Path(__file__).resolve()}", "--model", "{problem}"]',
        'output = { file = "result.json", format = "json", array = "/y" }',
        "[surrogate]",
        f'design = {{ kind = "lhs", n = {design_n}, seed = {seed} }}',
    ]
    if adaptive:
        lines.append(f"adaptive = {{ batch = 2, max_runs = 300, tolerance = 0.1{ADAPTIVE_EXTRA} }}")
    if reduced_basis:
        lines.append("reduced_basis = true")
    lines += ["[sensitivity]", "n = 256", "[sampler]", "samples = 20000", f"seed = {seed}"]
    return "\n".join(lines) + "\n"


def exact_study(problem):
    p = PROBLEMS[problem]
    lines = [f'name = "{problem}-exact"', "[parameters]"]
    lines += [f"{k} = {{ uniform = [{lo}, {hi}] }}" for k, (lo, hi) in p["parameters"].items()]
    lines += [
        "[likelihood]",
        'data = { file = "data.csv", x = "x", y = "y", y_err = "y_err" }',
        "modelling_error = false",
        f'prediction = "{p["formula"]}"',
        "[sampler]",
        "samples = 50000",
        "seed = 5",
    ]
    return "\n".join(lines) + "\n"


def iuq_json(args, cwd):
    out = subprocess.run([str(IUQ), *args, "--json"], cwd=cwd, capture_output=True, text=True)
    if out.returncode != 0:
        raise RuntimeError(f"iuq {' '.join(args)} failed: {out.stderr[-2000:]}")
    return json.loads(out.stdout)


def moments_of(value):
    return {p["parameter"]: (p["mean"], p["std"]) for p in value["posterior"][0]["parameters"]}


def accurate(moments, truth):
    return all(
        abs(moments[k][0] - m) < 0.1 * s and abs(moments[k][1] / s - 1) < 0.1
        for k, (m, s) in truth.items()
    )


def worst(moments, truth):
    """The largest |Δmean|/std and |Δstd|/std over the parameters."""
    dm = max(abs(moments[k][0] - m) / s for k, (m, s) in truth.items())
    ds = max(abs(moments[k][1] / s - 1) for k, (m, s) in truth.items())
    return dm, ds


def gpry_run(problem, truth, seed=1, options=None):
    """GPry on the problem's exact log-likelihood: (calls, moments by name, seconds)."""
    p = PROBLEMS[problem]
    obs = data(problem)
    noise = p["noise"]

    def log_likelihood(theta):
        y = curve(problem, list(theta))
        if y is None:
            return -math.inf
        return -0.5 * sum(((yo - ym) / noise) ** 2 for (_, yo), ym in zip(obs, y))

    names = list(p["parameters"])
    calls, mean, std, seconds = gpry_posterior(
        log_likelihood, names, [p["parameters"][n] for n in names], seed=seed, options=options)
    return calls, {n: (mean[i], std[i]) for i, n in enumerate(names)}, seconds


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--model", help=argparse.SUPPRESS)
    parser.add_argument("--problems", default=",".join(PROBLEMS))
    parser.add_argument("--skip-gpry", action="store_true")
    parser.add_argument("--work", default=str(ROOT / "target" / "bench-adaptive"))
    parser.add_argument("--skip-lhs", action="store_true", help="leave out the one-shot designs")
    parser.add_argument("--skip-adaptive", action="store_true", help="leave out iuq's adaptive engine")
    parser.add_argument("--results", help="append each row to this CSV as it is measured")
    args = parser.parse_args()
    if args.model:
        return run_model(args.model)
    if not IUQ.exists():
        sys.exit(f"{IUQ} is missing: cargo build --release -p iuq")
    rows = []

    class Rows(list):
        """The table's rows, each also appended to --results as soon as it is measured."""

        def append(self, row):
            super().append(row)
            if args.results:
                new = not os.path.exists(args.results)
                with open(args.results, "a", encoding="utf-8") as f:
                    if new:
                        f.write("problem,parameters,outputs,method,model_runs,accurate,worst_mean_error_stds,worst_std_error,note\n")
                    problem, method, runs, ok, dm, ds, note = row
                    p = PROBLEMS[problem]
                    f.write(f"{problem},{len(p['parameters'])},{len(p['x'])},{method},{runs},{ok},{dm:.4f},{ds:.4f},\"{note}\"\n")

    rows = Rows()
    for problem in args.problems.split(","):
        work = Path(args.work) / problem
        shutil.rmtree(work, ignore_errors=True)
        work.mkdir(parents=True)
        with open(work / "data.csv", "w", encoding="utf-8") as f:
            f.write("x,y,y_err\n")
            for x, y in data(problem):
                f.write(f"{x},{y:.6f},{PROBLEMS[problem]['noise']}\n")
        (work / "exact.toml").write_text(exact_study(problem))
        t = iuq_json(["basis", "exact.toml", "--out", "exact"], work)
        truth = {k: (t["mean"][k], t["std"][k]) for k in PROBLEMS[problem]["parameters"]}
        print(f"\n{problem}: truth " + ", ".join(f"{k} = {m:.5g} ± {s:.3g}" for k, (m, s) in truth.items()))

        variants = [] if args.skip_adaptive else [("iuq adaptive", False)]
        if not args.skip_adaptive and len(PROBLEMS[problem]["x"]) >= REDUCED_BASIS_MIN_POINTS:
            variants.append(("iuq adaptive, reduced basis", True))
        for method, reduced in variants:
            name = "adaptive-rb" if reduced else "adaptive"
            (work / f"{name}.toml").write_text(
                study_text(problem, f"{problem}-{name}", INITIAL_RUNS, True, reduced_basis=reduced))
            started = time.time()
            try:
                v = iuq_json(["pipeline", f"{name}.toml", "--out", f"{name}-report"], work)
            except RuntimeError as e:
                rows.append((problem, method, "failed", False, float("nan"), float("nan"), str(e).splitlines()[-1][:120]))
                print(f"  {method} failed: {str(e).splitlines()[-1]}")
                continue
            seconds = time.time() - started
            m = moments_of(v)
            first = None
            for r in v["adaptive"]["rounds"]:
                rm = dict(zip(v["adaptive"]["parameters"], zip(r["mean"], r["std"])))
                if accurate(rm, truth):
                    first = r["runs"]
                    break
            dm, ds = worst(m, truth)
            rows.append((problem, method, v["runs"], accurate(m, truth), dm, ds,
                         f"{v['rounds']} rounds, converged {v['converged']} ({v['adaptive']['stop_reason'][:60]}), first accurate round after {first} runs, {seconds:.0f} s"))
            print(f"  {method}: {v['runs']} runs, accurate {accurate(m, truth)} (mean off {dm:.3f} std, std off {100 * ds:.1f} %), {seconds:.0f} s")

        needed = None
        last = None
        for n in ([] if args.skip_lhs else [8, 16, 32, 64, 128, 256, 512]):
            name = f"lhs-{n}"
            (work / f"{name}.toml").write_text(study_text(problem, f"{problem}-{name}", n, False))
            try:
                v = iuq_json(["pipeline", f"{name}.toml", "--out", f"{name}-report"], work)
            except RuntimeError as e:
                print(f"  one-shot LHS n = {n}: {str(e).splitlines()[-1]}")
                continue
            m = moments_of(v)
            dm, ds = worst(m, truth)
            last = (n, dm, ds)
            ok = accurate(m, truth)
            print(f"  one-shot LHS n = {n}: accurate {ok} (mean off {dm:.3f} std, std off {100 * ds:.1f} %)")
            if ok:
                needed = n
                break
        if not args.skip_lhs:
            rows.append((problem, "one-shot maximin LHS", needed if needed else f"> {last[0] if last else 512}",
                         needed is not None, last[1] if last else float("nan"), last[2] if last else float("nan"),
                         "smallest n of 8, 16, ..., 512 whose posterior is accurate"))

        if not args.skip_gpry:
            try:
                evals, m, seconds = gpry_run(problem, truth)
                dm, ds = worst(m, truth)
                rows.append((problem, "GPry", evals, accurate(m, truth), dm, ds, f"default settings, {seconds:.0f} s"))
                print(f"  GPry: {evals} runs, accurate {accurate(m, truth)} (mean off {dm:.3f} std, std off {100 * ds:.1f} %)")
            except Exception as e:  # report, do not hide
                rows.append((problem, "GPry", "failed", False, float("nan"), float("nan"), repr(e)[:120]))
                print(f"  GPry failed: {e!r}")
                options = raised_initial_budget(e, len(PROBLEMS[problem]["parameters"]))
                if options is not None:
                    max_initial = options["max_initial"]
                    try:
                        evals, m, seconds = gpry_run(problem, truth, options=options)
                        dm, ds = worst(m, truth)
                        rows.append((problem, f"GPry, max_initial = {max_initial}", evals, accurate(m, truth), dm, ds, f"{seconds:.0f} s"))
                        print(f"  GPry (max_initial {max_initial}): {evals} runs, accurate {accurate(m, truth)} (mean off {dm:.3f} std, std off {100 * ds:.1f} %)")
                    except Exception as e2:  # report, do not hide
                        rows.append((problem, "GPry, max_initial raised", "failed", False, float("nan"), float("nan"), repr(e2)[:120]))
                        print(f"  GPry (max_initial raised) failed: {e2!r}")

    print("\n| problem | method | model runs | accurate | worst mean error (stds) | worst std error | note |")
    print("|---|---|---|---|---|---|---|")
    for problem, method, runs, ok, dm, ds, note in rows:
        print(f"| {problem} | {method} | {runs} | {'yes' if ok else 'no'} | {dm:.3f} | {100 * ds:.1f} % | {note} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
