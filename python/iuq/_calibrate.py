"""Calibrate a Python function: the adaptive engine of ``iuq pipeline`` on a callable model."""

from __future__ import annotations

import hashlib
import inspect
import json
import math
import os
import re
import sys
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple, Union

import numpy as np

from . import _native
from ._args import count, parameter_priors, real, seed_of, vector
from ._model_posterior import ModelPosteriorSamples, read_model_posterior

__all__ = ["calibrate", "CalibrationResult"]

PathLike = Union[str, "os.PathLike[str]"]

STUDY_FILE = "calibration.toml"
DATA_FILE = "data.csv"


@dataclass(frozen=True)
class CalibrationResult:
    """What :func:`calibrate` found.

    Attributes
    ----------
    names : list of str
        The columns of :attr:`samples`: the parameters, then ``sigma_m`` when the modelling
        error is sampled.
    parameters : list of str
        The parameters.
    samples : numpy.ndarray, shape (N, p)
        Equally weighted samples of the surrogate posterior.
    log_likelihood : numpy.ndarray, shape (N,)
        The log-likelihood at each sample.
    mean, std, map, q05, q95 : numpy.ndarray, shape (p,)
        Mean, standard deviation, MAP and the 5 % and 95 % quantiles per column.
    converged : bool
        Whether the adaptive engine's stopping rule held.
    stop_reason : str
        Why the engine stopped.
    rounds : list of dict
        The adaptive engine's rounds (runs, posterior moments, shift, surrogate error, …, as
        ``iuq pipeline --json`` gives them).
    model_runs, failed_runs : int
        Model evaluations in the store, and those that failed.
    surrogate_runs : int
        The evaluations the engine made for the surrogate (initial design and rounds; the rest
        are the posterior check's and the model posterior's).
    runs : list of dict
        Every model evaluation in the store: parameters, ``outputs``, ``status``, ``reason``.
    data : dict
        The abscissae ``x``, the observations ``y`` and their stds ``y_std``.
    model_posterior : dict or None
        With ``model_posterior=True``: the model's own posterior's summary (k̂, ESS, MCSE,
        whether it is certified, …).
    model_posterior_samples : ModelPosteriorSamples or None
        Its weighted members as arrays.
    sensitivity : dict or None
        Sobol' indices on the surrogate (with ``sensitivity`` > 0).
    out : pathlib.Path or None
        The pipeline's output directory (report, tables, figures); ``None`` when it was
        temporary.
    store : pathlib.Path or None
        The campaign store; ``None`` when it was temporary.
    seconds : float
        Wall time.
    posterior_predictive : numpy.ndarray or None
        Where the surrogate is a GP per data point: the surrogate's mean at each sample plus
        the likelihood's Gaussian noise, shape (N, m).

    Examples
    --------
    >>> import numpy as np
    >>> import iuq
    >>> t = np.linspace(0.5, 4.0, 5)
    >>> result = iuq.calibrate(lambda theta: np.exp(-theta[:, :1] * t), {"k": (0.05, 0.8)},
    ...                        np.exp(-0.3 * t), np.full(5, 0.02), x=t, samples=1000,
    ...                        sensitivity=0, seed=1, progress=False)
    >>> result
    CalibrationResult(8 runs, 2 rounds, converged: k = 0.3007 ± 0.00862)
    >>> result.samples.shape, result.converged
    ((1000, 1), True)
    """

    names: List[str]
    parameters: List[str]
    samples: np.ndarray
    log_likelihood: np.ndarray
    mean: np.ndarray
    std: np.ndarray
    map: np.ndarray
    q05: np.ndarray
    q95: np.ndarray
    converged: bool
    stop_reason: str
    rounds: List[Dict[str, Any]]
    model_runs: int
    surrogate_runs: int
    failed_runs: int
    runs: List[Dict[str, Any]]
    data: Dict[str, np.ndarray]
    model_posterior: Optional[Dict[str, Any]]
    sensitivity: Optional[Dict[str, Any]]
    out: Optional[Path]
    store: Optional[Path]
    seconds: float
    posterior_predictive: Optional[np.ndarray] = field(default=None, repr=False)
    raw: Dict[str, Any] = field(default_factory=dict, repr=False)
    model_posterior_samples: Optional[ModelPosteriorSamples] = field(default=None, repr=False)

    def summary(self) -> Dict[str, Dict[str, float]]:
        """MAP, mean, std and the 5 % and 95 % quantiles per column.

        Returns
        -------
        dict
            ``{name: {"map", "mean", "std", "q05", "q95"}}`` of floats, in column order.

        Examples
        --------
        >>> import numpy as np
        >>> import iuq
        >>> t = np.linspace(0.5, 4.0, 5)
        >>> result = iuq.calibrate(lambda theta: np.exp(-theta[:, :1] * t), {"k": (0.05, 0.8)},
        ...                        np.exp(-0.3 * t), np.full(5, 0.02), x=t, samples=1000,
        ...                        sensitivity=0, seed=1, progress=False)
        >>> sorted(result.summary()["k"])
        ['map', 'mean', 'q05', 'q95', 'std']
        """
        return {
            n: {
                "map": float(self.map[k]),
                "mean": float(self.mean[k]),
                "std": float(self.std[k]),
                "q05": float(self.q05[k]),
                "q95": float(self.q95[k]),
            }
            for k, n in enumerate(self.names)
        }

    def to_pandas(self):
        """The posterior samples as a ``pandas.DataFrame`` (needs pandas).

        Returns
        -------
        pandas.DataFrame
            One row per sample, one column per name of :attr:`names`.

        Raises
        ------
        ImportError
            If pandas is not installed (``pip install "./python[arviz]"``).

        Examples
        --------
        >>> import numpy as np
        >>> import iuq
        >>> t = np.linspace(0.5, 4.0, 5)
        >>> result = iuq.calibrate(lambda theta: np.exp(-theta[:, :1] * t), {"k": (0.05, 0.8)},
        ...                        np.exp(-0.3 * t), np.full(5, 0.02), x=t, samples=1000,
        ...                        sensitivity=0, seed=1, progress=False)
        >>> result.to_pandas().shape
        (1000, 1)
        """
        import pandas as pd

        return pd.DataFrame(self.samples, columns=self.names)

    def to_arviz(self, source: str = "surrogate", draws: Optional[int] = None, seed: int = 0):
        """The calibration as ArviZ ``InferenceData`` (needs arviz).

        With ``source="surrogate"``: the posterior (one chain of the N equally weighted samples),
        ``sample_stats`` (``lp``, the log-likelihood), the ``observed_data`` ``y`` (dimension
        ``point``, coordinate ``x``) and, where the surrogate is a GP per data point, the
        ``posterior_predictive`` ``y``: the surrogate's mean at each posterior sample plus the
        likelihood's Gaussian noise (measurement and modelling error).

        Parameters
        ----------
        source : {"surrogate", "model"}, default "surrogate"
            ``"model"``: the model's own posterior instead
            (:meth:`iuq.ModelPosteriorSamples.to_arviz`, with ``observed_data``), which needs
            ``calibrate(..., model_posterior=True)``.
        draws : int, optional
            With ``source="model"``: the number of resampled draws (default: the members').
        seed : int, default 0
            With ``source="model"``: the seed of the resampling.

        Returns
        -------
        arviz.InferenceData

        Raises
        ------
        ValueError
            If ``source`` is unknown, or ``"model"`` without a model posterior.
        ImportError
            If ArviZ is not installed.

        Examples
        --------
        >>> import numpy as np
        >>> import iuq
        >>> t = np.linspace(0.5, 4.0, 5)
        >>> result = iuq.calibrate(lambda theta: np.exp(-theta[:, :1] * t), {"k": (0.05, 0.8)},
        ...                        np.exp(-0.3 * t), np.full(5, 0.02), x=t, samples=1000,
        ...                        sensitivity=0, seed=1, progress=False)
        >>> idata = result.to_arviz()
        >>> sorted(idata.groups())
        ['observed_data', 'posterior', 'posterior_predictive', 'sample_stats']
        """
        import arviz as az

        if source == "model":
            if self.model_posterior_samples is None:
                raise ValueError("source: 'model' needs the model posterior (calibrate(..., model_posterior=True))")
            return self.model_posterior_samples.to_arviz(
                draws,
                seed,
                observed_data={"y": np.asarray(self.data["y"])},
                coords={"point": np.asarray(self.data["x"])},
                dims={"y": ["point"]},
            )
        if source != "surrogate":
            raise ValueError(f"source: {source!r} is neither 'surrogate' nor 'model'")

        posterior = {n: self.samples[None, :, k] for k, n in enumerate(self.names)}
        coords = {"point": np.asarray(self.data["x"])}
        dims = {"y": ["point"]}
        kwargs: Dict[str, Any] = {
            "posterior": posterior,
            "sample_stats": {"lp": self.log_likelihood[None, :]},
            "observed_data": {"y": np.asarray(self.data["y"])},
            "coords": coords,
            "dims": dims,
        }
        if self.posterior_predictive is not None:
            kwargs["posterior_predictive"] = {"y": self.posterior_predictive[None, :, :]}
        return az.from_dict(**kwargs)

    def _repr_html_(self) -> str:
        state = "converged" if self.converged else f"not converged ({_escape(self.stop_reason)})"
        rows = "".join(
            f"<tr><td>{_escape(n)}</td><td>{self.mean[k]:.5g}</td><td>{self.std[k]:.4g}</td>"
            f"<td>{self.map[k]:.5g}</td><td>{self.q05[k]:.5g}</td><td>{self.q95[k]:.5g}</td></tr>"
            for k, n in enumerate(self.names)
        )
        report = "" if self.out is None else f"<p>Report: <code>{_escape(str(self.out / 'report.html'))}</code></p>"
        return (
            f"<div><p><b>iuq calibration</b>: {self.model_runs} model runs ({self.failed_runs} failed), "
            f"{len(self.rounds)} adaptive rounds, {state}, {self.seconds:.1f} s</p>"
            "<table><thead><tr><th>parameter</th><th>mean</th><th>std</th><th>MAP</th>"
            f"<th>5 %</th><th>95 %</th></tr></thead><tbody>{rows}</tbody></table>{report}</div>"
        )

    def __repr__(self) -> str:
        moments = ", ".join(f"{n} = {self.mean[k]:.4g} ± {self.std[k]:.3g}" for k, n in enumerate(self.names))
        state = "converged" if self.converged else "not converged"
        return f"CalibrationResult({self.model_runs} runs, {len(self.rounds)} rounds, {state}: {moments})"


