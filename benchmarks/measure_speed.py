"""Wall time of ``harp measure`` as a whole process, and of its stages, at 2 MP and 24 MP.

Usage::

    .venv/bin/python benchmarks/measure_speed.py [--repeat 5] [--no-24mp] [--profile]

Per image, the median over ``--repeat`` runs of:

* ``harp measure --json IMAGE`` as a **whole process** (``python -m station.cli``, started
  with ``subprocess``: interpreter start-up, imports, image decode, measurement, JSON),
  with its user and system CPU time (``os.wait4``), Python's bytecode cache in use as after
  a first run (in a temporary ``PYTHONPYCACHEPREFIX``, written by the uncounted warm-up
  run), and again without any
  bytecode cache (``PYTHONDONTWRITEBYTECODE=1``, as in the development sandbox: every
  project module compiled at each start);
* in process: the PNG/PGM decode (``station.imageio.read_grey``) and
  :func:`pipeline.measure.measure_image` split into its stages: sub-pixel edges
  (``detect_edges``), grouping (``group_string_edges``), per-edge smoothing +
  straightness + hf residual (``measure_grouping``);
* one ``cv2.Canny`` pass on the same image (thresholds 20/40, 3x3 Sobel), the
  reference the issue asks for;
* the modules the command imports that it does not need (any ``scipy`` module).

Images: the real photograph IMG_6931 (1761x1174, PGM), a synthetic 2 MP harp (PNG) and a
synthetic 24 MP harp (6000x4000 PNG; strings 8 px wide, 200 px apart, 80 degrees,
barrel distortion of ~20 px at the corners, noise 1.5). ``--profile`` prints the top
functions of one 24 MP ``measure_image``. Target (issue 8): the whole process on the 24 MP
PNG <= 1.5 s on the 2-core machine.
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from benchmarks.startup import bytecode_environment  # noqa: E402
from pipeline.edges import detect_edges  # noqa: E402
from pipeline.grouping import group_string_edges  # noqa: E402
from pipeline.measure import border_px, measure_grouping, measure_image  # noqa: E402
from pipeline.models.radial import RadialModel  # noqa: E402
from pipeline.render import HarpScene, render_harp  # noqa: E402
from station.imageio import read_grey  # noqa: E402

REAL = ROOT.parent / "shared" / "data" / "real-harp" / "IMG_6931.pgm"
HARP = [sys.executable, "-m", "station.cli"]


def _median_time(fn, repeat):
    ts = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        ts.append(time.perf_counter() - t0)
    return float(np.median(ts))


def whole_process(path: Path, repeat: int, pycache: Path | None) -> tuple[float, float, float]:
    """Median wall, user and system seconds of ``harp measure --json path`` as a process; with
    ``pycache`` the bytecode cache lives there, else none is written (``PYTHONDONTWRITEBYTECODE``)."""
    env = bytecode_environment(pycache)
    walls, users, syss = [], [], []
    for _ in range(repeat + 1):  # the first run warms the file (and bytecode) cache, not counted
        t0 = time.perf_counter()
        proc = subprocess.Popen([*HARP, "measure", "--json", str(path)], stdout=subprocess.DEVNULL, cwd=ROOT, env=env)
        _, status, usage = os.wait4(proc.pid, 0)  # this child's own CPU time
        walls.append(time.perf_counter() - t0)
        proc.returncode = os.waitstatus_to_exitcode(status)
        if proc.returncode != 0:
            raise SystemExit(f"harp measure {path} exited with {proc.returncode}")
        users.append(usage.ru_utime)
        syss.append(usage.ru_stime)
    med = [float(np.median(v[1:])) for v in (walls, users, syss)]
    return med[0], med[1], med[2]


def unneeded_imports(path: Path) -> str:
    code = (
        "import sys, io, contextlib\n"
        "from station.cli import main\n"
        "with contextlib.redirect_stdout(io.StringIO()): main(['measure', '--json', sys.argv[1]])\n"
        "print(' '.join(sorted(m for m in sys.modules if m == 'scipy' or m.startswith('scipy.'))[:6]) or 'none')\n"
    )
    out = subprocess.run([sys.executable, "-c", code, str(path)], check=True, capture_output=True, text=True, cwd=ROOT)
    return out.stdout.strip().splitlines()[-1]


def bench(name, path, repeat, pycache):
    img = read_grey(path)
    h, w = img.shape
    stage = {}
    stage["decode"] = _median_time(lambda: read_grey(path), repeat)
    stage["edges"] = _median_time(lambda: detect_edges(img), repeat)
    chains = detect_edges(img)
    b = border_px()
    stage["group"] = _median_time(lambda: group_string_edges(chains, img.shape, border_px=b), repeat)
    g = group_string_edges(chains, img.shape, border_px=b)
    stage["per-edge"] = _median_time(lambda: measure_grouping(g, w, h, border=b), repeat)
    total = _median_time(lambda: measure_image(img), repeat)
    canny = _median_time(
        lambda: cv2.Canny(img if img.dtype == np.uint8 else (img >> 8).astype(np.uint8), 20, 40), repeat
    )
    proc_wall, proc_user, proc_sys = whole_process(path, repeat, pycache)
    raw_wall, raw_user, raw_sys = whole_process(path, repeat, None)
    m = measure_image(img)
    return (
        f"| {name} | {w}x{h} ({w * h / 1e6:.1f} MP) | {m.n_lines} | {proc_wall:.2f} | "
        f"{proc_user + proc_sys:.2f} ({proc_user:.2f} + {proc_sys:.2f}) | {raw_wall:.2f} | "
        f"{raw_user + raw_sys:.2f} | "
        f"{stage['decode']:.2f} | {total:.2f} | {stage['edges']:.2f} | {stage['group']:.2f} | "
        f"{stage['per-edge']:.2f} | {canny:.3f} | {unneeded_imports(path)} |"
    )


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--no-24mp", action="store_true")
    ap.add_argument("--profile", action="store_true")
    args = ap.parse_args(argv)

    cases = []
    if REAL.is_file():
        cases.append(("real photo IMG_6931 (PGM)", REAL))
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
        p = tmp / f"synthetic_{w}x{h}.png"
        cv2.imwrite(str(p), r.image)
        cases.append((f"synthetic {w * h / 1e6:.0f} MP (PNG)", p))

    print(
        f"harp measure speed, {os.cpu_count()} cores (load average {os.getloadavg()[0]:.1f} when started), "
        f"median of {args.repeat} runs, wall seconds unless said"
    )
    print()
    print(
        "| image | size | edges found | `harp measure` whole process | its CPU s (user + sys) | "
        "same, no bytecode cache | its CPU s | decode | measure_image | "
        "- sub-pixel edges | - grouping | - per-edge smoothing+straightness | cv2.Canny | scipy modules imported |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    try:
        for name, path in cases:
            print(bench(name, path, args.repeat, tmp / "pycache"), flush=True)
        if args.profile and not args.no_24mp:
            import cProfile
            import pstats

            img = read_grey(cases[-1][1])
            pr = cProfile.Profile()
            pr.enable()
            measure_image(img)
            pr.disable()
            print()
            print("profile of one 24 MP measure_image (top 15 by own time):")
            pstats.Stats(pr, stream=sys.stdout).sort_stats("tottime").print_stats(15)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    print()
    print(f"load average at end: {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
