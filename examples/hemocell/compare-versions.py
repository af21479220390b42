#!/usr/bin/env python3
"""Tabulate a campaign of a later HemoCell (this folder's adapter) against HemoCell 2.1 and the
native model at the same points.

    compare-versions.py STUDY.toml --reference data/hemocell_vs_native.csv --out TABLE.csv
                        [--label 2.7]

STUDY.toml is the study of the campaign (a copy of hemocell-shear.toml with a file design);
`$IUQ export STUDY.toml --json` gives every run's status and failure reason, and the successful
runs' `el.json` (EL of each frame), `hemocell-frames.json` (iterations, centroids, layout) and
their wall time (from run-hemocell.sh's first file, RBC_HO.pos, to el.json) are read from the
store's run folders, as compare-native.py reads them. --reference is the table of
compare-native.py: its HemoCell 2.1 columns and the native model with HemoCell's orientation of the
mesh (`native_hemocell_orientation_*`, scaled protocol) are set beside the new version's.

Columns, one row per point of the campaign (sorted by parameters, then stress):
  kLink, kBend, viscosityRatio, stress
  v<label>_status, v<label>_reason               the run's status; the failure reason
  v<label>_el_mean, _el_std, _el_trend           the 10 frames' mean, sample std, and change of EL
                                                 over the window (as compare-native.py)
  v<label>_centre_drift_um                       the cell centre's displacement over the window
                                                 (x, gradient), from the frames' centroids
  v<label>_wall_s                                wall seconds of the run
  v2.1_el_mean, _el_std, v2.1_wall_s             HemoCell 2.1 (the reference table)
  native_el_mean, native_el_std, native_s        the native model, HemoCell's orientation
  diff_v<label>_v2.1, z_v<label>_v2.1            new - 2.1, and over sqrt(s^2 + s^2)
  diff_v<label>_native, z_v<label>_native        new - native, and over sqrt(s^2 + s^2)
  v<label>_el_frames                             the new version's frame ELs, ';'-separated
"""

import argparse
import csv
import importlib.util
import json
import math
import os
import subprocess
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
_spec = importlib.util.spec_from_file_location("compare_native", os.path.join(HERE, "compare-native.py"))
compare_native = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(compare_native)


def export(iuq, study):
    result = subprocess.run([iuq, "export", study, "--json"], capture_output=True, text=True)
    if result.returncode != 0:
        sys.exit(f"compare-versions.py: {iuq} export {study} failed: {result.stderr.strip()}")
    return json.loads(result.stdout)


def centre_drift(folder, layout_gradient_axis):
    frames = json.load(open(os.path.join(folder, "hemocell-frames.json")))["frames"]
    first, last = frames[0]["centroid_um"], frames[-1]["centroid_um"]
    return (last[0] - first[0], last[layout_gradient_axis] - first[layout_gradient_axis])


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("study", help="the campaign's study file")
    parser.add_argument("--reference", required=True, help="compare-native.py's table (HemoCell 2.1, native)")
    parser.add_argument("--out", required=True)
    parser.add_argument("--label", default="2.7", help="the new version's label in the column names")
    args = parser.parse_args()
    iuq = os.environ.get("IUQ", "iuq")
    store = os.path.splitext(args.study)[0] + ".campaign"
    runs = compare_native.hemocell_runs(store)
    by_id = {r["run_id"]: (key, r) for key, r in runs.items()}
    reference = {}
    with open(args.reference) as f:
        for row in csv.DictReader(f):
            reference[compare_native.key_of(row)] = row
    v = f"v{args.label}"
    rows = []
    for record in export(iuq, args.study):
        key = compare_native.key_of(record)
        row = dict(zip(["kLink", "kBend", "viscosityRatio", "stress"], key))
        row[f"{v}_status"] = record["status"]
        row[f"{v}_reason"] = record.get("reason") or ""
        found = by_id.get(int(record["run_id"]))
        mean = std = None
        if record["status"] == "succeeded" and found:
            run = found[1]
            mean, std = compare_native.mean_std(run["el"])
            folder = os.path.join(store, "runs", f"{int(record['run_id']):06d}")
            layout = json.load(open(os.path.join(folder, "hemocell-frames.json"))).get("layout", "y-walls")
            dx, dg = centre_drift(folder, 2 if layout == "z-walls" else 1)
            row.update({
                f"{v}_el_mean": mean, f"{v}_el_std": std,
                f"{v}_el_trend": compare_native.trend(run["el"], run["strain"]),
                f"{v}_centre_drift_um": f"{dx:.2f};{dg:.2f}",
                f"{v}_wall_s": run["seconds"],
                f"{v}_el_frames": ";".join(f"{e:.6f}" for e in run["el"]),
            })
        ref = reference.get(key)
        if ref:
            row["v2.1_el_mean"] = float(ref["hemocell_el_mean"])
            row["v2.1_el_std"] = float(ref["hemocell_el_std"])
            row["v2.1_wall_s"] = float(ref["hemocell_wall_s"])
            row["native_el_mean"] = float(ref["native_hemocell_orientation_mean"])
            row["native_el_std"] = float(ref["native_hemocell_orientation_std"])
            row["native_s"] = float(ref["native_hemocell_orientation_s"])
            if mean is not None:
                for name, m, s in (("v2.1", row["v2.1_el_mean"], row["v2.1_el_std"]),
                                   ("native", row["native_el_mean"], row["native_el_std"])):
                    row[f"diff_{v}_{name}"] = mean - m
                    row[f"z_{v}_{name}"] = (mean - m) / math.sqrt(std ** 2 + s ** 2)
        rows.append(row)
    rows.sort(key=lambda r: (r["kLink"], r["kBend"], r["viscosityRatio"], r["stress"]))
    columns = ["kLink", "kBend", "viscosityRatio", "stress", f"{v}_status",
               f"{v}_el_mean", f"{v}_el_std", f"{v}_el_trend", f"{v}_centre_drift_um", f"{v}_wall_s",
               "v2.1_el_mean", "v2.1_el_std", "v2.1_wall_s", "native_el_mean", "native_el_std", "native_s",
               f"diff_{v}_v2.1", f"z_{v}_v2.1", f"diff_{v}_native", f"z_{v}_native",
               f"{v}_el_frames", f"{v}_reason"]
    with open(args.out, "w", newline="") as f:
        w = csv.writer(f, lineterminator="\n")
        w.writerow(columns)
        for row in rows:
            w.writerow([compare_native.fmt(row.get(c, "")) for c in columns])
    print(f"compare-versions.py: {len(rows)} points -> {args.out}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
