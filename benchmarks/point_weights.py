"""Per-point weights from the along-edge smoother's variance: do they help on held-out data? (issue 19 item 2)

Usage::

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/point_weights.py [--real DIR] [--skip-real]
        [--seeds 20] [--first-seed 0] [--workers 2] [--size 1000x750] [--points]

Three fits of the same data, only the least-squares weights differing (the figures, d, are the
paper's unweighted ones in every case):

* ``unweighted``: every smoothed point weighs the same (the fit as it is);
* ``smoother x edge noise``: residual ``i`` weighted by ``1 / sigma_i``, ``sigma_i`` the smoother's
  variance factor at the point (the squared norm of its hat-matrix row, large at the ends of a piece)
  times the edge's noise, estimated robustly from the raw points' scatter about the smooth
  (``pipeline.measure.point_sigmas``);
* ``smoother x local noise``: the same with the noise measured along the edge (its growth towards
  the ends and corners, ``local=True``).
* ``smoother + misfit floor``: the edge-noise sigma with, in quadrature, what the unweighted fit's
  residual RMS of the edge leaves unexplained by it (the string's shape, the shot's own systematic
  error: the real residuals are ten times the smoother's noise), so that the end points are
  down-weighted only as much as their extra noise matters against the misfit.
* ``smoother, within edges``: the local-noise sigma scaled per edge so that its points' weights
  average 1: only the shape along each edge (its noisy ends down-weighted), no edge weighing more
  or less than in the plain fit (the other weightings also rank whole edges by their noise: the
  blurred corners' edges lose weight).

Three parts:

* **The real photographs** (``../shared/data/real-harp`` or ``$HARP_REAL_DATA``), every 2+1 split:
  fitted on two shots, held-out d of the third, whole strings (``harp measure``'s points) and
  interior only (``smoothing="gaussian"``: 72 px dropped at both ends of every piece), for the
  radial candidates that win or nearly win on these photographs.
* **The realistic simulated population** (the set-up of ``benchmarks/strings_separated.py``): per seed
  a lens of ``pipeline.lens_population``, a harp, mount and camera effects of
  ``pipeline.realism.realistic_session``, shots at turntable angles 0..150 degrees and three unseen
  ones at 17, 77 and 137 degrees, measured as ``harp measure`` does; radial4+tangential+prism fitted
  on the six shots, and on three of them (0, 60, 120); field RMS against the exact lens (modulo a
  homography, ``compare_models``) and the unseen shots' d (whole strings).
* ``--points`` (instead of the rendered population): ``benchmarks/model_choice.py``'s point-set
  population (raw points every pixel with 0.06 px noise, strings bent, every shot moved by a smooth
  field of its own), three shots fitted, three unseen; unweighted against smoother x edge noise.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))  # model_choice's point-set population, real_photos

from real_photos import Measured, real_measurements

from pipeline.compare import compare_models
from pipeline.edgeset import FitResult, corrected_straightness
from pipeline.fit import fit_distortion
from pipeline.fitspec import FitSpec, parse
from pipeline.measure import measure_image, point_sigmas

REAL = Path(os.environ.get("HARP_REAL_DATA", Path(__file__).resolve().parents[2] / "shared" / "data" / "real-harp"))
VARIANTS = (
    "unweighted",
    "smoother x edge noise",
    "smoother x local noise",
    "smoother + misfit floor",
    "smoother, within edges",
)
POINT_VARIANTS = ("unweighted", "smoother x edge noise", "smoother + misfit floor", "smoother, within edges")
REAL_CANDIDATES = (
    "radial4+tangential",
    "radial4+tangential+prism",
    "radial6+tangential+prism",
    "radial4+tangential+prism+centre-prior",
)
FITTED = (0.0, 30.0, 60.0, 90.0, 120.0, 150.0)
FEW = (0, 2, 4)  # three of the six: 0, 60, 120 degrees
UNSEEN = (17.0, 77.0, 137.0)
SPEC = FitSpec("radial", 4, True, True)


def sigmas_of(m, variant: str):  # type: ignore[no-untyped-def]
    if variant == "unweighted":
        return None
    return point_sigmas(m, local=variant == "smoother x local noise")


def within_edges(sig: list[list[np.ndarray]]) -> list[list[np.ndarray]]:
    """Each edge's sigmas scaled so that its points' weights average 1: the smoother's end effect
    (and the noise's growth along the edge) alone, every edge weighing as much as in the plain fit."""
    return [[s * np.sqrt(np.mean(1.0 / s**2)) for s in shot] for shot in sig]


def misfit_floor(sig: list[list[np.ndarray]], plain: FitResult) -> list[list[np.ndarray]]:
    """Each point's sigma with its edge's misfit added in quadrature: ``sqrt(sigma^2 + s_e^2)``,
    ``s_e^2 = max(0, rms_e^2 - mean sigma^2)`` from the unweighted fit's residual RMS of the edge (what
    the smoother's noise does not explain: the string's shape, the shot's own systematic error)."""
    rms = {(e.image, e.line): e.rms_after for e in plain.edges}
    out = []
    for i, shot in enumerate(sig):
        row = []
        for j, s in enumerate(shot):
            floor2 = max(0.0, rms.get((i, j), 0.0) ** 2 - float(np.mean(s**2)))
            row.append(np.sqrt(s**2 + floor2))
        out.append(row)
    return out


def fit_variant(lines, ms, v, w, h, spec, plain=None):  # type: ignore[no-untyped-def]
    """The fit of ``lines`` (the measurements ``ms``) with the weights of variant ``v``."""
    if v == "unweighted":
        return fit_distortion(lines, w, h, **spec.fit_arguments())
    if v == "smoother + misfit floor":
        if not plain:
            return plain
        sig = misfit_floor([point_sigmas(m) for m in ms], plain)
    elif v == "smoother, within edges":
        sig = within_edges([point_sigmas(m, local=True) for m in ms])
    else:
        sig = [sigmas_of(m, v) for m in ms]
    return fit_distortion(lines, w, h, **spec.fit_arguments(), point_sigma=sig)


# ------------------------------------------------------------------------ real photographs
FitVariant = Callable[..., Any]
"""``fit(lines, measurements, variant, width, height, spec, plain)``: the fit of ``lines`` (the ``measurements``
they come from, ``pipeline.measure``'s) by ``variant``; ``plain`` the base variant's fit of the same lines."""


def real_splits(
    measured: Measured,
    variants: Sequence[str],
    fit: FitVariant,
    candidates: Sequence[str],
    word: str,
    base: str,
) -> dict[str, list[tuple[float, float]]]:
    """Every 2+1 split of the photographs: each candidate fitted on two by each variant (``fit``), the
    held-out d of the third (whole strings and interior only), a row each and a summary against ``base``;
    ``word`` names the variants' column."""
    folder, names, whole, interior, (w, h) = measured
    print(f"## Real photographs ({folder}: {', '.join(names)}), {w}x{h}, every 2+1 split")
    print()
    print(f"| held out | candidate | {word} | fit d px | held-out d, whole px | held-out d, interior px |")
    print("|---|---|---|---:|---:|---:|")
    out: dict[str, list[tuple[float, float]]] = {v: [] for v in variants}
    for held in names:
        fit_on = [n for n in names if n != held]
        lines = [[ln.points for ln in whole[n].lines] for n in fit_on]
        for label in candidates:
            spec = parse(label)
            plain = None
            for v in variants:
                f = fit(lines, [whole[n] for n in fit_on], v, w, h, spec, plain)
                plain = f if v == base else plain
                if not f:
                    print(f"| {held} | {label} | {v} | failed: {f.reason} | | |")
                    out[v].append((float("nan"), float("nan")))
                    continue
                hw = corrected_straightness(f.model, [ln.points for ln in whole[held].lines])[0]
                hi = corrected_straightness(f.model, interior[held])[0]
                out[v].append((hw, hi))
                print(f"| {held} | {label} | {v} | {f.d_after:.4f} | {hw:.4f} | {hi:.4f} |", flush=True)
    print()
    ref = np.array(out[base])
    print(f"| {word} | held-out d whole, mean px | interior, mean px | whole / {base} (mean, worst, better in) |")
    print("|---|---:|---:|---|")
    for v in variants:
        a = np.array(out[v])
        rw = a[:, 0] / ref[:, 0]
        print(
            f"| {v} | {np.nanmean(a[:, 0]):.4f} | {np.nanmean(a[:, 1]):.4f} | {np.nanmean(rw):.3f}, "
            f"{np.nanmax(rw):.3f}, {int(np.sum(rw < 1))} / {len(rw)} |"
        )
    print()
    return out


def real_part(directory: Path) -> dict[str, list[tuple[float, float]]]:
    measured = real_measurements(directory)
    if measured is None:
        return {}
    return real_splits(measured, VARIANTS, fit_variant, REAL_CANDIDATES, "weights", "unweighted")


def variant_columns(variants: Sequence[str]) -> str:
    """The header cells of a population table: each variant's field RMS, then each one's unseen d."""
    return " | ".join([*(f"field, {v}" for v in variants), *(f"unseen d, {v}" for v in variants)])


def variant_cells(vals: Sequence[Any]) -> str:
    """A population row's cells from each variant's (field RMS, unseen d), as :func:`variant_columns` orders them."""
    return " | ".join([*(f"{x[0]:.4f}" for x in vals), *(f"{x[1]:.4f}" for x in vals)])


# ------------------------------------------------------------------------ realistic population
def one(seed: int, w: int, h: int) -> dict[str, object]:
    from pipeline.lens_population import lens_population
    from pipeline.realism import realistic_session, render_shots

    member = lens_population(seed, 1, w, h)[0]
    lens = member.model
    ses = realistic_session(seed, w, h)
    shots = render_shots(lens, ses.harp, ses.mount, FITTED + UNSEEN, w, h, ses.effects, seed=seed)
    ms = [measure_image(s.image) for s in shots]
    fitted, unseen = ms[: len(FITTED)], [ln.points for m in ms[len(FITTED) :] for ln in m.lines]
    row: dict[str, object] = {"seed": seed, "kind": member.design}
    for n_label, idx in (("6", tuple(range(len(FITTED)))), ("3", FEW)):
        plain = None
        for v in VARIANTS:
            sub = [fitted[i] for i in idx]
            f = fit_variant([[ln.points for ln in m.lines] for m in sub], sub, v, w, h, SPEC, plain)
            plain = f if v == "unweighted" else plain
            if not f:
                row[(n_label, v)] = (float("nan"), float("nan"))
                continue
            row[(n_label, v)] = (
                compare_models(f.model, lens, w, h, step=20).rms,
                corrected_straightness(f.model, unseen)[0],
            )
    return row


def population_part(seeds: range, w: int, h: int, workers: int) -> None:
    print(
        f"## Realistic population, {w}x{h}, seeds {seeds.start}..{seeds.stop - 1}: radial4+tangential+prism, "
        "field RMS vs the exact lens / d of 3 unseen shots (px)"
    )
    print()
    print(f"| seed | lens | shots | {variant_columns(VARIANTS)} |")
    print("|---:|---|---:|" + "---:|" * (2 * len(VARIANTS)))
    with ProcessPoolExecutor(max_workers=workers) as ex:
        rows = list(ex.map(one, seeds, [w] * len(seeds), [h] * len(seeds)))
    for n_label in ("6", "3"):
        for r in rows:
            print(f"| {r['seed']} | {r['kind']} | {n_label} | {variant_cells([r[(n_label, v)] for v in VARIANTS])} |")
    print()
    summary({n: [{v: r[(n, v)] for v in VARIANTS} for r in rows] for n in ("6", "3")}, VARIANTS, lambda r, v: r[v])


# ------------------------------------------------------------------------ point-set population
def one_points(seed: int, variants: Sequence[str], fit: FitVariant, base: str) -> dict[str, object]:
    """Lens ``seed`` of the point-set population, three shots fitted by each variant (``fit``, given the point
    sets' own smoother sigmas as the measurements), its field RMS and the d of three unseen shots."""
    from model_choice import H_PT, W_PT, point_session

    sg: list[list[np.ndarray]] = []
    lens, fs, ts = point_session(seed, 3, sg)
    unseen = [p for shot in ts for p in shot]
    row: dict[str, object] = {"seed": seed}
    plain = None
    for v in variants:
        f = fit(fs, sg, v, W_PT, H_PT, SPEC, plain)
        plain = f if v == base else plain
        row[v] = (
            (compare_models(f.model, lens, W_PT, H_PT, step=20).rms, corrected_straightness(f.model, unseen)[0])
            if f
            else (float("nan"), float("nan"))
        )
    return row


def point_rows(
    seeds: range, workers: int, variants: Sequence[str], fit: FitVariant, base: str
) -> list[dict[str, object]]:
    """:func:`one_points` of every seed (``workers`` processes), a row each."""
    print(
        f"## Point-set population (benchmarks/model_choice.py's), seeds {seeds.start}..{seeds.stop - 1}: 3 shots "
        "fitted, radial4+tangential+prism; field RMS vs the exact lens / d of 3 unseen shots (px)"
    )
    print()
    print(f"| seed | {variant_columns(variants)} |")
    print("|---:|" + "---:|" * (2 * len(variants)))
    with ProcessPoolExecutor(max_workers=workers) as ex:
        rows = list(ex.map(partial(one_points, variants=variants, fit=fit, base=base), seeds))
    for r in rows:
        print(f"| {r['seed']} | {variant_cells([r[v] for v in variants])} |")
    print()
    return rows


def fit_points(fs, sg, v, w, h, spec, plain):  # type: ignore[no-untyped-def]
    """The point sets ``fs`` fitted with the weights of variant ``v`` (``sg``: their smoother sigmas)."""
    if v == "unweighted":
        return fit_distortion(fs, w, h, **spec.fit_arguments())
    sig = misfit_floor(sg, plain) if v == "smoother + misfit floor" and plain else sg
    sig = within_edges(sg) if v == "smoother, within edges" else sig
    return fit_distortion(fs, w, h, **spec.fit_arguments(), point_sigma=sig)


def points_part(seeds: range, workers: int) -> None:
    rows = point_rows(seeds, workers, POINT_VARIANTS, fit_points, "unweighted")
    summary({"3": rows}, POINT_VARIANTS, lambda r, v: r[v])


def summary(groups, variants, get):  # type: ignore[no-untyped-def]
    """Per group of rows (label: the shots fitted) and variant: the field RMS (median, RMS over the
    lenses, ratio to unweighted) and the unseen shots' d."""
    print(
        "| shots | weights | field RMS median px | RMS over lenses px | ratio to unweighted: median, worst, "
        "lower in | unseen d median px | unseen ratio median, worst |"
    )
    print("|---:|---|---:|---:|---|---:|---|")
    for label, rows in groups.items():
        base = np.array([get(r, "unweighted") for r in rows])
        for v in variants:
            print(f"| {label} | {v} | {ratio_cells(np.array([get(r, v) for r in rows]), base)} |")
    print()


def ratio_cells(a: np.ndarray, base: np.ndarray) -> str:
    """A variant's summary cells over the lenses from its (field RMS, unseen d) rows ``a`` and the base
    variant's ``base``: field median, RMS over the lenses, ratio to the base (median, worst, lower in),
    unseen d median, its ratio (median, worst)."""
    rf, ru = a[:, 0] / base[:, 0], a[:, 1] / base[:, 1]
    return (
        f"{np.nanmedian(a[:, 0]):.4f} | {np.sqrt(np.nanmean(a[:, 0] ** 2)):.4f} | "
        f"{np.nanmedian(rf):.3f}, {np.nanmax(rf):.3f}, {int(np.sum(rf < 1))} / {len(rf)} | "
        f"{np.nanmedian(a[:, 1]):.4f} | {np.nanmedian(ru):.3f}, {np.nanmax(ru):.3f}"
    )


def harness_arguments(description: str) -> argparse.ArgumentParser:
    """The harness's command line: the photographs (``--real``, ``--skip-real``) and the population's seeds
    and workers."""
    ap = argparse.ArgumentParser(description=description)
    ap.add_argument("--real", type=Path, default=REAL)
    ap.add_argument("--skip-real", action="store_true")
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--first-seed", type=int, default=0)
    ap.add_argument("--workers", type=int, default=2)
    return ap


def main(argv: list[str] | None = None) -> int:
    ap = harness_arguments(__doc__.splitlines()[0])
    ap.add_argument("--size", default="1000x750")
    ap.add_argument("--points", action="store_true", help="the point-set population instead of the rendered one")
    args = ap.parse_args(argv)
    w, h = (int(v) for v in args.size.split("x"))
    print(
        f"# Per-point weights from the smoother's variance ({os.cpu_count()} CPUs, load {os.getloadavg()[0]:.1f}; "
        f"`benchmarks/point_weights.py {' '.join(argv if argv is not None else sys.argv[1:])}`)"
    )
    print()
    t0 = time.perf_counter()
    if not args.skip_real:
        real_part(args.real)
    if args.seeds > 0 and args.points:
        points_part(range(args.first_seed, args.first_seed + args.seeds), args.workers)
    elif args.seeds > 0:
        population_part(range(args.first_seed, args.first_seed + args.seeds), w, h, args.workers)
    print(f"({time.perf_counter() - t0:.0f} s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
