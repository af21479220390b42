#!/usr/bin/env python3
"""The HemoCell 2.7 calibration three ways, side by side: HemoCell alone (the reference), HemoCell
with the native cell model as a cheap second fidelity, and the native cell model alone (its bias).

    export PATH=/path/to/iuq/dir:$PATH       # or IUQ=/path/to/iuq
    python3 examples/hemocell/compare-fidelities.py [--out data/hemocell27_fidelities.csv]

Each study is replayed from its shipped store with `iuq pipeline --json` (no model run where the
store is complete; a study whose campaign is still under way runs on from where it stopped, so
run this only where HemoCell is installed or the stores are complete). Printed per study: runs of
each fidelity (succeeded/failed; of the expensive model, the runs the study used, which its
report lists — the two-fidelity store began as a copy of the HemoCell-only one), the model time
they cost (the sum of the runs' wall times on one core each, of each run's last attempt), the
rounds, whether the engine converged, and every parameter's posterior mean ± std with its 90 %
interval. The table is also written as CSV.
"""

import argparse
import csv
import json
import os
import sqlite3
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
STUDIES = [
    ("HemoCell alone", "hemocell27-healthy"),
    ("HemoCell + native (two fidelities)", "hemocell27-healthy-two-fidelity"),
    ("native alone", "native-healthy"),
]


def store_runs(store: Path, used=None):
    """(succeeded, failed, model hours) of a campaign store's runs, or None where there is none;
    with `used` (parameter vectors), of the succeeded runs at those parameters alone (a store
    may hold runs another campaign made that this study did not ask for)."""
    if not store.is_file():
        return None
    with sqlite3.connect(f"file:{store}?mode=ro", uri=True) as db:
        runs = db.execute("SELECT id, parameters, status FROM runs").fetchall()
        # Each run's last attempt, the one whose answer it holds (an attempt interrupted when its
        # machine went away counts until the campaign noticed, hours that were no model time).
        seconds = dict(db.execute(
            "SELECT a.run_id, a.finished_at - a.started_at FROM attempts a "
            "WHERE a.started_at IS NOT NULL AND a.finished_at IS NOT NULL AND a.number = "
            "(SELECT MAX(b.number) FROM attempts b WHERE b.run_id = a.run_id)"
        ).fetchall())
    if used is not None:
        runs = [r for r in runs if r[2] == "succeeded" and tuple(json.loads(r[1])) in used]
    succeeded = sum(1 for r in runs if r[2] == "succeeded")
    failed = sum(1 for r in runs if r[2] == "failed")
    return succeeded, failed, sum(seconds.get(r[0], 0.0) for r in runs) / 3600.0


def used_points(report: Path, names):
    """The parameter vectors of the model runs a replayed study's report lists."""
    with open(report / "model-runs.csv", newline="") as f:
        return {tuple(float(row[n]) for n in names) for row in csv.DictReader(f)}


def replay(stem: str, out: Path) -> dict:
    iuq = os.environ.get("IUQ", "iuq")
    result = subprocess.run(
        [iuq, "pipeline", f"{stem}.toml", "--json", "--out", str(out / f"{stem}-report")],
        cwd=HERE, capture_output=True, text=True,
    )
    if result.returncode != 0:
        sys.exit(f"iuq pipeline {stem}.toml exited {result.returncode}: {result.stderr[-2000:]}")
    return json.loads(result.stdout)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=None, help="write the table as CSV here")
    parser.add_argument("--reports", type=Path, default=Path("hemocell-fidelities-reports"),
                        help="folder of the replays' reports (default ./hemocell-fidelities-reports)")
    args = parser.parse_args()
    rows = []
    for label, stem in STUDIES:
        summary = replay(stem, args.reports.resolve())
        campaign = HERE / f"{stem}.campaign"
        names = [p["parameter"] for p in summary["posterior"][0]["parameters"] if p["parameter"] != "sigma_m"]
        # The study's own runs: its succeeded model runs (as its report lists them) and, from the
        # summary, the failed ones it met.
        if stem.startswith("native"):
            expensive, cheap = None, store_runs(campaign / "campaign.sqlite")
        else:
            used = used_points(args.reports.resolve() / f"{stem}-report", names)
            expensive = store_runs(campaign / "campaign.sqlite", used)
            expensive = (expensive[0], summary.get("failed", 0), expensive[2])
            cheap = store_runs(campaign / "low-fidelity" / "campaign.sqlite")
        row = {
            "study": label,
            "hemocell_runs": f"{expensive[0]} + {expensive[1]} failed" if expensive else "0",
            "hemocell_hours": round(expensive[2], 1) if expensive else 0.0,
            "native_runs": f"{cheap[0]} + {cheap[1]} failed" if cheap else "0",
            "native_hours": round(cheap[2], 2) if cheap else 0.0,
            "rounds": summary["rounds"],
            "converged": summary["converged"],
        }
        for p in summary["posterior"][0]["parameters"]:
            row[p["parameter"]] = f"{p['mean']:.4g} ± {p['std']:.3g} ({p['q05']:.4g}–{p['q95']:.4g})"
        rows.append(row)
    keys = list(dict.fromkeys(k for row in rows for k in row))
    print("| " + " | ".join(keys) + " |")
    print("|" + "---|" * len(keys))
    for row in rows:
        print("| " + " | ".join(str(row.get(k, "")) for k in keys) + " |")
    if args.out:
        with open(args.out, "w", newline="") as f:
            writer = csv.DictWriter(f, fieldnames=keys)
            writer.writeheader()
            writer.writerows(rows)


if __name__ == "__main__":
    main()
