"""The per-point robust fit (``fit_distortion(point_loss=...)``) where there are no kinks to remove: does it
hurt? (issue 19 item 5)

Usage::

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/point_robust.py [--real DIR] [--skip-real]
        [--seeds 20] [--first-seed 0] [--workers 2]

Three fits of the same data, differing only in the per-point stage (``pipeline.robust_points``): none
(the fit as it is: edge-level Huber weights and outlier rejection), Tukey's biweight, Huber's weight.

The harness (splits, population rows) is ``benchmarks/point_weights.py``'s, with the losses as its variants.

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

import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))  # point_weights' harness, model_choice's population

from point_weights import harness_arguments, point_rows, ratio_cells, real_splits
from real_photos import real_measurements

from pipeline.fit import fit_distortion
from pipeline.measure import point_sigmas

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


def fit_loss(lines, measurements, v, w, h, spec, plain=None):  # type: ignore[no-untyped-def]
    """``lines`` fitted with the per-point loss of variant ``v`` (:data:`LOSSES`); the "own sigma" variants take
    each point's standard deviation as the scale: ``pipeline.measure.point_sigmas`` of ``measurements`` (the
    photographs'), or ``measurements`` themselves (the point sets' smoother sigmas)."""
    scale = {}
    if v.endswith("own sigma"):
        scale = {"point_scale": [m if isinstance(m, list) else point_sigmas(m) for m in measurements]}
    return fit_distortion(lines, w, h, **dict(LOSSES)[v], **scale, **spec.fit_arguments())


def real_part(directory: Path) -> None:
    measured = real_measurements(directory)
    if measured is not None:
        real_splits(measured, [n for n, _ in LOSSES], fit_loss, REAL_CANDIDATES, "point loss", "none")


def points_part(seeds: range, workers: int) -> None:
    rows = point_rows(seeds, workers, [n for n, _ in LOSSES], fit_loss, "none")
    print(
        "| point loss | field median px | RMS over lenses px | field / none: median, worst, lower in | "
        "unseen d median px | unseen / none: median, worst |"
    )
    print("|---|---:|---:|---|---:|---|")
    base = np.array([r["none"] for r in rows])
    for name, _ in LOSSES:
        print(f"| {name} | {ratio_cells(np.array([r[name] for r in rows]), base)} |")
    print()


def main(argv: list[str] | None = None) -> int:
    args = harness_arguments(__doc__.splitlines()[0]).parse_args(argv)
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
