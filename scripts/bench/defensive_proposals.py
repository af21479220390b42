"""Defensive second batches for a noisy model's posterior, compared on the "lure" problem.

A design study in numpy (not iuq itself): which proposal should a noisy model's second batch be
drawn from when the moment-matched correction is refused (docs/methods.md §5b)?

The problem is the one of the Rust test
`a_noisy_models_correction_lured_into_a_heavy_tail_is_refused_and_a_defensive_batch_run`, in d
parameters: the model is noisy (one run's likelihood N(y; θ + τz, σ²), z a fresh standard normal),
its averaged posterior N(y, T²·I), T² = σ² + τ²; the surrogate's posterior q is exact in every
parameter but x1, where it is a core half as wide (99.9 %) and a flat tail to the prior's bound
(0.1 %). A first batch of 400 members of q is run; the second batch of 400 is drawn from

- `tempered`: q_β ∝ π·L_s^β, β = ½·min_k σ²_q,k/m_w,k in [0.1, ½] (what iuq does since
  2026-11-28, `iuq_basis::defensive_tempering`);
- `gaussian`: N(μ_w, diag(2·m_w)) truncated to the prior box, μ_w the weighted mean and m_w,k the
  weighted second moment about the batch's mean (not multiplied by q, so q's tail is not raised);

and both batches are weighed as one sample of ½q + ½p₂ (exact normalising constants here; iuq
bridge-samples them). `one` is the first batch alone. Printed per d over 40 seeds: the mean of
x1's std estimate (exact T = 1.118), over all seeds and over the certified ones (k̂ of the raw
weights within min(1 − 1/log₁₀ S, 0.7)), the certified count and the median ESS.

    .venv-model-posterior/bin/python scripts/bench/defensive_proposals.py     # about 2 minutes

Measured 2026-11-28 (std over the certified seeds, certified of 40): d = 2: one 0.863 (17),
tempered 1.102 (39), gaussian 1.112 (39); d = 4: 0.839 (20), 1.080 (32), 1.113 (40); d = 6:
0.794 (23), 1.011 (27), 1.088 (38); d = 10: 0.814 (22), 0.955 (31), 1.060 (35).
"""
import numpy as np
from scipy.stats import norm


def khat(logw):
    """Pareto k̂ of importance log-weights: Zhang & Stephens (2009) fit to the top
    M = ⌈min(S/5, 3√S)⌉ weights' excesses, with the weakly informative prior of Vehtari et al.
    (2024)."""
    w = np.exp(logw - logw.max()); w /= w.sum()
    S = len(w); M = int(np.ceil(min(0.2*S, 3*np.sqrt(S))))
    ws = np.sort(w); tail = ws[-M:]; u = ws[-M-1]; x = tail - u
    n = len(x); xs = np.sort(x); mm = 30 + int(np.sqrt(n))
    bs = 1/xs[-1] + (1 - np.sqrt(mm/(np.arange(1, mm+1) - 0.5)))/3/xs[int(n/4 + 0.5) - 1]
    ks = np.array([-np.mean(np.log1p(-b*x)) for b in bs])
    L = n*(np.log(bs/ks) + ks - 1)
    wts = 1/np.array([np.sum(np.exp(L - l)) for l in L])
    b = np.sum(bs*wts); k = np.mean(np.log1p(-b*x))
    return (k*n + 10*0.5)/(n + 10)


sigma, tau = 1.0, 0.5
T = np.hypot(sigma, tau)
core, eps, bound = 0.5 * T, 0.001, 10.0

def setup(d):
    y = np.array([1.0, -2.0, 0.5, 3.0, -1.0, 2.0, 0.0, 1.5, -0.5, 2.5][:d])
    return y

def logq(x, y):
    out = np.zeros(len(x))
    for k in range(x.shape[1]):
        if k == 1:
            tail = np.where(x[:, 1] >= y[1], 1.0 / (bound - y[1]), 0.0)
            out += np.log((1 - eps) * norm.pdf(x[:, 1], y[1], core) + eps * tail)
        else:
            out += norm.logpdf(x[:, k], y[k], T)
    return out

