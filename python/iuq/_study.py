"""Study files (``docs/study-file.md``): the calibration pipeline, campaign status and export."""

from __future__ import annotations

import json
import os
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Dict, List, Optional, Union

import numpy as np

from . import _native
from ._args import count, real, seed_of
from ._basis import BasisResult
from ._basis import result_from_raw as _basis_result
from ._model_posterior import ModelPosteriorSamples, read_model_posterior
from ._sensitivity import SobolResult
from ._sensitivity import result_from_raw as _sobol_result

__all__ = ["Study", "PipelineResult", "CampaignStatus"]

PathLike = Union[str, "os.PathLike[str]"]


@dataclass(frozen=True)
class PipelineResult:
    """The outcome of :meth:`Study.run`: the fields of ``iuq pipeline --json``.

    Attributes
    ----------
    study : str
        The study's name.
    out : pathlib.Path
        The output directory.
    report : pathlib.Path or None
        The report page (``None`` with ``runs_only``).
    runs, failed : int
        Model runs over the initial, test and adaptive designs, and those that failed.
    converged : bool
        The adaptive engine's decision (``True`` without the engine).
    rounds : int
        Adaptive rounds.
    adaptive : dict or None
        The adaptive engine's rounds and stopping decision (``None`` without
        ``[surrogate] adaptive``).
    q2 : numpy.ndarray
        The test-set Q2 of each surrogate.
    posterior : list of dict
        The posterior tables, per source (as in ``pipeline.json``).
    posterior_check : dict or None
        The model at the posterior, per data point.
    model_posterior : dict or None
        With ``model_posterior=True``: the model's own posterior from the surrogate's —
        ``mean``, ``std``, ``mcse_mean``, ``mcse_std``, ``map`` by parameter, ``pareto_k`` with
        its threshold, ``effective_sample_size``, ``certified``, the ``stages`` and the
        ``model_runs`` it asked for.
    model_posterior_samples : ModelPosteriorSamples or None
        Its weighted members as arrays, with ``to_arviz()``.
    stage_seconds : dict
        Wall time of each stage.
    seconds : float
        Wall time in all.
    raw : dict
        The whole ``--json`` object.
    """

    study: str
    out: Path
    report: Optional[Path]
    runs: int
    failed: int
    converged: bool
    rounds: int
    adaptive: Optional[Dict[str, Any]]
    q2: np.ndarray
    posterior: Any
    posterior_check: Any
    model_posterior: Optional[Dict[str, Any]]
    stage_seconds: Dict[str, float]
    seconds: float
    raw: Dict[str, Any] = field(repr=False, default_factory=dict)
    model_posterior_samples: Optional[ModelPosteriorSamples] = field(default=None, repr=False)


@dataclass(frozen=True)
class CampaignStatus:
    """Where a study's campaign of model runs stands (``iuq status --json``).

    Attributes
    ----------
    study : str
        The study's name.
    store : pathlib.Path
        The campaign store.
    counts : dict
        Runs per status (``pending``, ``queued``, ``running``, ``succeeded``, ``failed``,
        ``cancelled``).
    total : int
        Runs in all.
    attempts : dict
        Attempts per outcome.
    failures : list of dict
        The failed runs with their reasons.
    journal_mode : str or None
        The store's SQLite journal mode.
    designs : list of dict
        Every design recorded in the store (each batch the pipeline asked for), oldest first:
        ``id``, ``label``, ``size``, ``created_at``, ``counts`` of its runs per status, and what
        its runs cost since it was recorded: ``run_seconds`` (their attempts' summed duration),
        ``first_started_at`` and ``last_finished_at`` (Unix seconds; ``None`` before one
        finished).
    """

    study: str
    store: Path
    counts: Dict[str, int]
    total: int
    attempts: Dict[str, int]
    failures: List[Dict[str, Any]]
    journal_mode: Any = None
    #: Every design recorded in the store (each batch the pipeline asked for), oldest first:
    #: ``id``, ``label``, ``size``, ``created_at``, ``counts`` of its runs per status, and what
    #: its runs cost since it was recorded: ``run_seconds`` (their attempts' summed duration),
    #: ``first_started_at`` and ``last_finished_at`` (Unix seconds; ``None`` before one finished).
    designs: List[Dict[str, Any]] = field(default_factory=list)


def _print_progress(line: str) -> None:
    print(line, file=sys.stderr, flush=True)


