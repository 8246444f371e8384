"""Wall time of the whole measurement (``harp measure``) at 2 MP and 24 MP.

Usage::

    .venv/bin/python benchmarks/measure_speed.py [--repeat 3] [--no-24mp] [--profile]

Per image: the median over ``--repeat`` runs of the wall time of

* ``harp measure`` on the image file, in process (read the PGM + measure,
  no output),
* :func:`pipeline.measure.measure_image` alone, split into its stages:
  sub-pixel edges (``detect_edges``), grouping (``group_string_edges``),
  per-edge smoothing + straightness + hf residual (``measure_grouping``),
* one ``cv2.Canny`` pass on the same image (thresholds 20/40, 3x3 Sobel),
  the reference the issue asks for,

on a real photograph (1761x1174, 2.1 MP), a synthetic 2 MP harp and a
synthetic 24 MP harp (6000x4000; strings 8 px wide, 200 px apart, 80
degrees, barrel distortion of ~20 px at the corners, noise 1.5). Also
prints the CPU time (all threads) of ``measure_image`` and the number of
cores. ``--profile`` prints the top functions of one 24 MP run.
Target (issue 2): 24 MP in <= 2 s.
"""

from __future__ import annotations

import argparse
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from pipeline.edges import detect_edges  # noqa: E402
from pipeline.grouping import group_string_edges  # noqa: E402
from pipeline.measure import measure_grouping, measure_image  # noqa: E402
from pipeline.models.radial import RadialModel  # noqa: E402
from pipeline.render import HarpScene, render_harp  # noqa: E402
from station.cli import main as harp_main  # noqa: E402

REAL = ROOT.parent / "shared" / "data" / "real-harp" / "IMG_6931.pgm"


def _median_time(fn, repeat):
    ts = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        ts.append(time.perf_counter() - t0)
    return float(np.median(ts))


def _cpu_time(fn):
    c0 = time.process_time()
    fn()
    return time.process_time() - c0


def bench(name, img, path, repeat):
    h, w = img.shape
    border = 4.0
    stage = {}
    stage["edges"] = _median_time(lambda: detect_edges(img), repeat)
    chains = detect_edges(img)
    stage["group"] = _median_time(lambda: group_string_edges(chains, img.shape, border_px=border), repeat)
    g = group_string_edges(chains, img.shape, border_px=border)
    stage["per-edge"] = _median_time(lambda: measure_grouping(g, w, h), repeat)
    total = _median_time(lambda: measure_image(img), repeat)
    cpu = _cpu_time(lambda: measure_image(img))
    devnull = open(os.devnull, "w")

    def cli():
        old = sys.stdout
        sys.stdout = devnull
        try:
            assert harp_main(["measure", "--json", str(path)]) == 0
        finally:
            sys.stdout = old

    cli_t = _median_time(cli, repeat)
    canny = _median_time(
        lambda: cv2.Canny(img if img.dtype == np.uint8 else (img >> 8).astype(np.uint8), 20, 40), repeat
    )
    m = measure_image(img)
    return (
        f"| {name} | {w}x{h} ({w * h / 1e6:.1f} MP) | {m.n_lines} | {cli_t:.2f} | {total:.2f} | "
        f"{stage['edges']:.2f} | {stage['group']:.2f} | {stage['per-edge']:.2f} | {cpu:.2f} | {canny:.3f} | "
        f"{total / canny:.0f}x |"
    )


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--no-24mp", action="store_true")
    ap.add_argument("--profile", action="store_true")
    args = ap.parse_args(argv)

    cases = []
    if REAL.is_file():
        cases.append(("real photo IMG_6931", cv2.imread(str(REAL), cv2.IMREAD_UNCHANGED), REAL))
    tmp = Path(tempfile.mkdtemp(prefix="harp-bench-"))
    sizes = [(1732, 1155, 60.0, 3.0)] + ([] if args.no_24mp else [(6000, 4000, 200.0, 8.0)])
    for w, h, spacing, width in sizes:
        lens = RadialModel.for_image(w, h, k=(1.0, 0.0, 0.006))
        r = render_harp(
            w,
            h,
            HarpScene(angle_deg=80.0, spacing_px=spacing, string_width_px=width),
            lens=lens,
            noise_sigma=1.5,
            seed=0,
        )
        p = tmp / f"synthetic_{w}x{h}.pgm"
        cv2.imwrite(str(p), r.image)
        cases.append((f"synthetic {w * h / 1e6:.0f} MP", r.image, p))

    load = os.getloadavg()[0]
    print(
        f"harp measure speed, {os.cpu_count()} cores (load average {load:.1f} when started), "
        f"median of {args.repeat} runs, wall seconds"
    )
    print()
    print(
        "| image | size | edges found | `harp measure` (read+measure) | measure_image | "
        "- sub-pixel edges | - grouping | - per-edge smoothing+straightness | measure_image CPU s | "
        "cv2.Canny | measure / Canny |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    try:
        for name, img, path in cases:
            print(bench(name, img, path, args.repeat), flush=True)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    if args.profile and not args.no_24mp:
        import cProfile
        import pstats

        img = cases[-1][1]
        pr = cProfile.Profile()
        pr.enable()
        measure_image(img)
        pr.disable()
        print()
        print("profile of one 24 MP measure_image (top 15 by own time):")
        pstats.Stats(pr, stream=sys.stdout).sort_stats("tottime").print_stats(15)


if __name__ == "__main__":
    main()