def _escape(text: str) -> str:
    return text.replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;")


def _toml_string(text: str) -> str:
    return json.dumps(text, ensure_ascii=False)


def _toml_number(value: float) -> str:
    return repr(float(value))


def _model_posterior_lines(model_posterior: Any, seed: int) -> List[str]:
    """The `[model_posterior]` lines of ``calibrate``'s study: its seed, and a dict's keys."""
    options = model_posterior if isinstance(model_posterior, dict) else {}
    lines = [] if "seed" in options else [f"seed = {seed}"]
    for key, value in options.items():
        if not (isinstance(key, str) and key.replace("_", "").isalnum() and key.isascii()):
            raise ValueError(f"model_posterior: `{key}` is not a key of [model_posterior]")
        if isinstance(value, bool):
            text = "true" if value else "false"
        elif isinstance(value, (int, np.integer)):
            text = str(int(value))
        elif isinstance(value, (float, np.floating)):
            text = _toml_number(value)
        elif isinstance(value, str):
            text = _toml_string(value)
        else:
            raise ValueError(f"model_posterior.{key}: {value!r} is not a number, bool or string")
        lines.append(f"{key} = {text}")
    return lines


def _describe(model: Callable[..., Any], description: Optional[str]) -> str:
    """What names the model in the store: the caller's text, else the function's qualified
    name and a digest of its source code (so that an edited function does not reuse the runs
    of the old one)."""
    if description is not None:
        return str(description)
    name = getattr(model, "__qualname__", None) or type(model).__name__
    module = getattr(model, "__module__", None) or ""
    try:
        source = inspect.getsource(model)
    except (OSError, TypeError):
        source = ""
    digest = hashlib.sha256(source.encode()).hexdigest()[:16] if source else "no source"
    return f"{module}.{name} ({digest})"


