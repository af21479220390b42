#!/usr/bin/env python3
"""Is the cell model's elongation chaotic in its parameters? Runs nudged by a billionth.

Runs `iuq rbc shear` at one cell (kLink, kBend, Λ) and stress, and again with kLink moved by
k·1e-9 of itself (k = 1 … --copies), and prints the window's EL of each (its mean and frame std)
and their spread. A smooth model moves by about 1e-9 of its value; a chaotic one by its whole
run-to-run spread. With `--trace` the cell is followed from strain 1.5 to 30 (frames every 0.25
strain) for the first two runs, and the strain at which their EL parts is printed
(docs/cell-model-high-stress.md, "The elongation at 9.04 Pa is chaotic").

    python3 scripts/rbc/nudge_divergence.py --klink 40.8488 --kbend 120.265 --viscosity-ratio 4.6807 --stress 9.04
    python3 scripts/rbc/nudge_divergence.py … --stress 9.04 --trace

Every run uses the shipped studies' settings (scaled protocol, HemoCell's orientation of the
mesh, carry-on past the singularities), one core each (`RAYON_NUM_THREADS=1`), `--parallel`
at a time. `--iuq` names the binary (default `target/release/iuq`). Needs numpy.
"""

import argparse
import json
import os
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor

import numpy as np


def shear(iuq, klink, args, extra=()):
    """One run's JSON result."""
    command = [
        iuq, "rbc", "shear", "--json",
        "--klink", repr(klink), "--kbend", repr(args.kbend),
        "--viscosity-ratio", repr(args.viscosity_ratio), "--stress", repr(args.stress),
        "--initial-orientation", "hemocell", *extra,
    ]
    env = dict(os.environ, RAYON_NUM_THREADS="1")
    done = subprocess.run(command, capture_output=True, text=True, env=env)
    if done.returncode != 0:
        sys.exit(f"{' '.join(command)} failed ({done.returncode}): {done.stderr.strip()}")
    return json.loads(done.stdout)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--klink", type=float, required=True)
    parser.add_argument("--kbend", type=float, required=True)
    parser.add_argument("--viscosity-ratio", type=float, required=True)
    parser.add_argument("--stress", type=float, required=True, help="shear stress, Pa")
    parser.add_argument("--copies", type=int, default=7, help="nudged runs (default 7)")
    parser.add_argument("--parallel", type=int, default=2, help="runs at a time (default 2)")
    parser.add_argument("--trace", action="store_true", help="follow two runs to strain 30")
    parser.add_argument("--iuq", default="target/release/iuq")
    args = parser.parse_args()
    if args.copies < 1 or args.parallel < 1:
        sys.exit("--copies and --parallel must be at least 1")
    if not os.access(args.iuq, os.X_OK):
        sys.exit(f"{args.iuq}: not an executable (build with `cargo build --release -p iuq`)")
    klinks = [args.klink * (1 + k * 1e-9) for k in range(args.copies + 1)]
    with ThreadPoolExecutor(args.parallel) as pool:
        runs = list(pool.map(lambda k: shear(args.iuq, k, args), klinks))
    print(f"{args.stress} Pa, kBend {args.kbend}, Λ {args.viscosity_ratio}: window EL (frame std)")
    for k, (klink, run) in enumerate(zip(klinks, runs)):
        print(f"  kLink {klink!r} (+{k}e-9 of itself): {run['el_mean']:.5f} ({run['el_std']:.5f})")
    el = np.array([r["el_mean"] for r in runs])
    own = np.array([r["el_std"] for r in runs])
    print(f"spread of the window means: std {el.std(ddof=1):.5f}, range {el.max() - el.min():.5f}; "
          f"the runs' own frame std: median {np.median(own):.5f}")
    if args.trace:
        extra = ["--start-strain", "1.5", "--window-factor", "20", "--frames", "115"]
        with ThreadPoolExecutor(min(2, args.parallel)) as pool:
            a, b = pool.map(lambda k: shear(args.iuq, k, args, extra), klinks[:2])
        strain = np.array(a["frame_steps"]) * a["lattice_shear_rate"]
        gap = np.abs(np.array(a["el_frames"]) - np.array(b["el_frames"]))
        parted = np.flatnonzero(gap > 1e-3)
        print("strain  EL  EL(nudged)  |difference|")
        for i in range(0, len(strain), 3):
            print(f"{strain[i]:6.2f}  {a['el_frames'][i]:.4f}  {b['el_frames'][i]:.4f}  {gap[i]:.4f}")
        if parted.size:
            print(f"the two runs part (|ΔEL| > 0.001) from strain {strain[parted[0]]:.2f}")
        else:
            print("the two runs never part by more than 0.001")


if __name__ == "__main__":
    main()
