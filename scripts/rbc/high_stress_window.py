#!/usr/bin/env python3
"""Follow one cell far beyond the study's measuring window and show why its elongation drifts.

Runs `iuq rbc shear` once with the window stretched from strain 7.5 to `--end-strain` (default
75) and 101 frames, writes the shapes, and prints, per stretch of 10 frames, the mean and std of
the elongation index (EL) and the cell's extents along flow (x), gradient (y) and vorticity (z)
with the inclination of its long axis in the shear plane.

    python3 scripts/rbc/high_stress_window.py --klink 38 --kbend 300 --viscosity-ratio 5 --stress 9.04

The mesh starts in HemoCell's orientation unless `--initial-orientation unrotated`.

About 4-9 minutes of one core per cell (250,000 steps); needs numpy and an `iuq` on PATH (or
IUQ=/path/to/iuq). The findings are in docs/cell-model-high-stress.md.
"""

import argparse
import glob
import json
import os
import re
import statistics
import subprocess
import sys
import tempfile

import numpy as np

START_STRAIN = 7.5
DX_UM = 0.5


def read_vtk_points(path):
    """The vertex positions of a legacy VTK polydata file written by `--shape-format vtk`."""
    lines = open(path).read().split("\n")
    start = next(k for k, line in enumerate(lines) if line.startswith("POINTS"))
    n = int(lines[start].split()[1])
    values = []
    k = start + 1
    while len(values) < 3 * n:
        values += [float(v) for v in lines[k].split()]
        k += 1
    return np.array(values).reshape(n, 3)


def shape_summary(points):
    """Extents along x, y, z in µm and the inclination (degrees) of the long axis in x-y."""
    centred = points - points.mean(axis=0)
    extents = (centred.max(axis=0) - centred.min(axis=0)) * DX_UM
    xy = centred[:, :2]
    _, vectors = np.linalg.eigh(xy.T @ xy)
    long_axis = vectors[:, 1]
    angle = np.degrees(np.arctan2(long_axis[1], long_axis[0]))
    angle = (angle + 90.0) % 180.0 - 90.0
    return extents, angle


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--klink", type=float, required=True)
    parser.add_argument("--kbend", type=float, required=True)
    parser.add_argument("--viscosity-ratio", type=float, required=True)
    parser.add_argument("--stress", type=float, default=9.04)
    parser.add_argument("--end-strain", type=float, default=75.0)
    parser.add_argument("--frames", type=int, default=101)
    parser.add_argument("--initial-orientation", choices=["unrotated", "hemocell"],
                        default="hemocell", help="the mesh's orientation in the disk plane")
    parser.add_argument("--shapes", help="keep the shapes in this folder")
    args = parser.parse_args()
    if not args.end_strain > START_STRAIN:
        sys.exit(f"--end-strain: must exceed the window's start {START_STRAIN}")
    iuq = os.environ.get("IUQ", "iuq")
    shapes = args.shapes or tempfile.mkdtemp(prefix="iuq-window-")
    os.makedirs(shapes, exist_ok=True)
    command = [
        iuq, "rbc", "shear", "--json",
        "--klink", str(args.klink), "--kbend", str(args.kbend),
        "--viscosity-ratio", str(args.viscosity_ratio), "--stress", str(args.stress),
        "--window-factor", str(args.end_strain / START_STRAIN), "--frames", str(args.frames),
        "--shape-out", shapes, "--shape-format", "vtk",
        "--initial-orientation", args.initial_orientation,
    ]
    done = subprocess.run(command, capture_output=True, text=True,
                          env={**os.environ, "RAYON_NUM_THREADS": "1"})
    if done.returncode != 0:
        sys.exit(f"{' '.join(command)} failed: {done.stderr.strip()}")
    run = json.loads(done.stdout)
    rate = run["lattice_shear_rate"]
    el = run["el_frames"]
    steps = run["frame_steps"]
    files = sorted(glob.glob(os.path.join(shapes, "*.vtk")),
                   key=lambda p: int(re.search(r"step_(\d+)", p).group(1)))
    print(f"kLink {args.klink}, kBend {args.kbend}, viscosity ratio {args.viscosity_ratio}, "
          f"{args.stress} Pa, {run['past_singularity']}, {args.initial_orientation} mesh; the study's window is strain 7.5-9.4 "
          f"(EL over all frames {run['el_mean']:.3f} ± {run['el_std']:.3f})")
    print("strain        EL mean ± std    Lx     Ly     Lz (µm)   inclination")
    stride = max(1, (len(el) - 1) // 10)
    for i in range(0, len(el) - 1, stride):
        segment = el[i:i + stride + 1]
        extents, angle = shape_summary(read_vtk_points(files[i]))
        print(f"{steps[i] * rate:5.1f}-{steps[min(i + stride, len(el) - 1)] * rate:5.1f}  "
              f"{statistics.mean(segment):.3f} ± {statistics.stdev(segment):.3f}   "
              f"{extents[0]:5.1f}  {extents[1]:5.1f}  {extents[2]:5.1f}      {angle:5.1f}°")


if __name__ == "__main__":
    main()