def _write_atomically(path: Path, text: str) -> None:
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_text(text, encoding="utf-8")
    os.replace(tmp, path)


def _progress_printer(progress: Any) -> Optional[Callable[[str], Any]]:
    """The line callback for ``progress``: ``False`` quiet; ``True`` a progress bar (tqdm's, in
    a terminal or a notebook, where tqdm is installed) or lines on stderr; a callable gets the
    lines."""
    if progress is False or progress is None:
        return None
    if callable(progress) and progress is not True:
        return progress
    if progress is not True:
        raise TypeError("progress: expected a bool or a callable taking a line of text")
    try:
        from tqdm.auto import tqdm
    except ImportError:
        return lambda line: print(line, file=sys.stderr, flush=True)
    bar = tqdm(total=0, unit="run", desc="model runs", leave=True)
    finished = re.compile(r"(\d+)/(\d+) finished")

    def update(line: str) -> None:
        m = finished.search(line)
        if m:
            done, total = int(m.group(1)), int(m.group(2))
            if bar.total != total:
                bar.total = total
            bar.n = done
            bar.refresh()
        elif line.startswith("pipeline:"):
            bar.set_postfix_str(line[len("pipeline: ") :][:60], refresh=True)

    update.close = bar.close  # type: ignore[attr-defined]
    return update


