#!/usr/bin/env python3
"""How the adaptive engine's surrogate error ε falls with the runs, and which run group holds it:
the evidence behind the red-cell studies' run counts (issue: the engine at scale, item 4).

    cargo build --release -p iuq
    target/release/iuq pipeline examples/rbc-healthy-hemocell.toml --out /tmp/healthy
    python3 scripts/bench/surrogate_error_trend.py /tmp/healthy [--from-runs 230] [--tolerance 0.1]

Reads the pipeline's `adaptive/rounds.json` (per round: runs, ε = `surrogate_error`, each run
group's ε_g) and `gp-bank.json` (each group's final GP: training runs, fitted noise std and
signal std in output units) and prints:
- per round the runs, ε and the group with the largest ε_g (its share of ε²);
- a least-squares fit ln ε = a + b·ln n over the rounds from `--from-runs` runs on, with the
  run count at which the fit reaches `--tolerance` (the study's adaptive tolerance). For a GP
  that learns a noisy output's mean from runs near the posterior, ε falls at most like n^(−1/2)
  (the predictive variance of a mean from m noisy runs is σ_noise²/m); a smaller |b| means new
  runs went where they help less;
- per group its training runs, fitted noise std and signal std.

Standard library only (json, math, argparse); no model runs.
"""

import argparse
import json
import math
import sys
from pathlib import Path


def fit_power_law(runs, errors):
    """Least squares of ln ε on ln n: returns (a, b, residual std)."""
    xs = [math.log(n) for n in runs]
    ys = [math.log(e) for e in errors]
    k = len(xs)
    if k < 3:
        raise ValueError(f"the fit needs at least 3 rounds, found {k}")
    mx, my = sum(xs) / k, sum(ys) / k
    sxx = sum((x - mx) ** 2 for x in xs)
    if sxx == 0.0:
        raise ValueError("the fit needs rounds with different run counts")
    b = sum((x - mx) * (y - my) for x, y in zip(xs, ys)) / sxx
    a = my - b * mx
    residuals = [y - (a + b * x) for x, y in zip(xs, ys)]
    sd = math.sqrt(sum(r * r for r in residuals) / (k - 2))
    return a, b, sd


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("out", type=Path, help="the pipeline's output directory")
    parser.add_argument("--from-runs", type=int, default=230, help="first run count of the fit")
    parser.add_argument("--tolerance", type=float, default=0.1, help="the adaptive tolerance")
    args = parser.parse_args()
    rounds_path = args.out / "adaptive" / "rounds.json"
    bank_path = args.out / "gp-bank.json"
    try:
        rounds = json.loads(rounds_path.read_text())
        bank = json.loads(bank_path.read_text())
    except (OSError, json.JSONDecodeError) as e:
        sys.exit(f"error: {e}")
    names = bank["output_names"]

    print(f"{'round':>5} {'runs':>5} {'eps':>7}  largest group share")
    for r in rounds:
        groups = r.get("group_surrogate_error") or []
        line = f"{r['round']:>5} {r['runs']:>5} {r['surrogate_error']:>7.3f}"
        if groups:
            total = sum(e * e for e in groups)
            g = max(range(len(groups)), key=lambda i: groups[i])
            share = groups[g] ** 2 / total if total > 0 else float("nan")
            line += f"  {names[g]} eps_g {groups[g]:.3f} ({100 * share:.0f} % of eps^2)"
        print(line)

    later = [r for r in rounds if r["runs"] >= args.from_runs]
    try:
        a, b, sd = fit_power_law(
            [r["runs"] for r in later], [r["surrogate_error"] for r in later]
        )
        at_tolerance = math.exp((math.log(args.tolerance) - a) / b) if b < 0 else float("inf")
        print(
            f"\nfit over {len(later)} rounds from {args.from_runs} runs: eps ~ n^{b:.2f} "
            f"(residual std of ln eps {sd:.2f}); eps(200) = {math.exp(a) * 200 ** b:.3f}; "
            f"eps = {args.tolerance} at n = {at_tolerance:.0f}"
        )
    except ValueError as e:
        print(f"\nno power-law fit of the rounds from {args.from_runs} runs on (--from-runs): {e}")

    print(f"\n{'group':>12} {'runs':>5} {'noise std':>10} {'signal std':>10}")
    for name, gp in zip(names, bank["gps"]):
        h = gp["hyperparameters"]
        scale = gp["output_scaling"]["std"]
        print(
            f"{name:>12} {len(gp['training_inputs']):>5} "
            f"{math.sqrt(h['noise_variance']) * scale:>10.5f} "
            f"{math.sqrt(h['signal_variance']) * scale:>10.4f}"
        )


if __name__ == "__main__":
    main()
