"""Wall time of the harp renderer (pipeline/render.py) and of its ground truth.

Usage::

    .venv/bin/python benchmarks/render_speed.py [--repeat 3] [--no-24mp]

Renders an 8-bit harp (strings 3 px wide, 60 px apart, 30 degrees, read noise
1.5, vignetting 0.3) at 2 MP (1761 x 1174, the size of the real photos) and
24 MP (6000 x 4000), without distortion and through the simulated camera's
demo lens (``drivers.sim.lens.lens_for_focus``) -- mapping every pixel through
the lens, and with the lens map computed once (``ideal=ideal_grid(...)``, what the
simulated camera does for the frames at one focus) -- and times
``true_edge_curves`` on the result. Median of ``--repeat`` runs; the CPU
time (all threads, ``time.process_time``) is given too because wall time on
a shared machine depends on the load. Prints a Markdown table (results:
benchmarks/RESULTS-render.md).
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from drivers.sim.lens import lens_for_focus
from pipeline.render import HarpScene, ideal_grid, render_harp, true_edge_curves

SIZES = [("2 MP", 1761, 1174), ("24 MP", 6000, 4000)]


def _median_time(fn, repeat):
    """Median wall time and median CPU time (all threads) of ``fn()``, and its result."""
    wall, cpu, out = [], [], None
    for _ in range(repeat):
        t, c = time.perf_counter(), time.process_time()
        out = fn()
        wall.append(time.perf_counter() - t)
        cpu.append(time.process_time() - c)
    return statistics.median(wall), statistics.median(cpu), out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--no-24mp", action="store_true")
    args = ap.parse_args(argv)
    scene = HarpScene(angle_deg=30.0)
    print(
        f"harp renderer speed ({platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, "
        f"median of {args.repeat})\n"
    )
    print("| size | lens | render_harp wall (s) | render_harp CPU (s) | true_edge_curves wall (s) | edges |")
    print("| --- | --- | ---: | ---: | ---: | ---: |")
    for name, w, h in SIZES:
        if args.no_24mp and w * h > 5e6:
            continue
        demo = lens_for_focus(0.5, w, h)
        cases = [("identity", None, None), ("demo lens, focus 0.5", demo, None)]
        cases.append(("demo lens, focus 0.5, lens map kept", demo, ideal_grid(demo, w, h)))
        for lens_name, lens, grid in cases:
            t_r, c_r, r = _median_time(lambda: render_harp(w, h, scene, lens=lens, seed=1, ideal=grid), args.repeat)
            t_t, _, curves = _median_time(lambda: true_edge_curves(r), args.repeat)
            print(f"| {name} ({w}x{h}) | {lens_name} | {t_r:.3f} | {c_r:.3f} | {t_t:.3f} | {len(curves)} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