def calibrate(
    model: Callable[..., Any],
    parameters: Any,
    y: Any,
    y_std: Any = None,
    *,
    x: Any = None,
    per_point: bool = False,
    initial_runs: Optional[int] = None,
    batch: int = 2,
    max_runs: int = 300,
    tolerance: float = 0.1,
    surrogate_error_multiple: float = 2.0,
    modelling_error: Optional[Tuple[float, float]] = None,
    computational_error: str = "absolute",
    posterior_check: int = 0,
    model_posterior: Union[bool, Dict[str, Any]] = False,
    samples: int = 10000,
    sensitivity: int = 256,
    seed: int = 0,
    store: Optional[PathLike] = None,
    report: Optional[PathLike] = None,
    on_error: str = "fail",
    batch_size: int = 16,
    description: Optional[str] = None,
    progress: Any = True,
    low_fidelity: Optional[Callable[..., Any]] = None,
    cost_ratio: Optional[float] = None,
) -> CalibrationResult:
    """Calibrate the Python function ``model`` on data with iuq's adaptive engine.

    The engine (the book's adaptive-engine chapter): an initial maximin Latin hypercube of
    ``initial_runs`` runs, then rounds of up to ``batch`` runs placed where they most reduce
    the surrogate's error on the posterior, until every posterior mean and std is stable to
    ``tolerance`` posterior stds and twice the surrogate's typical error is below it too (a
    mean or std within ``tolerance`` of the model's posterior at about 95 %), or ``max_runs``. One GP per data point stands in for the model; BASIS samples the posterior.

    The likelihood is the prediction-error likelihood (the methods' chapter on it). By default
    it is exactly the Gaussian N(y | model(θ), diag(y_std²)), the surrogate adding its own
    predictive variance v(θ) while it stands in for the model: Σ_jj = y_std_j² + v_j(θ).

    With ``store`` every evaluation is stored as it completes in
    ``store/calibration.campaign/campaign.sqlite``; calling again with the same store reuses
    them and continues where the last call stopped (after a crash, a kill or a
    ``KeyboardInterrupt``). A Ctrl-C raises ``KeyboardInterrupt`` within a second, also while
    the engine computes (its work then stops in the background at its next check, and the next
    call waits for that).

    Parameters
    ----------
    model : callable
        ``model(theta)`` with ``theta`` an (n, d) array of parameter vectors (columns in the
        order of ``parameters``) returns an (n, m) array, one value per data point, or a pair
        ``(values, std)`` of such arrays, ``std`` the model's own computational std. With
        ``per_point=True`` it is called as ``model(theta, x)`` with θ (n, d) and the abscissae
        ``x`` (n,) and returns (n,).
    parameters : dict, sequence or SALib problem
        The priors, as :func:`iuq.basis` takes them: ``{name: (lo, hi) or {"normal": [m, s]}}``,
        a list of pairs, or SALib's ``problem``.
    y : array_like, shape (m,)
        The observations.
    y_std : array_like, shape (m,), optional
        Their measurement standard deviations (each > 0).
    x : array_like, shape (m,), optional
        Their abscissae (default 0, 1, …).
    per_point : bool, default False
        One run per (θ, x) instead of one per θ.
    initial_runs : int, optional
        Runs of the initial design (default max(6, d + 2); with ``per_point=True`` and a
        ``low_fidelity``, per data point ⌈4(d + 2)/m⌉ for m data points, at least 3 and at most
        that default: the data points share one discrepancy and pool their expensive runs).
    batch : int, default 2
        Runs per adaptive round at most.
    max_runs : int, default 300
        Runs at most.
    tolerance : float, default 0.1
        The stopping rule's tolerance, in posterior stds.
    surrogate_error_multiple : float, default 2.0
        How many times the surrogate's typical error on a posterior mean or std counts against
        ``tolerance``: at 2 every mean and std stands within ``tolerance`` of the model's
        posterior at about 95 %, at 1 about one in three may stand further (fewer runs).
    modelling_error : (float, float), optional
        ``(lo, hi)``: a modelling error relative to the data, Σ_jj += σ_m²·y_j², σ_m ~ U(lo, hi)
        sampled with θ (the red-cell study's (0.001, 0.1): 0.1 % to 10 % of each datum).
        Without ``y_std`` it is needed, for the likelihood to have a spread at all.
    computational_error : {"absolute", "relative", "absolute-times-data", "none"}, default "absolute"
        How a computational std s_j enters: s_j², (s_j·y_j/q_j)² (the published study's),
        (s_j·y_j)², or not at all.
    posterior_check : int, default 0
        Run the model at the posterior's MAP and at this many posterior samples.
    model_posterior : bool or dict, default False
        Also give the model's own posterior, certified from the surrogate's (300 runs by
        default where one importance stage holds; a batch more where the first shows the
        surrogate off, and up to that many more for each bridging stage). A dict gives its
        ``[model_posterior]`` keys (the book's study-file reference; its ``seed`` is ``seed``
        unless the dict gives one), e.g. ``{"samples": 400, "replicates": 4}`` for a stochastic
        or chaotic function.
    samples : int, default 10000
        The final BASIS population.
    sensitivity : int, default 256
        Sobol' base points on the surrogate (0: none).
    seed : int, default 0
        Seeds everything.
    store : str or os.PathLike, optional
        A directory for the campaign store (default: a temporary one, removed afterwards).
    report : str or os.PathLike, optional
        Where the report and every table and figure go (default ``store/report``, or a
        temporary directory).
    on_error : {"fail", "raise"}, default "fail"
        ``"fail"``: runs where the function raises or returns non-finite values are failed runs,
        their reason stored, which a classifier keeps the posterior away from; ``"raise"``:
        stop and raise the exception.
    batch_size : int, default 16
        Runs waiting at once that are evaluated in one call of ``model``.
    description : str, optional
        Names the model in the store (default: its name and a digest of its source, so that an
        edited function's runs are not reused).
    progress : bool or callable, default True
        ``True``: a progress bar (tqdm, where installed) or lines on stderr; ``False``: quiet;
        a callable receives each line.
    low_fidelity : callable, optional
        A cheaper model of the same outputs, called as ``model`` is (the book's how-to on two
        fidelities): the surrogate of ``model`` becomes ρ·(a GP of ``low_fidelity``) + a GP
        discrepancy, per data point (or, for a whole curve of 50 points or more, per principal
        component of both models' curves), and each round runs ``low_fidelity`` instead of ``model`` where that
        removes more of the surrogate's variance per unit cost. ``model_runs`` and ``runs``
        count ``model``'s runs; ``low_fidelity``'s are stored beside them.
    cost_ratio : float, optional
        A run of ``model`` costs this many runs of ``low_fidelity`` (default: the ratio of
        their measured median run times).

    Returns
    -------
    CalibrationResult
        Posterior samples and summaries, the rounds, every run, and ``.to_arviz()``.

    Raises
    ------
    TypeError
        If ``model`` is not callable.
    ValueError
        If an argument is out of range (the message starts with its name), e.g. a ``y_std``
        that is not positive, neither ``y_std`` nor ``modelling_error``, or a bad
        ``model_posterior`` key (named ``model_posterior.<key>``).
    KeyboardInterrupt
        On Ctrl-C; the runs made so far stay in ``store``.
    Exception
        Whatever ``model`` raises, with ``on_error="raise"``.

    See Also
    --------
    iuq.Study.run : the same engine on a study file (a program as the model).

    Examples
    --------
    >>> import numpy as np
    >>> import iuq
    >>> t = np.linspace(0.5, 4.0, 5)
    >>> result = iuq.calibrate(lambda theta: np.exp(-theta[:, :1] * t), {"k": (0.05, 0.8)},
    ...                        np.exp(-0.3 * t), np.full(5, 0.02), x=t, samples=1000,
    ...                        sensitivity=0, seed=1, progress=False)
    >>> result
    CalibrationResult(8 runs, 2 rounds, converged: k = 0.3007 ± 0.00862)
    >>> bool(abs(result.mean[0] - 0.3) < 3 * result.std[0])
    True
    """
    if not callable(model):
        raise TypeError("model: expected a callable taking an (n, d) array")
    if low_fidelity is not None and not callable(low_fidelity):
        raise TypeError("low_fidelity: expected a callable taking an (n, d) array, as model")
    if cost_ratio is not None:
        cost_ratio = real("cost_ratio", cost_ratio)
        if not cost_ratio > 0:
            raise ValueError(f"cost_ratio: must be > 0, got {cost_ratio}")
        if low_fidelity is None:
            raise ValueError("cost_ratio: only with a low_fidelity model")
    names, priors = parameter_priors(parameters, "parameters")
    d = len(names)
    values = vector("y", y)
    m = values.shape[0]
    std = None if y_std is None else vector("y_std", y_std, m)
    if std is not None and not np.all(std > 0):
        raise ValueError("y_std: every measurement std must be > 0")
    abscissa = np.arange(m, dtype=np.float64) if x is None else vector("x", x, m)
    if on_error not in ("raise", "fail"):
        raise ValueError(f"on_error: `{on_error}` is not one of raise, fail")
    if computational_error not in ("relative", "absolute-times-data", "absolute", "none"):
        raise ValueError(
            f"computational_error: `{computational_error}` is not one of relative, absolute-times-data, absolute, none"
        )
    # Without `initial_runs` the command line's default applies (max(6, d + 2) per run group;
    # fewer per data point where a cheap model's discrepancy is shared across per-point runs).
    initial = None if initial_runs is None else count("initial_runs", initial_runs, 3)
    batch = count("batch", batch, 1)
    max_runs = count("max_runs", max_runs, 1)
    tolerance = real("tolerance", tolerance)
    if not tolerance > 0:
        raise ValueError(f"tolerance: must be > 0, got {tolerance}")
    surrogate_error_multiple = real("surrogate_error_multiple", surrogate_error_multiple)
    if not surrogate_error_multiple > 0:
        raise ValueError(f"surrogate_error_multiple: must be > 0, got {surrogate_error_multiple}")
    samples = count("samples", samples, 2)
    sensitivity = count("sensitivity", sensitivity, 0)
    posterior_check = count("posterior_check", posterior_check, 0, 100_000)
    batch_size = count("batch_size", batch_size, 1)
    seed = seed_of(seed)
    if modelling_error is not None:
        lo, hi = (real("modelling_error", v) for v in modelling_error)
        if not (0 < lo < hi):
            raise ValueError(f"modelling_error: expected 0 < lo < hi, got ({lo}, {hi})")
        modelling_error = (lo, hi)
    elif std is None:
        raise ValueError(
            "y_std: give the measurement stds, or a modelling_error=(lo, hi) prior (σ_m relative "
            "to the data): without either the likelihood has no spread"
        )
    for reserved in ("x", "sigma_m"):
        if reserved in names:
            raise ValueError(f"parameters: `{reserved}` is a name iuq uses; rename the parameter")

    temporary = None
    if store is None:
        temporary = tempfile.TemporaryDirectory(prefix="iuq-calibrate-")
        directory = Path(temporary.name)
    else:
        directory = Path(store)
        if directory.exists() and not directory.is_dir():
            raise ValueError(f"store: {directory} is not a directory")
        directory.mkdir(parents=True, exist_ok=True)
    out = Path(report) if report is not None else directory / "report"
    try:
        lines = ["x,y" + (",y_err" if std is not None else "")]
        for j in range(m):
            row = f"{float(abscissa[j])!r},{float(values[j])!r}"
            if std is not None:
                row += f",{float(std[j])!r}"
            lines.append(row)
        _write_atomically(directory / DATA_FILE, "\n".join(lines) + "\n")
        study = [f'name = "calibration"', "[parameters]"]
        for name, (kind, args) in zip(names, priors):
            study.append(f"{_toml_string(name)} = {{ {kind} = [{', '.join(_toml_number(v) for v in args)}] }}")
        data = f'file = "{DATA_FILE}", x = "x", y = "y"' + (', y_err = "y_err"' if std is not None else "")
        study += ["[likelihood]", f"data = {{ {data} }}"]
        if modelling_error is None:
            study.append("modelling_error = false")
        else:
            study.append(f"modelling_error = {{ uniform = [{_toml_number(modelling_error[0])}, {_toml_number(modelling_error[1])}] }}")
        study.append(f"computational_error = {_toml_string(computational_error)}")
        study += ["[model]", 'kind = "callable"', f"description = {_toml_string(_describe(model, description))}"]
        if per_point:
            study.append('abscissa = "x"')
        # More samples per round only once the surrogate's error is below the tolerance: early
        # rounds keep their cost (docs/study-file: `more_samples`).
        adaptive = (
            f"batch = {batch}, max_runs = {max_runs}, tolerance = {_toml_number(tolerance)}, "
            f"surrogate_error_multiple = {_toml_number(surrogate_error_multiple)}, "
            'more_samples = "when-resolving"'
        )
        design_n = "" if initial is None else f"n = {initial}, "
        study += ["[surrogate]", f'design = {{ kind = "lhs", {design_n}seed = {seed} }}', f"adaptive = {{ {adaptive} }}"]
        if posterior_check > 0:
            study.append(f"posterior_check = {{ samples = {posterior_check}, seed = {seed} }}")
        if sensitivity > 0:
            study += ["[sensitivity]", f"n = {sensitivity}", f"seed = {seed}"]
        study += ["[sampler]", f"samples = {samples}", f"seed = {seed}"]
        study += ["[model_posterior]", *_model_posterior_lines(model_posterior, seed)]
        if low_fidelity is not None:
            study += ["[low_fidelity]", 'kind = "callable"', f"description = {_toml_string(_describe(low_fidelity, None))}"]
            if per_point:
                study.append('abscissa = "x"')
            if cost_ratio is not None:
                study.append(f"cost_ratio = {_toml_number(cost_ratio)}")
        study += ["[executor]", 'kind = "local"']
        path = directory / STUDY_FILE
        _write_atomically(path, "\n".join(study) + "\n")

        def per_point_call(f: Callable[..., Any]) -> Callable[[np.ndarray], Any]:
            def call(a: np.ndarray) -> Any:
                result = f(a[:, :d], a[:, d])
                if isinstance(result, tuple) and len(result) == 2:
                    return np.asarray(result[0], dtype=np.float64), np.asarray(result[1], dtype=np.float64)
                return np.asarray(result, dtype=np.float64)

            return call

        function = per_point_call(model) if per_point else model
        cheap = None
        if low_fidelity is not None:
            cheap = per_point_call(low_fidelity) if per_point else low_fidelity

        native = _native.Study.load(os.fspath(path))
        printer = _progress_printer(progress)
        try:
            text = native.calibrate(
                os.fspath(out),
                function,
                dict(
                    outputs=1 if per_point else m,
                    on_error=on_error,
                    max_parallel=batch_size,
                    model_posterior=bool(model_posterior) or isinstance(model_posterior, dict),
                ),
                printer,
                cheap,
            )
        finally:
            close = getattr(printer, "close", None)
            if close is not None:
                close()
        raw = json.loads(text)
        result = _result(raw, native, out, names, d, abscissa, values, std, modelling_error, seed)
        if temporary is not None:
            result = _without_out(result)
        return result
    finally:
        if temporary is not None:
            temporary.cleanup()


