#!/usr/bin/env python3
"""Decode the elongation index of a HemoCell oneCellShear run for iuq.

Reads the membrane vertex positions HemoCell wrote as HDF5 at the measuring iterations in
[--from, --to], one frame per iteration, merged over all MPI ranks; writes each frame as a vertex
CSV in micrometres (header x,y,z); and measures the frames with `iuq rbc elongation --unit um`,
which writes {"el": {"value": mean, "std": sample std}, "el_frames": [...], "frames": n} to
--out (the file the campaign's JSON decoder reads).

HemoCell's layout (HemoCell >= 2, and the IUQ study's version):
    <hdf5 dir>/<iteration, 12 digits>/<cell type>.<iteration, 12 digits>.p.<rank>.h5
with a dataset `Position` (n x 3); HemoCell 1 wrote <hdf5 dir>/<type>.<iteration>.p.<rank>.h5
without the per-iteration folder. Both are read, whatever the zero padding. Positions are in
lattice units, or in metres when the case sets `outputInSiUnits` (oneCellShear does, and some
HemoCell versions still write lattice units then): `--unit auto` tells them apart by magnitude
(a cell a few micrometres across has every coordinate below 1e-3 in metres, and lattice
coordinates of several units in a 40 x 40 x 20 box).

A rank writes every cell that has a vertex in its part of the domain, complete (its envelope
holds the rest), so a cell on a rank boundary appears in several files: vertices are merged by
(`Cell Id`, `Vertex Id`) when HemoCell wrote those datasets, else exact duplicate rows are
dropped (the copies are synchronised, hence bit-identical).

The wall layout (--layout): oneCellShear up to HemoCell 2.1 shears between walls on the y planes
(19.5 um apart; the IUQ study's experiment, flow x, gradient y, vorticity z); from 2.2 on
(Lees-Edwards commit 267a21d) its walls lie on the z planes, 9.5 um apart (flow x, gradient z,
vorticity -y). Either way the frames are written in the shear frame of the study, x = flow,
y = velocity gradient, z = vorticity, so that `iuq rbc elongation` measures the projection on the
shear plane in both: HemoCell's (x, y, z) for the y-wall layout, (x, z, -y) for the z-wall one.
`--layout auto` (the default) reads the direction of the velocity gradient from HemoCell's fluid
output (`Fluid.<iteration>.p.<rank>.h5`, dataset `Velocity`) at the last frame, and takes the
y-wall layout with a note when there is none; a named layout is checked against the fluid output
when there is one, and a mismatch fails the run.

Checks made against the real HemoCell (v2.1, the IUQ study's, and v2.7):
* a cell HemoCell deleted: with --log (HemoCell's stdout, as run-hemocell.sh keeps it), any
  "(Delete Cells) WARNING! Particle deleted" line fails the run with that line as the reason,
  even when frames were written; a frame with fewer vertices than the cell's first output also
  fails;
* a cell that left the box: a vertex beyond a wall (--box gives the domain, oneCellShear's
  40 x 40 x 20 nodes), or a cell split by a periodic boundary (written partly at each end of
  the box) fails the run with the frame and the coordinates. (HemoCell on one process deletes a
  cell that reaches a periodic boundary: the case above.)
A summary of the frames (iteration, vertices, centroid and extent in um in HemoCell's axes, the
layout, and the fluid's shear rate when available) is written to --summary (default
hemocell-frames.json).

Exit status: 0 with --out written; 1 when the run produced no usable frames (no output in the
window, a deleted cell, non-finite positions: the membrane broke) or `iuq` reported a failure;
2 for bad arguments. Needs Python 3, numpy and h5py; the `iuq` binary is $IUQ or `iuq` on PATH.
"""

import argparse
import json
import os
import re
import shutil
import subprocess
import sys

try:
    import h5py
    import numpy as np
except ImportError as _missing:  # reported by main() with a hint
    h5py = np = None
    IMPORT_ERROR = _missing
else:
    IMPORT_ERROR = None

FILE_PATTERN = re.compile(r"^(?P<type>.+)\.(?P<iteration>\d+)\.p\.(?P<rank>\d+)\.h5$")


class DecodeError(Exception):
    """A run whose output cannot give an elongation index (exit status 1)."""


def fail(message, status=1):
    print(f"decode-el.py: {message}", file=sys.stderr)
    sys.exit(status)


def scan(hdf5_dir):
    """Map (cell type, iteration) -> [(rank, path)] for every HemoCell particle file."""
    found = {}
    candidates = []
    for entry in sorted(os.listdir(hdf5_dir)):
        path = os.path.join(hdf5_dir, entry)
        if os.path.isdir(path) and entry.isdigit():
            candidates.extend(os.path.join(path, name) for name in sorted(os.listdir(path)))
        elif os.path.isfile(path):
            candidates.append(path)
    for path in candidates:
        match = FILE_PATTERN.match(os.path.basename(path))
        if match is None:
            continue
        key = (match["type"], int(match["iteration"]))
        found.setdefault(key, []).append((int(match["rank"]), path))
    return found


