#!/usr/bin/env python3
"""How smooth is the cell model's elongation in its parameters? Pairs of nearly equal runs, per stress.

Reads a campaign store of an `rbc-shear` study (read-only) and, for every stress, takes every
pair of succeeded runs whose parameters lie within `--within` of each other (Euclidean distance
with each parameter scaled by its prior range, read from the study file) and prints how much
their elongation index differs: median, 90 % quantile and largest |ΔEL|, and the pairs that
differ most. A smooth output differs little between such neighbours (about its gradient times
the distance); an output that jumps between nearby parameters cannot be learned by any smooth
surrogate faster than its spread over √runs (docs/cell-model-high-stress.md).

    python3 scripts/rbc/neighbour_spread.py examples/rbc-healthy-hemocell.toml
    python3 scripts/rbc/neighbour_spread.py examples/rbc-tbhp-hemocell.toml --within 0.03

The store is the study's campaign (`<study stem>.campaign/campaign.sqlite`) unless `--store`
names another; it is opened read-only, so a running campaign is not disturbed. Needs numpy.
"""

import argparse
import json
import os
import sqlite3
import sys
import tomllib

import numpy as np


def prior_ranges(study_path):
    """Names and (low, high) of the study's uniform priors, in the store's parameter order."""
    with open(study_path, "rb") as f:
        study = tomllib.load(f)
    names, ranges = [], []
    for name, prior in study["parameters"].items():
        if "uniform" not in prior:
            sys.exit(f"{study_path}: parameters.{name}: only uniform priors are scaled by this script")
        low, high = prior["uniform"]
        names.append(name)
        ranges.append((float(low), float(high)))
    return names, np.array(ranges)


def runs_by_stress(store):
    """{stress: (θ array, EL array)} of the store's succeeded runs (stress is the last column)."""
    uri = f"file:{store}?mode=ro"
    with sqlite3.connect(uri, uri=True) as db:
        rows = db.execute(
            "select r.parameters, o.value from runs r join outputs o on o.run_id = r.id "
            "where r.status = 'succeeded' and o.name = 'el'"
        ).fetchall()
    grouped = {}
    for parameters, el in rows:
        p = json.loads(parameters)
        grouped.setdefault(round(p[-1], 6), []).append((p[:-1], el))
    return {s: (np.array([t for t, _ in v]), np.array([e for _, e in v])) for s, v in grouped.items()}


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("study", help="the study file (TOML) whose priors scale the distance")
    parser.add_argument("--store", help="campaign store (default: the study's)")
    parser.add_argument("--within", type=float, default=0.02,
                        help="largest scaled distance of a pair (default 0.02: 2 %% of each prior range)")
    parser.add_argument("--show", type=int, default=3, help="pairs that differ most, per stress (default 3)")
    args = parser.parse_args()
    store = args.store or os.path.join(
        os.path.splitext(args.study)[0] + ".campaign", "campaign.sqlite")
    if not os.path.exists(store):
        sys.exit(f"{store}: no campaign store (run the study, or name one with --store)")
    names, ranges = prior_ranges(args.study)
    print(f"{store}: pairs of runs within {args.within} of each other "
          f"({', '.join(names)} scaled by their prior ranges)")
    print("| stress | runs | pairs | median abs(dEL) | 90 % | largest |")
    print("|---|---|---|---|---|---|")
    largest = {}
    for stress, (theta, el) in sorted(runs_by_stress(store).items()):
        scaled = (theta - ranges[:, 0]) / (ranges[:, 1] - ranges[:, 0])
        distance = np.sqrt(((scaled[:, None, :] - scaled[None, :, :]) ** 2).sum(-1))
        i, j = np.where(np.triu(distance <= args.within, k=1))
        if len(i) == 0:
            print(f"| {stress} | {len(el)} | 0 | – | – | – |")
            continue
        d = np.abs(el[i] - el[j])
        print(f"| {stress} | {len(el)} | {len(i)} | {np.median(d):.4f} | "
              f"{np.quantile(d, 0.9):.4f} | {d.max():.4f} |")
        order = np.argsort(-d)[: args.show]
        largest[stress] = [(theta[i[k]], theta[j[k]], el[i[k]], el[j[k]]) for k in order]
    for stress, pairs in largest.items():
        print(f"\n{stress}: the pairs that differ most ({', '.join(names)} → EL)")
        for a, b, ea, eb in pairs:
            print(f"  {np.round(a, 2)} → {ea:.3f}   {np.round(b, 2)} → {eb:.3f}")


if __name__ == "__main__":
    main()
