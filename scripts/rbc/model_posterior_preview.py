#!/usr/bin/env python3
"""Preview the model posterior's first importance stage from the part of its batch already run.

`iuq pipeline --model-posterior` runs `[model_posterior] samples` members of the surrogate
posterior through the cell model (the design `model-posterior-1` of the campaign store, one run
per member and stress) and weighs each member by exp(r), r = ℓ_model − ℓ_surrogate. While that
batch is still being made, this script computes r for the members whose runs at every stress have
succeeded and prints what the first stage would see: the spread of r, the weights' effective
sample size and their coefficient of variation (the stage reaches β = 1 at once only when that CV
is at most `cv_target`, default 1; otherwise the method corrects the surrogate, which costs one
more batch, and bridges; docs/study-file.md, `[model_posterior]`). With `--with-scatter` it also
shows r when each run's std is combined with its stress's GP noise std (the scatter between runs
that no smooth function of the parameters explains), for comparison. Every summary gives the
weights' k̂ as the method computes it (Pareto-smoothed importance sampling) beside its threshold.

For a noisy study with `replicates = m` (`[model_posterior]`), once the replicate runs
(`model-posterior-replicates`: each member's irregular stress run m times, its own run and m − 1
nudged ones) are partly made, it also shows the one pseudo-marginal step the method weighs the
members by: r with the irregular stresses' likelihoods averaged over the replicates, for the
members whose replicates all succeeded; the replicates' spread (how chaotic the output is) beside
the runs' own std; and how that spread depends on the parameters (a regression of its log on the
standardised parameters).

The surrogate population and its log-likelihoods come from a replay of the study into OUT; make
it on a copy of the store so that a running campaign is not touched:

    python3 - <<'EOF'
    import sqlite3
    src = sqlite3.connect("file:examples/rbc-healthy-hemocell.campaign/campaign.sqlite?mode=ro", uri=True)
    dst = sqlite3.connect("/tmp/copy/examples/rbc-healthy-hemocell.campaign/campaign.sqlite")
    src.backup(dst); dst.execute("pragma journal_mode=DELETE"); dst.close()
    EOF
    # with the study file in /tmp/copy/examples/ and its data file in /tmp/copy/data/:
    (cd /tmp/copy/examples && iuq pipeline rbc-healthy-hemocell.toml --out /tmp/copy/out)
    python3 scripts/rbc/model_posterior_preview.py examples/rbc-healthy-hemocell.toml /tmp/copy/out

The likelihood is the study's prediction-error likelihood (docs/methods.md §4) with
`computational_error = "relative"` (the red-cell studies' convention; others are refused).
The store read is the study's own (read-only) unless `--store` names another. Needs numpy.
"""

import argparse
import csv
import json
import os
import sqlite3
import sys
import tomllib

import numpy as np

DESIGN = "model-posterior-1"


def read_data(study_path, study):
    """{stress: (datum, measurement std)} of the study's data rows within its x_range."""
    spec = study["likelihood"]["data"]
    path = os.path.join(os.path.dirname(os.path.abspath(study_path)), spec["file"])
    with open(path) as f:
        rows = list(csv.DictReader(line for line in f if not line.startswith("#")))
    low, high = spec.get("x_range", [-np.inf, np.inf])
    return {
        round(float(r[spec["x"]]), 6): (float(r[spec["y"]]), float(r[spec["y_err"]]))
        for r in rows
        if low <= float(r[spec["x"]]) <= high
    }


def gp_noise_std(out):
    """Per stress, the fitted noise std of its GP in OUT/gp-bank.json, in EL units."""
    with open(os.path.join(out, "gp-bank.json")) as f:
        bank = json.load(f)
    noise = {}
    for name, gp in zip(bank["output_names"], bank["gps"]):
        stress = round(float(name.split("_")[-1].removesuffix("Pa")), 6)
        noise[stress] = np.sqrt(gp["hyperparameters"]["noise_variance"]) * gp["output_scaling"]["std"]
    return noise


def batch_members(store):
    """{(θ without the stress): {stress: (status, EL, EL std)}} of the design's runs."""
    with sqlite3.connect(f"file:{store}?mode=ro", uri=True) as db:
        design = db.execute("select id from designs where label = ?", (DESIGN,)).fetchone()
        if design is None:
            sys.exit(f"{store}: no design `{DESIGN}` (the model posterior's batch was never requested)")
        rows = db.execute(
            "select r.parameters, r.status, o.value, o.std from design_points dp "
            "join runs r on r.id = dp.run_id "
            "left join outputs o on o.run_id = r.id and o.name = 'el' where dp.design_id = ?",
            (design[0],),
        ).fetchall()
    members = {}
    for parameters, status, value, std in rows:
        p = json.loads(parameters)
        members.setdefault(tuple(p[:-1]), {})[round(p[-1], 6)] = (status, value, std)
    return members, len(rows)