def choose_cell_type(found, requested):
    types = sorted({t for t, _ in found if t.lower() != "fluid"})
    if requested:
        if requested not in types:
            raise DecodeError(
                f"no files of cell type {requested!r} (cell types found: {', '.join(types) or 'none'})"
            )
        return requested
    for preferred in ("RBC_HO", "RBC"):
        if preferred in types:
            return preferred
    if len(types) == 1:
        return types[0]
    raise DecodeError(
        "cannot tell which cell type is the red blood cell; give --cell-type "
        f"(cell types found: {', '.join(types) or 'none'})"
    )


def read_frame(files):
    """Positions of one iteration merged over the ranks, and the file's dx attribute."""
    blocks, ids, dx = [], [], None
    with_ids = True
    for rank, path in sorted(files):
        try:
            with h5py.File(path, "r") as f:
                if dx is None and "dx" in f.attrs:
                    dx = float(np.asarray(f.attrs["dx"]).reshape(-1)[0])
                if "Position" not in f:
                    continue
                position = np.asarray(f["Position"], dtype=float)
                if position.size == 0:
                    continue
                if position.ndim != 2 or position.shape[1] != 3:
                    raise DecodeError(f"{path}: dataset Position has shape {position.shape}, expected (n, 3)")
                blocks.append(position)
                if "Cell Id" in f and "Vertex Id" in f:
                    cell = np.asarray(f["Cell Id"], dtype=float).reshape(-1)
                    vertex = np.asarray(f["Vertex Id"], dtype=float).reshape(-1)
                    if len(cell) == len(position) and len(vertex) == len(position):
                        ids.append(np.stack([cell, vertex], axis=1))
                        continue
                with_ids = False
        except OSError as e:
            raise DecodeError(f"{path}: cannot read as HDF5: {e}") from e
    if not blocks:
        return np.zeros((0, 3)), dx
    positions = np.concatenate(blocks)
    if with_ids and ids:
        keys = np.concatenate(ids)
        if len(np.unique(keys[:, 0])) > 1:
            raise DecodeError(f"{len(np.unique(keys[:, 0]))} cells in the output; oneCellShear has one")
        _, first = np.unique(keys, axis=0, return_index=True)
    else:
        _, first = np.unique(positions, axis=0, return_index=True)
    return positions[np.sort(first)], dx


def velocity_gradient(files):
    """Mean d(u_x)/d(index) along y and along z of HemoCell's fluid output at one iteration,
    over all ranks (per-file slopes of the plane-averaged u_x, weighted by the planes' sizes;
    the one-node envelope around each rank's block is left out). Units: velocity per node."""
    totals = {"y": [0.0, 0.0], "z": [0.0, 0.0]}
    for _, path in sorted(files):
        try:
            with h5py.File(path, "r") as f:
                if "Velocity" not in f:
                    continue
                velocity = np.asarray(f["Velocity"], dtype=float)
        except OSError as e:
            raise DecodeError(f"{path}: cannot read as HDF5: {e}") from e
        if velocity.ndim != 4 or velocity.shape[3] != 3:
            continue
        ux = velocity[1:-1, 1:-1, 1:-1, 0]  # (z, y, x), as HemoCell writes for ParaView
        if min(ux.shape) < 3:
            continue
        for axis, name in ((1, "y"), (0, "z")):
            other = tuple(a for a in range(3) if a != axis)
            profile = ux.mean(axis=other)
            slope = np.polyfit(np.arange(len(profile), dtype=float), profile, 1)[0]
            totals[name][0] += slope * ux.size
            totals[name][1] += ux.size
    if totals["y"][1] == 0:
        return None
    return {name: total / count for name, (total, count) in totals.items()}


LAYOUTS = {
    # gradient axis, and HemoCell's axes -> the shear frame (x flow, y gradient, z vorticity)
    "y-walls": {"gradient": "y", "walls": 1},
    "z-walls": {"gradient": "z", "walls": 2},
}


def to_shear_frame(um, layout):
    """HemoCell's coordinates (um) in the study's shear frame: x flow, y gradient, z vorticity."""
    if layout == "z-walls":
        return np.stack([um[:, 0], um[:, 2], -um[:, 1]], axis=1)
    return um


def layout_from_gradient(gradient):
    return "z-walls" if abs(gradient["z"]) > abs(gradient["y"]) else "y-walls"


