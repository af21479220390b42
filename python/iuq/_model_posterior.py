"""The model's own posterior as arrays: the weighted members ``iuq pipeline --model-posterior``
writes to ``model-posterior/samples.csv``, and an ArviZ view of them."""

from __future__ import annotations

import csv
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Dict, List, Optional

import numpy as np

from ._args import count, seed_of

__all__ = ["ModelPosteriorSamples"]

#: The columns of ``samples.csv`` after the parameters' (``docs/methods.md`` §5b).
_WEIGHT_COLUMNS = ("weight", "log_weight", "raw_log_weight", "ll_model", "ll_surrogate", "lp")


@dataclass(frozen=True)
class ModelPosteriorSamples:
    """The members of the model's own posterior with their importance weights.

    What ``iuq pipeline --model-posterior`` writes to ``model-posterior/samples.csv``, as
    arrays: :attr:`iuq.PipelineResult.model_posterior_samples` and
    :attr:`iuq.CalibrationResult.model_posterior_samples` are of this class.

    Parameters
    ----------
    names : list of str
        The parameters' names (``sigma_m`` too when the modelling error is sampled).
    samples : numpy.ndarray, shape (n, p)
        The members' parameters, columns in the order of ``names``.
    weights : numpy.ndarray, shape (n,)
        The members' normalised Pareto-smoothed importance weights (sum 1), so that
        ``weights @ samples`` is the posterior mean.
    log_likelihood : numpy.ndarray, shape (n,)
        The model's own log-likelihood at each member (−inf where its run failed).
    log_prior : numpy.ndarray, shape (n,)
        The log prior density at each member.
    summary : dict, optional
        The method's summary (``iuq pipeline --json``'s ``model_posterior``: k̂ and its
        threshold, the effective sample size, the Monte Carlo standard errors, whether it is
        certified, …).

    See Also
    --------
    iuq.calibrate : ``model_posterior=True`` computes one for a Python function.
    iuq.Study.run : ``model_posterior=True`` computes one for a study file.

    Examples
    --------
    >>> import numpy as np
    >>> import iuq
    >>> members = iuq.ModelPosteriorSamples(
    ...     names=["k"], samples=np.array([[0.2], [0.3], [0.4]]),
    ...     weights=np.array([0.25, 0.5, 0.25]), log_likelihood=np.array([-1.0, -0.5, -1.0]),
    ...     log_prior=np.zeros(3), summary={"certified": True})
    >>> members.mean
    array([0.3])
    >>> members.std.round(4)
    array([0.0707])
    """

    names: List[str]
    samples: np.ndarray
    weights: np.ndarray
    log_likelihood: np.ndarray
    log_prior: np.ndarray
    summary: Dict[str, Any] = field(default_factory=dict, repr=False)

    @property
    def mean(self) -> np.ndarray:
        """The weighted mean of each column of :attr:`samples`, shape (p,).

        The summary's ``mean`` and ``std`` are these, except where ``summary["paired"]`` is
        true: one certified step from a uniform subset of the surrogate's posterior samples,
        whose moments the summary then pairs with the members' (the surrogate samples' moments
        plus the shift the weights give the members', a control variate with a smaller Monte
        Carlo error; ``docs/methods/model-posterior.md``).
        """
        return self.weights @ self.samples

    @property
    def std(self) -> np.ndarray:
        """The weighted standard deviation of each column of :attr:`samples`, shape (p,)."""
        centred = self.samples - self.mean
        return np.sqrt(self.weights @ (centred * centred))

    def resample(self, draws: Optional[int] = None, seed: int = 0) -> np.ndarray:
        """Indices of equally weighted draws from the members, by systematic resampling.

        One uniform offset from ``seed`` (Kitagawa 1996): member i is drawn ⌊draws·wᵢ⌋ or
        ⌈draws·wᵢ⌉ times, a member of weight 0 never.

        Parameters
        ----------
        draws : int, optional
            Number of draws (default: as many as there are members).
        seed : int, default 0
            Seed of the offset.

        Returns
        -------
        numpy.ndarray of int, shape (draws,)
            Member indices, in increasing order; ``samples[indices]`` are the draws.

        Raises
        ------
        ValueError
            If ``draws`` is not a positive integer or there are no members.

        Examples
        --------
        >>> import numpy as np
        >>> import iuq
        >>> members = iuq.ModelPosteriorSamples(
        ...     names=["k"], samples=np.array([[0.2], [0.3], [0.4]]),
        ...     weights=np.array([0.25, 0.5, 0.25]), log_likelihood=np.zeros(3), log_prior=np.zeros(3))
        >>> members.resample(4, seed=0)
        array([0, 1, 1, 2])
        """
        n = len(self.weights) if draws is None else count("draws", draws, 1)
        seed = seed_of(seed)
        if len(self.weights) == 0:
            raise ValueError("draws: the model posterior has no members to draw from")
        cumulative = np.cumsum(self.weights)
        offset = np.random.default_rng(seed).uniform()
        positions = (offset + np.arange(n)) / n * cumulative[-1]
        return np.searchsorted(cumulative, positions, side="right").clip(max=len(self.weights) - 1)

    def to_arviz(self, draws: Optional[int] = None, seed: int = 0, **groups: Any):
        """ArviZ ``InferenceData`` of the model's posterior (needs ``arviz``).

        One chain of equally weighted draws resampled from the members (:meth:`resample`; copies
        of a member repeat it), with ``sample_stats`` ``lp`` (as in
        :meth:`iuq.CalibrationResult.to_arviz`: the log-likelihood, here the model's own, at each
        draw) and ``log_weight`` (the draw's member's normalised log-weight). ArviZ reads the draws
        as an unweighted sample, so its own ``ess`` counts the copies; the method's effective
        sample size, k̂ and certificate are the posterior group's attributes (``pareto_k``,
        ``pareto_k_threshold``, ``effective_sample_size``, ``certified``).

        Parameters
        ----------
        draws : int, optional
            Number of draws (default: as many as there are members).
        seed : int, default 0
            Seed of the resampling.
        **groups
            Further arguments of ``arviz.from_dict`` (``observed_data``, ``coords``, ``dims``, …).

        Returns
        -------
        arviz.InferenceData
            Groups ``posterior`` and ``sample_stats``, and those of ``groups``.

        Raises
        ------
        ImportError
            If ArviZ is not installed (``pip install "./python[arviz]"``).

        Examples
        --------
        >>> import numpy as np
        >>> import iuq
        >>> members = iuq.ModelPosteriorSamples(
        ...     names=["k"], samples=np.array([[0.2], [0.3], [0.4]]),
        ...     weights=np.array([0.25, 0.5, 0.25]), log_likelihood=np.zeros(3), log_prior=np.zeros(3),
        ...     summary={"certified": True})
        >>> idata = members.to_arviz(draws=8)
        >>> idata.posterior["k"].shape, idata.posterior.attrs["certified"]
        ((1, 8), 1)
        """
        import arviz as az

        chosen = self.resample(draws, seed)
        posterior = {n: self.samples[None, chosen, k] for k, n in enumerate(self.names)}
        with np.errstate(divide="ignore"):
            log_weight = np.log(self.weights[chosen])
        stats = {
            "lp": self.log_likelihood[None, chosen],
            "log_weight": log_weight[None, :],
        }
        # Numbers only: netCDF has no booleans (``certified`` is 1 or 0).
        attrs = {
            key: float(self.summary[key])
            for key in ("pareto_k", "pareto_k_threshold", "effective_sample_size")
            if isinstance(self.summary.get(key), (int, float))
        }
        if "certified" in self.summary:
            attrs["certified"] = int(bool(self.summary["certified"]))
        attrs["source"] = "model posterior (iuq --model-posterior), systematic resample"
        return az.from_dict(posterior=posterior, sample_stats=stats, posterior_attrs=attrs, **groups)


