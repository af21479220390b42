"""The example notebook (examples/python/calibrate.ipynb) runs end to end: iuq.calibrate on a
small Python simulator, ArviZ's summary and plots."""

from __future__ import annotations

from pathlib import Path

import pytest

NOTEBOOK = Path(__file__).resolve().parents[2] / "examples" / "python" / "calibrate.ipynb"


def test_the_calibration_notebook_runs(tmp_path):
    nbformat = pytest.importorskip("nbformat")
    nbclient = pytest.importorskip("nbclient")
    pytest.importorskip("arviz")
    notebook = nbformat.read(NOTEBOOK, as_version=4)
    nbclient.NotebookClient(
        notebook, timeout=600, kernel_name="python3", resources={"metadata": {"path": str(tmp_path)}}
    ).execute()
    texts = [
        output["data"].get("text/plain", "")
        for cell in notebook.cells
        if cell.cell_type == "code"
        for output in cell.outputs
        if "data" in output
    ]
    assert any(t.startswith("CalibrationResult(") and "converged" in t for t in texts), texts
    assert any("hdi_3%" in t for t in texts), texts
    assert (tmp_path / "logistic-calibration" / "calibration.campaign" / "campaign.sqlite").is_file()
