"""Gaussian-process surrogates (``iuq gp fit|predict|validate``) on numpy arrays."""

from __future__ import annotations

import os
from typing import Optional, Sequence, Tuple, Union

import numpy as np

from . import _native
from ._args import count, matrix, seed_of, vector

__all__ = ["GaussianProcess"]

PathLike = Union[str, "os.PathLike[str]"]


class GaussianProcess:
    """A Gaussian process fitted by maximising its log marginal likelihood.

    The kernel is a squared exponential with one length scale per input (``"ard"``), one for
    all (``"isotropic"``) or the published study's (``"study-original"``), plus a noise
    variance; the hyper-parameters are found by multi-start L-BFGS-B (Rasmussen & Williams
    2006, ch. 5; ``docs/methods.md``). Inputs are mapped to the unit cube and outputs
    standardised unless switched off. ``save``/``load`` use the file format of ``iuq gp fit``,
    so files move freely between Python and the command line.

    Create one with :meth:`fit` or :meth:`load`.
    """

    __slots__ = ("_native",)

    def __init__(self, native: "_native.GaussianProcess") -> None:
        if not isinstance(native, _native.GaussianProcess):
            raise TypeError("use GaussianProcess.fit(X, y) or GaussianProcess.load(path)")
        self._native = native

    @classmethod
    def fit(
        cls,
        X,
        y,
        *,
        restarts: int = 10,
        seed: int = 0,
        kernel: str = "ard",
        scale_inputs: bool = True,
        standardize_outputs: bool = True,
        input_names: Optional[Sequence[str]] = None,
        output_name: str = "y",
    ) -> "GaussianProcess":
        """Fit a GP to the rows of ``X`` (n, d) and the values ``y`` (n,).

        ``restarts`` random starts of the optimiser in addition to the data-driven start, from
        a design seeded with ``seed`` (as ``iuq gp fit --restarts --seed``). ``input_names``
        (default ``x1`` … ``xd``) and ``output_name`` are recorded in the saved file.
        """
        X = matrix("X", X)
        y = vector("y", y)
        if y.shape[0] != X.shape[0]:
            raise ValueError(f"y: {y.shape[0]} values for {X.shape[0]} rows of X")
        if X.shape[0] < 2:
            raise ValueError("X: at least two data rows are needed")
        names = (
            [f"x{k + 1}" for k in range(X.shape[1])]
            if input_names is None
            else [str(n) for n in input_names]
        )
        if len(names) != X.shape[1]:
            raise ValueError(f"input_names: {len(names)} names for {X.shape[1]} columns of X")
        native = _native.GaussianProcess.fit(
            X,
            y,
            count("restarts", restarts, 0, 10_000),
            seed_of(seed),
            str(kernel),
            bool(scale_inputs),
            bool(standardize_outputs),
            names,
            str(output_name),
        )
        return cls(native)

    @classmethod
    def load(cls, path: PathLike) -> "GaussianProcess":
        """Read a GP file written by :meth:`save` or by ``iuq gp fit --out``."""
        return cls(_native.GaussianProcess.load(os.fspath(path)))

    def save(self, path: PathLike) -> None:
        """Write the GP file (atomically), in the format of ``iuq gp fit --out``."""
        self._native.save(os.fspath(path))

    def predict(
        self, X, return_std: bool = False, *, include_noise: bool = False
    ) -> Union[np.ndarray, Tuple[np.ndarray, np.ndarray]]:
        """Predictive mean at the rows of ``X``; with ``return_std``, also the standard deviation.

        The std is the latent function's (the CLI's ``std`` column); ``include_noise=True``
        adds the noise variance (the CLI's ``std_with_noise``).
        """
        X = matrix("X", X, self.dimension)
        mean, variance, noise = self._native.predict(X)
        if not return_std:
            return mean
        if include_noise:
            variance = variance + noise
        return mean, np.sqrt(variance)

    def q2(self, X, y) -> float:
        """Predictivity Q2 = 1 − Σ(y − ŷ)² / Σ(y − ȳ)² on a test set (``iuq gp validate``)."""
        X = matrix("X", X, self.dimension)
        y = vector("y", y, X.shape[0])
        return self._native.q2(X, y)

    @property
    def log_marginal_likelihood(self) -> float:
        """ln p(y | X, θ̂) on the working scale (unit-cube inputs, standardised outputs unless
        switched off)."""
        return self._native.log_marginal_likelihood

    @property
    def loo_q2(self) -> Optional[float]:
        """Leave-one-out Q2 of the training data (``None`` when undefined)."""
        return self._native.loo_q2

    @property
    def length_scales(self) -> np.ndarray:
        """Length scales on the working scale."""
        return np.asarray(self._native.length_scales)

    @property
    def length_scales_input_units(self) -> np.ndarray:
        """Length scales in the units of the inputs."""
        return np.asarray(self._native.length_scales_input_units)

    @property
    def signal_variance(self) -> float:
        """Signal variance on the working scale."""
        return self._native.signal_variance

    @property
    def noise_variance(self) -> float:
        """Noise variance on the working scale."""
        return self._native.noise_variance

    @property
    def input_names(self) -> list:
        """Names of the inputs."""
        return self._native.input_names

    @property
    def output_name(self) -> str:
        """Name of the output."""
        return self._native.output_name

    @property
    def dimension(self) -> int:
        """Number of inputs d."""
        return self._native.dimension

    @property
    def n_training(self) -> int:
        """Number of training points."""
        return self._native.n_training

    @property
    def warnings(self) -> list:
        """Warnings of the fit (a degenerate optimum, a poor leave-one-out Q2, …)."""
        return self._native.warnings

    def __repr__(self) -> str:
        return (
            f"GaussianProcess(dimension={self.dimension}, n_training={self.n_training}, "
            f"log_marginal_likelihood={self.log_marginal_likelihood:.6g})"
        )
