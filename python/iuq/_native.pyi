"""Type stubs of the Rust extension ``iuq._native`` (use the documented wrappers in ``iuq``)."""

from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple

import numpy as np
import numpy.typing as npt

__version__: str

Bounds = Optional[Sequence[Tuple[float, float]]]

def lhs(
    n: int,
    dim: int,
    seed: int = 0,
    method: str = "maximin",
    candidates: int = 100,
    bounds: Bounds = None,
) -> npt.NDArray[np.float64]: ...
def sobol(
    n: int, dim: int, seed: int = 0, scramble: bool = True, bounds: Bounds = None
) -> npt.NDArray[np.float64]: ...
def saltelli(
    n: int, dim: int, seed: int = 0, scramble: bool = True, bounds: Bounds = None
) -> npt.NDArray[np.float64]: ...
def sobol_indices(
    function: Optional[Callable[[npt.NDArray[np.float64]], Any]],
    expressions: Optional[Sequence[Tuple[str, str]]],
    names: Sequence[str],
    priors: Sequence[Tuple[str, Sequence[float]]],
    outputs: Sequence[str],
    settings: Dict[str, Any],  # n, seed, resamples, replicates, confidence, on_error
) -> Dict[str, Any]: ...
def basis(
    log_likelihood: Optional[Callable[[npt.NDArray[np.float64]], Any]],
    formula: Optional[str],
    data: Optional[Dict[str, Any]],
    names: Sequence[str],
    priors: Sequence[Tuple[str, Sequence[float]]],
    settings: Dict[str, Any],  # samples, burn, max_chain, seed, cv_target, proposal_scale, max_stages, on_error
) -> Dict[str, Any]: ...

class GaussianProcess:
    @staticmethod
    def fit(
        x: npt.NDArray[np.float64],
        y: npt.NDArray[np.float64],
        settings: Dict[str, Any],  # restarts, seed, kernel, scale_inputs, standardize_outputs
        inputs: List[str],
        output: str,
    ) -> GaussianProcess: ...
    @staticmethod
    def load(path: str) -> GaussianProcess: ...
    def save(self, path: str) -> None: ...
    def predict(
        self, x: npt.NDArray[np.float64]
    ) -> Tuple[npt.NDArray[np.float64], npt.NDArray[np.float64], float]: ...
    def q2(self, x: npt.NDArray[np.float64], y: npt.NDArray[np.float64]) -> float: ...
    @property
    def log_marginal_likelihood(self) -> float: ...
    @property
    def loo_q2(self) -> Optional[float]: ...
    @property
    def length_scales(self) -> List[float]: ...
    @property
    def length_scales_input_units(self) -> List[float]: ...
    @property
    def signal_variance(self) -> float: ...
    @property
    def noise_variance(self) -> float: ...
    @property
    def input_names(self) -> List[str]: ...
    @property
    def output_name(self) -> str: ...
    @property
    def dimension(self) -> int: ...
    @property
    def n_training(self) -> int: ...
    @property
    def warnings(self) -> List[str]: ...

class Study:
    @staticmethod
    def load(path: str) -> Study: ...
    @property
    def name(self) -> str: ...
    @property
    def path(self) -> str: ...
    @property
    def parameters(self) -> List[str]: ...
    @property
    def ranges(self) -> List[Tuple[float, float]]: ...
    def run(
        self,
        out: str,
        settings: Dict[str, Any],  # max_parallel, model_posterior, fresh, runs_only, recompute_rounds
        progress: Optional[Callable[[str], Any]],
    ) -> str: ...
    def calibrate(
        self,
        out: str,
        model: Callable[[Any], Any],
        settings: Dict[str, Any],  # outputs, on_error, max_parallel, model_posterior
        progress: Optional[Callable[[str], Any]],
        low_fidelity: Optional[Callable[[Any], Any]] = None,
    ) -> str: ...
    def sobol(
        self,
        n: Optional[int],
        seed: Optional[int],
        replicates: Optional[int],
        resamples: Optional[int],
        confidence: Optional[float],
    ) -> Dict[str, Any]: ...
    def basis(
        self,
        out: str,
        samples: Optional[int],
        burn: Optional[int],
        max_chain: Optional[int],
        seed: Optional[int],
    ) -> Dict[str, Any]: ...
    def status(self) -> str: ...
    def export(self, out: Optional[str], format: Optional[str]) -> str: ...