class Study:
    r"""A study file, loaded and checked (the book's study-file reference).

    Its pipeline (:meth:`run`) makes or reuses the model runs through the study's campaign
    (``<study>.campaign/campaign.sqlite``), fits the surrogates, runs the adaptive engine when
    configured, computes Sobol' indices, samples the posterior with BASIS and writes the report
    — exactly ``iuq pipeline``. :meth:`status` and :meth:`export` read the campaign.

    Create one with :meth:`load`; the constructor is not public.

    Examples
    --------
    >>> import os, tempfile
    >>> import iuq
    >>> folder = tempfile.mkdtemp()
    >>> with open(os.path.join(folder, "data.csv"), "w") as f:
    ...     _ = f.write("x,y,y_err\n0.5,1.9,0.1\n1.0,3.1,0.1\n1.5,4.0,0.1\n2.0,5.1,0.1\n")
    >>> with open(os.path.join(folder, "line.toml"), "w") as f:
    ...     _ = f.write('''name = "line"
    ... [parameters]
    ... a = { uniform = [0, 5] }
    ... b = { uniform = [0, 5] }
    ... [likelihood]
    ... data = { file = "data.csv", x = "x", y = "y", y_err = "y_err" }
    ... [model]
    ... kind = "expression"
    ... abscissa = "x"
    ... outputs = { y = "a + b*x" }
    ... [surrogate]
    ... design = { kind = "lhs", n = 10, seed = 1 }
    ... [sampler]
    ... samples = 2000
    ... seed = 1
    ... [sensitivity]
    ... n = 256
    ... ''')
    >>> study = iuq.Study.load(os.path.join(folder, "line.toml"))
    >>> study.name, study.parameters
    ('line', ['a', 'b'])
    """

    __slots__ = ("_native",)

    def __init__(self, native: "_native.Study") -> None:
        if not isinstance(native, _native.Study):
            raise TypeError("use Study.load(path)")
        self._native = native

    @classmethod
    def load(cls, path: PathLike) -> "Study":
        """Read and check a study file.

        Parameters
        ----------
        path : str or os.PathLike
            The study file (TOML). Relative paths inside it are taken from its folder.

        Returns
        -------
        Study

        Raises
        ------
        ValueError
            If the file cannot be read or is not a valid study; the message names the file, the
            key and the reason.

        Examples
        --------
        >>> import iuq
        >>> study = iuq.Study.load("examples/rbc-healthy-hemocell.toml")   # from the repository root
        >>> study.name, study.parameters
        ('rbc-healthy-hemocell', ['kLink', 'kBend', 'viscosityRatio'])
        """
        return cls(_native.Study.load(os.fspath(path)))

    @property
    def name(self) -> str:
        """The study's ``name``."""
        return self._native.name

    @property
    def path(self) -> Path:
        """The study file."""
        return Path(self._native.path)

    @property
    def parameters(self) -> List[str]:
        """Parameter names, in file order."""
        return self._native.parameters

    @property
    def ranges(self) -> List[tuple]:
        """Each parameter's range (the prior's support, or the plotting range of an unbounded prior)."""
        return self._native.ranges

    def run(
        self,
        out: Optional[PathLike] = None,
        *,
        max_parallel: Optional[int] = None,
        model_posterior: bool = False,
        fresh: bool = False,
        runs_only: bool = False,
        recompute_rounds: bool = False,
        progress: Union[bool, Callable[[str], Any]] = False,
    ) -> PipelineResult:
        r"""Run the calibration pipeline into ``out`` (``iuq pipeline``).

        The GIL is released while the pipeline works.

        Parameters
        ----------
        out : str or os.PathLike, optional
            The output directory (default ``<study stem>-report`` in the current directory).
        max_parallel : int, optional
            Model runs at once (default: the executor's setting, else the cores).
        model_posterior : bool, default False
            Also give the model's own posterior (``[model_posterior]``: from the surrogate's by
            certified importance stages, or ``method = "basis"``).
        fresh : bool, default False
            Move the campaign aside and recompute every run.
        runs_only : bool, default False
            Stop after the training and test runs.
        recompute_rounds : bool, default False
            Recompute each adaptive round's measurement instead of reading back the one the
            campaign store recorded for the same runs and settings.
        progress : bool or callable, default False
            ``True`` prints the pipeline's news on stderr as the CLI does; a callable receives each
            line (an exception it raises stops the reporting and is raised when the pipeline
            returns).

        Returns
        -------
        PipelineResult
            The fields of ``iuq pipeline --json``.

        Raises
        ------
        ValueError
            If the study's input is bad (the message names the file, key and reason).
        TypeError
            If ``progress`` is neither a bool nor a callable.
        RuntimeError
            If the work fails.

        Examples
        --------
        >>> import os, tempfile
        >>> import iuq
        >>> folder = tempfile.mkdtemp()
        >>> with open(os.path.join(folder, "data.csv"), "w") as f:
        ...     _ = f.write("x,y,y_err\n0.5,1.9,0.1\n1.0,3.1,0.1\n1.5,4.0,0.1\n2.0,5.1,0.1\n")
        >>> with open(os.path.join(folder, "line.toml"), "w") as f:
        ...     _ = f.write('''name = "line"
        ... [parameters]
        ... a = { uniform = [0, 5] }
        ... b = { uniform = [0, 5] }
        ... [likelihood]
        ... data = { file = "data.csv", x = "x", y = "y", y_err = "y_err" }
        ... [model]
        ... kind = "expression"
        ... abscissa = "x"
        ... outputs = { y = "a + b*x" }
        ... [surrogate]
        ... design = { kind = "lhs", n = 10, seed = 1 }
        ... [sampler]
        ... samples = 2000
        ... seed = 1
        ... [sensitivity]
        ... n = 256
        ... ''')
        >>> study = iuq.Study.load(os.path.join(folder, "line.toml"))
        >>> result = study.run(os.path.join(folder, "line-report"))
        >>> result.runs, result.failed, result.converged
        (72, 0, True)
        >>> result.report.name
        'report.html'
        """
        if out is None:
            out = Path(f"{self.path.stem}-report")
        if max_parallel is not None:
            max_parallel = count("max_parallel", max_parallel, 1)
        callback: Optional[Callable[[str], Any]]
        if progress is True:
            callback = _print_progress
        elif progress is False or progress is None:
            callback = None
        elif callable(progress):
            callback = progress
        else:
            raise TypeError("progress: expected a bool or a callable taking a line of text")
        raw = json.loads(
            self._native.run(
                os.fspath(out),
                dict(
                    max_parallel=max_parallel,
                    model_posterior=bool(model_posterior),
                    fresh=bool(fresh),
                    runs_only=bool(runs_only),
                    recompute_rounds=bool(recompute_rounds),
                ),
                callback,
            )
        )
        report = raw.get("report")
        return PipelineResult(
            study=raw["study"],
            out=Path(raw["out"]),
            report=None if report is None else Path(report),
            runs=raw["runs"],
            failed=raw["failed"],
            converged=raw.get("converged", True),
            rounds=raw.get("rounds", 0),
            adaptive=raw.get("adaptive"),
            q2=np.asarray(raw.get("q2", []), dtype=np.float64),
            posterior=raw.get("posterior"),
            posterior_check=raw.get("posterior_check"),
            model_posterior=raw.get("model_posterior"),
            stage_seconds={s["stage"]: s["seconds"] for s in raw.get("stage_seconds", [])},
            seconds=raw["seconds"],
            raw=raw,
            model_posterior_samples=read_model_posterior(Path(raw["out"]), raw.get("model_posterior")),
        )

    def sobol(
        self,
        n: Optional[int] = None,
        seed: Optional[int] = None,
        *,
        replicates: Optional[int] = None,
        resamples: Optional[int] = None,
        confidence: Optional[float] = None,
    ) -> SobolResult:
        r"""Sobol' indices of the study's model over its priors (``iuq sobol STUDY``).

        The model is the study's (``expression``, ``rbc-shear`` or ``umbridge``); the result equals
        ``iuq sobol``'s. Unset options come from the study's ``[sensitivity]`` section, else the
        command line's defaults.

        Parameters
        ----------
        n : int, optional
            Base points (default 1024).
        seed : int, optional
            Seed (default 0).
        replicates : int, optional
            Intervals from independent scramblings instead of the bootstrap.
        resamples : int, optional
            Bootstrap resamples (default 100).
        confidence : float, optional
            Confidence level (default 0.95).

        Returns
        -------
        SobolResult

        Raises
        ------
        ValueError
            If an option is out of range or the study's model cannot be run in process.

        Examples
        --------
        >>> import iuq
        >>> study = iuq.Study.load("examples/ishigami.toml")   # from the repository root
        >>> s = study.sobol(n=1024)
        >>> s.S1[:2].round(2), s.ST.round(2)
        (array([0.3 , 0.46]), array([0.54, 0.43, 0.23]))
        """
        raw = self._native.sobol(
            None if n is None else count("n", n, 2),
            None if seed is None else seed_of(seed),
            None if replicates is None else count("replicates", replicates, 2, 2**16),
            None if resamples is None else count("resamples", resamples, 2, 2**20),
            None if confidence is None else real("confidence", confidence),
        )
        return _sobol_result(raw)

    def basis(
        self,
        out: Optional[PathLike] = None,
        *,
        samples: Optional[int] = None,
        burn: Optional[int] = None,
        max_chain: Optional[int] = None,
        seed: Optional[int] = None,
    ) -> BasisResult:
        r"""BASIS posterior of the study's ``[likelihood]`` (``iuq basis STUDY --out OUT``).

        Unset settings come from the study's ``[sampler]`` section; every result file
        (``samples.csv``, ``summary.json``, ``stages.json``, checkpoints, marginals) is written into
        ``out``. The result equals ``iuq basis``'s.

        Parameters
        ----------
        out : str or os.PathLike, optional
            The output directory (default ``<study name>-basis``).
        samples : int, optional
            Population size.
        burn : int, optional
            Fixed burn-in steps of every chain.
        max_chain : int, optional
            Longest chain.
        seed : int, optional
            Seed.

        Returns
        -------
        BasisResult

        Raises
        ------
        ValueError
            If a setting is out of range or the study has no usable likelihood.

        Examples
        --------
        >>> import os, tempfile
        >>> import iuq
        >>> study = iuq.Study.load("examples/cooling/cooling-exact.toml")   # from the repository root
        >>> posterior = study.basis(os.path.join(tempfile.mkdtemp(), "exact"), samples=1000)
        >>> posterior.names, posterior.mean.round(2)
        (['k', 'T0'], array([ 0.31, 88.84]))
        """
        if out is None:
            out = Path(f"{self.name}-basis")
        raw = self._native.basis(
            os.fspath(out),
            None if samples is None else count("samples", samples, 2),
            None if burn is None else count("burn", burn, 0),
            None if max_chain is None else count("max_chain", max_chain, 1),
            None if seed is None else seed_of(seed),
        )
        return _basis_result(raw)

    def status(self) -> CampaignStatus:
        """Runs per status, attempts per outcome and the failures with their reasons (``iuq status``).

        Returns
        -------
        CampaignStatus

        Raises
        ------
        ValueError
            If the study's model runs in process (``expression``, ``umbridge``, ``callable``): their
            runs are made and read by the pipeline alone.

        Examples
        --------
        >>> import iuq
        >>> study = iuq.Study.load("examples/rbc-healthy-hemocell.toml")   # from the repository root
        >>> status = study.status()
        >>> status.total == sum(status.counts.values()), status.counts["failed"]
        (True, 0)
        """
        raw = json.loads(self._native.status())
        return CampaignStatus(
            study=raw["study"],
            store=Path(raw["store"]),
            counts=dict(raw["counts"]),
            total=raw["total"],
            attempts=dict(raw["attempts"]),
            failures=list(raw["failures"]),
            journal_mode=raw.get("journal_mode"),
            designs=list(raw.get("designs", [])),
        )

    def export(
        self, out: Optional[PathLike] = None, *, format: Optional[str] = None
    ) -> Union[List[Dict[str, Any]], int]:
        """Every run of the campaign — parameters, outputs, status, reason (``iuq export``).

        Parameters
        ----------
        out : str or os.PathLike, optional
            Write the table to this file instead of returning it.
        format : {"csv", "json"}, optional
            The file's format (default from the extension, else CSV).

        Returns
        -------
        list of dict or int
            Without ``out``: the rows. With ``out``: the number of rows written.

        Raises
        ------
        ValueError
            If ``format`` is unknown or the study's model runs in process.

        Examples
        --------
        >>> import iuq
        >>> study = iuq.Study.load("examples/rbc-healthy-hemocell.toml")   # from the repository root
        >>> rows = study.export()
        >>> {"kLink", "kBend", "viscosityRatio", "el"} <= set(rows[0])
        True
        """
        if format is not None and format not in ("csv", "json"):
            raise ValueError(f"format: `{format}` is not one of csv, json")
        text = self._native.export(None if out is None else os.fspath(out), format)
        value = json.loads(text)
        if out is None:
            return value
        return int(value["rows"])

    def __repr__(self) -> str:
        return f"Study(name={self.name!r}, path={str(self.path)!r}, parameters={self.parameters!r})"
