#!/usr/bin/env python3
"""A calibration study driven from Python: the cooling example's study file (a command model,
one run per parameter vector returning the whole curve, with the adaptive engine), its
campaign's status, and every run as rows.

    pip install ./python
    python examples/python/study.py [OUT_DIR]

Equivalent to `iuq pipeline examples/cooling/cooling-curve.toml --out OUT_DIR`, then
`iuq status` and `iuq export` of the same study (about 10 s; the model needs python3). The
campaign's runs are kept in examples/cooling/cooling-curve.campaign/ and reused by a second run.
"""

import sys
from pathlib import Path

import iuq

HERE = Path(__file__).resolve().parent
out = Path(sys.argv[1]) if len(sys.argv) > 1 else Path("cooling-curve-report")

study = iuq.Study.load(HERE.parent / "cooling" / "cooling-curve.toml")
print(f"{study.name}: parameters {study.parameters}, ranges {study.ranges}")
result = study.run(out, progress=True)
print(f"report: {result.report} ({result.seconds:.1f} s)")
print(f"{result.runs} model runs ({result.failed} failed) in {result.rounds} adaptive rounds, "
      f"{'converged' if result.converged else 'not converged'}")
print(f"test-set Q2 of the surrogates: {result.q2.round(4)}")

status = study.status()
print(f"campaign: {status.total} runs, {status.counts}")
for failure in status.failures[:3]:
    print(f"  failed run {failure['run_id']} at {failure['parameters']}: {failure['reason']}")
rows = study.export()
print(f"exported {len(rows)} rows; the first: {rows[0]}")
