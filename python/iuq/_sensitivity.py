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

    As :func:`iuq.sobol` returns them. With one output the arrays have shape (d,); with m
    outputs (m, d), rows in the order of :attr:`outputs`.

    Attributes
    ----------
    names : list of str
        The inputs.
    outputs : list of str
        The outputs.
    S1, ST : numpy.ndarray
        First-order and total indices.
    S1_conf, ST_conf : numpy.ndarray
        Their confidence half-widths at the level :attr:`confidence`.
    variance : numpy.ndarray, shape (m,)
        The variance of each output over the design.
    evaluations, failed_evaluations : int
        Model evaluations, and those that failed.
    dropped_groups : int
        Base points dropped because one of their rows failed.
    failure_handling : str
        How failures were treated.
    failure_reasons : dict
        Failed evaluations per reason.
    base_points : int
        Base points N of the Saltelli design.
    confidence : float
        Confidence level of the half-widths.

    Examples
    --------
    >>> import iuq
    >>> s = iuq.sobol({"f": "x1 + 2*x2", "g": "x1*x2"}, [(0, 1)] * 2, n=256)
    >>> s.outputs, s.S1.shape
    (['f', 'g'], (2, 2))
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
        """[lower, upper] of each S1 (a last axis of length 2): index ∓ half-width."""
        return np.stack([self.S1 - self.S1_conf, self.S1 + self.S1_conf], axis=-1)

    @property
    def ST_interval(self) -> np.ndarray:
        """[lower, upper] of each ST (a last axis of length 2): index ∓ half-width."""
        return np.stack([self.ST - self.ST_conf, self.ST + self.ST_conf], axis=-1)

    def to_dict(self) -> Dict[str, Any]:
        """The indices in SALib's layout.

        Returns
        -------
        dict
            ``{"S1", "S1_conf", "ST", "ST_conf"}``, each an array as in this result.

        Examples
        --------
        >>> import iuq
        >>> sorted(iuq.sobol("x1 + x2", [(0, 1)] * 2, n=64).to_dict())
        ['S1', 'S1_conf', 'ST', 'ST_conf']
        """
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

    The model is run on a Saltelli design of ``n`` base points (N = n(d + 2) rows), mapped
    from the unit cube through each prior's quantile function; first-order indices by
    Saltelli's (2010) estimator, total indices by Jansen's (the methods' chapter on Sobol'
    indices). The result for a given ``seed`` equals ``iuq sobol`` on the same study.

    Parameters
    ----------
    model : callable, str or dict
        A Python callable taking an (N, d) array and returning (N,) or (N, m), called once per
        design; or a formula (``"sin(x1) + 7*sin(x2)^2"``), or a dict of formulas
        ``{output: formula}``, evaluated in Rust (a study's ``kind = "expression"``).
    bounds : sequence, dict or SALib problem
        ``[(lo, hi), ...]`` (uniform inputs ``x1`` … ``xd``; an item may also be a prior as in
        a study file, ``{"normal": [0, 1]}``), ``{name: (lo, hi) or prior}``, or SALib's
        ``problem`` dict (``dists`` unif, norm, lognorm, truncnorm).
    n : int, default 1024
        Base points N (a power of two keeps the design balanced).
    seed : int, default 0
        Seed of the design's scrambling and of the bootstrap.
    outputs : int or sequence of str, optional
        The number or names of a callable's outputs; saves the one extra call at the centre of
        the box that otherwise finds the number of outputs.
    resamples : int, default 100
        Bootstrap resamples of the base points for the intervals.
    replicates : int, optional
        Instead of the bootstrap: intervals from this many independent scramblings of the design
        (the honest interval for quasi-random designs).
    confidence : float, default 0.95
        Confidence level of the intervals.
    on_error : {"raise", "fail"}, default "raise"
        ``"fail"`` turns exceptions of the model into failed points (the batch is evaluated
        again point by point; failed points' groups are dropped and counted); ``"raise"``
        re-raises them.

    Returns
    -------
    SobolResult
        ``S1``, ``ST`` and their half-widths, per output.

    Raises
    ------
    ValueError
        If an argument is out of range (the message starts with its name) or a dict of formulas
        is empty.
    TypeError
        If ``model`` is neither a callable nor formulas.
    Exception
        Whatever the model raises, with ``on_error="raise"``.

    Examples
    --------
    A Python model (``outputs=1`` skips the call that counts the outputs):

    >>> import numpy as np
    >>> import iuq
    >>> s = iuq.sobol(lambda x: x[:, 0] + 2 * x[:, 1], [(0, 1)] * 2, n=512, seed=0, outputs=1)
    >>> s.S1.round(1), s.ST.round(1)
    (array([0.2, 0.8]), array([0.2, 0.8]))

    The Ishigami function as a formula, evaluated in Rust:

    >>> s = iuq.sobol("sin(x1) + 7*sin(x2)^2 + 0.1*x3^4*sin(x1)", [(-np.pi, np.pi)] * 3,
    ...               n=1024, seed=0)
    >>> s.S1[:2].round(2), s.ST.round(2)
    (array([0.31, 0.44]), array([0.54, 0.44, 0.24]))
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
        dict(
            n=n,
            seed=seed_of(seed),
            resamples=resamples,
            replicates=replicates,
            confidence=confidence,
            on_error=on_error,
        ),
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
