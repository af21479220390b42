#!/usr/bin/env python3
"""iuq from Python in one page: a design, a Gaussian-process surrogate, Sobol' indices and a
BASIS posterior, with numpy arrays and plain Python functions as the model.

    pip install ./python          # from the repository root (builds the Rust extension)
    python examples/python/quickstart.py

The "simulator" is the Ishigami function; in practice it is any Python function taking an
(n, d) array of parameter vectors and returning (n,) or (n, m) outputs.
"""

import numpy as np

import iuq

PI = np.pi
BOUNDS = [(-PI, PI)] * 3


def simulator(x: np.ndarray) -> np.ndarray:
    """Ishigami (a = 7, b = 0.1), evaluated on a batch of rows."""
    return np.sin(x[:, 0]) + 7 * np.sin(x[:, 1]) ** 2 + 0.1 * x[:, 2] ** 4 * np.sin(x[:, 0])


# 1. A space-filling design and the training runs (same points as `iuq design lhs --seed 1`).
x_train = iuq.design.lhs(120, 3, seed=1, bounds=BOUNDS)
y_train = simulator(x_train)

# 2. A Gaussian-process surrogate, checked on fresh points and saved in the CLI's format.
gp = iuq.GaussianProcess.fit(x_train, y_train, restarts=5, seed=0)
x_test = iuq.design.sobol(256, 3, seed=2, bounds=BOUNDS)
mean, std = gp.predict(x_test, return_std=True)
print(f"GP: log marginal likelihood {gp.log_marginal_likelihood:.2f}, "
      f"Q2 on 256 test points {gp.q2(x_test, simulator(x_test)):.3f}, "
      f"mean predictive std {std.mean():.3f}")

# 3. Sobol' indices of the simulator itself (one batch of N(d + 2) rows) and of the surrogate.
for label, model in [("simulator", simulator), ("GP surrogate", gp.predict)]:
    s = iuq.sobol(model, BOUNDS, n=2048, seed=0, outputs=1)
    print(f"Sobol' ({label}): S1 = {np.round(s.S1, 3)} ± {np.round(s.S1_conf, 3)}, "
          f"ST = {np.round(s.ST, 3)}")

# 4. A posterior with BASIS: which (x1, x2, x3) explain an observation y = 6 ± 0.5?
def log_likelihood(theta: np.ndarray) -> np.ndarray:
    """ln f(y_obs | θ) of a batch of parameter vectors, on the surrogate."""
    return -0.5 * ((gp.predict(theta) - 6.0) / 0.5) ** 2


posterior = iuq.basis(log_likelihood, BOUNDS, samples=2000, seed=0)
print(f"BASIS: ln Z = {posterior.log_evidence:.3f} after {posterior.n_stages} stages "
      f"({posterior.evaluations} likelihood evaluations)")
for name, row in posterior.summary().items():
    print(f"  {name}: mean {row['mean']:+.3f}, std {row['std']:.3f}, MAP {row['map']:+.3f}")
