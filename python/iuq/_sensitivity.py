"""Sobol' sensitivity indices (``iuq sobol``) of a Python model or of formulas."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable, Dict, List, Mapping, Optional, Union

import numpy as np

from . import _native
from ._args import count, output_count, parameter_priors, prior_centre, real, seed_of

__all__ = ["sobol", "SobolResult"]


@dataclass(frozen=True)
class SobolResult:
    """First-order (``S1``) and total (``ST``) Sobol' indices with confidence half-widths.

    With one output the arrays have shape (d,); with m outputs (m, d), rows in the order of
    ``outputs``. ``S1_interval``/``ST_interval`` add a last axis [lower, upper] =
    index ∓ half-width at the ``confidence`` level.
    """

    names: List[str]
    outputs: List[str]
    S1: np.ndarray
    ST: np.ndarray
    S1_conf: np.ndarray
    ST_conf: np.ndarray
    variance: np.ndarray
    evaluations: int
    failed_evaluations: int
    dropped_groups: int
    failure_handling: str
    failure_reasons: Dict[str, int] = field(default_factory=dict)
    base_points: int = 0
    confidence: float = 0.95

    @property
    def S1_interval(self) -> np.ndarray:
        """[lower, upper] of each S1 (last axis)."""
        return np.stack([self.S1 - self.S1_conf, self.S1 + self.S1_conf], axis=-1)

    @property
    def ST_interval(self) -> np.ndarray:
        """[lower, upper] of each ST (last axis)."""
        return np.stack([self.ST - self.ST_conf, self.ST + self.ST_conf], axis=-1)

    def to_dict(self) -> Dict[str, Any]:
        """The indices in SALib's layout (``S1``, ``S1_conf``, ``ST``, ``ST_conf``)."""
        return {"S1": self.S1, "S1_conf": self.S1_conf, "ST": self.ST, "ST_conf": self.ST_conf}


Model = Union[Callable[[np.ndarray], Any], str, Mapping[str, str]]


def sobol(
    model: Model,
    bounds: Any,
    n: int = 1024,
    seed: int = 0,
    *,
    outputs: Any = None,
    resamples: int = 100,
    replicates: Optional[int] = None,
    confidence: float = 0.95,
    on_error: str = "raise",
) -> SobolResult:
    """Sobol' indices of ``model`` with independent inputs distributed as ``bounds`` says.

    ``model`` is a Python callable taking an (N, d) array and returning (N,) or (N, m) —
    called once per Saltelli design of ``n`` base points (N = n(d + 2) rows) — or a formula
    (``"sin(x1) + 7*sin(x2)^2"``) or a dict of formulas ``{output: formula}`` evaluated in Rust
    (a study's ``kind = "expression"``). ``bounds``: ``[(lo, hi), ...]`` (uniform inputs
    ``x1`` … ``xd``; an item may also be a prior as in a study file, ``{"normal": [0, 1]}``),
    ``{name: (lo, hi) or prior}``, or SALib's ``problem`` dict (``dists`` unif, norm, lognorm,
    truncnorm). The unit-cube design is mapped through each prior's quantile function.

    Estimators: Saltelli (2010) first order and Jansen total order on a scrambled Sobol'
    design; intervals from ``resamples`` bootstrap resamples, or from ``replicates``
    independent scramblings. ``outputs`` (a count or names) saves the one extra model call at
    the centre of the box that otherwise finds the number of outputs. ``on_error="fail"``
    turns exceptions of the model into failed points (the batch is evaluated again point by
    point; failed points' groups are dropped and counted); ``"raise"`` re-raises them.
    The result for a given ``seed`` equals ``iuq sobol`` on the same study.
    """
    names, priors = parameter_priors(bounds)
    n = count("n", n, 2)
    if on_error not in ("raise", "fail"):
        raise ValueError(f"on_error: `{on_error}` is not one of raise, fail")
    confidence = real("confidence", confidence)
    if replicates is not None:
        replicates = count("replicates", replicates, 2, 2**16)
    resamples = count("resamples", resamples, 2, 2**20)
    function = None
    expressions = None
    if isinstance(model, str):
        expressions = [("y", model)]
    elif isinstance(model, Mapping):
        expressions = [(str(k), str(v)) for k, v in model.items()]
        if not expressions:
            raise ValueError("model: at least one formula is needed")
    elif callable(model):
        function = model
    else:
        raise TypeError(
            f"model: expected a callable or formulas (str or dict), got {type(model).__name__}"
        )
    output_names = (
        [name for name, _ in expressions]
        if expressions is not None
        else output_count(model, [prior_centre(k, v) for k, v in priors], outputs)
    )
    raw = _native.sobol_indices(
        function,
        expressions,
        names,
        priors,
        output_names,
        n,
        seed_of(seed),
        resamples,
        replicates,
        confidence,
        on_error,
    )
    return result_from_raw(raw)


def result_from_raw(raw: Dict[str, Any]) -> SobolResult:
    """The :class:`SobolResult` of the native result dict."""
    per = raw["outputs"]
    order = raw["output_names"]

    def stack(key: str) -> np.ndarray:
        rows = np.array([per[o][key] for o in order], dtype=np.float64)
        return rows[0] if len(order) == 1 else rows

    return SobolResult(
        names=list(raw["inputs"]),
        outputs=list(order),
        S1=stack("S1"),
        ST=stack("ST"),
        S1_conf=stack("S1_conf"),
        ST_conf=stack("ST_conf"),
        variance=np.array([per[o]["variance"] for o in order], dtype=np.float64),
        evaluations=raw["evaluations"],
        failed_evaluations=raw["failed_evaluations"],
        dropped_groups=raw["dropped_groups"],
        failure_handling=raw["failure_handling"],
        failure_reasons=dict(raw["failure_reasons"]),
        base_points=raw["base_points"],
        confidence=raw["confidence"],
    )