def _without_out(result: CalibrationResult) -> CalibrationResult:
    from dataclasses import replace

    return replace(result, out=None, store=None)


def _result(
    raw: Dict[str, Any],
    native: Any,
    out: Path,
    parameters: List[str],
    d: int,
    x: np.ndarray,
    y: np.ndarray,
    y_std: Optional[np.ndarray],
    modelling_error: Optional[Tuple[float, float]],
    seed: int,
) -> CalibrationResult:
    table = np.genfromtxt(out / "basis-gp" / "samples.csv", delimiter=",", names=True)
    columns = [c for c in table.dtype.names if c not in ("ll", "lp")]
    samples = np.column_stack([table[c] for c in columns]).astype(np.float64)
    log_likelihood = np.asarray(table["ll"], dtype=np.float64)
    names = columns
    mean = samples.mean(axis=0)
    std = samples.std(axis=0)
    q05, q95 = np.quantile(samples, [0.05, 0.95], axis=0)
    map_ = samples[int(np.argmax(log_likelihood + np.asarray(table["lp"], dtype=np.float64)))]
    adaptive = raw.get("adaptive") or {}
    store = _store_of(native)
    runs = _runs(store, parameters, x)
    failed = sum(1 for r in runs if r["status"] == "failed")
    report = json.loads((out / "report.json").read_text()) if (out / "report.json").exists() else {}
    sensitivity = (report.get("derived") or {}).get("sensitivity") if isinstance(report, dict) else None
    predictive = _posterior_predictive(out, samples, d, x, y, y_std, names, seed)
    return CalibrationResult(
        names=names,
        parameters=parameters,
        samples=samples,
        log_likelihood=log_likelihood,
        mean=mean,
        std=std,
        map=map_,
        q05=q05,
        q95=q95,
        converged=bool(raw.get("converged", True)),
        stop_reason=str(adaptive.get("stop_reason", "")),
        rounds=list(adaptive.get("rounds", [])),
        model_runs=len(runs),
        surrogate_runs=int(raw.get("runs", len(runs))),
        failed_runs=failed,
        runs=runs,
        data={"x": x, "y": y, "y_std": y_std},
        model_posterior=raw.get("model_posterior"),
        model_posterior_samples=read_model_posterior(out, raw.get("model_posterior")),
        sensitivity=sensitivity,
        out=out,
        store=store,
        seconds=float(raw.get("seconds", 0.0)),
        posterior_predictive=predictive,
        raw=raw,
    )


