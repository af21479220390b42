#!/usr/bin/env python3
"""Tabulate a campaign of real HemoCell runs (this folder's adapter) against iuq's native model.

    compare-native.py CAMPAIGN_DIR --out data/hemocell_vs_native.csv [--cache native.json]

CAMPAIGN_DIR is the store folder of an `iuq run` of hemocell-shear.toml (or a copy of it with a
file design), `<study>.campaign`: every successful run's `params.json`, `el.json` (EL of each
frame) and `hemocell-frames.json` (the frames' iterations) are read. For each point the native
model runs twice, one run at a time (`$IUQ rbc shear --json --protocol scaled|reference
--past-singularity carry-on`, as HemoCell carries on past the force singularities); results are
cached in --cache so a second call only adds new points.

Columns of the table, one row per point (sorted by parameters, then stress):
  kLink, kBend, viscosityRatio, stress            the point
  hemocell_el_mean, hemocell_el_std              mean and sample std of HemoCell's 10 frames
  hemocell_el_trend                              least-squares change of EL over the window
                                                 (slope in strain x window length in strain)
  native_scaled_mean/std/trend                   the same for `--protocol scaled`
  native_reference_mean/std/trend                the same for `--protocol reference`
  diff_scaled, diff_reference                    native mean - HemoCell mean
  z_scaled, z_reference                          diff / sqrt(s_h^2 + s_n^2)
  hemocell_wall_s, native_scaled_s, native_reference_s   wall-clock seconds per run
  hemocell_el_frames, native_scaled_el_frames, native_reference_el_frames   the frames' EL, ';'
"""

import argparse
import csv
import glob
import json
import math
import os
import subprocess
import sys

DT = 0.5e-7
RHO_NU = 1025 * 1.1e-6


def trend(el, strain):
    """Least-squares slope of EL against strain, times the window's length in strain."""
    n = len(el)
    ms, me = sum(strain) / n, sum(el) / n
    sxx = sum((s - ms) ** 2 for s in strain)
    sxy = sum((s - ms) * (e - me) for s, e in zip(strain, el))
    return sxy / sxx * (strain[-1] - strain[0])


def mean_std(el):
    n = len(el)
    m = sum(el) / n
    return m, math.sqrt(sum((e - m) ** 2 for e in el) / (n - 1))


def key_of(p):
    return (float(p["kLink"]), float(p["kBend"]), float(p["viscosityRatio"]), float(p["stress"]))


def hemocell_runs(campaign):
    """Per point: EL frames, strains and wall time of the successful HemoCell runs (wall time:
    from run-hemocell.sh's first file, RBC_HO.pos, to el.json)."""
    runs = {}
    for params_path in sorted(glob.glob(os.path.join(campaign, "runs", "*", "params.json"))):
        folder = os.path.dirname(params_path)
        el_path = os.path.join(folder, "el.json")
        frames_path = os.path.join(folder, "hemocell-frames.json")
        if not (os.path.exists(el_path) and os.path.exists(frames_path)):
            continue
        params = json.load(open(params_path))
        el = json.load(open(el_path))["el_frames"]
        iterations = [f["iteration"] for f in json.load(open(frames_path))["frames"]]
        rate_dt = params["stress"] / RHO_NU * DT
        runs[key_of(params)] = {
            "el": el,
            "strain": [i * rate_dt for i in iterations],
            "seconds": os.path.getmtime(el_path) - os.path.getmtime(os.path.join(folder, "RBC_HO.pos")),
            "run_id": int(params["run_id"]),
        }
    return runs


