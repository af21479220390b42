"""Checks and conversions of user arguments shared by the modules of :mod:`iuq`.

Every error is a :class:`ValueError` (or :class:`TypeError` for a wrong kind of value) whose
message starts with the argument's name, as the command line's messages start with the flag.
"""

from __future__ import annotations

import math
import numbers
from typing import Any, Mapping, Sequence

import numpy as np

__all__ = ["count", "seed_of", "matrix", "vector", "parameter_box", "parameter_priors"]


#: The largest count any argument takes (2**31 - 1, as the study files): sizes beyond it would
#: overflow the products made of them or ask for more memory than any machine has.
MAX_COUNT = 2**31 - 1


def count(name: str, value: Any, minimum: int = 0, maximum: int = MAX_COUNT) -> int:
    """``value`` as an ``int`` from ``minimum`` to ``maximum`` (``bool`` is refused)."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise TypeError(f"{name}: expected an integer, got {type(value).__name__}")
    value = int(value)
    if value < minimum:
        raise ValueError(f"{name}: must be at least {minimum}, got {value}")
    if value > maximum:
        raise ValueError(f"{name}: must be at most {maximum}, got {value}")
    return value


def seed_of(value: Any, name: str = "seed") -> int:
    """A seed: an integer in [0, 2**64)."""
    value = count(name, value, 0)
    if value >= 2**64:
        raise ValueError(f"{name}: must be below 2**64, got {value}")
    return value


def real(name: str, value: Any) -> float:
    """``value`` as a finite ``float``."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise TypeError(f"{name}: expected a number, got {type(value).__name__}")
    value = float(value)
    if not math.isfinite(value):
        raise ValueError(f"{name}: must be finite, got {value}")
    return value


def matrix(name: str, value: Any, columns: int | None = None) -> np.ndarray:
    """``value`` as a C-contiguous (n, d) ``float64`` array; a 1-D array is one column."""
    try:
        array = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as error:
        raise ValueError(f"{name}: not an array of numbers ({error})") from None
    if array.ndim == 1:
        array = array.reshape(-1, 1)
    if array.ndim != 2:
        raise ValueError(f"{name}: expected a 2-D array (n, d), got shape {array.shape}")
    if columns is not None and array.shape[1] != columns:
        raise ValueError(f"{name}: expected {columns} columns, got shape {array.shape}")
    if not np.all(np.isfinite(array)):
        raise ValueError(f"{name}: holds non-finite values")
    return np.ascontiguousarray(array)


def vector(name: str, value: Any, length: int | None = None) -> np.ndarray:
    """``value`` as a contiguous 1-D ``float64`` array of finite values."""
    try:
        array = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as error:
        raise ValueError(f"{name}: not an array of numbers ({error})") from None
    if array.ndim == 2 and array.shape[1] == 1:
        array = array[:, 0]
    if array.ndim != 1:
        raise ValueError(f"{name}: expected a 1-D array, got shape {array.shape}")
    if length is not None and array.shape[0] != length:
        raise ValueError(f"{name}: expected {length} values, got {array.shape[0]}")
    if not np.all(np.isfinite(array)):
        raise ValueError(f"{name}: holds non-finite values")
    return np.ascontiguousarray(array)


