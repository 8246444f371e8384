"""Precision and speed of the sub-pixel edge detector (pipeline/edges.py).

Usage::

    .venv/bin/python benchmarks/edge_precision.py [--seeds 4] [--no-24mp]

Part 1: straight anti-aliased step edges (8-bit, background 200 / dark 30,
Gaussian optical blur 0.7 px, pixel integration 4x4) through the centre of a
240x240 image, direction 0..90 degrees, additive Gaussian noise 0..3 grey
levels ("float": no noise and no 8-bit quantisation), a random sub-pixel
position per seed. Signed distances of the detected points to the TRUE line
(points > 6 px from the border), pooled over the seeds: mean bias, the largest
|bias| of a single edge, raw RMS, and RMS after t=30 smoothing of the chain
trimmed to the measurement's 4 px border: the paper's plain Gaussian (valid
part only, ``smoothing="gaussian"``; number of smoothed points), and the
default local-quadratic regression over the whole piece, inside points and
the first and last smoothed points separately (their noise is larger, see
:mod:`pipeline.resample`); the same raw figures for the classic Devernay
parabola (``interpolation="parabola"``) for comparison.

Part 2: error of the three sub-pixel models against the optical blur
(Gaussian PSF std), noise-free float images, for an isolated step edge and for
the edges of a 3 px wide dark string (whose constant outward shift is
removed). What remains at small blur is the aliasing of the input image.

Part 3: d of the two edges of one straight 3 px / 8 px dark string, 8-bit,
noise 1.5, nearly aligned with the pixel grid (where pixel locking of the
sub-pixel model is not averaged out by the t=30 smoothing).

Part 4: wall and CPU time (all threads) of ``detect_edges`` (best of 5 runs)
on synthetic images of dark straight strings (3 px wide, 3 degrees tilt, noise
1.5) at 2 MP and 24 MP, on the real photo IMG_6931 (1761x1174) and on that photo tiled 4x4 to
6000x4000, next to one ``cv2.Canny`` pass on the same image.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import cv2
import numpy as np
from scipy.special import ndtr

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from pipeline.edges import detect_edges
from pipeline.resample import smooth_subsample
from tests.pipeline.synthetic_edges import line_normal, quantise, render_step, render_string

_DEFAULT_REAL = Path(__file__).resolve().parents[2] / "shared" / "data" / "real-harp"
REAL_HARP = Path(os.environ.get("HARP_REAL_DATA", _DEFAULT_REAL))
ANGLES = [0, 15, 30, 45, 60, 75, 90]
NOISES = [None, 0.0, 0.5, 1.5, 3.0]  # None: float image, no noise, no quantisation
N = 240
MARGIN = 6
BORDER = 4.0  # the measurement's border (pipeline.measure.border_px)


def precision_row(angle, noise, seeds):
    """Pooled statistics over ``seeds`` edges (random sub-pixel positions)."""
    raw, raw_par, smooth, lq_in, lq_first, lq_last = [], [], [], [], [], []
    for seed in range(seeds):
        rng = np.random.default_rng(seed * 7919 + angle * 31 + int((noise or 0) * 10))
        p = (N / 2 + rng.uniform(-0.5, 0.5), N / 2 + rng.uniform(-0.5, 0.5))
        img = render_step((N, N), angle, p)
        img = img if noise is None else quantise(img, noise, rng)
        nrm = line_normal(angle)
        for interp, out in (("continuous", raw), ("parabola", raw_par)):
            chains = detect_edges(img, interpolation=interp)
            xy = chains[0].xy
            inside = np.all((xy > MARGIN) & (xy < N - 1 - MARGIN), axis=1)
            out.append((xy[inside] - p) @ nrm)
            if interp == "continuous":
                kept = xy[np.all((xy >= BORDER) & (xy <= N - 1 - BORDER), axis=1)]
                smooth.append((smooth_subsample(kept, t=30, method="gaussian") - p) @ nrm)
                d = (smooth_subsample(kept, t=30) - p) @ nrm
                lq_in.append(d[1:-1])
                lq_first.append(d[:1])
                lq_last.append(d[-1:])
    rms = lambda v: float(np.sqrt(np.mean(np.concatenate(v) ** 2)))  # noqa: E731
    maxbias = lambda v: float(max(abs(x.mean()) for x in v))  # noqa: E731
    return (
        float(np.concatenate(raw).mean()),
        maxbias(raw),
        rms(raw),
        rms(smooth),
        sum(x.size for x in smooth),
        rms(lq_in),
        rms(lq_first),
        rms(lq_last),
        maxbias(raw_par),
        rms(raw_par),
    )


MODELS = ("continuous", "gaussian", "parabola")


def blur_row(blur, width=None):
    """Noise-free float images: largest |error| of one point against the true edge, per
    sub-pixel model, over 10 sub-pixel positions x directions 0, 5, 10, 30, 45 deg off the
    y axis. ``width``: the two edges of a dark string of that width instead of a step edge;
    their outward shift (the same along a straight string, slightly orientation dependent)
    is removed: error = |distance| - its median over the 10 positions at that direction."""
    out = []
    for interp in MODELS:
        worst = 0.0
        for ang in (0, 5, 10, 30, 45):
            ds = []
            for off in np.linspace(0.0, 0.9, 10):
                a = 90 + ang
                p = (24.0 + off, 24.0)
                if width is None:
                    img = render_step((48, 48), a, p, blur=blur, ss=8)
                else:
                    img = render_string((48, 48), a, p, width, blur=blur, ss=8)
                for c in detect_edges(img, interpolation=interp):
                    inside = np.all((c.xy > MARGIN) & (c.xy < 47 - MARGIN), axis=1)
                    d = (c.xy[inside] - p) @ line_normal(a)
                    ds.append(d if width is None else np.abs(d))
            d = np.concatenate(ds)
            if width is not None:
                d = d - np.median(d)
            worst = max(worst, float(np.abs(d).max()))
        out.append(worst)
    return out


def string_straightness(width, angle, interp, seeds=2, shape=(160, 900), method="local-quadratic"):
    """d (RMS distance of the t=30 smoothed points to their own TLS line) for the two edges
    of one straight dark string, 8-bit, noise 1.5, pooled over seeds."""
    h, w = shape
    ds = []
    for seed in range(seeds):
        rng = np.random.default_rng(seed)
        p = (w / 2 + rng.uniform(-0.5, 0.5), h / 2 + rng.uniform(-0.5, 0.5))
        img = quantise(render_string(shape, angle, p, width), 1.5, rng)
        chains = [c for c in detect_edges(img, interpolation=interp) if len(c) > 0.5 * w]
        assert len(chains) == 2, len(chains)
        for c in chains:
            xy = c.xy[np.all((c.xy >= BORDER) & (c.xy <= np.array([w, h]) - 1 - BORDER), axis=1)]
            sm = smooth_subsample(xy, t=30, method=method)
            centred = sm - sm.mean(axis=0)
            normal = np.linalg.svd(centred)[2][1]
            ds.append(centred @ normal)
    return float(np.sqrt(np.mean(np.concatenate(ds) ** 2)))


def strings_image(h, w, n_strings=14, width=3.0, angle_deg=3.0, noise=1.5, seed=0):
    rng = np.random.default_rng(seed)
    a = np.deg2rad(angle_deg)
    xs = np.arange(w, dtype=np.float32)[None, :]
    ys = np.arange(h, dtype=np.float32)[:, None]
    d = xs * np.float32(np.cos(a)) + ys * np.float32(np.sin(a))
    img = np.full((h, w), 200.0, np.float32)
    for k in range(n_strings):
        c = (k + 0.5) * w / n_strings
        img -= (170.0 * (ndtr((d - c + width / 2) / 0.7) - ndtr((d - c - width / 2) / 0.7))).astype(np.float32)
    img += rng.normal(0.0, noise, (h, w)).astype(np.float32)
    return np.clip(np.round(img), 0, 255).astype(np.uint8)


def timed(fn, reps=5):
    """Best wall time and best process CPU time (all threads) of ``reps`` runs of ``fn()``
    (the minimum is the least sensitive to other jobs on the machine)."""
    ts, cs = [], []
    out = None
    for _ in range(reps):
        c0 = time.process_time()
        t0 = time.perf_counter()
        out = fn()
        ts.append(time.perf_counter() - t0)
        cs.append(time.process_time() - c0)
    return float(np.min(ts)), float(np.min(cs)), out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=4)
    ap.add_argument("--no-24mp", action="store_true")
    args = ap.parse_args(argv)

    print(
        f"# Edge precision: {N}x{N} 8-bit step edge 200/30, blur 0.7 px, sigma=1, "
        f"{args.seeds} seeds per cell; distances to the true line in px"
    )
    print()
    print(
        "| angle | noise | mean bias | max abs bias | raw RMS | Gaussian t=30 RMS (pts) | local-quadratic inside RMS "
        "| first point RMS | last point RMS | parabola max abs bias | parabola RMS |"
    )
    print("|------:|------:|----------:|-------------:|--------:|------:|------:|------:|------:|------:|------:|")
    for noise in NOISES:
        for angle in ANGLES:
            b, mb, r, s, ns, li, lf, ll, mbp, rp = precision_row(angle, noise, args.seeds)
            nz = "float" if noise is None else f"{noise:5.1f}"
            print(
                f"| {angle:5d} | {nz:>5s} | {b:+9.4f} | {mb:12.4f} | {r:7.4f} "
                f"| {s:8.4f} ({ns:3d}) | {li:.4f} | {lf:.4f} | {ll:.4f} | {mbp:21.4f} | {rp:12.4f} |"
            )
    print()
    print("# Sub-pixel model error vs optical blur (noise-free float images, sigma=1): max |error| px")
    print()
    print("| edge | blur px | continuous (default) | gaussian (log-parabola) | parabola |")
    print("|:-----|--------:|---------------------:|------------------------:|---------:|")
    for width in (None, 3.0):
        for blur in (0.3, 0.5, 0.7, 1.0, 1.5):
            e = blur_row(blur, width)
            name = "step" if width is None else f"{width:g} px string"
            print(f"| {name} | {blur:7.1f} | {e[0]:20.4f} | {e[1]:23.4f} | {e[2]:8.4f} |")
    print()
    print(
        "# Straight dark string (8-bit 200/30, blur 0.7, noise 1.5, 900 px long), "
        "d = RMS distance of the t=30 points (local quadratic, whole piece, unless said) to their own line, px"
    )
    print()
    print(
        "| width px | angle deg | continuous (default) | gaussian (log-parabola) | parabola "
        "| continuous, paper's plain Gaussian smoothing |"
    )
    print("|---------:|----------:|---------------------:|------------------------:|---------:|------:|")
    for width in (3.0, 8.0):
        for angle in (0.0, 0.3, 1.0, 5.0):
            e = [string_straightness(width, angle, m) for m in MODELS]
            g = string_straightness(width, angle, "continuous", method="gaussian")
            print(f"| {width:8.0f} | {angle:9.1f} | {e[0]:20.4f} | {e[1]:23.4f} | {e[2]:8.4f} | {g:.4f} |")
    print()
    print(
        f"# Detector speed ({os.cpu_count()} CPUs, cv2 threads {cv2.getNumThreads()}, "
        f"load average {os.getloadavg()[0]:.1f} at start), best of 5 runs. Synthetic: "
        "14 dark strings 3 px wide, noise 1.5. Tiled photo: real noise and dust, 4x the "
        "strings of a real 24 MP harp photo (pessimistic)"
    )
    print()
    print("| image | MP | detect_edges wall s | detect_edges CPU s | chains | points | cv2.Canny wall s |")
    print("|------:|---:|--------------------:|-------------------:|-------:|-------:|-----------------:|")
    sizes = [(1200, 1700)] + ([] if args.no_24mp else [(4000, 6000)])
    images = [(f"synthetic {w}x{h}", strings_image(h, w)) for h, w in sizes]
    real = REAL_HARP / "IMG_6931.pgm"
    if real.is_file():
        photo = cv2.imread(str(real), cv2.IMREAD_UNCHANGED)
        images.append(("IMG_6931 (real)", photo))
        if not args.no_24mp:
            tiled = np.ascontiguousarray(np.tile(photo, (4, 4))[:4000, :6000])
            images.append(("IMG_6931 tiled 4x4 -> 6000x4000", tiled))
    for name, img in images:
        h, w = img.shape
        t_det, c_det, chains = timed(lambda: detect_edges(img))
        t_canny, _, _ = timed(lambda: cv2.Canny(img, 20, 40))
        npts = sum(len(c) for c in chains)
        print(
            f"| {name} | {h * w / 1e6:4.1f} | {t_det:19.3f} | {c_det:18.3f} | {len(chains):6d} "
            f"| {npts:6d} | {t_canny:16.3f} |"
        )
    print()
    print(f"load average at end: {os.getloadavg()[0]:.1f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
