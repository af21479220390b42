"""iuq — inverse uncertainty quantification of expensive simulation models, from Python.

numpy arrays in and out, any Python function as the model:

- :mod:`iuq.design`: ``lhs``, ``sobol``, ``saltelli`` space-filling designs;
- :class:`iuq.GaussianProcess`: ``fit``, ``predict``, ``q2``, ``save``/``load`` (the CLI's format);
- :func:`iuq.sobol`: Sobol' indices of a Python model (or formulas), with intervals;
- :func:`iuq.basis`: BASIS posterior samples and evidence of a Python log-likelihood, or of a
  Python model against data with the prediction-error likelihood;
- :func:`iuq.calibrate`: calibrate a Python function on data with the adaptive engine (a
  store that survives the session, results as numpy, pandas and ArviZ);
- :class:`iuq.Study`: a study file's calibration pipeline (the adaptive engine included),
  campaign status and export;
- :class:`iuq.ModelPosteriorSamples`: the model's own posterior (``model_posterior=True``) as
  weighted members, and in ArviZ.

Every function calls the Rust libraries of the ``iuq`` command line: for the same seeds the
results equal the CLI's bit for bit. Python callables are called in batches (one 2-D array per
design or stage), the GIL is released during the Rust work, and an exception in a callable is
re-raised (or, with ``on_error="fail"``, becomes a failed point). Methods and references:
``docs/methods.md`` in the repository.
"""

from . import _native, design
from ._basis import BasisResult, basis
from ._calibrate import CalibrationResult, calibrate
from ._gp import GaussianProcess
from ._model_posterior import ModelPosteriorSamples
from ._sensitivity import SobolResult, sobol
from ._study import CampaignStatus, PipelineResult, Study

__version__: str = _native.__version__

__all__ = [
    "design",
    "GaussianProcess",
    "sobol",
    "SobolResult",
    "basis",
    "BasisResult",
    "calibrate",
    "CalibrationResult",
    "ModelPosteriorSamples",
    "Study",
    "PipelineResult",
    "CampaignStatus",
    "__version__",
]
