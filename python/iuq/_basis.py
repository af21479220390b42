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
    """The final BASIS population and its summaries.

    ``samples`` (N, d) are equally weighted posterior samples (columns ``names``; with the
    data form the last is the modelling error ``sigma_m``). ``log_evidence`` is ln Z.
    ``stages`` holds each stage's diagnostics (stage 0 = prior draws): exponent p, step, CV,
    ESS fraction, acceptance rate, ln Z so far, evaluations, failures, …; ``n_stages`` counts
    the stages after the prior stage (the CLI's ``stages``). ``quantiles[k, q]`` is quantile
    ``probabilities[q]`` of parameter k.
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
        """``{name: {"map", "mean", "std"}}`` per parameter."""
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
    """Sample the posterior π(θ)·f(D | θ) with BASIS (Wu et al. 2017).

    Either ``log_likelihood`` — a Python callable taking an (N, d) array of parameter vectors
    and returning ln f(D | θ) of each row, shape (N,), called once per stage; or a formula
    string evaluated in Rust (a study's ``[likelihood] log_density``) — or the data form:
    ``model`` (a callable (N, d) → (N, m), or a pair ``(values, std)`` of such arrays with the
    model's computational std) compared with ``data`` (m values) through the prediction-error
    likelihood, with measurement stds ``data_std`` and, by default, nothing else: exactly
    N(data | model(θ), diag(data_std²)), plus std² where the model returns ``(values, std)``
    (``computational_error="absolute"``; ``"relative"``, ``"absolute-times-data"`` and
    ``"none"`` are the other conventions, ``docs/methods.md`` §4). ``modelling_error=(lo, hi)``
    adds σ_m²·data² to each variance with σ_m ~ U(lo, hi) sampled with θ; without ``data_std``
    it is needed.

    ``bounds`` gives the priors π: ``[(lo, hi), ...]`` (uniform; an item may also be a prior as
    in a study file, ``{"normal": [0, 1]}``), ``{name: (lo, hi) or prior}``, or SALib's
    ``problem`` dict.
    ``samples`` N, ``burn``, ``max_chain``, ``seed``, ``cv_target``, ``proposal_scale`` and
    ``max_stages`` are the ``[sampler]`` settings: with neither ``burn`` nor ``proposal_scale``
    given the chains move until they decorrelate at an adapted scale (``burn = "auto"``,
    ``docs/methods.md`` §5), with either given they take ``burn`` steps (default 0) at scale
    ``proposal_scale`` (default 0.2). Non-finite log-likelihoods are rejections;
    ``on_error="fail"`` makes exceptions of the callable rejections too (counted with their
    reason), ``"raise"`` re-raises them. For a given seed the result equals ``iuq basis``.
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
        count("samples", samples, 2),
        None if burn is None else count("burn", burn, 0, 2**20),
        count("max_chain", max_chain, 1, 2**20),
        seed_of(seed),
        real("cv_target", cv_target),
        None if proposal_scale is None else real("proposal_scale", proposal_scale),
        count("max_stages", max_stages, 1, 2**20),
        on_error,
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