def parameter_box(
    bounds: Any, names: Sequence[str] | None = None, argument: str = "bounds"
) -> tuple[list[str], list[tuple[float, float]]]:
    """Names and (lo, hi) ranges of uniform parameters.

    ``bounds`` is a sequence of ``(lo, hi)`` pairs (names ``x1``, ``x2``, … unless ``names``
    is given), a mapping ``{name: (lo, hi)}``, or SALib's ``problem`` dict
    (``{"num_vars": d, "names": [...], "bounds": [[lo, hi], ...]}``; only uniform ``dists``).
    """
    if isinstance(bounds, Mapping) and "bounds" in bounds:
        problem = bounds
        dists = problem.get("dists")
        if dists is not None and any(d != "unif" for d in dists):
            raise ValueError(
                f"{argument}: only uniform distributions ('unif') are supported, got dists={list(dists)}"
            )
        pairs = list(problem["bounds"])
        problem_names = problem.get("names")
        if problem_names is not None:
            names = list(problem_names)
        if "num_vars" in problem and int(problem["num_vars"]) != len(pairs):
            raise ValueError(
                f"{argument}: num_vars = {problem['num_vars']} but {len(pairs)} bounds are given"
            )
    elif isinstance(bounds, Mapping):
        names = [str(k) for k in bounds.keys()]
        pairs = list(bounds.values())
    elif bounds is None:
        raise ValueError(f"{argument}: give the parameter ranges, e.g. [(0, 1), (0, 1)]")
    else:
        pairs = list(bounds)
    if not pairs:
        raise ValueError(f"{argument}: at least one parameter is needed")
    ranges: list[tuple[float, float]] = []
    for k, pair in enumerate(pairs):
        try:
            lo, hi = (float(v) for v in pair)
        except (TypeError, ValueError):
            raise ValueError(f"{argument}: range {k} is not a (lo, hi) pair: {pair!r}") from None
        if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
            raise ValueError(f"{argument}: range {k} must have finite lo < hi, got ({lo}, {hi})")
        ranges.append((lo, hi))
    if names is None:
        names = [f"x{k + 1}" for k in range(len(ranges))]
    names = [str(n) for n in names]
    if len(names) != len(ranges):
        raise ValueError(f"{argument}: {len(names)} names for {len(ranges)} ranges")
    return names, ranges


def output_count(model: Any, centre: Sequence[float], outputs: Any) -> list[str]:
    """Output names of a Python model: ``outputs`` (a count or names), else learnt from one call
    of the model at ``centre`` (the one extra evaluation is documented)."""
    if outputs is not None:
        if isinstance(outputs, numbers.Integral) and not isinstance(outputs, bool):
            m = count("outputs", outputs, 1)
            return ["y"] if m == 1 else [f"y{j + 1}" for j in range(m)]
        names = [str(o) for o in outputs]
        if not names:
            raise ValueError("outputs: at least one output is needed")
        return names
    result = model(np.ascontiguousarray([list(centre)], dtype=np.float64))
    if isinstance(result, tuple) and len(result) == 2:
        result = result[0]
    shape = np.shape(result)
    if shape == (1,):
        return ["y"]
    if len(shape) == 2 and shape[0] == 1 and shape[1] >= 1:
        return ["y"] if shape[1] == 1 else [f"y{j + 1}" for j in range(shape[1])]
    raise ValueError(
        f"model: returned shape {shape} for 1 point; expected (1,) or (1, m) (an (n, d) array in, (n,) or (n, m) out)"
    )


#: Prior kinds and their parameters, as in a study file's ``[parameters]`` section.
PRIOR_KINDS = {"uniform": 2, "normal": 2, "log_normal": 2, "truncated_normal": 4}

#: SALib's ``dists`` with the order of their ``bounds`` entries mapped to ours.
_SALIB_DISTS = {
    "unif": lambda b: ("uniform", [b[0], b[1]]),
    "norm": lambda b: ("normal", [b[0], b[1]]),
    "lognorm": lambda b: ("log_normal", [b[0], b[1]]),
    "truncnorm": lambda b: ("truncated_normal", [b[2], b[3], b[0], b[1]]),
}


