#!/usr/bin/env python3
"""The README's figure: the cooling example calibrated by `iuq pipeline`, its calibrated curve with
the 95 % band beside the corner plot of the posterior, both as the report draws them.

    python scripts/figures/readme_figure.py [--iuq target/release/iuq] [--out docs/images/cooling-calibration.png]

It runs `iuq pipeline examples/cooling/cooling-curve.toml` on a copy of examples/cooling/ in a
temporary folder (about 10 s; the model needs python3), so the checkout is left as it was, then
puts the report's `figures/data_fit.png` and `figures/corner.png` side by side (matplotlib).
"""

import argparse
import os
import shutil
import subprocess
import tempfile
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.image as mpimg  # noqa: E402
import matplotlib.pyplot as plt  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--iuq", default=os.environ.get("IUQ_BIN", str(ROOT / "target/release/iuq")))
    parser.add_argument("--out", default=str(ROOT / "docs/images/cooling-calibration.png"))
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix="iuq-readme-figure-") as tmp:
        work = Path(tmp)
        shutil.copytree(ROOT / "examples/cooling", work / "cooling",
                        ignore=shutil.ignore_patterns("*.campaign", "*.campaign.previous-*"))
        report = work / "report"
        subprocess.run([args.iuq, "pipeline", "cooling/cooling-curve.toml", "--out", str(report)],
                       cwd=work, check=True, stderr=subprocess.DEVNULL)
        fit = mpimg.imread(report / "figures/data_fit.png")
        corner = mpimg.imread(report / "figures/corner.png")
    height = 4.0
    widths = [img.shape[1] / img.shape[0] * height for img in (fit, corner)]
    fig, axes = plt.subplots(1, 2, figsize=(sum(widths), height), dpi=150,
                             gridspec_kw={"width_ratios": widths, "wspace": 0.0})
    for ax, img in zip(axes, (fit, corner)):
        ax.imshow(img, interpolation="lanczos")
        ax.set_axis_off()
    fig.subplots_adjust(left=0, right=1, top=1, bottom=0)
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(args.out)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
