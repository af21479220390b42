#!/usr/bin/env python3
"""Would one GP across the abscissa pay on the red-cell studies? A replay of a study's stored
runs, round by round, with two emulators side by side (issue: the engine at scale, item 4).

    python3 -m venv .venv-adaptive && .venv-adaptive/bin/pip install -r scripts/bench/requirements-adaptive.txt
    cargo build --release -p iuq
    .venv-adaptive/bin/python scripts/bench/joint_emulator_replay.py [--study healthy] [--out DIR]

The red-cell studies run the cell model once per (θ, stress): each stress is a run group with a
GP of its own (iuq's default). The alternative tried here is one GP over (θ, ln stress) so that
a run at one stress informs the others, with the noise allowed to change with the stress: each
stress's noise variance is taken from its own GP (a two-stage heteroscedastic fit) and enters
the joint GP as a fixed per-run noise (scikit-learn's per-sample `alpha`).

Both emulators are scikit-learn GPs here (squared-exponential ARD kernel on unit-cube inputs,
standardised outputs, 3 restarts), fitted to the same runs: those the adaptive engine had made
before each recorded round (the store's designs `batch-1`, `adaptive-round-1…k-1`; no new cell
model runs). From each, the posterior of (kLink, kBend, viscosityRatio, sigma_m) under the
study's likelihood (Σ_jj = σ_d,j² + (s_j·ŷ_j/q_j)² + σ_m²·ŷ_j², docs/methods.md §4, s_j the
emulator's predictive std with its noise) by adaptive importance sampling (three rounds of a
Student-t proposal fitted to the last weighted sample, 60,000 draws each; the ESS is printed).
Reported per round: runs, each posterior's largest error of a mean and of a std in std units of
the study's converged posterior (`iuq pipeline`, its `basis-gp/samples.csv`), and each
emulator's RMSE at the study's model-posterior runs (cell-model runs at samples of the
converged posterior, design `model-posterior-1`), per stress, divided by the datum's σ_d.

This is the measurement of a trial, not of the engine: the engine's stopping rule and
acquisition are not replayed, only the runs it chose with per-stress GPs.
"""

import argparse
import json
import os
import sqlite3
import subprocess
import sys
import warnings

import numpy as np

warnings.filterwarnings("ignore")
from sklearn.gaussian_process import GaussianProcessRegressor  # noqa: E402
from sklearn.gaussian_process.kernels import RBF, WhiteKernel  # noqa: E402
from sklearn.gaussian_process.kernels import ConstantKernel as C  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
PRIOR = {
    "healthy": dict(lo=[10, 50, 1, 0.001], hi=[300, 400, 15, 0.1], column="el_healthy"),
    "tbhp": dict(lo=[10, 50, 1, 0.001], hi=[1500, 1500, 15, 0.1], column="el_tbhp"),
}
NAMES = ["kLink", "kBend", "viscosityRatio", "sigma_m"]


def load_runs(store):
    con = sqlite3.connect(f"file:{store}?mode=ro", uri=True)
    rows = con.execute(
        "select r.id, r.parameters, o.value, d.label from runs r "
        "join outputs o on o.run_id = r.id and o.name = 'el' "
        "join design_points p on p.run_id = r.id join designs d on d.id = p.design_id "
        "where r.status = 'succeeded' order by d.id, p.position"
    ).fetchall()
    seen, out = set(), []
    for rid, params, value, label in rows:
        if rid in seen:
            continue
        seen.add(rid)
        out.append((rid, json.loads(params), value, label))
    return out


def load_data(column, stresses):
    lines = [ln for ln in open(os.path.join(ROOT, "data/ektacytometry_gutierrez2018.csv")) if not ln.startswith("#")]
    head = lines[0].strip().split(",")
    rows = [dict(zip(head, map(float, ln.strip().split(",")))) for ln in lines[1:]]
    by = {round(r["stress_pa"], 2): r for r in rows}
    y = np.array([by[round(s, 2)][column] for s in stresses])
    e = np.array([by[round(s, 2)][column + "_err"] for s in stresses])
    return y, e


