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
    """Latin hypercube of ``n`` points in ``dim`` dimensions (``iuq design lhs``).

    Each coordinate has exactly one point in each of the ``n`` strata ``[k/n, (k+1)/n)``.
    For the same arguments the array equals, bit for bit, the CSV file the command line writes.

    Parameters
    ----------
    n : int
        Number of points, at least 1.
    dim : int
        Number of dimensions, at least 1.
    seed : int, default 0
        Seed of the random streams.
    method : {"maximin", "optimized", "random"}, default "maximin"
        ``"maximin"``: the best of ``candidates`` random Latin hypercubes by their minimum
        pairwise distance (as pyDOE's ``criterion="maximin"``); ``"optimized"``: the enhanced
        stochastic evolutionary algorithm (ESE) minimising the φ_p criterion; ``"random"``: one
        random Latin hypercube.
    candidates : int, default 100
        Random designs among which ``"maximin"`` chooses.
    bounds : sequence of (float, float), optional
        ``(lo, hi)`` per dimension: the points are mapped affinely onto that box. Without it
        they lie in the unit cube.

    Returns
    -------
    numpy.ndarray
        The points, shape (n, dim).

    Raises
    ------
    ValueError
        If ``n`` or ``dim`` is not a positive integer, the method is unknown, or ``bounds`` does
        not give ``dim`` ranges.
    TypeError
        If ``method`` is not a string.

    See Also
    --------
    sobol, saltelli

    Examples
    --------
    >>> import numpy as np
    >>> import iuq
    >>> x = iuq.design.lhs(8, 2, seed=1)
    >>> x.shape
    (8, 2)
    >>> np.sort(np.floor(x[:, 0] * 8)).astype(int)   # one point in each of the 8 strata
    array([0, 1, 2, 3, 4, 5, 6, 7])
    >>> x = iuq.design.lhs(5, 2, seed=1, bounds=[(0, 10), (-1, 1)])
    >>> bool(x[:, 0].min() >= 0 and x[:, 0].max() <= 10)
    True
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
    """The first ``n`` points of the ``dim``-dimensional Sobol' sequence (``iuq design sobol``).

    Direction numbers of Joe & Kuo (2008); scrambled by a random linear matrix scramble and a
    digital shift, as SciPy does. Powers of two keep the balance properties.

    Parameters
    ----------
    n : int
        Number of points, at least 1 (a power of two for balance).
    dim : int
        Number of dimensions, at least 1.
    seed : int, default 0
        Seed of the scrambling.
    scramble : bool, default True
        ``False``: the plain sequence, equal to ``scipy.stats.qmc.Sobol(dim, scramble=False)``,
        the origin first.
    bounds : sequence of (float, float), optional
        ``(lo, hi)`` per dimension; without it the unit cube.

    Returns
    -------
    numpy.ndarray
        The points, shape (n, dim).

    Raises
    ------
    ValueError
        If ``n`` or ``dim`` is not a positive integer or ``bounds`` does not give ``dim`` ranges.

    See Also
    --------
    lhs, saltelli

    Examples
    --------
    >>> import iuq
    >>> iuq.design.sobol(4, 2, scramble=False)
    array([[0.  , 0.  ],
           [0.5 , 0.5 ],
           [0.75, 0.25],
           [0.25, 0.75]])
    """
    n, dim = count("n", n, 1), count("dim", dim, 1)
    return _native.sobol(n, dim, seed_of(seed), bool(scramble), _bounds(bounds, dim))


def saltelli(
    n: int, dim: int, seed: int = 0, *, scramble: bool = True, bounds: Bounds = None
) -> np.ndarray:
    """The Saltelli design of ``n`` base points for Sobol' indices (``iuq design saltelli``).

    Two independent ``n × dim`` matrices A and B from one ``2·dim``-dimensional Sobol'
    sequence and, for each input i, A with column i taken from B; rows grouped per base point
    j as A_j, AB_1j … AB_dj, B_j.

    Parameters
    ----------
    n : int
        Number of base points N, at least 1.
    dim : int
        Number of inputs d, at least 1.
    seed : int, default 0
        Seed of the scrambling.
    scramble : bool, default True
        ``False``: the unscrambled sequence.
    bounds : sequence of (float, float), optional
        ``(lo, hi)`` per input; without it the unit cube.

    Returns
    -------
    numpy.ndarray
        The design, shape (n·(dim + 2), dim).

    Raises
    ------
    ValueError
        If ``n`` or ``dim`` is not a positive integer or ``bounds`` does not give ``dim`` ranges.

    See Also
    --------
    iuq.sobol : Sobol' indices of a model on this design.

    Examples
    --------
    >>> import iuq
    >>> iuq.design.saltelli(8, 3, seed=0).shape   # 8 · (3 + 2) rows
    (40, 3)
    """
    n, dim = count("n", n, 1), count("dim", dim, 1)
    return _native.saltelli(n, dim, seed_of(seed), bool(scramble), _bounds(bounds, dim))