REPLICATES = "model-posterior-replicates"


def replicate_groups(store, m):
    """{(θ without the stress): {stress: [(status, EL, EL std)] × m}} of the replicate design, the
    member's own run first (`None` when the store has no replicates)."""
    with sqlite3.connect(f"file:{store}?mode=ro", uri=True) as db:
        design = db.execute("select max(id) from designs where label = ?", (REPLICATES,)).fetchone()[0]
        if design is None:
            return None
        rows = db.execute(
            "select dp.position, r.parameters, r.status, o.value, o.std from design_points dp "
            "join runs r on r.id = dp.run_id "
            "left join outputs o on o.run_id = r.id and o.name = 'el' where dp.design_id = ? "
            "order by dp.position",
            (design,),
        ).fetchall()
    stresses = sorted({round(json.loads(p)[-1], 6) for _, p, _, _, _ in rows})
    per_member = m * len(stresses)
    own = {}
    members = {}
    for position, parameters, status, value, std in rows:
        p = json.loads(parameters)
        theta = own.setdefault(position // per_member, tuple(p[:-1]))
        members.setdefault(theta, {}).setdefault(round(p[-1], 6), []).append((status, value, std))
    return members


def log_likelihood(data, runs, sigma_m, extra_std):
    """The prediction-error log-likelihood of one member's runs (relative computational error)."""
    total = 0.0
    for stress, (y, sd) in data.items():
        _, q, s = runs[stress]
        s = np.hypot(s, extra_std.get(stress, 0.0))
        variance = sd**2 + (s * y / q) ** 2 + (sigma_m * y) ** 2
        total += -0.5 * ((y - q) ** 2 / variance + np.log(2 * np.pi * variance))
    return total


def pareto_k(log_weights):
    """PSIS k̂ of log-weights, as `iuq_basis::pareto_smooth` computes it (ArviZ's conventions:
    tail of ⌈min(0.2·S, 3√S)⌉ weights, Zhang & Stephens' fit, prior of 10 at ½); inf for a tail
    of 4 or fewer."""
    x = np.sort(np.exp(log_weights - log_weights.max()))
    s = len(x)
    m = int(np.ceil(min(0.2 * s, 3 * np.sqrt(s))))
    cut = max(x[s - m - 1], np.finfo(float).tiny)
    tail = x[x > cut] - cut
    n = len(tail)
    if n <= 4:
        return np.inf
    grid = 30 + int(np.sqrt(n))
    b = (1 - np.sqrt(grid / (np.arange(1, grid + 1) - 0.5))) / (3 * tail[int(n / 4 + 0.5) - 1]) + 1 / tail[-1]
    k = np.array([np.mean(np.log1p(-bj * tail)) for bj in b])
    length = n * (np.log(-b / k) - k - 1)
    weight = 1 / np.array([np.sum(np.exp(length - lj)) for lj in length])
    keep = weight >= 10 * np.finfo(float).eps
    b_post = np.sum(b[keep] * weight[keep]) / np.sum(weight[keep])
    k_post = np.mean(np.log1p(-b_post * tail))
    return (n * k_post + 10 * 0.5) / (n + 10)


def weights_summary(r):
    w = np.exp(r - r.max())
    w /= w.sum()
    s = len(r)
    return (f"{s} members: r mean {r.mean():.2f}, std {r.std():.2f}, min {r.min():.2f}, "
            f"max {r.max():.2f}; ESS {1 / np.sum(w**2):.1f}; CV {np.std(w * s):.2f}; "
            f"k̂ {pareto_k(r):.3f} (threshold at {s} members {min(1 - 1 / np.log10(s), 0.7):.3f})")


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("study", help="the study file (TOML)")
    parser.add_argument("out", help="the output directory of a replay of the study")
    parser.add_argument("--store", help="campaign store (default: the study's)")
    parser.add_argument("--with-scatter", action="store_true",
                        help="also r with each run's std combined with its stress's GP noise std")
    args = parser.parse_args()
    with open(args.study, "rb") as f:
        study = tomllib.load(f)
    convention = study["likelihood"].get("computational_error", "relative")
    if convention != "relative":
        sys.exit(f"{args.study}: likelihood.computational_error = {convention!r}: only \"relative\" is previewed")
    store = args.store or os.path.join(os.path.splitext(args.study)[0] + ".campaign", "campaign.sqlite")
    data = read_data(args.study, study)
    names = list(study["parameters"])
    population = np.genfromtxt(os.path.join(args.out, "basis-gp", "samples.csv"), delimiter=",", names=True)
    index = {tuple(row[n] for n in names): i for i, row in enumerate(population)}
    members, points = batch_members(store)
    complete = [(theta, runs) for theta, runs in members.items()
                if set(runs) == set(data) and all(status == "succeeded" for status, _, _ in runs.values())]
    print(f"{store}: {DESIGN} has {len(members)} members ({points} runs); {len(complete)} complete")
    missing = [theta for theta, _ in complete if theta not in index]
    if missing:
        sys.exit(f"{len(missing)} complete members are not in {args.out}/basis-gp/samples.csv: "
                 "the replay's population is not the one the batch was drawn from")
    variants = [("each run's own std (the study's likelihood)", {})]
    if args.with_scatter:
        variants.append(("each run's std combined with its stress's GP noise std", gp_noise_std(args.out)))
    for label, extra in variants:
        r = np.array([
            log_likelihood(data, runs, population["sigma_m"][index[theta]], extra)
            - population["ll"][index[theta]]
            for theta, runs in complete
        ])
        print(f"{label}:\n  {weights_summary(r)}")
    m = int(study.get("model_posterior", {}).get("replicates", 1))
    replicates = replicate_groups(store, m) if m > 1 else None
    if replicates:
        show_replicates(data, complete, replicates, m, population, index, names)
    print("model EL − datum per stress over the complete members:")
    for stress, (y, _) in data.items():
        d = np.array([runs[stress][1] - y for _, runs in complete])
        print(f"  {stress} Pa: mean {d.mean():+.4f}, std {d.std():.4f}")


def show_replicates(data, complete, replicates, m, population, index, names):
    """The pseudo-marginal step over the members whose replicates all succeeded (module docs)."""
    irregular = sorted({s for runs in replicates.values() for s in runs})
    done = [(theta, runs) for theta, runs in complete
            if theta in replicates and all(
                len(replicates[theta].get(s, [])) == m
                and all(status == "succeeded" for status, _, _ in replicates[theta][s])
                for s in irregular)]
    print(f"replicates = {m} at {', '.join(f'{s} Pa' for s in irregular)}: "
          f"{len(done)} of {len(replicates)} members have all theirs")
    if len(done) < 10:
        return
    r = []
    for theta, runs in done:
        sigma_m = population["sigma_m"][index[theta]]
        regular = {s: d for s, d in data.items() if s not in irregular}
        total = log_likelihood(regular, runs, sigma_m, {})
        for s in irregular:
            terms = np.array([log_likelihood({s: data[s]}, {s: run}, sigma_m, {})
                              for run in replicates[theta][s]])
            top = terms.max()
            total += top + np.log(np.mean(np.exp(terms - top)))
        r.append(total - population["ll"][index[theta]])
    print(f"the one pseudo-marginal step (irregular stresses' likelihoods averaged over the replicates):\n"
          f"  {weights_summary(np.array(r))}")
    theta = np.array([t for t, _ in done])
    for s in irregular:
        el = np.array([[v for _, v, _ in replicates[t][s]] for t, _ in done])
        own = np.array([[sd for _, _, sd in replicates[t][s]] for t, _ in done])
        spread = el.std(axis=1, ddof=1)
        print(f"  {s} Pa: EL spread between a member's replicates: median {np.median(spread):.4f} "
              f"(quartiles {np.percentile(spread, 25):.4f}–{np.percentile(spread, 75):.4f}); "
              f"the runs' own std: median {np.median(own):.4f}")
        x = (theta - theta.mean(axis=0)) / theta.std(axis=0)
        design = np.column_stack([np.ones(len(x)), x])
        coefficients, *_ = np.linalg.lstsq(design, np.log(np.maximum(spread, 1e-12) ** 2), rcond=None)
        print("  ln(spread²) against the standardised parameters: "
              + ", ".join(f"{n} {c:+.2f}" for n, c in zip(names, coefficients[1:])))


if __name__ == "__main__":
    main()
