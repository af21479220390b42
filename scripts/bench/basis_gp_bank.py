#!/usr/bin/env python3
"""Side-by-side benchmark of BASIS on a GP bank (issue 3): iuq vs a vectorised NumPy reference.

The problem: a 4-parameter posterior (kLink, kBend, viscosityRatio on the RBC prior box, plus the
modelling error sigma_m ~ U(0.001, 0.1)) whose model is a bank of 8 GPs (one per shear stress of a
synthetic elongation-index curve), each trained on a 500-point maximin LHS; the GP's predictive std
(with the noise term, scikit-learn's `predict(return_std=True)`) enters the likelihood as the
computational error (relative convention, docs/methods.md §4). N = 10,000 samples, n_burn = 10.

1. `iuq bench basis-gp-bank --out WORK` generates the training data and the synthetic data, fits
   the bank (fit time reported separately), writes WORK/bank.json (the fitted GPs: kernels,
   hyper-parameters, scalers, training data) and WORK/data.json (data, prior, settings, and our
   predictions at a few check points), and runs the sampler once.
2. The reference rebuilds the same 8 GPs in scikit-learn from bank.json (fixed kernels,
   optimizer=None, normalize_y=True on the scaled inputs, alpha = our jitter), checks that their
   predictions equal ours, and runs a vectorised NumPy implementation of the same BASIS algorithm
   (same settings; every MCMC step is one batch per GP to `predict(X, return_std=True)`).
3. Timings, back to back and repeated: ours in-process (`iuq bench basis-gp-bank --bank ...`,
   sampler only), the reference around its sampler. The reference is slow, so by default it runs
   at --reference-samples (2000) and its time is extrapolated linearly in N (the number of
   model evaluations is proportional to N at a fixed number of stages); the output says so.
   Ours is also timed at the reference's N, for a measured like-for-like ratio.

Usage: cargo build --release -p iuq && python3 scripts/bench/basis_gp_bank.py
       [--samples 10000] [--burn 10] [--seed 1] [--reference-samples 2000] [--repeats 3]
       [--threads T] [--work DIR] [--quick]
Environment: IUQ_BIN overrides the binary (default target/release/iuq).
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
LN_2PI = np.log(2.0 * np.pi)


def iuq(*args):
    out = subprocess.run([IUQ, *map(str, args), "--json"], capture_output=True, text=True)
    if out.returncode != 0:
        sys.exit(f"iuq {' '.join(map(str, args))} failed: {out.stderr}")
    return json.loads(out.stdout)


def uptime():
    try:
        with open("/proc/loadavg") as f:
            return "load average " + ", ".join(f.read().split()[:3])
    except OSError:
        return "load average unknown"


# ---------------------------------------------------------------------------------------------
# The surrogate in scikit-learn
# ---------------------------------------------------------------------------------------------

class SklearnBank:
    """The 8 GPs of bank.json as scikit-learn regressors with fixed kernels."""

    def __init__(self, bank, predictive_std):
        from sklearn.gaussian_process import GaussianProcessRegressor
        from sklearn.gaussian_process.kernels import RBF, ConstantKernel, WhiteKernel

        if predictive_std != "with_noise":
            sys.exit("the reference implements the predictive std with the noise term only")
        self.gps = []
        self.scalings = []
        for g in bank["gps"]:
            h = g["hyperparameters"]
            if g["kernel"]["length_scales"] != "ard":
                sys.exit("the reference expects ARD kernels")
            lower = np.array(g["input_scaling"]["lower"])
            scale = np.array(g["input_scaling"]["range"])
            x = (np.array(g["training_inputs"]) - lower) / scale
            y = np.array(g["training_outputs"])
            kernel = (ConstantKernel(h["signal_variance"], "fixed")
                      * RBF(h["length_scales"], "fixed")
                      + WhiteKernel(h["noise_variance"], "fixed"))
            # Our outputs are standardised with the training mean and std (ddof 0), as
            # normalize_y=True; our jitter is scikit-learn's alpha.
            gp = GaussianProcessRegressor(kernel, alpha=g["jitter"], optimizer=None, normalize_y=True)
            gp.fit(x, y)
            self.gps.append(gp)
            self.scalings.append((lower, scale))

    def predict(self, x):
        """Means and stds (n_points × n_outputs), one whole-batch `predict` per GP."""
        means = np.empty((len(x), len(self.gps)))
        stds = np.empty_like(means)
        with warnings.catch_warnings():
            # scikit-learn warns when round-off makes a variance negative (it clips to 0).
            warnings.simplefilter("ignore")
            for j, (gp, (lower, scale)) in enumerate(zip(self.gps, self.scalings)):
                means[:, j], stds[:, j] = gp.predict((x - lower) / scale, return_std=True)
        return means, stds


class Likelihood:
    """ln f(D | θ) of the prediction-error model (docs/methods.md §4), vectorised over points."""

    def __init__(self, bank, data):
        self.bank = bank
        self.y = np.array(data["observations"])
        self.sd = np.array(data["measurement_std"])
        self.convention = data["computational_error"]
        self.n_model = len(data["parameters"])
        self.evaluations = 0

    def __call__(self, theta):
        self.evaluations += len(theta)
        q, s = self.bank.predict(theta[:, :self.n_model])
        sigma_m = theta[:, self.n_model][:, None]
        y = self.y[None, :]
        if self.convention == "relative":
            with np.errstate(divide="ignore", invalid="ignore"):
                comp = np.where(s == 0.0, 0.0, (s * y / q) ** 2)
        elif self.convention == "absolute-times-data":
            comp = (s * y) ** 2
        elif self.convention == "absolute":
            comp = s * s
        else:
            comp = 0.0
        var = self.sd[None, :] ** 2 + comp + sigma_m ** 2 * y ** 2
        r = y - q
        ll = -0.5 * np.sum(r * r / var + LN_2PI + np.log(var), axis=1)
        ok = np.all(np.isfinite(var) & (var > 0), axis=1) & np.all(np.isfinite(q), axis=1)
        return np.where(ok & np.isfinite(ll), ll, -np.inf)


# ---------------------------------------------------------------------------------------------
# BASIS in NumPy: the algorithm of crates/iuq-basis (docs/methods.md §5), vectorised over chains
# ---------------------------------------------------------------------------------------------

JITTERS = [1e-12, 1e-11, 1e-10, 1e-9, 1e-8, 1e-7, 1e-6, 1e-5, 1e-4]


def cv_of_step(ll, dp, max_ll):
    w = np.where(np.isfinite(ll), np.exp(dp * (ll - max_ll)), 0.0)
    mean = w.mean()
    return np.inf if mean <= 0 else w.std() / mean  # population std (ddof 0)


def next_step(ll, p, gamma, max_ll):
    remaining = 1.0 - p
    if cv_of_step(ll, remaining, max_ll) <= gamma:
        return remaining, True
    lo, hi = 0.0, remaining
    for _ in range(400):
        if hi - lo <= 1e-10 * hi:
            break
        mid = 0.5 * (lo + hi)
        if cv_of_step(ll, mid, max_ll) <= gamma:
            lo = mid
        else:
            hi = mid
    return (lo if lo > 0 else hi), False


def proposal_factor(theta, w, beta, widths):
    mean = w @ theta
    d = theta - mean
    cov = beta ** 2 * (d * w[:, None]).T @ d  # weighted, biased
    try:
        return np.linalg.cholesky(cov)
    except np.linalg.LinAlgError:
        pass
    scale = np.trace(cov) / len(cov)
    if np.isfinite(scale) and scale > 0:
        for j in JITTERS:
            try:
                return np.linalg.cholesky(cov + j * scale * np.eye(len(cov)))
            except np.linalg.LinAlgError:
                pass
    floor = (1e-6 * beta * widths) ** 2
    return np.diag(np.sqrt(np.maximum(np.nan_to_num(np.diag(cov), nan=0.0), floor)))


def basis(loglik, lower, upper, n, burn, seed, gamma=1.0, beta=0.2, min_step=1e-6, max_stages=100):
    """BASIS with l_max = 1 (every resampled copy is one chain of burn + 1 steps), multinomial
    resampling, rejection outside the prior support without evaluation, the final pass at p = 1."""
    rng = np.random.default_rng(seed)
    d = len(lower)
    widths = upper - lower
    log_prior_in = -np.sum(np.log(widths))
    theta = lower + rng.random((n, d)) * widths
    lp = np.full(n, log_prior_in)
    ll = loglik(theta)
    p, log_z, stage = 0.0, 0.0, 0
    stages = []
    while True:
        final = p >= 1.0
        finite = np.isfinite(ll)
        max_ll = ll[finite].max()
        if final:
            dp, new_p = 0.0, 1.0
        else:
            dp, reaches = next_step(ll, p, gamma, max_ll)
            if not reaches and dp < min_step:
                dp = min(min_step, 1.0 - p)
            new_p = 1.0 if (reaches or p + dp >= 1.0) else p + dp
        if dp > 0:
            m = dp * max_ll
            log_z += m + np.log(np.sum(np.exp(dp * ll[finite] - m))) - np.log(n)
        w = np.where(finite, np.exp(dp * (ll - max_ll)), 0.0)
        w /= w.sum()
        chol = proposal_factor(theta, w, beta, widths)
        counts = rng.multinomial(n, w)
        seeds = np.repeat(np.arange(n), counts)
        cur, cur_ll, cur_lp = theta[seeds].copy(), ll[seeds].copy(), lp[seeds].copy()
        accepted = 0
        for _ in range(burn + 1):
            z = rng.standard_normal((n, d))
            log_u = np.log(rng.random(n))
            prop = cur + z @ chol.T
            inside = np.all((prop >= lower) & (prop <= upper), axis=1)
            prop_ll = np.full(n, -np.inf)
            if inside.any():
                prop_ll[inside] = loglik(prop[inside])
            prop_lp = np.where(inside, log_prior_in, -np.inf)
            with np.errstate(invalid="ignore"):
                ratio = new_p * (prop_ll - cur_ll) + (prop_lp - cur_lp)
            accept = inside & np.isfinite(prop_ll) & (log_u < ratio)
            accepted += int(accept.sum())
            cur[accept], cur_ll[accept], cur_lp[accept] = prop[accept], prop_ll[accept], prop_lp[accept]
        theta, ll, lp = cur, cur_ll, cur_lp
        stage += 1
        p = new_p
        stages.append({"exponent": p, "acceptance": accepted / (n * (burn + 1)), "log_evidence": log_z})
        if final or (p < 1.0 and stage >= max_stages):
            break
    return {"samples": theta, "log_likelihood": ll, "log_evidence": log_z, "stages": stage,
            "stage_log": stages}


# ---------------------------------------------------------------------------------------------

def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--samples", type=int, default=10_000)
    ap.add_argument("--burn", type=int, default=10)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--reference-samples", type=int, default=2000,
                    help="N of the reference run (its time is extrapolated linearly to --samples)")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--threads", type=int, default=None, help="threads of our sampler")
    ap.add_argument("--work", default=None, help="directory for bank.json and data.json")
    ap.add_argument("--quick", action="store_true", help="N = 2000, reference at 500, 1 repeat")
    args = ap.parse_args()
    if args.quick:
        args.samples, args.reference_samples, args.repeats = 2000, 500, 1
    n, n_ref = args.samples, min(args.reference_samples, args.samples)
    work = args.work or tempfile.mkdtemp(prefix="iuq-basis-gp-bank-")
    threads = ["--threads", args.threads] if args.threads else []
    print(f"{uptime()} (2-core machine shared with other work: read ratios, not absolute times)")

    # 1. Training data, fit, files; our first run.
    first = iuq("bench", "basis-gp-bank", "--samples", n, "--burn", args.burn, "--seed", args.seed,
                "--out", work, *threads)
    bank_file = os.path.join(work, "bank.json")
    with open(bank_file) as f:
        bank_json = json.load(f)
    with open(os.path.join(work, "data.json")) as f:
        data = json.load(f)
    print(f"GP bank: {first['outputs']} GPs × {first['n_training']} points (maximin LHS), "
          f"fit in {first['fit_seconds']:.2f} s (iuq, {first['threads']} threads); files in {work}")

    # 2. The same GPs in scikit-learn, checked against ours.
    bank = SklearnBank(bank_json, data["predictive_std"])
    check = data["check"]
    q, s = bank.predict(np.array(check["points"]))
    dmean = np.abs(q.T - np.array(check["mean"]))
    dstd = np.abs(s.T - np.array(check["std"]))
    rel_std = dstd / np.array(check["std"])
    print(f"scikit-learn vs iuq predictions at {len(check['points'])} points × {len(bank.gps)} GPs: "
          f"max |Δmean| = {dmean.max():.1e}, max |Δstd| = {dstd.max():.1e} (relative {rel_std.max():.1e}; "
          f"stds ≈ {np.median(check['std']):.1e}, set by the noise term)")
    if dmean.max() > 1e-8 or dstd.max() > 1e-8:
        print("WARNING: the surrogates differ by more than 1e-8")

    names = [p["name"] for p in data["parameters"]] + [data["modelling_error"]["name"]]
    lower = np.array([p["lower"] for p in data["parameters"]] + [data["modelling_error"]["lower"]])
    upper = np.array([p["upper"] for p in data["parameters"]] + [data["modelling_error"]["upper"]])

    def reference(size, seed):
        lik = Likelihood(bank, data)
        start = time.perf_counter()
        out = basis(lik, lower, upper, size, args.burn, seed)
        out["seconds"] = time.perf_counter() - start
        out["evaluations"] = lik.evaluations
        return out

    # 3. Back to back, repeated.
    ours, ours_small, refs = [], [], []
    for r in range(args.repeats):
        print(f"repeat {r + 1}/{args.repeats}: {uptime()}", flush=True)
        seed = args.seed + r
        ours.append(first if r == 0 else iuq("bench", "basis-gp-bank", "--bank", bank_file, "--samples", n,
                                              "--burn", args.burn, "--seed", seed, *threads))
        if n_ref != n:
            ours_small.append(iuq("bench", "basis-gp-bank", "--bank", bank_file, "--samples", n_ref,
                                  "--burn", args.burn, "--seed", seed, *threads))
        refs.append(reference(n_ref, seed))
        print(f"  iuq N={n}: {ours[-1]['seconds_median']:.2f} s"
              + (f", iuq N={n_ref}: {ours_small[-1]['seconds_median']:.2f} s" if ours_small else "")
              + f", reference N={n_ref}: {refs[-1]['seconds']:.1f} s", flush=True)
    print(f"after the runs: {uptime()}")

    ours_s = float(np.median([o["seconds_median"] for o in ours]))
    ref_s = float(np.median([x["seconds"] for x in refs]))
    o = ours[-1]
    ref_evals = int(np.median([x["evaluations"] for x in refs]))
    print()
    print(f"iuq       N={n}, n_burn={args.burn}: sampler {ours_s:.2f} s (median of {len(ours)}), "
          f"{o['stages']} stages, {o['evaluations']} evaluations, {o['predictions']} predictions with "
          f"variance, {ours_s / o['predictions'] * 1e6:.2f} µs/prediction, {o['threads']} threads")
    if n_ref == n:
        extrapolated = ref_s
        print(f"reference N={n}: {ref_s:.1f} s measured (median of {len(refs)}), {ref_evals} evaluations, "
              f"{ref_s / (ref_evals * len(bank.gps)) * 1e6:.1f} µs/prediction")
    else:
        extrapolated = ref_s * n / n_ref
        small_s = float(np.median([x["seconds_median"] for x in ours_small]))
        print(f"reference N={n_ref}: {ref_s:.1f} s measured (median of {len(refs)}), {ref_evals} evaluations, "
              f"{ref_s / (ref_evals * len(bank.gps)) * 1e6:.1f} µs/prediction; "
              f"iuq at N={n_ref}: {small_s:.2f} s → measured ratio {ref_s / small_s:.1f}×")
        print(f"reference extrapolated linearly to N={n}: {extrapolated:.0f} s (NOT measured: "
              f"{ref_s:.1f} s × {n}/{n_ref})")
    target = "met" if ours_s < 10 else "NOT met"
    print(f"ratio at N={n}: {extrapolated / ours_s:.1f}× (target ≥ 10×); iuq under 10 s: {target}")

    print()
    print(f"{'':>16} {'iuq N=' + str(n):>22} {'reference N=' + str(n_ref):>26}")
    lz_ref = [x["log_evidence"] for x in refs]
    lz_ours = [x["log_evidence"] for x in ours]
    print(f"{'log evidence':>16} {np.mean(lz_ours):13.4f} ± {np.std(lz_ours):6.4f} "
          f"{np.mean(lz_ref):17.4f} ± {np.std(lz_ref):.4f}   (mean ± sd over {len(refs)} seeds)")
    for k, name in enumerate(names):
        our_means = [x["mean"][name] for x in ours]
        ref_means = [x["samples"][:, k].mean() for x in refs]
        ref_stds = [x["samples"][:, k].std() for x in refs]
        print(f"{'mean ' + name:>16} {np.mean(our_means):13.5g} ± {np.std(our_means):6.2g} "
              f"{np.mean(ref_means):17.5g} ± {np.std(ref_means):.2g}"
              f"   (posterior std: iuq {o['std'][name]:.3g}, reference {np.mean(ref_stds):.3g})")
    print(f"{'stages':>16} {o['stages']:22d} {int(np.median([x['stages'] for x in refs])):18d}")


if __name__ == "__main__":
    main()
