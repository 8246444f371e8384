"""Fit time vs number of edges and model degree (pipeline.fit.fit_distortion).

Synthetic harp point sets (a decentred lens with tangential terms, 1761x1174
like the real photos, points every 30 px, noise 0.005 px), 3 orientations per
set of shots; the number of edges is varied by the string spacing and the
number of shots. Each fit runs the full robust procedure (LM, Huber-weighted
LM, outlier rejection, final LM). Prints a markdown table; ``--write`` saves
it to benchmarks/RESULTS-fit.md.

    .venv/bin/python benchmarks/fit_speed.py [--write]
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from pipeline.edgeset import FitResult
from pipeline.fit import fit_distortion
from pipeline.models import RadialModel
from tests.pipeline.harp_points import harp_point_sets

W, H = 1761, 1174
LENS = RadialModel.for_image(W, H, k=(1.0, 0.0, 0.02, 0.0, 0.003), center=(900, 570), tangential=(0.0005, -0.0003))
CONFIGS = [
    ("radial4", dict(model="radial", degree=4)),
    ("radial4+tangential+prism", dict(model="radial", degree=4, tangential=True, prism=True)),
    ("radial6+tangential+prism", dict(model="radial", degree=6, tangential=True, prism=True)),
    ("poly3", dict(model="poly", degree=3)),
    ("poly5", dict(model="poly", degree=5)),
    ("poly7", dict(model="poly", degree=7)),
    ("poly9", dict(model="poly", degree=9)),
    ("poly11", dict(model="poly", degree=11)),
]
DATASETS = [
    ("3 shots, spacing 120 px", 3, 120.0),
    ("3 shots, spacing 60 px", 3, 60.0),
    ("6 shots, spacing 60 px", 6, 60.0),
    ("12 shots, spacing 40 px", 12, 40.0),
]


LOAD_AT_START = os.getloadavg()[0]


def main() -> str:
    rows = []
    header = "| data | edges | points | " + " | ".join(n for n, _ in CONFIGS) + " |"
    rows.append(header)
    rows.append("|" + "---|" * (3 + len(CONFIGS)))
    for label, n_shots, spacing in DATASETS:
        angles = [float(a) for a in np.linspace(0, 180, n_shots, endpoint=False) + 5]
        shots = harp_point_sets(LENS, W, H, angles, spacing=spacing, noise=0.005, seed=0)
        n_e = sum(len(s) for s in shots)
        n_p = sum(len(p) for s in shots for p in s)
        cells = []
        for _, kw in CONFIGS:
            best = float("inf")
            for _ in range(3):
                t0 = time.perf_counter()
                r = fit_distortion(shots, W, H, **kw)
                best = min(best, time.perf_counter() - t0)
            ok = isinstance(r, FitResult)
            cells.append(f"{best:.3f} s" + ("" if ok else " (failed)") + (f" / d {r.d_after:.4f}" if ok else ""))
        rows.append(f"| {label} | {n_e} | {n_p} | " + " | ".join(cells) + " |")
        print(rows[-1], flush=True)
    info = (
        f"Fit time (best of 3, wall clock) and fitted d (px) of `fit_distortion`, {W}x{H} images.\n"
        f"Machine: {platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, "
        f"Python {platform.python_version()}, numpy {np.__version__}; load average at start "
        f"{LOAD_AT_START:.1f} (the machine is shared: times are upper bounds).\n"
        f"Command: `.venv/bin/python benchmarks/fit_speed.py --write`\n\n"
    )
    return info + "\n".join(rows) + "\n"


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--write", action="store_true", help="save the table to benchmarks/RESULTS-fit.md")
    args = ap.parse_args()
    text = main()
    print(text)
    if args.write:
        (Path(__file__).parent / "RESULTS-fit.md").write_text("# Fit speed\n\n" + text)
