#!/usr/bin/env python3
"""Write membrane shapes into HemoCell's HDF5 output layout, for testing decode-el.py without
HemoCell.

    write_hemocell_hdf5.py OUT_DIR --frame ITERATION SHAPE.vtk [--frame ITERATION SHAPE.vtk ...]
                           [--ranks 3] [--unit m|lattice] [--cell-type RBC_HO] [--with-ids]
                           [--fluid y|z] [--layout y-walls|z-walls] [--drop-vertices ITERATION:N]
                           [--wrap-x NODES]

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

--fluid y|z also writes HemoCell's fluid output, `Fluid.<iteration>.p.0.h5` with a `Velocity`
dataset (nz+2, ny+2, nx+2, 3) in m/s (ParaView order, one envelope node around the block, as
HemoCell v2.1 writes it): a Couette flow u_x = gamma (c - c_mid) along y (HemoCell <= 2.1's
oneCellShear, walls on the y planes) or z (HemoCell >= 2.2, walls on the z planes).
--layout z-walls writes the shapes as HemoCell >= 2.2 holds them (walls on the z planes): the
shear frame of the shapes (x flow, y gradient, z vorticity) turned into HemoCell's axes (x flow,
z gradient, -y vorticity) and moved to the middle of the 20-node gap; y-walls (the default)
writes them as they are (HemoCell <= 2.1).
--wrap-x NODES moves the cell along x by NODES and wraps each vertex into the periodic box
(0 <= x < 40): a cell split by the periodic boundary, as HemoCell would hold one that crossed it.
--drop-vertices ITERATION:N leaves the last N vertices out of that iteration's frame (a cell
HemoCell lost part of).
"""

import argparse
import os
import sys

import h5py
import numpy as np

DX = 0.5e-6
DT = 0.5e-7
DOMAIN_X = 40
DOMAIN = (40, 40, 20)  # x, y, z nodes
SHEAR_RATE = 5000.0  # 1/s, for the fluid output


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
    parser.add_argument("--fluid", choices=["y", "z"], default=None)
    parser.add_argument("--layout", choices=["y-walls", "z-walls"], default="y-walls")
    parser.add_argument("--wrap-x", type=float, default=None)
    parser.add_argument("--drop-vertices", default=None, metavar="ITERATION:N")
    args = parser.parse_args()
    drop = {}
    if args.drop_vertices:
        iteration_text, count = args.drop_vertices.split(":")
        drop[int(iteration_text)] = int(count)
    edges = np.linspace(0.0, DOMAIN_X, args.ranks + 1)
    for iteration_text, shape in args.frame:
        iteration = int(iteration_text)
        points, triangles = read_vtk(shape)
        if args.layout == "z-walls":
            points = to_z_walls(points)
        if args.wrap_x is not None:
            points = points.copy()
            points[:, 0] = np.mod(points[:, 0] + args.wrap_x, DOMAIN[0])
        if drop.get(iteration):
            points = points[: len(points) - drop[iteration]]
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
        if args.fluid:
            write_fluid(os.path.join(folder, f"Fluid.{iteration:012d}.p.0.h5"), iteration, args.fluid)
    return 0


def to_z_walls(points):
    """Shear-frame lattice coordinates (x flow, y gradient about node 19.5 of 40, z vorticity
    about 9.5 of 20) as HemoCell >= 2.2 holds them: x flow, z gradient about node 9.5 of 20,
    y = -vorticity about 19.5 of 40."""
    nx, ny, nz = DOMAIN
    x, y, z = points[:, 0], points[:, 1], points[:, 2]
    gradient = y - (ny - 1) / 2.0
    vorticity = z - (nz - 1) / 2.0
    return np.stack([x, (ny - 1) / 2.0 - vorticity, (nz - 1) / 2.0 + gradient], axis=1)


def write_fluid(path, iteration, axis):
    nx, ny, nz = DOMAIN
    # Node coordinates with the one-node envelope, in ParaView's (z, y, x) order.
    z, y, x = np.meshgrid(np.arange(-1, nz + 1), np.arange(-1, ny + 1), np.arange(-1, nx + 1), indexing="ij")
    coordinate, n = (y, ny) if axis == "y" else (z, nz)
    velocity = np.zeros(x.shape + (3,), dtype=np.float32)
    velocity[..., 0] = SHEAR_RATE * DX * (coordinate - (n - 1) / 2.0)
    with h5py.File(path, "w") as f:
        f.attrs["dx"] = DX
        f.attrs["dt"] = DT
        f.attrs["iteration"] = np.int64(iteration)
        f.attrs["processorId"] = np.int32(0)
        f.attrs["subdomainSize"] = np.array([nz + 2, ny + 2, nx + 2], dtype=np.int32)
        f.create_dataset("Velocity", data=velocity, chunks=True, compression="gzip")


if __name__ == "__main__":
    sys.exit(main())
