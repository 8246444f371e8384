"""Assessments per second of the live view (issue 13; target >= 5 per second at 5 MP on 2 cores).

Usage::

    .venv/bin/python benchmarks/live_rate.py [--frames 20] [--loop-seconds 8]

For each frame size, frames of the simulated camera (the demo lens at focus 0.5, noise 1.5,
the camera's defocus on: best focus 0.37, here at focus 0.37) are rendered first; then
:func:`pipeline.assess.assess_frame` runs on them as the live view runs it: the analysis
scale from the last measured string width, the edge thresholds of the previous frame reused.
*Tracked*: the same frames assessed with ``previous=`` a search of the first one (the strings
not searched again; every figure of the strings and the exposure measured on each frame), as the
live loop does between searches (it searches again after a move, every second, and whenever a
string is found more than 0.5 px from where it was).

It reports the median wall time per assessment, its CPU time (``time.process_time``, all
threads of the process: what the assessment costs whatever else runs on the machine), and its stages (exposure figures, downscale,
sub-pixel edges, grouping, full-resolution string refinement, coverage), the rate it allows,
and the cost of what the live loop adds per frame (JPEG of the displayed frame, the page's
JSON). Sizes: 1280x960 (the demo camera: 3 px strings 60 px apart) and 2592x1944 (5 MP: the
same harp imaged at twice the resolution, 6 px strings 120 px apart, found on the 2x
downscaled image), and 5 MP with 3 px strings (twice as many strings to refine; the grouping
still finds 1.5 px strings on the 2x downscaled image).

``--loop-seconds``: also runs the whole live loop (:class:`station.live.runner.LiveStation`,
capture on one thread, assessment on another) on the simulated camera for that long and
reports frames assessed per second -- there the simulator's rendering (not the assessment)
sets the rate.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from drivers.sim.camera import SimulatedCamera  # noqa: E402
from pipeline import assess as A  # noqa: E402
from pipeline.assess import assessment as frame_job  # noqa: E402
from pipeline.edges import detect_edges  # noqa: E402
from pipeline.grouping import group_string_edges  # noqa: E402
from pipeline.render import HarpScene  # noqa: E402
from station.live.view import encode_frame, view_of  # noqa: E402

CASES = [
    ("1280x960, 3 px strings", 1280, 960, 1.0),
    ("5 MP, 6 px strings", 2592, 1944, 2.0),
    ("5 MP, 3 px strings", 2592, 1944, 1.0),
]


def frames(w, h, k, n):
    scene = HarpScene(spacing_px=60.0 * k, string_width_px=3.0 * k, blur_px=0.7 * k)
    cam = SimulatedCamera(width=w, height=h, scene=scene, seed=1, best_focus=0.37, defocus_blur_px=8.0 * k)
    out = []
    with cam:
        cam.lock_focus(0.37)
        for i in range(n):
            cam.world.harp_offset_deg = 5.0 + 0.01 * i  # a new pose (and noise) every frame
            out.append(cam.capture().image)
    return out


def stages(img, scale, th):
    t = [time.perf_counter()]
    A.exposure_figures(img)
    t.append(time.perf_counter())
    small = frame_job._downscale(img, scale)
    t.append(time.perf_counter())
    chains = detect_edges(small, low=th[0], high=th[1], min_length=8, interpolation="parabola")
    t.append(time.perf_counter())
    g = group_string_edges(chains, small.shape, border_px=A.BORDER_PX)
    t.append(time.perf_counter())
    sx = img.shape[1] / small.shape[1]
    by = {}
    for e in g.edges:
        by.setdefault(e.string_id, []).append(frame_job._to_frame(e.xy, sx, sx))
    A.string_sharpness(img, [(i, *xs) for i, xs in by.items() if len(xs) == 2])
    t.append(time.perf_counter())
    A.edge_coverage([xs for v in by.values() for xs in v], img.shape[1], img.shape[0])
    t.append(time.perf_counter())
    return np.diff(t)


def bench(name, w, h, k, n):
    imgs = frames(w, h, k, n)
    first = A.assess_frame(imgs[0])
    scale = A.analysis_scale(w, h, first.string_width_px)
    a = A.assess_frame(imgs[0], scale=scale)
    th = a.thresholds
    total, cpu, st, extra = [], [], [], []
    for img in imgs:
        t0, c0 = time.perf_counter(), time.process_time()
        a = A.assess_frame(img, scale=scale, thresholds=th)
        total.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
        t0 = time.perf_counter()
        encode_frame(img, 960, a.exposure.full_scale)
        json.dumps(view_of(a, [], 960))
        extra.append(time.perf_counter() - t0)
    searched = A.assess_frame(imgs[0], scale=scale, thresholds=th)
    tr, tr_cpu = [], []
    for img in imgs:
        t0, c0 = time.perf_counter(), time.process_time()
        A.assess_frame(img, previous=searched)
        tr.append(time.perf_counter() - t0)
        tr_cpu.append(time.process_time() - c0)
    for img in imgs[: max(3, n // 4)]:
        st.append(stages(img, scale, th))
    s = np.median(st, axis=0)
    med = float(np.median(total))
    return (
        f"| {name} | {w}x{h} | {scale:g} | {a.n_strings} | {med:.3f} | {1 / med:.1f} | {np.median(cpu):.3f} | "
        f"{1 / np.median(cpu):.1f} | "
        + " | ".join(f"{v:.3f}" for v in s)
        + f" | {np.median(extra):.3f} | {1 / (med + np.median(extra)):.1f} |"
        + f" {np.median(tr):.3f} | {1 / np.median(tr):.1f} | {np.median(tr_cpu):.3f} | {1 / np.median(tr_cpu):.1f} |"
    )


def loop_rate(seconds, w, h, k):
    from station.live.runner import LiveStation

    scene = HarpScene(spacing_px=60.0 * k, string_width_px=3.0 * k, blur_px=0.7 * k)
    cam = SimulatedCamera(width=w, height=h, scene=scene, seed=1, best_focus=0.37, defocus_blur_px=8.0 * k)
    with cam:
        cam.lock_focus(0.37)
        t0 = time.perf_counter()
        cam.capture()
        render = time.perf_counter() - t0
        with LiveStation(cam) as st:
            time.sleep(2.0)  # warm up: first thresholds and scale
            n0, t0 = st.frames_assessed, time.monotonic()
            time.sleep(seconds)
            n1, t1 = st.frames_assessed, time.monotonic()
    return render, (n1 - n0) / (t1 - t0)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--frames", type=int, default=20)
    ap.add_argument("--loop-seconds", type=float, default=8.0)
    args = ap.parse_args()
    print(subprocess.run(["uptime"], capture_output=True, text=True).stdout.strip())
    print(f"live view assessment rate, {os.cpu_count()} cores, median of {args.frames} frames, wall seconds")
    print()
    print(
        "| frames | size | analysis scale | strings | assessment s | assessments/s | CPU s | per CPU s |"
        " exposure | downscale | edges | grouping | string refinement | coverage | + JPEG & JSON | with them /s |"
        " tracked s | tracked/s | tracked CPU s | per CPU s |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for name, w, h, k in CASES:
        print(bench(name, w, h, k, args.frames), flush=True)
    if args.loop_seconds > 0:
        print()
        print(
            "| whole live loop (LiveStation, simulated camera) | size | one simulated capture s | frames assessed/s |"
        )
        print("|---|---|---|---|")
        for name, w, h, k in CASES[:2]:
            render, rate = loop_rate(args.loop_seconds, w, h, k)
            print(f"| {name} | {w}x{h} | {render:.2f} | {rate:.1f} |", flush=True)
    print()
    print(subprocess.run(["uptime"], capture_output=True, text=True).stdout.strip())


if __name__ == "__main__":
    main()
