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
    variance; the hyper-parameters are found by multi-start bounded L-BFGS (Rasmussen &
    Williams 2006, ch. 5; the methods' chapter on GP surrogates). Inputs are mapped to the unit
    cube and outputs standardised unless switched off. :meth:`save` and :meth:`load` use the
    file format of ``iuq gp fit``, so files move freely between Python and the command line.

    Create one with :meth:`fit` or :meth:`load`; the constructor is not public.

    Examples
    --------
    >>> import numpy as np
    >>> import iuq
    >>> X = iuq.design.lhs(20, 2, seed=1)
    >>> gp = iuq.GaussianProcess.fit(X, np.sin(3 * X[:, 0]) + X[:, 1], restarts=2, seed=0)
    >>> gp.dimension, gp.n_training
    (2, 20)
    >>> X_test = iuq.design.sobol(64, 2, seed=2)
    >>> bool(gp.q2(X_test, np.sin(3 * X_test[:, 0]) + X_test[:, 1]) > 0.99)
    True
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
        """Fit a GP to the rows of ``X`` and the values ``y`` (``iuq gp fit``).

        Parameters
        ----------
        X : array_like, shape (n, d)
            Training inputs, one row per point; at least two rows.
        y : array_like, shape (n,)
            Training outputs.
        restarts : int, default 10
            Random starts of the optimiser in addition to the data-driven start, from a Latin
            hypercube seeded with ``seed`` (as ``iuq gp fit --restarts --seed``).
        seed : int, default 0
            Seed of the random starts.
        kernel : {"ard", "isotropic", "study-original"}, default "ard"
            One length scale per input, one for all, or the published IUQ study's kernel.
        scale_inputs : bool, default True
            Map the inputs onto the unit cube by the training minimum and range.
        standardize_outputs : bool, default True
            Standardise the outputs by the training mean and standard deviation.
        input_names : sequence of str, optional
            Names of the inputs, recorded in the saved file (default ``x1`` … ``xd``).
        output_name : str, default "y"
            Name of the output, recorded in the saved file.

        Returns
        -------
        GaussianProcess
            The fitted GP; :attr:`warnings` names doubtful fits (an optimum at a bound, a poor
            leave-one-out Q2).

        Raises
        ------
        ValueError
            If ``X`` is not a 2-D array of finite numbers with at least two rows, ``y`` does not
            have one value per row, the kernel is unknown, or ``input_names`` does not name every
            column.

        Examples
        --------
        >>> import numpy as np
        >>> import iuq
        >>> X = iuq.design.lhs(20, 2, seed=1)
        >>> gp = iuq.GaussianProcess.fit(X, X[:, 0] ** 2 + X[:, 1], restarts=2, seed=0,
        ...                              input_names=["a", "b"], output_name="f")
        >>> gp.input_names, gp.output_name
        (['a', 'b'], 'f')
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
            dict(
                restarts=count("restarts", restarts, 0, 10_000),
                seed=seed_of(seed),
                kernel=str(kernel),
                scale_inputs=bool(scale_inputs),
                standardize_outputs=bool(standardize_outputs),
            ),
            names,
            str(output_name),
        )
        return cls(native)

    @classmethod
    def load(cls, path: PathLike) -> "GaussianProcess":
        """Read a GP file written by :meth:`save` or by ``iuq gp fit --out``.

        Parameters
        ----------
        path : str or os.PathLike
            The GP file (JSON).

        Returns
        -------
        GaussianProcess
            The GP, predicting exactly as the one that was saved.

        Raises
        ------
        ValueError
            If the file cannot be read or is not a GP file.

        Examples
        --------
        >>> import os, tempfile
        >>> import numpy as np
        >>> import iuq
        >>> X = iuq.design.lhs(12, 1, seed=1)
        >>> gp = iuq.GaussianProcess.fit(X, np.sin(X[:, 0]), restarts=1)
        >>> path = os.path.join(tempfile.mkdtemp(), "gp.json")
        >>> gp.save(path)
        >>> bool(np.array_equal(iuq.GaussianProcess.load(path).predict(X), gp.predict(X)))
        True
        """
        return cls(_native.GaussianProcess.load(os.fspath(path)))

    def save(self, path: PathLike) -> None:
        """Write the GP file (atomically), in the format of ``iuq gp fit --out``.

        The file is readable by :meth:`load`, ``iuq gp predict --model`` and
        ``iuq serve umbridge --surrogate``.

        Parameters
        ----------
        path : str or os.PathLike
            The file to write (replaced if it exists).

        Raises
        ------
        ValueError
            If the file cannot be written.

        Examples
        --------
        >>> import os, tempfile
        >>> import numpy as np
        >>> import iuq
        >>> gp = iuq.GaussianProcess.fit(iuq.design.lhs(12, 1, seed=1), np.arange(12.0), restarts=1)
        >>> path = os.path.join(tempfile.mkdtemp(), "gp.json")
        >>> gp.save(path)
        >>> os.path.exists(path)
        True
        """
        self._native.save(os.fspath(path))

    def predict(
        self, X, return_std: bool = False, *, include_noise: bool = False
    ) -> Union[np.ndarray, Tuple[np.ndarray, np.ndarray]]:
        """Predictive mean at the rows of ``X``, and with ``return_std`` the standard deviation.

        Parameters
        ----------
        X : array_like, shape (n, d)
            Points to predict at, in the units of the training inputs.
        return_std : bool, default False
            Also return the predictive standard deviation.
        include_noise : bool, default False
            With ``return_std``: the std of a new observation, the latent function's plus the noise
            variance (the CLI's ``std_with_noise``); by default the latent function's (``std``).

        Returns
        -------
        mean : numpy.ndarray, shape (n,)
            The predictive mean.
        std : numpy.ndarray, shape (n,)
            The predictive standard deviation (only with ``return_std=True``).

        Raises
        ------
        ValueError
            If ``X`` does not have :attr:`dimension` columns or holds non-finite values.

        Examples
        --------
        >>> import numpy as np
        >>> import iuq
        >>> X = iuq.design.lhs(20, 2, seed=1)
        >>> gp = iuq.GaussianProcess.fit(X, np.sin(3 * X[:, 0]) + X[:, 1], restarts=2, seed=0)
        >>> mean, std = gp.predict([[0.5, 0.5], [0.1, 0.9]], return_std=True)
        >>> mean.shape, std.shape
        ((2,), (2,))
        >>> bool(abs(mean[0] - (np.sin(1.5) + 0.5)) < 0.01)
        True
        """
        X = matrix("X", X, self.dimension)
        mean, variance, noise = self._native.predict(X)
        if not return_std:
            return mean
        if include_noise:
            variance = variance + noise
        return mean, np.sqrt(variance)

    def q2(self, X, y) -> float:
        """Predictivity on a test set (``iuq gp validate``).

        Q2 = 1 − Σ(y − ŷ)² / Σ(y − ȳ)²: 1 is perfect, 0 no better than the test set's mean.

        Parameters
        ----------
        X : array_like, shape (n, d)
            Test inputs.
        y : array_like, shape (n,)
            The model's values there.

        Returns
        -------
        float
            Q2 of the predictive mean.

        Raises
        ------
        ValueError
            If ``X`` does not have :attr:`dimension` columns or ``y`` does not have one value per row.

        Examples
        --------
        >>> import numpy as np
        >>> import iuq
        >>> X = iuq.design.lhs(20, 2, seed=1)
        >>> gp = iuq.GaussianProcess.fit(X, X[:, 0] + X[:, 1], restarts=2, seed=0)
        >>> X_test = iuq.design.sobol(32, 2, seed=3)
        >>> bool(gp.q2(X_test, X_test[:, 0] + X_test[:, 1]) > 0.99)
        True
        """
        X = matrix("X", X, self.dimension)
        y = vector("y", y, X.shape[0])
        return self._native.q2(X, y)

    @property
    def log_marginal_likelihood(self) -> float:
        """ln p(y | X, θ̂) at the fitted hyper-parameters, on the working scale.

        The working scale is that of the fit: unit-cube inputs and standardised outputs, unless
        switched off.
        """
        return self._native.log_marginal_likelihood

    @property
    def loo_q2(self) -> Optional[float]:
        """Leave-one-out Q2 of the training data, without refitting (``None`` when undefined)."""
        return self._native.loo_q2

    @property
    def length_scales(self) -> np.ndarray:
        """Length scales on the working scale (unit-cube inputs), one per input (ARD)."""
        return np.asarray(self._native.length_scales)

    @property
    def length_scales_input_units(self) -> np.ndarray:
        """Length scales in the units of the inputs."""
        return np.asarray(self._native.length_scales_input_units)

    @property
    def signal_variance(self) -> float:
        """Signal variance c on the working scale."""
        return self._native.signal_variance

    @property
    def noise_variance(self) -> float:
        """Noise variance σ² on the working scale."""
        return self._native.noise_variance

    @property
    def input_names(self) -> list:
        """Names of the inputs (``x1`` … ``xd`` unless given to :meth:`fit`)."""
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
        """Warnings of the fit (an optimum at a bound, a poor leave-one-out Q2, …)."""
        return self._native.warnings

    def __repr__(self) -> str:
        return (
            f"GaussianProcess(dimension={self.dimension}, n_training={self.n_training}, "
            f"log_marginal_likelihood={self.log_marginal_likelihood:.6g})"
        )