def outside_box(um, nodes, dx_um, walls_axis):
    """Why a frame's cell is not inside the box (None when it is): a vertex beyond a wall (the
    wall nodes 0 and n-1), or a cell split by a periodic boundary (its vertices wrapped to both
    sides: along that axis the largest gap between neighbouring vertex coordinates is wider than
    the room the cell leaves in the periodic box, L - (max - min))."""
    names = "xyz"
    for axis in range(3):
        low, high = float(um[:, axis].min()), float(um[:, axis].max())
        if axis == walls_axis:
            top = (nodes[axis] - 1) * dx_um
            if low < 0.0 or high > top:
                return (f"the cell left the box: vertices beyond a wall along {names[axis]} "
                        f"({low:.2f} to {high:.2f} um; the walls at 0 and {top:.2f} um)")
            continue
        period = nodes[axis] * dx_um
        gaps = np.diff(np.sort(um[:, axis]))
        if len(gaps) and float(gaps.max()) > period - (high - low):
            return (f"the cell lies across the periodic boundary along {names[axis]} (vertices "
                    f"from {low:.2f} to {high:.2f} um with a gap of {float(gaps.max()):.2f} um "
                    f"in a {period:.2f} um box)")
    return None


def deletion_in_log(log_path):
    """The first "(Delete Cells)" warning of HemoCell's stdout with the lines after it, or None."""
    if not log_path or not os.path.isfile(log_path):
        return None
    with open(log_path, errors="replace") as f:
        lines = f.read().splitlines()
    for k, line in enumerate(lines):
        if "Particle deleted" in line or "(Delete Cells)" in line:
            detail = " ".join(l.strip() for l in lines[k:k + 3])
            return detail[:300]
    return None


def detect_unit(positions):
    return "m" if float(np.max(np.abs(positions))) < 1e-3 else "lattice"


