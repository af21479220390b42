"""Shared fixtures: the `iuq` command line, to compare the package with it."""

from __future__ import annotations

import csv
import json
import os
import subprocess
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[2]


def _find_cli() -> Path | None:
    explicit = os.environ.get("IUQ_BIN")
    if explicit:
        return Path(explicit)
    for profile in ("release", "debug"):
        candidate = REPO / "target" / profile / "iuq"
        if candidate.is_file():
            return candidate
    return None


@pytest.fixture(scope="session")
def cli():
    """Run the `iuq` binary (IUQ_BIN, else target/release or target/debug); skipped when it is
    absent unless IUQ_REQUIRE_CLI=1 (scripts/test.sh sets it after building the binary)."""
    path = _find_cli()
    if path is None or not path.is_file():
        if os.environ.get("IUQ_REQUIRE_CLI") == "1":
            pytest.fail(f"the iuq binary is required but missing ({path})")
        pytest.skip("the iuq binary is not built (cargo build --release -p iuq)")

    def run(*args: str, cwd: Path | None = None) -> dict:
        done = subprocess.run(
            [str(path), *[str(a) for a in args], "--json"],
            capture_output=True,
            text=True,
            cwd=cwd,
            check=False,
        )
        assert done.returncode == 0, f"iuq {' '.join(map(str, args))} failed: {done.stderr}"
        return json.loads(done.stdout)

    return run


def read_csv(path: Path) -> tuple[list[str], np.ndarray]:
    """A numeric CSV with a header, parsed exactly (Python's float() round-trips)."""
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    return rows[0], np.array([[float(v) for v in r] for r in rows[1:]], dtype=np.float64)


def write_csv(path: Path, columns: list[str], rows: np.ndarray) -> None:
    """Rows written with repr() so that the CLI reads the same floats."""
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(columns)
        for r in rows:
            w.writerow([repr(float(v)) for v in r])
