"""Undistortion speed: maps computation and cv2.remap, 24 MP and 2 MP.

Run:  .venv/bin/python benchmarks/undistort_speed.py [--exact-2mp]
Prints a table (commit it as benchmarks/RESULTS-undistort.md). Maps are
computed by pipeline.undistort_maps.fast_undistortion_maps (exact inverse on
nodes every 16 px + bicubic spline; its measured interpolation error is in
the table); with --exact-2mp also the exact per-pixel base-class maps at 2 MP
for comparison. remap: grey uint8, grey uint16 and colour uint8 with the
default Lanczos-4 kernel and with bilinear. Times are best of 3 (remap) /
1 (maps) runs, wall clock, on this machine (see the header line).
"""

from __future__ import annotations

import argparse
import os
import platform
import time

import cv2
import numpy as np

from pipeline.models import RadialModel
from pipeline.models.polynomial import PolynomialModel
from pipeline.undistort_maps import fast_undistortion_maps


def poly_lens(w, h, degree=7):
    m = PolynomialModel.identity(w, h, degree)
    a, b = np.array(m.a), np.array(m.b)
    rng = np.random.default_rng(0)
    a[3:] += rng.normal(0, 2e-3, len(a) - 3)
    b[3:] += rng.normal(0, 2e-3, len(b) - 3)
    return PolynomialModel(center=m.center, degree=degree, a=tuple(a), b=tuple(b), scale=m.scale)


def best(f, n=3):
    t = []
    for _ in range(n):
        t0 = time.perf_counter()
        f()
        t.append(time.perf_counter() - t0)
    return min(t)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--exact-2mp", action="store_true", help="also time exact per-pixel maps at 2 MP")
    args = ap.parse_args()
    print(
        f"# harp undistort speed — {platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, "
        f"OpenCV {cv2.__version__}, numpy {np.__version__}, load average {os.getloadavg()[0]:.1f} at start"
    )
    print()
    print(
        "| image | model | maps (s) | interp. err (px) | remap u8 lanczos (s) | remap u16 lanczos (s) "
        "| remap RGB u8 lanczos (s) | remap u8 linear (s) |"
    )
    print("|---|---|---|---|---|---|---|---|")
    rng = np.random.default_rng(1)
    for w, h, label in ((6000, 4000, "24 MP 6000x4000"), (1920, 1080, "2 MP 1920x1080")):
        g8 = rng.integers(0, 256, (h, w), dtype=np.uint8)
        g16 = rng.integers(0, 65536, (h, w), dtype=np.uint16)
        rgb = rng.integers(0, 256, (h, w, 3), dtype=np.uint8)
        for name, model in (
            (
                "radial k2,k4 + tangential",
                RadialModel.for_image(w, h, k=(1, 0, 0.04, 0, -0.01), tangential=(1e-3, 5e-4)),
            ),
            ("poly degree 7", poly_lens(w, h)),
        ):
            t0 = time.perf_counter()
            maps = fast_undistortion_maps(model, w, h)
            tm = time.perf_counter() - t0
            r = [
                best(lambda img=img, k=k: cv2.remap(img, maps.map_x, maps.map_y, k, borderMode=cv2.BORDER_CONSTANT))
                for img, k in (
                    (g8, cv2.INTER_LANCZOS4),
                    (g16, cv2.INTER_LANCZOS4),
                    (rgb, cv2.INTER_LANCZOS4),
                    (g8, cv2.INTER_LINEAR),
                )
            ]
            print(
                f"| {label} | {name} | {tm:.2f} | {maps.interp_error_px:.1e} | {r[0]:.2f} | {r[1]:.2f} "
                f"| {r[2]:.2f} | {r[3]:.3f} |"
            )
    if args.exact_2mp:
        w, h = 1920, 1080
        model = RadialModel.for_image(w, h, k=(1, 0, 0.04, 0, -0.01), tangential=(1e-3, 5e-4))
        t0 = time.perf_counter()
        ex, ey = model.undistortion_maps(w, h)
        te = time.perf_counter() - t0
        fast = fast_undistortion_maps(model, w, h)
        diff = max(np.abs(ex - fast.map_x).max(), np.abs(ey - fast.map_y).max())
        print()
        print(
            f"exact per-pixel maps (base-class Newton), 2 MP radial: {te:.2f} s; "
            f"max |fast - exact| = {diff:.1e} px (both stored as float32: 1 ulp at 1024-2047 px = 1.2e-4 px)"
        )


if __name__ == "__main__":
    main()