def read_model_posterior(out: Path, summary: Optional[Dict[str, Any]]) -> Optional[ModelPosteriorSamples]:
    """The members in ``out/model-posterior/samples.csv`` (``None`` where the pipeline made no
    model posterior by importance stages, e.g. without ``--model-posterior`` or with
    ``method = "basis"``). Columns by position: the parameters, then ``_WEIGHT_COLUMNS``."""
    path = Path(out) / "model-posterior" / "samples.csv"
    if summary is None or not path.is_file():
        return None
    with open(path, newline="") as f:
        header = next(csv.reader(f), [])
    p = len(header) - len(_WEIGHT_COLUMNS)
    if p < 1 or tuple(header[p:]) != _WEIGHT_COLUMNS:
        raise ValueError(f"{path}: expected the parameters' columns, then {', '.join(_WEIGHT_COLUMNS)}")
    table = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2, dtype=np.float64)
    column = {name: table[:, p + k] for k, name in enumerate(_WEIGHT_COLUMNS)}
    weights = column["weight"]
    return ModelPosteriorSamples(
        names=header[:p],
        samples=table[:, :p].copy(),
        weights=weights / weights.sum(),
        log_likelihood=column["ll_model"].copy(),
        log_prior=column["lp"].copy(),
        summary=dict(summary),
    )
