"""The per-point robust fit (``fit_distortion(point_loss=...)``) where there are no kinks to remove: does it
hurt? (issue 19 item 5)

Usage::

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/point_robust.py [--real DIR] [--skip-real]
        [--seeds 20] [--first-seed 0] [--workers 2]

Three fits of the same data, differing only in the per-point stage (``pipeline.robust_points``): none
(the fit as it is: edge-level Huber weights and outlier rejection), Tukey's biweight, Huber's weight.

* **The real photographs** (``../shared/data/real-harp`` or ``$HARP_REAL_DATA``), every 2+1 split, as
  ``benchmarks/point_weights.py``: fitted on two shots, held-out d of the third, whole strings
  (``harp measure``'s points) and interior only (``smoothing="gaussian"``), for the radial candidates
  that win or nearly win on these photographs.
* **The point-set population** of ``benchmarks/model_choice.py`` (raw points every pixel with 0.06 px
  noise, strings bent, every shot moved by a smooth field of its own; no kinks): three shots fitted by
  radial4+tangential+prism, three unseen; field RMS against the exact lens (modulo a homography,
  ``compare_models``) and the unseen shots' d.

The kinked lenses themselves are ``benchmarks/lens_limits.py --point-robust``.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))  # model_choice's point-set population

from pipeline.compare import compare_models
from pipeline.edgeset import corrected_straightness
from pipeline.fit import fit_distortion
from pipeline.fitspec import FitSpec, parse
from pipeline.measure import measure_image, point_sigmas

REAL = Path(os.environ.get("HARP_REAL_DATA", Path(__file__).resolve().parents[2] / "shared" / "data" / "real-harp"))
LOSSES: tuple[tuple[str, dict[str, object]], ...] = (
    ("none", {}),
    ("tukey", {"point_loss": "tukey"}),
    ("huber", {"point_loss": "huber"}),
    ("tukey, own sigma", {"point_loss": "tukey"}),
    ("huber, own sigma", {"point_loss": "huber"}),
)
"""The fits compared: none, and each loss with each point's scale from its edge's residuals or from its own
standard deviation (``point_scale``: ``pipeline.measure.point_sigmas`` of the measurement, or the point
sets' own smoother sigmas)."""
REAL_CANDIDATES = ("radial4+tangential", "radial4+tangential+prism", "radial4+tangential+prism+centre-prior")
SPEC = FitSpec("radial", 4, True, True)


def real_part(directory: Path) -> None:
    import cv2

    names = sorted(p.name for p in directory.glob("*.pgm"))
    if len(names) < 3:
        print(f"(no real photographs in {directory}: part skipped)")
        return
    whole, interior, sigma = {}, {}, {}
    size = (0, 0)
    for n in names:
        img = cv2.imread(str(directory / n), cv2.IMREAD_UNCHANGED)
        size = (img.shape[1], img.shape[0])
        m = measure_image(img)
        whole[n] = [ln.points for ln in m.lines]
        sigma[n] = point_sigmas(m)
        interior[n] = [ln.points for ln in measure_image(img, smoothing="gaussian").lines]
    w, h = size
    print(f"## Real photographs ({directory.name}: {', '.join(names)}), {w}x{h}, every 2+1 split")
    print()
    print("| held out | candidate | point loss | fit d px | held-out d, whole px | held-out d, interior px |")
    print("|---|---|---|---:|---:|---:|")
    out: dict[str, list[tuple[float, float]]] = {name: [] for name, _ in LOSSES}
    for held in names:
        lines = [whole[n] for n in names if n != held]
        own = [sigma[n] for n in names if n != held]
        for label in REAL_CANDIDATES:
            spec = parse(label)
            for name, kw in LOSSES:
                scale = {"point_scale": own} if name.endswith("own sigma") else {}
                f = fit_distortion(lines, w, h, **kw, **scale, **spec.fit_arguments())  # type: ignore[arg-type]
                if not f:
                    print(f"| {held} | {label} | {name} | failed: {f.reason} | | |")
                    out[name].append((float("nan"), float("nan")))
                    continue
                hw = corrected_straightness(f.model, whole[held])[0]
                hi = corrected_straightness(f.model, interior[held])[0]
                out[name].append((hw, hi))
                print(f"| {held} | {label} | {name} | {f.d_after:.4f} | {hw:.4f} | {hi:.4f} |", flush=True)
    print()
    base = np.array(out["none"])
    print("| point loss | held-out d whole, mean px | interior, mean px | whole / none (mean, worst, better in) |")
    print("|---|---:|---:|---|")
    for name, _ in LOSSES:
        a = np.array(out[name])
        rw = a[:, 0] / base[:, 0]
        print(
            f"| {name} | {np.nanmean(a[:, 0]):.4f} | {np.nanmean(a[:, 1]):.4f} | {np.nanmean(rw):.3f}, "
            f"{np.nanmax(rw):.3f}, {int(np.sum(rw < 1))} / {len(rw)} |"
        )
    print()


def one_points(seed: int) -> dict[str, object]:
    from model_choice import H_PT, W_PT, point_session

    sg: list[list[np.ndarray]] = []
    lens, fs, ts = point_session(seed, 3, sg)
    unseen = [p for shot in ts for p in shot]
    row: dict[str, object] = {"seed": seed}
    for name, kw in LOSSES:
        scale = {"point_scale": sg} if name.endswith("own sigma") else {}
        f = fit_distortion(fs, W_PT, H_PT, **kw, **scale, **SPEC.fit_arguments())  # type: ignore[arg-type]
        row[name] = (
            (compare_models(f.model, lens, W_PT, H_PT, step=20).rms, corrected_straightness(f.model, unseen)[0])
            if f
            else (float("nan"), float("nan"))
        )
    return row


def points_part(seeds: range, workers: int) -> None:
    print(
        f"## Point-set population (benchmarks/model_choice.py's), seeds {seeds.start}..{seeds.stop - 1}: 3 shots "
        "fitted, radial4+tangential+prism; field RMS vs the exact lens / d of 3 unseen shots (px)"
    )
    print()
    print(
        "| seed | "
        + " | ".join(f"field, {n}" for n, _ in LOSSES)
        + " | "
        + " | ".join(f"unseen d, {n}" for n, _ in LOSSES)
        + " |"
    )
    print("|---:|" + "---:|" * (2 * len(LOSSES)))
    with ProcessPoolExecutor(max_workers=workers) as ex:
        rows = list(ex.map(one_points, seeds))
    for r in rows:
        vals: list[tuple[float, float]] = [r[n] for n, _ in LOSSES]  # type: ignore[misc]
        print(
            f"| {r['seed']} | "
            + " | ".join(f"{x[0]:.4f}" for x in vals)
            + " | "
            + " | ".join(f"{x[1]:.4f}" for x in vals)
            + " |"
        )
    print()
    print(
        "| point loss | field median px | RMS over lenses px | field / none: median, worst, lower in | "
        "unseen d median px | unseen / none: median, worst |"
    )
    print("|---|---:|---:|---|---:|---|")
    base = np.array([r["none"] for r in rows])
    for name, _ in LOSSES:
        a = np.array([r[name] for r in rows])
        rf, ru = a[:, 0] / base[:, 0], a[:, 1] / base[:, 1]
        print(
            f"| {name} | {np.nanmedian(a[:, 0]):.4f} | {np.sqrt(np.nanmean(a[:, 0] ** 2)):.4f} | "
            f"{np.nanmedian(rf):.3f}, {np.nanmax(rf):.3f}, {int(np.sum(rf < 1))} / {len(rf)} | "
            f"{np.nanmedian(a[:, 1]):.4f} | {np.nanmedian(ru):.3f}, {np.nanmax(ru):.3f} |"
        )
    print()


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--real", type=Path, default=REAL)
    ap.add_argument("--skip-real", action="store_true")
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--first-seed", type=int, default=0)
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args(argv)
    cmd = " ".join(argv if argv is not None else sys.argv[1:])
    print(
        f"# The per-point robust fit where there are no kinks ({os.cpu_count()} CPUs, load "
        f"{os.getloadavg()[0]:.1f}; `benchmarks/point_robust.py {cmd}`)"
    )
    print()
    t0 = time.perf_counter()
    if not args.skip_real:
        real_part(args.real)
    if args.seeds > 0:
        points_part(range(args.first_seed, args.first_seed + args.seeds), args.workers)
    print(f"({time.perf_counter() - t0:.0f} s; load average at end {os.getloadavg()[0]:.1f})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
