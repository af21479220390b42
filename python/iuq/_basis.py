"""BASIS posterior sampling (``iuq basis``) of a Python log-likelihood or model."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from typing import Any, Callable, Dict, List, Optional, Tuple

import numpy as np

from . import _native
from ._args import count, parameter_priors, real, seed_of, vector

__all__ = ["basis", "BasisResult"]


@dataclass(frozen=True)
class BasisResult:
    """The final BASIS population and its summaries, as :func:`iuq.basis` returns it.

    Attributes
    ----------
    names : list of str
        The parameters, in the order of the columns of :attr:`samples` (with the data form and
        a ``modelling_error``, the last is the modelling error ``sigma_m``).
    samples : numpy.ndarray, shape (N, d)
        Equally weighted posterior samples.
    log_likelihood, log_prior : numpy.ndarray, shape (N,)
        ln f(D | θ) and ln π(θ) of each sample.
    log_evidence : float
        ln Z, the log-evidence.
    mean, std, map : numpy.ndarray, shape (d,)
        Mean, standard deviation (ddof 0) and the sample with the largest ln f + ln π.
    map_log_likelihood, map_log_prior : float
        ln f and ln π at the MAP.
    probabilities : numpy.ndarray
        The probabilities of :attr:`quantiles` (0.025, 0.05, 0.25, 0.5, 0.75, 0.95, 0.975).
    quantiles : numpy.ndarray, shape (d, len(probabilities))
        ``quantiles[k, q]`` is quantile ``probabilities[q]`` of parameter k.
    stages : list of dict
        Each stage's diagnostics (stage 0 = the prior draws): exponent p, step, CV, ESS
        fraction, acceptance rate, ln Z so far, evaluations, failures, ….
    n_stages : int
        The stages after the prior stage (the CLI's ``stages``).
    evaluations : int
        Likelihood evaluations in all.
    converged, stop_reason, stop_message, exponent
        Whether p reached 1, why the sampler stopped, and the last exponent p.
    failures, failure_reasons, out_of_support
        Failed evaluations, their count per reason, and proposals outside the prior's support.

    Examples
    --------
    >>> import iuq
    >>> result = iuq.basis("-0.5*((x1 - 1)/0.1)^2", [(-3, 3)], samples=500, seed=0)
    >>> result.samples.shape, result.quantiles.shape
    ((500, 1), (1, 7))
    """

    names: List[str]
    samples: np.ndarray
    log_likelihood: np.ndarray
    log_prior: np.ndarray
    log_evidence: float
    mean: np.ndarray
    std: np.ndarray
    map: np.ndarray
    map_log_likelihood: float
    map_log_prior: float
    probabilities: np.ndarray
    quantiles: np.ndarray
    stages: List[Dict[str, Any]]
    n_stages: int
    evaluations: int
    converged: bool
    stop_reason: str
    stop_message: str
    exponent: float
    failures: int
    failure_reasons: Dict[str, int] = field(default_factory=dict)
    out_of_support: int = 0

    def summary(self) -> Dict[str, Dict[str, float]]:
        """MAP, mean and standard deviation per parameter.

        Returns
        -------
        dict
            ``{name: {"map": float, "mean": float, "std": float}}``, in parameter order.

        Examples
        --------
        >>> import iuq
        >>> result = iuq.basis("-0.5*((x1 - 1)/0.1)^2", [(-3, 3)], samples=500, seed=0)
        >>> sorted(result.summary()["x1"])
        ['map', 'mean', 'std']
        """
        return {
            name: {"map": float(self.map[k]), "mean": float(self.mean[k]), "std": float(self.std[k])}
            for k, name in enumerate(self.names)
        }


def basis(
    log_likelihood: Optional[Any] = None,
    bounds: Any = None,
    *,
    samples: int = 1000,
    burn: Optional[int] = None,
    max_chain: int = 1,
    seed: int = 0,
    cv_target: float = 1.0,
    proposal_scale: Optional[float] = None,
    max_stages: int = 100,
    model: Optional[Callable[[np.ndarray], Any]] = None,
    data: Any = None,
    data_std: Any = None,
    modelling_error: Optional[Tuple[float, float]] = None,
    computational_error: str = "absolute",
    measurement_error: bool = True,
    on_error: str = "raise",
) -> BasisResult:
    """Sample the posterior π(θ)·f(D | θ) with BASIS (``iuq basis``; Wu et al. 2018).

    Bayesian annealed sequential importance sampling moves a population from the prior to the
    posterior through tempered distributions and estimates the evidence on the way (the
    methods' chapter on BASIS). The likelihood is given in one of three forms:

    - ``log_likelihood`` a Python callable taking an (N, d) array of parameter vectors and
      returning ln f(D | θ) of each row, shape (N,), called once per batch;
    - ``log_likelihood`` a formula string evaluated in Rust (a study's
      ``[likelihood] log_density``);
    - the data form: ``model`` compared with ``data`` through the prediction-error likelihood.

    For a given seed the result equals ``iuq basis`` on the same study.

    Parameters
    ----------
    log_likelihood : callable or str, optional
        The log-likelihood: ``f(theta) -> (N,)`` or a formula of the parameter names. Not with
        ``model``.
    bounds : sequence, dict or SALib problem
        The priors π: ``[(lo, hi), ...]`` (uniform ``x1`` … ``xd``; an item may also be a prior
        as in a study file, ``{"normal": [0, 1]}``), ``{name: (lo, hi) or prior}``, or SALib's
        ``problem`` dict.
    samples : int, default 1000
        Population size N.
    burn : int, optional
        Fixed burn-in steps of every chain. With neither ``burn`` nor ``proposal_scale`` the
        chains move until they decorrelate, at an adapted scale (``burn = "auto"``); with either,
        ``burn`` steps (default 0) at ``proposal_scale`` (default 0.2), as the published BASIS.
    max_chain : int, default 1
        Longest chain l_max.
    seed : int, default 0
        Seed of the random streams.
    cv_target : float, default 1.0
        Coefficient of variation of the weights that sets each annealing step.
    proposal_scale : float, optional
        Scale β of the random-walk proposal (see ``burn``).
    max_stages : int, default 100
        Stages at most.
    model : callable, optional
        The data form's model: ``f(theta) -> (N, m)`` outputs, or a pair ``(values, std)`` of
        such arrays with the model's computational std.
    data : array_like, shape (m,), optional
        The data form's observations, output j compared with datum j.
    data_std : array_like, shape (m,), optional
        The measurement standard deviations: the likelihood is then exactly
        N(data | model(θ), diag(data_std²)), plus std² where the model returns ``(values, std)``.
    modelling_error : (float, float), optional
        ``(lo, hi)``: adds σ_m²·data² to each variance, σ_m ~ U(lo, hi) sampled with θ as the
        last parameter ``sigma_m``. Needed without ``data_std``.
    computational_error : {"absolute", "relative", "absolute-times-data", "none"}, default "absolute"
        How the model's std enters the variance (the methods' chapter on the likelihood).
    measurement_error : bool, default True
        ``False`` leaves ``data_std`` out of the variance.
    on_error : {"raise", "fail"}, default "raise"
        ``"raise"`` re-raises an exception of a callable; ``"fail"`` makes it a rejection,
        counted with its reason. Non-finite log-likelihoods are always rejections.

    Returns
    -------
    BasisResult
        The samples, ln Z, MAP, mean, std, quantiles and the stages' diagnostics.

    Raises
    ------
    ValueError
        If an argument is out of range (the message starts with its name), or the data form
        has neither ``data_std`` nor ``modelling_error``.
    TypeError
        If ``log_likelihood`` is neither a callable nor a string and there is no ``model``.
    RuntimeError
        If the sampler cannot go on (e.g. no prior draw has a finite log-likelihood).
    Exception
        Whatever a callable raises, with ``on_error="raise"``.

    See Also
    --------
    iuq.calibrate : the adaptive engine, for a model too expensive to call this often.

    Examples
    --------
    A Python log-likelihood on a uniform prior:

    >>> import numpy as np
    >>> import iuq
    >>> result = iuq.basis(lambda t: -0.5 * ((t[:, 0] - 1) / 0.1) ** 2, [(-3, 3)],
    ...                    samples=1000, seed=0)
    >>> result.mean.round(2), result.std.round(2)
    (array([1.]), array([0.1]))

    A model against data with their stds (the prediction-error likelihood):

    >>> t = np.linspace(0.2, 1.0, 5)
    >>> result = iuq.basis(model=lambda theta: theta[:, :1] * t, data=2.0 * t,
    ...                    data_std=np.full(5, 0.05), bounds={"a": (0, 5)}, samples=500, seed=1)
    >>> result.names, result.mean.round(2)
    (['a'], array([2.]))
    """
    names, priors = parameter_priors(bounds)
    if on_error not in ("raise", "fail"):
        raise ValueError(f"on_error: `{on_error}` is not one of raise, fail")
    function = None
    formula = None
    data_args = None
    if model is not None or data is not None:
        if log_likelihood is not None:
            raise ValueError("log_likelihood: give either log_likelihood or model and data, not both")
        if model is None or not callable(model):
            raise ValueError("model: the data form needs a callable model")
        if data is None:
            raise ValueError("data: the data form needs the observations")
        values = vector("data", data)
        std = None if data_std is None else vector("data_std", data_std, values.shape[0])
        if modelling_error is not None:
            lo, hi = (real("modelling_error", v) for v in modelling_error)
            modelling_error = (lo, hi)
        elif std is None or not measurement_error:
            raise ValueError(
                "data_std: give the measurement stds, or a modelling_error=(lo, hi) prior (σ_m "
                "relative to the data): without either the likelihood has no spread"
            )
        data_args = {
            "model": model,
            "values": [float(v) for v in values],
            "measurement_std": None if std is None else [float(v) for v in std],
            "modelling_error": modelling_error,
            "computational_error": str(computational_error),
            "measurement_error": bool(measurement_error),
        }
    elif isinstance(log_likelihood, str):
        formula = log_likelihood
    elif callable(log_likelihood):
        function = log_likelihood
    else:
        raise TypeError(
            "log_likelihood: expected a callable, a formula string, or model= and data="
        )
    raw = _native.basis(
        function,
        formula,
        data_args,
        names,
        priors,
        dict(
            samples=count("samples", samples, 2),
            burn=None if burn is None else count("burn", burn, 0, 2**20),
            max_chain=count("max_chain", max_chain, 1, 2**20),
            seed=seed_of(seed),
            cv_target=real("cv_target", cv_target),
            proposal_scale=None if proposal_scale is None else real("proposal_scale", proposal_scale),
            max_stages=count("max_stages", max_stages, 1, 2**20),
            on_error=on_error,
        ),
    )
    return result_from_raw(raw)


def result_from_raw(raw: Dict[str, Any]) -> BasisResult:
    """The :class:`BasisResult` of the native result dict."""
    return BasisResult(
        names=list(raw["names"]),
        samples=raw["samples"],
        log_likelihood=raw["log_likelihood"],
        log_prior=raw["log_prior"],
        log_evidence=raw["log_evidence"],
        mean=raw["mean"],
        std=raw["std"],
        map=raw["map"],
        map_log_likelihood=raw["map_log_likelihood"],
        map_log_prior=raw["map_log_prior"],
        probabilities=raw["probabilities"],
        quantiles=raw["quantiles"],
        stages=json.loads(raw["stages_json"]),
        n_stages=raw["n_stages"],
        evaluations=raw["evaluations"],
        converged=raw["converged"],
        stop_reason=raw["stop_reason"],
        stop_message=raw["stop_message"],
        exponent=raw["exponent"],
        failures=raw["failures"],
        failure_reasons=dict(raw["failure_reasons"]),
        out_of_support=raw["out_of_support"],
    )
