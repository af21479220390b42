"""GPry 4.1 (El Gammal et al. 2023) as the reference of the run-count benchmarks
(`adaptive_calibration.py`, `python_calibrate.py`): its `Runner` with default settings on a
log-likelihood, then its Monte Carlo sample of the surrogate posterior."""

import time

import numpy as np


def gpry_posterior(log_likelihood, names, bounds, seed=1, options=None):
    """Run GPry on `log_likelihood` (a list of parameter values → ln L, −inf where the model
    fails) over the box `bounds` of the parameters `names`. Returns (likelihood calls, posterior
    mean, posterior std, wall seconds)."""
    from gpry import Runner

    calls = [0]

    def counted(theta):
        calls[0] += 1
        return log_likelihood(theta)

    # GPry reads the parameters from the likelihood's signature: one named argument each.
    namespace = {"_log_likelihood": counted}
    exec(f"def loglike({', '.join(names)}):\n    return _log_likelihood([{', '.join(names)}])", namespace)
    started = time.time()
    runner = Runner(namespace["loglike"], bounds=[list(b) for b in bounds], params=list(names), seed=seed,
                    verbose=0, options=options)
    runner.run()
    runner.generate_mc_sample()
    s = runner.last_mc_samples()
    X = s["X"]
    w = s["w"] if s["w"] is not None else np.ones(len(X))
    mean = np.average(X, axis=0, weights=w)
    std = np.sqrt(np.average((X - mean) ** 2, axis=0, weights=w))
    return calls[0], mean, std, time.time() - started


def raised_initial_budget(error, dimension):
    """GPry's options for a second try when `error` is its failure to find enough finite initial
    samples (a failing region starving its initial design): ten times its default budget of
    initial evaluations, the workaround its message names. None for any other error."""
    if "initial" not in str(error):
        return None
    max_initial = int(10 * 30 * dimension ** 1.5)
    return {"max_initial": max_initial, "max_total": max(max_initial, int(70 * dimension ** 1.5))}