def sample_q(n, y, rng):
    x = y + T * rng.standard_normal((n, len(y)))
    u = rng.random(n)
    x[:, 1] = np.where(u < eps, y[1] + (bound - y[1]) * rng.random(n), y[1] + core * rng.standard_normal(n))
    return x

grid = np.linspace(-10, 10, 200001)
def tempered_dim1(beta, y):
    dens = np.exp(beta * logq(np.column_stack([np.full_like(grid, y[0]), grid] + [np.full_like(grid, v) for v in y[2:]]), y)
                  - beta * sum(norm.logpdf(y[k], y[k], T) for k in range(len(y)) if k != 1))
    cdf = np.cumsum(dens); z = cdf[-1] * (grid[1] - grid[0]); cdf /= cdf[-1]
    return cdf, z

def log_model(x, y, rng):
    z = rng.standard_normal(x.shape)
    return -0.5 * np.sum(((y - x - tau * z) / sigma) ** 2, axis=1) - len(y) * np.log(sigma * np.sqrt(2 * np.pi))

def run(d, seed, kind, S=400):
    rng = np.random.default_rng(seed)
    y = setup(d)
    x1 = sample_q(S, y, rng)
    lq1 = logq(x1, y)
    lm1 = log_model(x1, y, rng)
    lw = lm1 - lq1
    w = np.exp(lw - lw.max()); w /= w.sum()
    mq = x1.mean(0); vq = x1.var(0); mw = (w[:, None] * (x1 - mq) ** 2).sum(0)
    if kind == "one":
        lwm, xs = lw, x1
    else:
        if kind == "tempered":
            beta = np.clip(0.5 * np.min(vq / mw), 0.1, 0.5)
            s = T / np.sqrt(beta)
            x2 = y + s * rng.standard_normal((S, d))
            cdf, z1 = tempered_dim1(beta, y)
            x2[:, 1] = np.interp(rng.random(S), cdf, grid)
            def logp2(x):
                out = np.zeros(len(x))
                for k in range(d):
                    if k == 1:
                        others = np.column_stack([np.full(len(x), y[0]), x[:, 1]] + [np.full(len(x), v) for v in y[2:]])
                        out += beta * logq(others, y) - beta * sum(norm.logpdf(y[k2], y[k2], T) for k2 in range(d) if k2 != 1) - np.log(z1)
                    else:
                        out += norm.logpdf(x[:, k], y[k], s)
                return out
        else:
            mu = (w[:, None] * x1).sum(0); s = np.sqrt(2 * mw)
            x2 = mu + s * rng.standard_normal((S, d))
            inside = np.all(np.abs(x2) < 10, axis=1)
            x2 = x2[inside]
            def logp2(x):
                return norm.logpdf(x, mu, s).sum(1)
        lm2 = log_model(x2, y, rng)
        xs = np.vstack([x1, x2]); lmall = np.concatenate([lm1, lm2])
        lmix = np.logaddexp(np.log(0.5) + logq(xs, y), np.log(0.5) + logp2(xs))
        lwm = lmall - lmix
    k = khat(lwm)
    w = np.exp(lwm - lwm.max()); w /= w.sum()
    m = (w * xs[:, 1]).sum(); sd = np.sqrt((w * (xs[:, 1] - m) ** 2).sum())
    n = len(lwm)
    return sd, k, k <= min(1 - 1 / np.log10(n), 0.7), 1 / np.sum(w ** 2)

for d in (2, 4, 6, 10):
    for kind in ("one", "tempered", "gaussian"):
        res = [run(d, s, kind) for s in range(40)]
        sd = np.array([r[0] for r in res]); cert = np.array([r[2] for r in res]); ess = np.array([r[3] for r in res])
        print(f"d={d:2} {kind:9}: x1 std mean {sd.mean():.3f} (exact {T:.3f}), over certified {sd[cert].mean() if cert.any() else float('nan'):.3f}, certified {cert.sum()}/40, ESS median {np.median(ess):.0f}")