def _store_of(native: Any) -> Path:
    """The campaign store of the calibration study (``<study>.campaign/campaign.sqlite``)."""
    path = Path(native.path)
    return path.with_name(path.stem + ".campaign") / "campaign.sqlite"


def _runs(store: Path, parameters: List[str], x: np.ndarray) -> List[Dict[str, Any]]:
    """Every run in the store: its parameters by name (and ``x`` for a run per data point),
    status, outputs and failure reason."""
    import sqlite3

    con = sqlite3.connect(f"file:{store}?mode=ro", uri=True)
    try:
        outputs: Dict[int, List[float]] = {}
        for run_id, value in con.execute("select run_id, value from outputs order by run_id, position"):
            outputs.setdefault(run_id, []).append(value)
        rows = []
        for run_id, params, status, reason in con.execute(
            "select id, parameters, status, reason from runs order by id"
        ):
            values = json.loads(params)
            row: Dict[str, Any] = dict(zip(parameters, values))
            if len(values) > len(parameters):
                row["x"] = values[len(parameters)]
            row.update(status=status, outputs=outputs.get(run_id), reason=reason)
            rows.append(row)
        return rows
    finally:
        con.close()


def _posterior_predictive(
    out: Path,
    samples: np.ndarray,
    d: int,
    x: np.ndarray,
    y: np.ndarray,
    y_std: Optional[np.ndarray],
    names: List[str],
    seed: int,
    draws: int = 1000,
) -> Optional[np.ndarray]:
    """y_rep at the data points for up to ``draws`` posterior samples: the surrogate's mean (a
    GP per data point, ``gp-bank.json``) plus the likelihood's Gaussian noise (σ_d² + σ_m²·y²);
    ``None`` for a reduced-basis surrogate."""
    bank_file = out / "gp-bank.json"
    if not bank_file.exists():
        return None
    from ._gp import GaussianProcess

    bank = json.loads(bank_file.read_text())
    rng = np.random.default_rng(seed)
    take = np.linspace(0, len(samples) - 1, min(draws, len(samples))).astype(int)
    theta = samples[take, :d]
    means = np.empty((len(take), len(y)))
    with tempfile.TemporaryDirectory(prefix="iuq-bank-") as tmp:
        for j, gp in enumerate(bank["gps"]):
            f = Path(tmp) / f"gp-{j}.json"
            # A GP file is a bank of one GP.
            f.write_text(json.dumps(dict(bank, output_names=[bank["output_names"][j]], gps=[gp])))
            model = GaussianProcess.load(f)
            points = theta if model.dimension == d else np.column_stack([theta, np.full(len(theta), x[j])])
            means[:, j] = model.predict(points)
    variance = np.zeros((len(take), len(y)))
    if y_std is not None:
        variance += y_std[None, :] ** 2
    if "sigma_m" in names:
        sm = samples[take, names.index("sigma_m")]
        variance += (sm[:, None] * y[None, :]) ** 2
    return means + rng.standard_normal(means.shape) * np.sqrt(variance)
