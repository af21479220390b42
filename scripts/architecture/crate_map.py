#!/usr/bin/env python3
"""Draw the workspace's crate map (docs/images/crate-map.svg) from its real dependency graph.

    python3 scripts/architecture/crate_map.py [--out docs/images/crate-map.svg] [--check]

Reads `cargo metadata --no-deps` (no build), keeps the workspace's own crates and their normal
(non-dev) dependencies on each other, and lays them out in layers: a crate sits one layer above
the highest crate it depends on, so every arrow points down, from a crate to what it uses.
`--check` exits 1 when the committed SVG differs from what the graph draws now (run by the
docs' checks, so the picture cannot drift from Cargo.toml).
"""

import argparse
import json
import os
import subprocess
import sys
from xml.sax.saxutils import escape

BOX_W, BOX_H, GAP_X, GAP_Y, MARGIN = 150, 34, 22, 64, 20


def graph(root):
    text = subprocess.run(["cargo", "metadata", "--format-version", "1", "--no-deps"],
                          cwd=root, check=True, capture_output=True, text=True).stdout
    packages = json.loads(text)["packages"]
    names = {p["name"] for p in packages}
    edges = {p["name"]: sorted({d["name"] for d in p["dependencies"]
                                if d["name"] in names and d["kind"] is None})
             for p in packages}
    return edges


def layers(edges):
    level = {}

    def depth(name):
        if name not in level:
            level[name] = 1 + max((depth(d) for d in edges[name]), default=-1)
        return level[name]

    for name in edges:
        depth(name)
    rows = {}
    for name, k in level.items():
        rows.setdefault(k, []).append(name)
    return [sorted(rows[k]) for k in sorted(rows, reverse=True)]


def svg(edges):
    rows = layers(edges)
    width = max(len(r) for r in rows) * (BOX_W + GAP_X) - GAP_X + 2 * MARGIN
    height = len(rows) * (BOX_H + GAP_Y) - GAP_Y + 2 * MARGIN
    where = {}
    for i, row in enumerate(rows):
        row_w = len(row) * (BOX_W + GAP_X) - GAP_X
        x0 = (width - row_w) / 2
        for j, name in enumerate(row):
            where[name] = (x0 + j * (BOX_W + GAP_X), MARGIN + i * (BOX_H + GAP_Y))
    out = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{width:.0f}" height="{height:.0f}" '
           f'viewBox="0 0 {width:.0f} {height:.0f}" font-family="sans-serif" font-size="13">',
           '<defs><marker id="arrow" viewBox="0 0 10 10" refX="9" refY="5" markerWidth="7" '
           'markerHeight="7" orient="auto-start-reverse"><path d="M 0 0 L 10 5 L 0 10 z" '
           'fill="#667"/></marker></defs>',
           f'<rect width="{width:.0f}" height="{height:.0f}" fill="white"/>']
    for name in sorted(edges):
        x, y = where[name]
        for dep in edges[name]:
            dx, dy = where[dep]
            out.append(f'<line x1="{x + BOX_W / 2:.1f}" y1="{y + BOX_H:.1f}" '
                       f'x2="{dx + BOX_W / 2:.1f}" y2="{dy:.1f}" stroke="#99a" stroke-width="1" '
                       'marker-end="url(#arrow)"/>')
    for name, (x, y) in sorted(where.items()):
        out.append(f'<rect x="{x:.1f}" y="{y:.1f}" width="{BOX_W}" height="{BOX_H}" rx="6" '
                   'fill="#eef3fb" stroke="#3a5a8c"/>')
        out.append(f'<text x="{x + BOX_W / 2:.1f}" y="{y + BOX_H / 2 + 4.5:.1f}" '
                   f'text-anchor="middle">{escape(name)}</text>')
    out.append("</svg>")
    return "\n".join(out) + "\n"


def main():
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default=os.path.join(root, "docs", "images", "crate-map.svg"))
    parser.add_argument("--check", action="store_true")
    args = parser.parse_args()
    drawn = svg(graph(root))
    if args.check:
        with open(args.out, encoding="utf-8") as f:
            if f.read() != drawn:
                sys.exit(f"{args.out} is out of date: run python3 scripts/architecture/crate_map.py")
        return
    os.makedirs(os.path.dirname(args.out), exist_ok=True)
    with open(args.out, "w", encoding="utf-8") as f:
        f.write(drawn)


if __name__ == "__main__":
    main()
