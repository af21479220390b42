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

    ``report`` is the report page (``None`` with ``runs_only``); ``runs``/``failed`` count the
    model runs over the initial, test and adaptive designs; ``adaptive`` holds the adaptive
    engine's rounds and stopping decision (``None`` without ``[surrogate] adaptive``); ``q2``
    the test-set Q2 of each surrogate; ``posterior`` the posterior tables (as in
    ``pipeline.json``); ``posterior_check`` the model at the posterior per data point;
    ``model_posterior`` (with ``model_posterior=True``) the model's own posterior from the
    surrogate's: ``mean``, ``std``, ``mcse_mean``, ``mcse_std``, ``map`` by parameter,
    ``pareto_k`` with its threshold, ``effective_sample_size``, ``certified``, the ``stages`` and
    the ``model_runs`` it asked for; ``model_posterior_samples`` its weighted members as arrays
    (:class:`iuq.ModelPosteriorSamples`, with ``to_arviz()``).
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
    """Where a study's campaign of model runs stands (``iuq status --json``)."""

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
    """A study file, loaded and checked (``Study.load(path)``).

    Its pipeline (:meth:`run`) makes or reuses the model runs through the study's campaign
    (``<study>.campaign/campaign.sqlite``), fits the surrogates, runs the adaptive engine when
    configured, computes Sobol' indices, samples the posterior with BASIS and writes the report
    — exactly ``iuq pipeline``. :meth:`status` and :meth:`export` read the campaign.
    """

    __slots__ = ("_native",)

    def __init__(self, native: "_native.Study") -> None:
        if not isinstance(native, _native.Study):
            raise TypeError("use Study.load(path)")
        self._native = native

    @classmethod
    def load(cls, path: PathLike) -> "Study":
        """Read and check a study file; bad input is a ``ValueError`` naming the file and key."""
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
        """Each parameter's range (prior support, or plotting range of an unbounded prior)."""
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
        """Run the calibration pipeline into ``out`` (default ``<study stem>-report``).

        ``max_parallel`` model runs at once (default: the executor's setting, else the cores);
        ``model_posterior`` also gives the model's own posterior (``[model_posterior]``: from
        the surrogate's by certified importance stages, or ``method = "basis"``); ``fresh`` moves the campaign aside
        and recomputes every run; ``runs_only`` stops after the training and test runs;
        ``recompute_rounds`` recomputes each adaptive round's measurement instead of reading
        back the one the campaign store recorded for the same runs and settings.
        ``progress=True`` prints the pipeline's news on stderr as the CLI does; a callable
        receives each line (an exception it raises stops the reporting and is raised when the
        pipeline returns). The GIL is released while the pipeline works.
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
                max_parallel,
                bool(model_posterior),
                bool(fresh),
                bool(runs_only),
                bool(recompute_rounds),
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
        """Sobol' indices of the study's model over its priors (``iuq sobol STUDY``).

        Unset options come from the study's ``[sensitivity]`` section, else the CLI's defaults
        (n = 1024, seed 0, 100 bootstrap resamples, confidence 0.95). The model is the study's
        (``expression``, ``rbc-shear`` or ``umbridge``); the result equals ``iuq sobol``'s.
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
        """BASIS posterior of the study's ``[likelihood]`` (``iuq basis STUDY --out OUT``).

        Unset settings come from the study's ``[sampler]`` section; every result file
        (``samples.csv``, ``summary.json``, ``stages.json``, checkpoints, marginals) is written into
        ``out`` (default ``<study name>-basis``). The result equals ``iuq basis``'s.
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
        """Runs per status, attempts per outcome and the failures with their reasons."""
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

        Without ``out``: the rows as a list of dicts. With ``out``: the table written to that
        file as CSV or JSON (``format``, default from the extension, else CSV); returns the
        number of rows.
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
