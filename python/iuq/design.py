"""Space-filling designs as numpy arrays: the designs of ``iuq design lhs|sobol|saltelli``.

For the same ``n``, ``dim``, ``seed`` (and method, bounds) the arrays equal, bit for bit, the
CSV files the command line writes. Without ``bounds`` the points lie in the unit cube.

References: Latin hypercubes — McKay, Beckman & Conover (1979), maximin selection as pyDOE,
ESE optimisation — Jin, Chen & Sudjianto (2005); Sobol' points — Joe & Kuo (2008) direction
numbers with Owen-type linear matrix scrambling and digital shift; Saltelli design — Saltelli
et al. (2010). See ``docs/methods.md``.
"""

from __future__ import annotations

from typing import Optional, Sequence, Tuple

import numpy as np

from . import _native
from ._args import count, parameter_box, seed_of

__all__ = ["lhs", "sobol", "saltelli", "DEFAULT_MAXIMIN_CANDIDATES"]

#: Candidate designs of the maximin Latin hypercube (``iuq design --candidates`` default).
DEFAULT_MAXIMIN_CANDIDATES = 100

Bounds = Optional[Sequence[Tuple[float, float]]]


def _bounds(bounds: Bounds, dim: int):
    if bounds is None:
        return None
    _, ranges = parameter_box(bounds)
    if len(ranges) != dim:
        raise ValueError(f"bounds: {len(ranges)} ranges given for dim {dim}")
    return ranges


def lhs(
    n: int,
    dim: int,
    seed: int = 0,
    method: str = "maximin",
    *,
    candidates: int = DEFAULT_MAXIMIN_CANDIDATES,
    bounds: Bounds = None,
) -> np.ndarray:
    """Latin hypercube of ``n`` points in ``dim`` dimensions, shape (n, dim).

    ``method``: ``"maximin"`` (best of ``candidates`` random designs by minimum distance),
    ``"optimized"`` (ESE optimisation of the φ_p criterion) or ``"random"``.
    """
    n, dim = count("n", n, 1), count("dim", dim, 1)
    if not isinstance(method, str):
        raise TypeError(f"method: expected a string, got {type(method).__name__}")
    return _native.lhs(
        n, dim, seed_of(seed), method, count("candidates", candidates, 1), _bounds(bounds, dim)
    )


def sobol(
    n: int, dim: int, seed: int = 0, *, scramble: bool = True, bounds: Bounds = None
) -> np.ndarray:
    """The first ``n`` points of the ``dim``-dimensional Sobol' sequence, shape (n, dim).

    Scrambled with ``seed`` unless ``scramble=False`` (then equal to
    ``scipy.stats.qmc.Sobol(d, scramble=False)``). Powers of two keep the balance properties.
    """
    n, dim = count("n", n, 1), count("dim", dim, 1)
    return _native.sobol(n, dim, seed_of(seed), bool(scramble), _bounds(bounds, dim))


def saltelli(
    n: int, dim: int, seed: int = 0, *, scramble: bool = True, bounds: Bounds = None
) -> np.ndarray:
    """The Saltelli design of ``n`` base points for Sobol' indices, shape (n·(dim + 2), dim).

    Rows are grouped per base point j as A_j, AB_1j … AB_dj, B_j (as ``iuq design saltelli``).
    """
    n, dim = count("n", n, 1), count("dim", dim, 1)
    return _native.saltelli(n, dim, seed_of(seed), bool(scramble), _bounds(bounds, dim))