def _prior_of(argument: str, k: int, item: Any) -> tuple[str, list[float]]:
    if isinstance(item, Mapping):
        if len(item) != 1:
            raise ValueError(f"{argument}: prior {k} must have one key, e.g. {{'normal': [0, 1]}}, got {item!r}")
        ((kind, values),) = item.items()
        if kind not in PRIOR_KINDS:
            raise ValueError(
                f"{argument}: prior {k}: `{kind}` is not one of {', '.join(PRIOR_KINDS)}"
            )
        try:
            values = [float(v) for v in values]
        except (TypeError, ValueError):
            raise ValueError(f"{argument}: prior {k}: {values!r} is not a list of numbers") from None
        if len(values) != PRIOR_KINDS[kind]:
            raise ValueError(
                f"{argument}: prior {k}: {kind} takes {PRIOR_KINDS[kind]} values, got {len(values)}"
            )
        return str(kind), values
    try:
        lo, hi = (float(v) for v in item)
    except (TypeError, ValueError):
        raise ValueError(f"{argument}: range {k} is not a (lo, hi) pair: {item!r}") from None
    if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
        raise ValueError(f"{argument}: range {k} must have finite lo < hi, got ({lo}, {hi})")
    return "uniform", [lo, hi]


def parameter_priors(
    bounds: Any, argument: str = "bounds"
) -> tuple[list[str], list[tuple[str, list[float]]]]:
    """Names and priors of the parameters of ``iuq.sobol`` and ``iuq.basis``.

    ``bounds`` is a sequence whose items are ``(lo, hi)`` pairs (uniform priors) or one-key
    prior dicts as in a study file (``{"normal": [mean, std]}``, ``{"log_normal": [mu, sigma]}``,
    ``{"truncated_normal": [mean, std, lo, hi]}``, ``{"uniform": [lo, hi]}``), with names
    ``x1``, ``x2``, …; a mapping ``{name: pair or prior}``; or SALib's ``problem`` dict
    (``dists`` ``unif``, ``norm``, ``lognorm``, ``truncnorm`` with SALib's ``bounds`` layout).
    """
    names: list[str] | None = None
    if isinstance(bounds, Mapping) and "bounds" in bounds:
        problem = bounds
        pairs = [list(b) for b in problem["bounds"]]
        dists = problem.get("dists")
        if "num_vars" in problem and int(problem["num_vars"]) != len(pairs):
            raise ValueError(
                f"{argument}: num_vars = {problem['num_vars']} but {len(pairs)} bounds are given"
            )
        if problem.get("names") is not None:
            names = [str(n) for n in problem["names"]]
        if dists is None:
            items: list[Any] = pairs
        else:
            dists = list(dists)
            if len(dists) != len(pairs):
                raise ValueError(f"{argument}: {len(dists)} dists for {len(pairs)} bounds")
            items = []
            for k, (dist, b) in enumerate(zip(dists, pairs)):
                if dist not in _SALIB_DISTS:
                    raise ValueError(
                        f"{argument}: dists[{k}] = {dist!r} is not supported (unif, norm, lognorm, truncnorm)"
                    )
                kind, values = _SALIB_DISTS[dist](b)
                items.append({kind: values})
    elif isinstance(bounds, Mapping):
        names = [str(k) for k in bounds.keys()]
        items = list(bounds.values())
    elif bounds is None:
        raise ValueError(f"{argument}: give the parameter ranges, e.g. [(0, 1), (0, 1)]")
    else:
        items = list(bounds)
    if not items:
        raise ValueError(f"{argument}: at least one parameter is needed")
    priors = [_prior_of(argument, k, item) for k, item in enumerate(items)]
    if names is None:
        names = [f"x{k + 1}" for k in range(len(priors))]
    if len(names) != len(priors):
        raise ValueError(f"{argument}: {len(names)} names for {len(priors)} parameters")
    return names, priors


def prior_centre(kind: str, values: Sequence[float]) -> float:
    """A central value of a prior (for the one probing call of a model)."""
    if kind == "uniform":
        return 0.5 * (values[0] + values[1])
    if kind == "normal":
        return values[0]
    if kind == "log_normal":
        return math.exp(values[0])
    mean, _, lo, hi = values
    return min(max(mean, lo), hi)
