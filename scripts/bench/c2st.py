#!/usr/bin/env python3
"""The classifier two-sample test of sbibm (Lueckmann et al. 2021, "Benchmarking simulation-based
inference"; Lopez-Paz & Oquab 2017): the cross-validated accuracy of an MLP telling samples of a
posterior from samples of the reference. 0.5 means the two cannot be told apart; 1.0 that they
do not overlap.

As sbibm's `c2st`: both sets z-scored by the reference's mean and std, an MLP with two hidden
layers of 10·d ReLU units (adam, up to 10,000 iterations), 5-fold stratified cross-validation,
the mean accuracy. Sets are cut to the same size (at most `n`, drawn without replacement with
`seed`).

    python3 scripts/bench/c2st.py SAMPLES.csv REFERENCE.csv [--columns a,b,c] [--n 5000]
"""

import argparse
import sys

import numpy as np


def c2st(samples, reference, seed=1, n_folds=5, n=5000):
    """C2ST accuracy of `samples` (k, d) against `reference` (m, d)."""
    from sklearn.model_selection import StratifiedKFold, cross_val_score
    from sklearn.neural_network import MLPClassifier

    rng = np.random.default_rng(seed)
    size = min(len(samples), len(reference), n)
    x = samples[rng.choice(len(samples), size, replace=False)]
    y = reference[rng.choice(len(reference), size, replace=False)]
    mean, std = y.mean(axis=0), y.std(axis=0)
    x, y = (x - mean) / std, (y - mean) / std
    d = x.shape[1]
    classifier = MLPClassifier(
        activation="relu",
        hidden_layer_sizes=(10 * d, 10 * d),
        max_iter=10000,
        solver="adam",
        random_state=seed,
    )
    data = np.concatenate([x, y])
    target = np.concatenate([np.zeros(size), np.ones(size)])
    folds = StratifiedKFold(n_splits=n_folds, shuffle=True, random_state=seed)
    return float(np.mean(cross_val_score(classifier, data, target, cv=folds, scoring="accuracy")))


def moment_errors(samples, reference):
    """(largest |mean − reference mean| in reference stds, std ratios) per column."""
    mean, std = reference.mean(axis=0), reference.std(axis=0)
    return np.abs(samples.mean(axis=0) - mean) / std, samples.std(axis=0) / std


def read(path, columns):
    import csv

    with open(path) as f:
        rows = list(csv.reader(f))
    header = rows[0]
    index = [header.index(c) for c in columns]
    return np.array([[float(r[i]) for i in index] for r in rows[1:]])


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("samples")
    parser.add_argument("reference")
    parser.add_argument("--columns", help="comma-separated columns (default: the reference's, less ll and lp)")
    parser.add_argument("--n", type=int, default=5000)
    args = parser.parse_args()
    with open(args.reference) as f:
        header = f.readline().strip().split(",")
    columns = args.columns.split(",") if args.columns else [c for c in header if c not in ("ll", "lp")]
    x, y = read(args.samples, columns), read(args.reference, columns)
    mean_error, std_ratio = moment_errors(x, y)
    print(f"c2st {c2st(x, y, n=args.n):.3f}  largest mean error {mean_error.max():.3f} sd  std ratios "
          + " ".join(f"{c}={r:.3f}" for c, r in zip(columns, std_ratio)))


if __name__ == "__main__":
    sys.exit(main())