def gp(kernel, alpha=1e-10):
    return GaussianProcessRegressor(kernel, alpha=alpha, normalize_y=True, n_restarts_optimizer=3, random_state=0)


class PerStress:
    """One GP per stress (iuq's default emulator)."""

    def __init__(self, theta, stress, y, stresses):
        self.gps, self.noise = [], []
        for s in stresses:
            m = stress == s
            k = C(1.0) * RBF([0.3] * theta.shape[1], (1e-2, 1e2)) + WhiteKernel(1e-4, (1e-10, 1e-1))
            g = gp(k).fit(theta[m], y[m])
            self.gps.append(g)
            self.noise.append(g.kernel_.k2.noise_level * g._y_train_std**2)

    def predict(self, theta):
        out = [g.predict(theta, return_std=True) for g in self.gps]
        return np.array([o[0] for o in out]), np.array([o[1] for o in out])


class Joint:
    """One GP over (θ, ln stress) with each stress's noise variance as a fixed per-run noise."""

    def __init__(self, theta, stress, y, stresses, noise, lnrange):
        self.lnrange, self.stresses = lnrange, stresses
        self.noise = dict(zip(stresses, noise))
        z = np.column_stack([theta, self.abscissa(stress)])
        alpha = np.array([self.noise[s] for s in stress]) / np.var(y)
        alpha = np.maximum(alpha, 1e-10)
        k = C(1.0) * RBF([0.3] * z.shape[1], (1e-2, 1e2))
        self.g = gp(k, alpha).fit(z, y)

    def abscissa(self, stress):
        lo, hi = self.lnrange
        return (np.log(stress) - lo) / (hi - lo)

    def predict(self, theta):
        means, stds = [], []
        for s in self.stresses:
            z = np.column_stack([theta, np.full(len(theta), self.abscissa(s))])
            m, sd = self.g.predict(z, return_std=True)
            means.append(m)
            stds.append(np.sqrt(sd**2 + self.noise[s]))
        return np.array(means), np.array(stds)


def log_posterior(emulator, x, lo, hi, data, err):
    inside = np.all((x >= lo) & (x <= hi), axis=1)
    lp = np.full(len(x), -np.inf)
    xi = x[inside]
    theta = (xi[:, :3] - lo[:3]) / (hi[:3] - lo[:3])
    q, s = emulator.predict(theta)
    sm = xi[:, 3]
    var = err[:, None] ** 2 + (s * data[:, None] / q) ** 2 + (sm[None, :] * data[:, None]) ** 2
    r = data[:, None] - q
    ll = -0.5 * np.sum(r**2 / var + np.log(2 * np.pi * var), axis=0)
    lp[inside] = ll
    return lp


def importance_posterior(emulator, lo, hi, data, err, start_mean, start_std, rng, n=60000):
    mean, cov = np.array(start_mean), np.diag((3 * np.array(start_std)) ** 2)
    df = 5
    for _ in range(3):
        chol = np.linalg.cholesky(cov)
        z = rng.standard_normal((n, 4))
        g = rng.chisquare(df, n) / df
        x = mean + (z @ chol.T) / np.sqrt(g)[:, None]
        lp = log_posterior(emulator, x, lo, hi, data, err)
        diff = np.linalg.solve(chol, (x - mean).T)
        lq = -0.5 * (df + 4) * np.log1p(np.sum(diff**2, axis=0) / df)
        lw = lp - lq
        w = np.exp(lw - np.max(lw))
        w /= w.sum()
        mean = w @ x
        cov = 1.5 * np.cov(x.T, aweights=w) + 1e-12 * np.eye(4)
    ess = 1.0 / np.sum(w**2)
    m = w @ x
    sd = np.sqrt(w @ (x - m) ** 2)
    return m, sd, ess


