#!/usr/bin/env python3
"""Write membrane shapes into HemoCell's HDF5 output layout, for testing decode-el.py without
HemoCell.

    write_hemocell_hdf5.py OUT_DIR --frame ITERATION SHAPE.vtk [--frame ITERATION SHAPE.vtk ...]
                           [--ranks 3] [--unit m|lattice] [--cell-type RBC_HO] [--with-ids]

Each SHAPE is a legacy ASCII VTK file of `iuq rbc shear --shape-out` (lattice units, HemoCell's
frame). For every frame this writes OUT_DIR/<iteration, 12 digits>/<type>.<iteration>.p.<rank>.h5
as HemoCell does: root attributes dx, dt, iteration, processorId, numberOfProcessors,
numberOfParticles; datasets Position (n x 3, float64; metres as with outputInSiUnits, or lattice
units) and Triangles. The domain (40 x 40 x 20 nodes) is split into --ranks slabs along x. Like
HemoCell, a rank writes the whole cell when at least one vertex lies in its slab (its envelope
holds the rest), so a cell across a slab boundary is written by several ranks; ranks without a
vertex write files without datasets. With --split the ranks instead write only their own
vertices (each vertex exactly once), the other layout a reader must handle. --with-ids adds the
`Cell Id` and `Vertex Id` datasets (HemoCell's OUTPUT_CELL_ID / OUTPUT_VERTEX_ID).
"""

import argparse
import os
import sys

import h5py
import numpy as np

DX = 0.5e-6
DT = 0.5e-7
DOMAIN_X = 40


def read_vtk(path):
    with open(path) as f:
        lines = f.read().split("\n")
    points, triangles = None, []
    i = 0
    while i < len(lines):
        words = lines[i].split()
        if words and words[0] == "POINTS":
            n = int(words[1])
            numbers = []
            i += 1
            while len(numbers) < 3 * n:
                numbers.extend(float(w) for w in lines[i].split())
                i += 1
            points = np.array(numbers[: 3 * n]).reshape(n, 3)
            continue
        if words and words[0] == "POLYGONS":
            for k in range(int(words[1])):
                triangles.append([int(w) for w in lines[i + 1 + k].split()[1:4]])
            i += int(words[1]) + 1
            continue
        i += 1
    if points is None:
        sys.exit(f"{path}: no POINTS")
    return points, np.array(triangles, dtype=np.int32).reshape(-1, 3)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("out_dir")
    parser.add_argument("--frame", nargs=2, action="append", metavar=("ITERATION", "SHAPE"), required=True)
    parser.add_argument("--ranks", type=int, default=3)
    parser.add_argument("--unit", choices=["m", "lattice"], default="m")
    parser.add_argument("--cell-type", default="RBC_HO")
    parser.add_argument("--split", action="store_true")
    parser.add_argument("--with-ids", action="store_true")
    args = parser.parse_args()
    edges = np.linspace(0.0, DOMAIN_X, args.ranks + 1)
    for iteration_text, shape in args.frame:
        iteration = int(iteration_text)
        points, triangles = read_vtk(shape)
        folder = os.path.join(args.out_dir, f"{iteration:012d}")
        os.makedirs(folder, exist_ok=True)
        # The slab of each vertex; the last slab is closed on the right.
        slab = np.clip(np.searchsorted(edges, points[:, 0], side="right") - 1, 0, args.ranks - 1)
        for rank in range(args.ranks):
            mine = slab == rank
            if args.split:
                index = np.flatnonzero(mine)
            else:
                index = np.arange(len(points)) if mine.any() else np.arange(0)
            path = os.path.join(folder, f"{args.cell_type}.{iteration:012d}.p.{rank}.h5")
            with h5py.File(path, "w") as f:
                f.attrs["dx"] = DX
                f.attrs["dt"] = DT
                f.attrs["iteration"] = np.int64(iteration)
                f.attrs["processorId"] = np.int32(rank)
                f.attrs["numberOfProcessors"] = np.int64(args.ranks)
                f.attrs["numberOfParticles"] = np.int64(len(index))
                if len(index) == 0:
                    continue
                position = points[index] * (DX if args.unit == "m" else 1.0)
                f.create_dataset("Position", data=position, dtype="f8", chunks=True, compression="gzip")
                if not args.split:
                    f.create_dataset("Triangles", data=triangles, dtype="i4")
                if args.with_ids:
                    f.create_dataset("Cell Id", data=np.zeros((len(index), 1)))
                    f.create_dataset("Vertex Id", data=index.reshape(-1, 1).astype(float))
    return 0


if __name__ == "__main__":
    sys.exit(main())
