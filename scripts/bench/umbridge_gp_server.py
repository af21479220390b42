#!/usr/bin/env python3
"""The Python reference for the UM-Bridge load check: a GP bank served by the `umbridge` package.

Usage: python3 scripts/bench/umbridge_gp_server.py BANK.json NAME PORT [--workers N]

Loads a GP bank written by `iuq bench basis-gp-bank --out DIR` (DIR/bank.json) and serves, as
model NAME, the same answers as `iuq serve umbridge --surrogate BANK.json`: per GP the
posterior mean ȳ + s·k*ᵀα (and, with config {"computational_std": true}, the predictive std
√(s²·(c − ‖L⁻¹k*‖²) + s²σ²) as a second vector), with K = c·R + (σ² + jitter)·I factorised
once by Cholesky (numpy/scipy, on the same scaled inputs and standardised outputs). Like the
Rust server, a request without the std computes only the means. Listens on 127.0.0.1 only.
"""
import argparse
import functools
import json

import numpy as np
import scipy.linalg
import umbridge
import umbridge.um


class Gp:
    def __init__(self, saved):
        h = saved["hyperparameters"]
        scaling = saved["input_scaling"]
        out = saved["output_scaling"]
        self.lower = np.array(scaling["lower"])
        self.range = np.array(scaling["range"])
        self.mean, self.scale = out["mean"], out["std"]
        d = len(self.lower)
        ls = np.array(h["length_scales"], dtype=float)
        self.inv_l2 = 1.0 / (np.full(d, ls[0]) if ls.size == 1 else ls) ** 2
        self.c = h["signal_variance"]
        self.noise = h["noise_variance"]
        self.x = (np.array(saved["training_inputs"]) - self.lower) / self.range
        y = (np.array(saved["training_outputs"]) - self.mean) / self.scale
        diff = self.x[:, None, :] - self.x[None, :, :]
        k = self.c * np.exp(-0.5 * np.einsum("ijk,k->ij", diff * diff, self.inv_l2))
        k[np.diag_indices_from(k)] += self.noise + saved["jitter"]
        self.chol = np.linalg.cholesky(k)
        self.alpha = scipy.linalg.cho_solve((self.chol, True), y)

    def kstar(self, point):
        xs = (np.asarray(point) - self.lower) / self.range
        diff = self.x - xs
        return self.c * np.exp(-0.5 * (diff * diff) @ self.inv_l2)

    def predict_mean(self, point):
        return self.mean + self.scale * (self.kstar(point) @ self.alpha)

    def predict(self, point):
        kstar = self.kstar(point)
        mean = self.mean + self.scale * (kstar @ self.alpha)
        v = scipy.linalg.solve_triangular(self.chol, kstar, lower=True, check_finite=False)
        variance = max(self.c - v @ v, 0.0) * self.scale**2
        return mean, np.sqrt(variance + self.scale**2 * self.noise)


class GpBankModel(umbridge.Model):
    def __init__(self, name, bank):
        super().__init__(name)
        self.inputs = bank["input_names"]
        self.gps = [Gp(g) for g in bank["gps"]]

    def get_input_sizes(self, config):
        return [len(self.inputs)]

    def get_output_sizes(self, config):
        m = len(self.gps)
        return [m, m] if config.get("computational_std") else [m]

    def __call__(self, parameters, config):
        if config.get("computational_std"):
            predictions = [gp.predict(parameters[0]) for gp in self.gps]
            return [[float(p[0]) for p in predictions], [float(p[1]) for p in predictions]]
        return [[float(gp.predict_mean(parameters[0])) for gp in self.gps]]

    def supports_evaluate(self):
        return True


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("bank")
    parser.add_argument("name")
    parser.add_argument("port", type=int)
    parser.add_argument("--workers", type=int, default=1)
    args = parser.parse_args()
    with open(args.bank) as f:
        model = GpBankModel(args.name, json.load(f))
    umbridge.um.web.run_app = functools.partial(umbridge.um.web.run_app, host="127.0.0.1", print=None)
    umbridge.serve_models([model], port=args.port, max_workers=args.workers)


if __name__ == "__main__":
    main()
