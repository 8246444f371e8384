"""Edges along the pixel grid: how much worse they are measured, in the realistic simulator and in the real photos.

Usage::

    .venv/bin/python benchmarks/grid_angle.py [--seeds 0,1] [--angles 0,0.25,0.5,1,2,4,8,22] [--no-real]
        [--lens-seeds 0:90 --cache DIR]

Part 1 (simulator): one realistic shot (``pipeline.realism.realistic_session``, 1000x750, strings 60 px apart and
3 px wide, an identity lens) with the strings at ``angle`` degrees to the pixel rows, for each demosaic of the raw
conversion (``bilinear``, ``ea``: edge-aware, ``half-size``: 2x2 binning). Per seed, demosaic and angle: the median
over the edges ``harp measure`` keeps of each edge's RMS about a quartic in its own frame (the strings' own shapes,
smooth over the edge, taken out), after the along-edge smoother (t = 30). Edges whose sub-pixel phase across the grid
drifts slowly along them carry the detector's and the demosaic's phase error as a wave the smoother does not
remove (:data:`pipeline.harp_shape.SHOT_NOISE_FACTOR`).

Part 2 (the three shared photographs): each photograph's strings' angle to the grid; the raw edge points' (before
the smoother) residual about a degree-8 Legendre fit per edge, regressed on four harmonics of the points' phase
across the grid (``y`` for rows-like edges, ``x`` for columns-like, period 2 px: the Bayer period, whose second
harmonic is the pixel's), per edge polarity: the largest harmonic's amplitude and the share of the residual's
variance it explains, for the edges within 10 degrees of the grid. Then that phase error, estimated on each
photograph's own edges, is taken off their raw points (a self-calibration, as for peak locking in particle image
velocimetry) and the photographs are measured again: radial4+tangential+prism (free centre) fitted on two,
straightness ``d`` of the third, as ``pytest tests/pipeline/test_fit.py -k real`` does, with and without.

Part 3 (``--lens-seeds``, the population of ``benchmarks/lens_limits.py``: six shots 30 degrees apart): the seeds
among those whose strings come within 2 degrees of the grid at some turntable angle; for each, radial4+tangential+prism
fitted as ``fit_distortion`` does, and again with the shots measured more than twice as noisy as the median weighed
by their variance (``pipeline.harp_shape.shot_weights`` on the fit's edge residuals, as the harp check weighs them,
given as ``point_sigma``): field error against the exact lens (modulo homography) and the straightness of the three
unseen shots. The renders are kept in ``--cache`` (``lens_limits.realistic_measured``).
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from pipeline.edges import detect_edges
from pipeline.edgeset import corrected_straightness
from pipeline.fit import fit_distortion
from pipeline.grouping import Grouping, group_string_edges
from pipeline.measure import border_px, measure_grouping, measure_image
from pipeline.models import RadialModel
from pipeline.realism import realistic_session, render_shots
from station.config.check import grid_offset_deg

W, H = 1000, 750
REAL = ("IMG_6931", "IMG_6950", "IMG_6964")
PERIOD, HARMONICS, DEGREE, NEAR_DEG = 2.0, 4, 8, 10.0
REAL_DIR = Path(os.environ.get("HARP_REAL_DATA", Path(__file__).resolve().parents[2] / "shared" / "data" / "real-harp"))


def quartic_rms(p: np.ndarray) -> float:
    """RMS of an edge's points about a quartic in the edge's own frame (px)."""
    d = (p[-1] - p[0]) / np.hypot(*(p[-1] - p[0]))
    s, q = (p - p[0]) @ d, (p - p[0]) @ np.array([-d[1], d[0]])
    x = (s - s.mean()) / (np.ptp(s) / 2)
    return float(np.sqrt(np.mean((q - np.polyval(np.polyfit(x, q, 4), x)) ** 2)))


def simulator(seeds: list[int], angles: list[float]) -> None:
    lens = RadialModel.for_image(W, H, k=(1.0, 0.0, 0.0, 0.0, 0.0))
    print("## Part 1: realistic shots, median edge RMS about a quartic after the smoother (px)\n")
    print("| seed | demosaic | " + " | ".join(f"{a:g} deg" for a in angles) + " |")
    print("|---:|---|" + "---:|" * len(angles))
    for seed in seeds:
        for dm in ("bilinear", "ea", "half-size"):
            row = []
            for a in angles:
                ses = realistic_session(seed, W, H, spacing_px=60.0, string_width_px=3.0, angle0_deg=a, demosaic=dm)
                shot = render_shots(lens, ses.harp, ses.mount, (0.0,), W, H, ses.effects, seed=seed)[0]
                lines = [ln.points for ln in measure_image(shot.image).lines if len(ln.points) >= 12]
                row.append(float(np.median([quartic_rms(p) for p in lines])))
            print(f"| {seed} | {dm} | " + " | ".join(f"{r:.4f}" for r in row) + " |", flush=True)
    print()


def _harmonics(phase: np.ndarray) -> np.ndarray:
    return np.column_stack(
        [f(2 * np.pi * k * phase / PERIOD) for k in range(1, HARMONICS + 1) for f in (np.cos, np.sin)]
    )


def phase_error(grouping: Grouping) -> tuple[Grouping, list[str], float]:
    """The grouping with the phase error, estimated on its own edges within :data:`NEAR_DEG` of the grid, taken off
    their raw points; a line per (orientation, polarity) with the largest harmonic and the variance it explains; and
    the median angle of the edges to the grid (degrees)."""
    rows, angles = [], []
    for i, e in enumerate(grouping.edges):
        p = np.asarray(e.xy, float)
        if len(p) < 50:
            continue
        d = (p[-1] - p[0]) / np.hypot(*(p[-1] - p[0]))
        n = np.array([-d[1], d[0]])
        ang = float(np.degrees(np.arctan2(d[1], d[0])) % 180.0)
        off = grid_offset_deg(ang)
        angles.append(off)
        if off > NEAR_DEG:
            continue
        rowlike = min(ang, 180.0 - ang) < 45.0
        s, q = (p - p[0]) @ d, (p - p[0]) @ n
        x = (s - s.min()) / (np.ptp(s) / 2) - 1
        r = q - np.polynomial.legendre.legval(x, np.polynomial.legendre.legfit(x, q, DEGREE))
        rows.append((i, rowlike, e.polarity, p[:, 1] if rowlike else p[:, 0], r, n))
    edges, text = list(grouping.edges), []
    for rowlike in (True, False):
        for pol in (-1, 1):
            sel = [t for t in rows if t[1] == rowlike and t[2] == pol]
            if len(sel) < 3:
                continue
            ph, r = np.concatenate([t[3] for t in sel]), np.concatenate([t[4] for t in sel])
            c, *_ = np.linalg.lstsq(_harmonics(ph), r, rcond=None)
            share = 1 - np.mean((r - _harmonics(ph) @ c) ** 2) / np.mean(r**2)
            amp = max(np.hypot(c[2 * k], c[2 * k + 1]) for k in range(HARMONICS))
            text.append(
                f"{'rows' if rowlike else 'columns'}, polarity {pol:+d}: {len(sel)} edges, largest harmonic "
                f"{amp:.4f} px, {share:.1%} of the raw residual's variance"
            )
            for i, _, _, phase, _, n in sel:
                xy = np.asarray(edges[i].xy, float) - (_harmonics(phase) @ c)[:, None] * n
                edges[i] = dataclasses.replace(edges[i], xy=xy)
    return dataclasses.replace(grouping, edges=tuple(edges)), text, float(np.median(angles))


def real(directory: Path) -> None:
    import cv2

    print("## Part 2: the shared photographs, phase error of the raw edge points, and held-out d without it\n")
    lines = {}
    for name in REAL:
        img = cv2.imread(str(directory / f"{name}.pgm"), cv2.IMREAD_UNCHANGED)
        h, w = img.shape
        b = border_px(1.0)
        g = group_string_edges(detect_edges(img, sigma=1.0), (h, w), border_px=b)
        fixed, text, median = phase_error(g)
        print(f"- {name}: strings at {median:.2f} deg to the grid (median over edges)" + (":" if text else ""))
        for t in text:
            print(f"  - {t}")
        lines[name] = {k: [ln.points for ln in measure_grouping(x, w, h, border=b).lines] for k, x in (("as measured", g),
                       ("phase error taken off", fixed))}  # fmt: skip
    print()
    print(
        "| held out | fit d, as measured | held-out d, as measured | fit d, phase error off | held-out d, phase error off |"
    )
    print("|---|---:|---:|---:|---:|")
    for held in REAL:
        cells = []
        for k in ("as measured", "phase error taken off"):
            r = fit_distortion([lines[n][k] for n in REAL if n != held], w, h, model="radial", degree=4,
                               tangential=True, prism=True, w_center=0.0)  # fmt: skip
            cells += [f"{r.d_after:.4f}", f"{corrected_straightness(r.model, lines[held][k])[0]:.4f}"]
        print(f"| {held} | " + " | ".join(cells) + " |", flush=True)


def lens_weights(seeds: range, cache: Path | None) -> None:
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from lens_limits import FITTED, SPEC, realistic_measured, seed_lens

    from pipeline.compare import compare_models
    from pipeline.harp_shape import shot_weights
    from pipeline.realism import realistic_session

    print("## Part 3: the lens fit with noisy shots weighed, population seeds near the grid\n")
    print("| seed | closest angle to the grid deg | shots weighed (noise ratio) | field px | field, weighed px | "
          "unseen d px | unseen d, weighed px |")  # fmt: skip
    print("|---:|---:|---|---:|---:|---:|---:|")
    for seed in seeds:
        mount = realistic_session(seed, W, H).mount
        offs = []
        for t in FITTED:
            d = np.asarray(mount.pose(t).direction)
            offs.append(grid_offset_deg(float(np.degrees(np.arctan2(d[1], d[0])))))
        if min(offs) >= 2.0:
            continue
        lines, unseen, _ = realistic_measured(seed, W, H, cache)
        lens = seed_lens(seed, W, H)[0]
        cells = []
        plain = fit_distortion(lines, W, H, **SPEC.fit_arguments())
        kept = [e for e in plain.edges if not e.rejected]
        w, noisy = shot_weights(np.array([e.rms_after for e in kept]), np.array([e.image for e in kept]))
        fits = [plain]
        if noisy:
            sigma = [[np.full(len(p), noisy.get(i, 1.0)) for p in shot] for i, shot in enumerate(lines)]
            fits.append(fit_distortion(lines, W, H, point_sigma=sigma, **SPEC.fit_arguments()))
        for f in fits:
            cells.append(compare_models(f.model, lens, W, H, step=20).rms)
            cells.append(float(np.sqrt(np.mean([corrected_straightness(f.model, u)[0] ** 2 for u in unseen]))))
        if not noisy:
            cells = [cells[0], float("nan"), cells[1], float("nan")]
        else:
            cells = [cells[0], cells[2], cells[1], cells[3]]
        shots = ", ".join(f"{FITTED[i]:g} deg ({r:.2f})" for i, r in sorted(noisy.items())) or "none"
        print(f"| {seed} | {min(offs):.2f} | {shots} | " + " | ".join(f"{c:.4f}" for c in cells) + " |", flush=True)
    print()


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="0,1")
    ap.add_argument("--angles", default="0,0.25,0.5,1,2,4,8,22")
    ap.add_argument("--no-real", action="store_true")
    ap.add_argument("--lens-seeds", default="", help="part 3: seeds a:b of the lens population (empty: skipped)")
    ap.add_argument("--cache", type=Path, default=None, help="part 3: directory of kept renders")
    args = ap.parse_args(argv)
    print(
        f"# Edges along the pixel grid ({os.cpu_count()} CPUs, load {os.getloadavg()[0]:.1f}; "
        f"`benchmarks/grid_angle.py {' '.join(argv if argv is not None else sys.argv[1:])}`)\n"
    )
    if args.lens_seeds:
        a, b = (int(v) for v in args.lens_seeds.split(":"))
        lens_weights(range(a, b), args.cache)
        return 0
    simulator([int(v) for v in args.seeds.split(",")], [float(v) for v in args.angles.split(",")])
    if not args.no_real:
        if REAL_DIR.is_dir():
            real(REAL_DIR)
        else:
            print(f"(no real photographs at {REAL_DIR}: set HARP_REAL_DATA)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
