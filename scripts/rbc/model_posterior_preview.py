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
that no smooth function of the parameters explains), for comparison.

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


def log_likelihood(data, runs, sigma_m, extra_std):
    """The prediction-error log-likelihood of one member's runs (relative computational error)."""
    total = 0.0
    for stress, (y, sd) in data.items():
        _, q, s = runs[stress]
        s = np.hypot(s, extra_std.get(stress, 0.0))
        variance = sd**2 + (s * y / q) ** 2 + (sigma_m * y) ** 2
        total += -0.5 * ((y - q) ** 2 / variance + np.log(2 * np.pi * variance))
    return total


def weights_summary(r):
    w = np.exp(r - r.max())
    w /= w.sum()
    return (f"{len(r)} members: r mean {r.mean():.2f}, std {r.std():.2f}, min {r.min():.2f}, "
            f"max {r.max():.2f}; ESS {1 / np.sum(w**2):.1f}; CV {np.std(w * len(w)):.2f}")


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
    print("model EL − datum per stress over the complete members:")
    for stress, (y, _) in data.items():
        d = np.array([runs[stress][1] - y for _, runs in complete])
        print(f"  {stress} Pa: mean {d.mean():+.4f}, std {d.std():.4f}")


if __name__ == "__main__":
    main()