def converged_posterior(study, out):
    samples = os.path.join(out, "basis-gp", "samples.csv")
    if not os.path.exists(samples):
        binary = os.environ.get("IUQ_BENCH_BIN", os.path.join(ROOT, "target/release/iuq"))
        subprocess.run([binary, "pipeline", study, "--out", out], check=True, stdout=subprocess.DEVNULL)
    x = np.loadtxt(samples, delimiter=",", skiprows=1)[:, :4]
    return x.mean(axis=0), x.std(axis=0)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--study", default="healthy", choices=sorted(PRIOR))
    ap.add_argument("--store", help="campaign.sqlite (default: the study's shipped store)")
    ap.add_argument("--report", help="the study's pipeline output (default: run iuq pipeline into DIR/report)")
    ap.add_argument("--out", default="joint-emulator-replay")
    ap.add_argument("--every", type=int, default=2, help="replay every k-th round")
    args = ap.parse_args()
    os.makedirs(args.out, exist_ok=True)
    study = os.path.join(ROOT, f"examples/rbc-{args.study}-hemocell.toml")
    store = args.store or os.path.join(ROOT, f"examples/rbc-{args.study}-hemocell.campaign/campaign.sqlite")
    truth_mean, truth_std = converged_posterior(study, args.report or os.path.join(args.out, "report"))
    prior = PRIOR[args.study]
    lo, hi = np.array(prior["lo"], float), np.array(prior["hi"], float)
    runs = load_runs(store)
    stresses = sorted({p[3] for _, p, _, _ in runs})
    data, err = load_data(prior["column"], stresses)
    lnrange = (np.log(stresses[0]), np.log(stresses[-1]))
    test = [(p, v) for _, p, v, label in runs if label.startswith("model-posterior")]
    tx = np.array([p for p, _ in test])
    ty = np.array([v for _, v in test])
    rounds = sorted({int(label.rsplit("-", 1)[1]) for *_, label in runs if label.startswith("adaptive-round-")})
    rng = np.random.default_rng(1)
    rows = []
    print(f"converged posterior: mean {np.round(truth_mean, 4)}, std {np.round(truth_std, 4)}")
    print("round runs | per-stress: mean err, std err, ESS, rmse/σd | joint: mean err, std err, ESS, rmse/σd")
    for k in [1] + rounds[args.every - 1 :: args.every] + [rounds[-1] + 1]:
        chosen = {"batch-1"} | {f"adaptive-round-{i}" for i in range(1, k)}
        use = [(p, v) for _, p, v, label in runs if label in chosen]
        x = np.array([p for p, _ in use])
        y = np.array([v for _, v in use])
        theta = (x[:, :3] - lo[:3]) / (hi[:3] - lo[:3])
        per = PerStress(theta, x[:, 3], y, stresses)
        joint = Joint(theta, x[:, 3], y, stresses, per.noise, lnrange)
        row = {"round": k, "runs": len(use)}
        for name, em in (("per_stress", per), ("joint", joint)):
            m, sd, ess = importance_posterior(em, lo, hi, data, err, truth_mean, truth_std, rng)
            tq, _ = em.predict((tx[:, :3] - lo[:3]) / (hi[:3] - lo[:3]))
            idx = np.array([stresses.index(s) for s in tx[:, 3]])
            pred = tq[idx, np.arange(len(tx))]
            rmse = [float(np.sqrt(np.mean((pred[idx == j] - ty[idx == j]) ** 2)) / err[j]) for j in range(len(stresses))]
            row[name] = {
                "mean": m.tolist(),
                "std": sd.tolist(),
                "mean_error": float(np.max(np.abs(m - truth_mean) / truth_std)),
                "std_error": float(np.max(np.abs(sd - truth_std) / truth_std)),
                "ess": float(ess),
                "rmse_over_data_std": rmse,
            }
        rows.append(row)
        p, j = row["per_stress"], row["joint"]
        print(
            f"{k:5d} {len(use):4d} | {p['mean_error']:.2f} {p['std_error']:.2f} {p['ess']:6.0f} {max(p['rmse_over_data_std']):6.2f}"
            f" | {j['mean_error']:.2f} {j['std_error']:.2f} {j['ess']:6.0f} {max(j['rmse_over_data_std']):6.2f}",
            flush=True,
        )
    with open(os.path.join(args.out, f"{args.study}.json"), "w") as f:
        json.dump({"converged_mean": truth_mean.tolist(), "converged_std": truth_std.tolist(), "rounds": rows}, f, indent=1)


if __name__ == "__main__":
    sys.exit(main())