def native(iuq, key, protocol):
    k_link, k_bend, ratio, stress = key
    command = [iuq, "rbc", "shear", "--json", "--klink", repr(k_link), "--kbend", repr(k_bend),
               "--viscosity-ratio", repr(ratio), "--stress", repr(stress), "--protocol", protocol,
               "--past-singularity", "carry-on"]
    print("compare-native.py: " + " ".join(command[1:]), file=sys.stderr)
    result = subprocess.run(command, capture_output=True, text=True)
    if result.returncode != 0:
        return {"error": (result.stderr.strip().splitlines() or ["failed"])[-1]}
    v = json.loads(result.stdout)
    if protocol == "scaled":
        rate_dt = v["lattice_shear_rate"]
    else:
        rate_dt = stress / RHO_NU * DT
    return {"el": v["el_frames"], "strain": [s * rate_dt for s in v["frame_steps"]],
            "seconds": v["seconds"]}


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("campaign", help="the campaign's store folder (<study>.campaign)")
    parser.add_argument("--out", required=True)
    parser.add_argument("--cache", default="native-runs.json")
    args = parser.parse_args()
    iuq = os.environ.get("IUQ", "iuq")
    runs = hemocell_runs(args.campaign)
    cache = json.load(open(args.cache)) if os.path.exists(args.cache) else {}
    rows = []
    for key in sorted(runs):
        h = runs[key]
        row = dict(zip(["kLink", "kBend", "viscosityRatio", "stress"], key))
        hm, hs = mean_std(h["el"])
        row.update(hemocell_el_mean=hm, hemocell_el_std=hs, hemocell_el_trend=trend(h["el"], h["strain"]))
        for protocol in ("scaled", "reference"):
            name = f"{protocol} {' '.join(map(repr, key))}"
            if name not in cache:
                cache[name] = native(iuq, key, protocol)
                with open(args.cache, "w") as f:
                    json.dump(cache, f, indent=1)
            n = cache[name]
            if "error" in n:
                print(f"compare-native.py: {name}: {n['error']}", file=sys.stderr)
                for c in ("mean", "std", "trend"):
                    row[f"native_{protocol}_{c}"] = ""
                row[f"diff_{protocol}"] = row[f"z_{protocol}"] = ""
                row[f"native_{protocol}_s"] = ""
                row[f"native_{protocol}_el_frames"] = ""
                continue
            nm, ns = mean_std(n["el"])
            row[f"native_{protocol}_mean"] = nm
            row[f"native_{protocol}_std"] = ns
            row[f"native_{protocol}_trend"] = trend(n["el"], n["strain"])
            row[f"diff_{protocol}"] = nm - hm
            row[f"z_{protocol}"] = (nm - hm) / math.sqrt(hs ** 2 + ns ** 2)
            row[f"native_{protocol}_s"] = n["seconds"]
            row[f"native_{protocol}_el_frames"] = ";".join(f"{e:.6f}" for e in n["el"])
        row["hemocell_wall_s"] = h["seconds"] if h["seconds"] is not None else ""
        row["hemocell_el_frames"] = ";".join(f"{e:.6f}" for e in h["el"])
        rows.append(row)
    columns = ["kLink", "kBend", "viscosityRatio", "stress",
               "hemocell_el_mean", "hemocell_el_std", "hemocell_el_trend",
               "native_scaled_mean", "native_scaled_std", "native_scaled_trend",
               "native_reference_mean", "native_reference_std", "native_reference_trend",
               "diff_scaled", "diff_reference", "z_scaled", "z_reference",
               "hemocell_wall_s", "native_scaled_s", "native_reference_s",
               "hemocell_el_frames", "native_scaled_el_frames", "native_reference_el_frames"]
    with open(args.out, "w", newline="") as f:
        w = csv.writer(f, lineterminator="\n")
        w.writerow(columns)
        for row in rows:
            w.writerow([fmt(row.get(c, "")) for c in columns])
    print(f"compare-native.py: {len(rows)} points -> {args.out}", file=sys.stderr)
    return 0


def fmt(v):
    if isinstance(v, float):
        return f"{v:.6g}" if abs(v) >= 1 or v == 0 else f"{v:.6f}"
    return str(v)


if __name__ == "__main__":
    sys.exit(main())