def main(argv=None):
    parser = argparse.ArgumentParser(
        description="Elongation index of a HemoCell oneCellShear run, measured by `iuq rbc elongation`."
    )
    parser.add_argument("hdf5_dir", help="HemoCell's HDF5 output folder (tmp/hdf5)")
    parser.add_argument("--from", dest="start", type=int, required=True, help="t_start: first iteration of the window")
    parser.add_argument("--to", dest="end", type=int, required=True, help="t_max: last iteration of the window")
    parser.add_argument("--frames", type=int, default=None,
                        help="keep the last N output iterations of the window (default: all)")
    parser.add_argument("--cell-type", default=None, help="file prefix of the cell (default: RBC_HO, RBC, or the only one)")
    parser.add_argument("--unit", choices=["auto", "m", "lattice", "um"], default="auto",
                        help="unit of Position (default: auto, metres or lattice units by magnitude)")
    parser.add_argument("--dx", type=float, default=None,
                        help="lattice spacing in metres for lattice-unit positions (default: the files' dx attribute, else 0.5e-6)")
    parser.add_argument("--csv-dir", default="el-frames", help="where the per-frame CSV files go (default: el-frames)")
    parser.add_argument("--out", default="el.json", help="the result file (default: el.json)")
    parser.add_argument("--log", default=None,
                        help="HemoCell's stdout: a cell deletion it reports fails the run with its message")
    parser.add_argument("--summary", default="hemocell-frames.json",
                        help="per-frame summary written here (default: hemocell-frames.json; '' for none)")
    parser.add_argument("--layout", choices=["auto", "y-walls", "z-walls"], default="auto",
                        help="oneCellShear's wall layout: y-walls (HemoCell <= 2.1), z-walls (>= 2.2), or auto: "
                             "from the fluid output's velocity gradient (default)")
    parser.add_argument("--box", default="40,40,20", metavar="NX,NY,NZ",
                        help="the domain in lattice nodes (default: oneCellShear's 40,40,20)")
    args = parser.parse_args(argv)
    if args.end < args.start:
        fail(f"--to {args.end} lies before --from {args.start}", 2)
    if args.frames is not None and args.frames < 2:
        fail("--frames must be at least 2", 2)
    try:
        nodes = [int(n) for n in args.box.split(",")]
        if len(nodes) != 3 or min(nodes) < 2:
            raise ValueError
    except ValueError:
        fail(f"--box {args.box!r}: expected three node counts of at least 2, e.g. 40,40,20", 2)
    if not os.path.isdir(args.hdf5_dir):
        fail(f"{args.hdf5_dir}: no such folder (did HemoCell run and write HDF5 output?)")
    if IMPORT_ERROR is not None:
        fail(f"needs numpy and h5py ({IMPORT_ERROR}); install them with `python3 -m pip install numpy h5py`", 2)

    try:
        deleted = deletion_in_log(args.log)
        if deleted:
            raise DecodeError(f"HemoCell deleted the cell ({args.log}: {deleted})")
        found = scan(args.hdf5_dir)
        cell_type = choose_cell_type(found, args.cell_type)
        iterations = sorted(i for t, i in found if t == cell_type)
        window = [i for i in iterations if args.start <= i <= args.end]
        if args.frames is not None and len(window) > args.frames:
            window = window[-args.frames:]
        if len(window) < 2:
            raise DecodeError(
                f"{len(window)} output iteration(s) of {cell_type} in [{args.start}, {args.end}] under "
                f"{args.hdf5_dir}; at least 2 are needed (iterations found: "
                f"{', '.join(map(str, iterations)) or 'none'}; did the run stop early?)"
            )
        gradient = None
        fluid = next((t for t in sorted({t for t, _ in found}) if t.lower() == "fluid"), None)
        if fluid and (fluid, window[-1]) in found:
            gradient = velocity_gradient(found[(fluid, window[-1])])
        layout = args.layout
        if gradient is None:
            if layout == "auto":
                layout = "y-walls"
                print("decode-el.py: no fluid velocity output at the last frame: the y-wall layout "
                      "(HemoCell <= 2.1) is assumed", file=sys.stderr)
        else:
            sheared = layout_from_gradient(gradient)
            if layout == "auto":
                layout = sheared
            elif layout != sheared:
                raise DecodeError(
                    f"the fluid is sheared along {LAYOUTS[sheared]['gradient']} (du_x/dy per node "
                    f"{gradient['y']:.3g}, du_x/dz {gradient['z']:.3g}) but the layout is {layout}: "
                    f"this oneCellShear has the {sheared} layout; run it with HEMOCELL_LAYOUT={sheared} "
                    "(run-hemocell.sh) or --layout auto")
        walls_axis = LAYOUTS[layout]["walls"]
        # The cell's vertex count: its first output (iteration 0 or the earliest written).
        reference_count = None
        if iterations:
            first_positions, _ = read_frame(found[(cell_type, iterations[0])])
            reference_count = len(first_positions) or None
        os.makedirs(args.csv_dir, exist_ok=True)
        csv_files = []
        summary = []
        for k, iteration in enumerate(window):
            positions, dx_attribute = read_frame(found[(cell_type, iteration)])
            if len(positions) == 0:
                raise DecodeError(
                    f"iteration {iteration}: no membrane vertices in the output (HemoCell deleted the cell: it broke or left the domain)"
                )
            if not np.all(np.isfinite(positions)):
                raise DecodeError(f"iteration {iteration}: non-finite vertex positions (the membrane broke)")
            if reference_count and len(positions) < reference_count:
                raise DecodeError(
                    f"iteration {iteration}: {len(positions)} of the cell's {reference_count} vertices in the "
                    "output (HemoCell lost part of the cell)")
            unit = detect_unit(positions) if args.unit == "auto" else args.unit
            if unit == "m":
                um = positions * 1e6
            elif unit == "lattice":
                dx = args.dx or (dx_attribute if dx_attribute and dx_attribute > 0 else 0.5e-6)
                um = positions * (dx * 1e6)
            else:
                um = positions
            escaped = outside_box(um, nodes, (args.dx or dx_attribute or 0.5e-6) * 1e6, walls_axis)
            if escaped:
                raise DecodeError(f"iteration {iteration}: {escaped}")
            shear = to_shear_frame(um, layout)
            path = os.path.join(args.csv_dir, f"frame_{k:02d}_iter_{iteration:012d}.csv")
            with open(path, "w") as f:
                f.write("x,y,z\n")
                for x, y, z in shear.tolist():
                    f.write(f"{x!r},{y!r},{z!r}\n")
            csv_files.append(path)
            summary.append({
                "iteration": iteration,
                "vertices": len(um),
                "centroid_um": [float(v) for v in um.mean(axis=0)],
                "extent_um": [float(v) for v in (um.max(axis=0) - um.min(axis=0))],
            })
            print(f"decode-el.py: iteration {iteration}: {len(positions)} vertices ({unit}) -> {path}", file=sys.stderr)
    except DecodeError as e:
        fail(str(e))
    if args.summary:
        record = {"layout": layout, "frames": summary}
        if gradient is not None:
            record["fluid_du_x_per_node"] = gradient
        with open(args.summary, "w") as f:
            json.dump(record, f, indent=1)

    iuq = os.environ.get("IUQ") or shutil.which("iuq")
    if not iuq:
        fail("the iuq binary was not found: set IUQ=/path/to/iuq or put iuq on PATH", 2)
    command = [iuq, "--json", "rbc", "elongation", "--unit", "um", "--out", args.out, *csv_files]
    result = subprocess.run(command)
    return result.returncode


if __name__ == "__main__":
    sys.exit(main())
