"""How often the harp's frame is wrong: the turntable axis and each string's number across shots
(issue 19 item 4, ``pipeline.harp_frame.harp_frame``) over seeded geometries a user could have.

Run::

    .venv/bin/python benchmarks/harp_frame_population.py [--seeds 0-239] [--workers 2] [--size 1000x750]

Each seed draws a harp (``pipeline.harp_scene.draw_harp``: 7-15 strings, pitch 30-120 px, width 2.5-4 px,
bows, kinks and twist of a drawn material; span 1.3-1.8 image diagonals as the realistic simulator's), a
turntable axis 0-2 pitches from the image centre in a random direction, the strings' angle at turntable 0 and
the sense of turning, a lens of the realistic population (``pipeline.lens_population``) and a plan of turntable
angles by ``seed % 4``:

* ``even``: 3-12 angles evenly spread over the half turn (a random start);
* ``0/45/90/135`` and ``0/30/../150``: those four and six angles;
* ``random``: 3-12 angles drawn from the 15-degree steps of the half turn.

The edges are the exact curves through the lens every 10 px with 0.01 px of noise
(``tests.pipeline.harp_points.drawn_harp_point_sets``). As ``fit_harp_shape`` does: the plain fit of
radial4+tangential+prism, its rejected edges left out, every kept edge corrected by its lens, then
``harp_frame``. Truth: the drawn axis mapped through the exact lens and back through the fitted one (the
fitted lens's ideal pixels), and the drawn string of each edge. "axis off" counts frames whose axis is more
than a quarter pitch from the truth; "misnumbered" frames in which some string's edges carry two numbers or
one number holds two strings; "refused" the frames refused (a FitFailure: e.g. an axis that these angles
cannot place). A refused frame is not counted as off or misnumbered: the session reports its reason. The frame's
pitch (``HarpFrame.pitch_px``, ``pipeline.harp_frame.harp_pitch``) is compared with the drawn one (the slope of the
strings' drawn positions, mapped at the axis through the exact lens and back through the fitted one).
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from collections import defaultdict
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from pipeline.fit import fit_distortion
from pipeline.fitspec import FitSpec
from pipeline.harp_frame import group_frames, harp_frame
from pipeline.harp_scene import HarpMount, draw_harp
from pipeline.lens_population import lens_population
from tests.pipeline.harp_points import drawn_harp_point_sets

SPEC = FitSpec("radial", 4, True, True)
PLANS = ("even", "0/45/90/135", "0/30/../150", "random")


def plan_angles(kind: str, rng: np.random.Generator) -> list[float]:
    """The turntable angles of plan ``kind`` (module docstring)."""
    if kind == "even":
        n = int(rng.integers(3, 13))
        return [float(rng.uniform(0, 180.0 / n)) + k * 180.0 / n for k in range(n)]
    if kind == "0/45/90/135":
        return [0.0, 45.0, 90.0, 135.0]
    if kind == "0/30/../150":
        return [0.0, 30.0, 60.0, 90.0, 120.0, 150.0]
    n = int(rng.integers(3, 13))
    return [float(v) for v in np.sort(rng.choice(np.arange(0.0, 180.0, 15.0), n, replace=False))]


def one(args: tuple[int, int, int, bool]) -> dict[str, object]:
    """Seed ``seed``'s geometry, its frame and how it compares with the truth (``groups``: two places, module
    docstring)."""
    seed, w, h, groups = args
    rng = np.random.default_rng([seed, 0xF4A3E])
    kind = PLANS[seed % len(PLANS)]
    turns = plan_angles(kind, rng)
    n_str = int(rng.integers(7, 16))
    pitch = float(rng.uniform(30.0, 120.0))
    width = float(rng.uniform(2.5, 4.0))
    off = float(rng.uniform(0.0, 2.0)) * pitch
    phi = float(rng.uniform(0.0, 2 * math.pi))
    diag = math.hypot(w, h)
    axis = np.array([(w - 1) / 2.0 + off * math.cos(phi), (h - 1) / 2.0 + off * math.sin(phi)])
    harp = draw_harp(int(rng.integers(2**31)), n_str, pitch, width, float(rng.uniform(1.3, 1.8)) * diag,
                     visible_px=0.5 * diag)  # fmt: skip
    mount = HarpMount((float(axis[0]), float(axis[1])), float(rng.uniform(0, 360)), int(rng.choice([-1, 1])))
    lens = lens_population(seed, 1, w, h)[0].model
    row: dict[str, object] = {"seed": seed, "plan": kind, "shots": len(turns), "strings": n_str, "pitch": pitch}
    row |= {"axis_off_pitches": off / pitch}
    if groups:
        return row | placed_groups(rng, lens, harp, mount, turns, pitch, w, h, seed)
    shots, strings = drawn_harp_point_sets(lens, w, h, turns, harp, mount, seed=seed)
    t0 = time.perf_counter()
    plain = fit_distortion(shots, w, h, **SPEC.fit_arguments())
    if not plain:
        return row | {"result": "plain fit failed"}
    out = {(r.image, r.line) for r in plain.rejected}
    corrected, truth = [], []
    for i, (shot, labels) in enumerate(zip(shots, strings, strict=True)):
        keep = [j for j in range(len(shot)) if (i, j) not in out]
        corrected.append([plain.model.undistort_points(shot[j]) for j in keep])
        truth.append([labels[j] for j in keep])
    t1 = time.perf_counter()
    framed = harp_frame(corrected, turns, w, h)
    row["frame_s"] = time.perf_counter() - t1
    row["fit_s"] = t1 - t0
    if not framed:
        return row | {"result": "refused", "reason": framed.reason}
    frame, numbers = framed
    true_axis = plain.model.undistort_points(lens.distort_points(axis[None, :]))[0]
    err = float(np.hypot(*(np.asarray(frame.centre) - true_axis)))
    # the drawn pitch (the slope of the strings' drawn positions), in the fitted lens's ideal px at the axis
    k = np.arange(n_str) - (n_str - 1) / 2.0
    drawn = float(k @ np.array([s.position_px for s in harp.strings]) / (k @ k))
    step = axis[None, :] + np.array([[0.0, 0.0], drawn * frame.normal(float(turns[0]))])
    ends = plain.model.undistort_points(lens.distort_points(step))
    pitch_true = float(np.hypot(*(ends[1] - ends[0])))
    return (
        row
        | {
            "result": "framed",
            "axis_err_pitches": err / pitch,
            "pitch_err_pct": 100.0 * (frame.pitch_px / pitch_true - 1.0),
            "axis_off": err > 0.25 * pitch,
        }
        | numbering(truth, numbers)
    )


def placed_groups(
    rng: np.random.Generator, lens: Any, harp: Any, mount: HarpMount, turns: list[float], pitch: float, w: int,
    h: int, seed: int,
) -> dict[str, object]:  # fmt: skip
    """``--groups``: the harp moved with its turntable to two places 1-2 pitches either side of the drawn axis (in a
    random direction), the same angles at each; ``group_frames`` without shifts (what ``fit_harp_shape`` does with
    ``axis_groups`` and no ``axis_shifts``) against each place's drawn axis and the drawn strings."""
    step = float(rng.uniform(1.0, 2.0)) * pitch
    phi = float(rng.uniform(0.0, 2 * math.pi))
    axes = {g: np.asarray(mount.centre) + g * step * np.array([math.cos(phi), math.sin(phi)]) for g in (-1, 1)}
    middle = (np.array([w, h], dtype=np.float64) - 1.0) / 2.0
    out: dict[str, object] = {"axis_off_pitches": max(float(np.hypot(*(a - middle))) for a in axes.values()) / pitch}
    shots, strings, labels = [], [], []
    for g in (-1, 1):
        moved = HarpMount((float(axes[g][0]), float(axes[g][1])), mount.angle0_deg, mount.direction)
        drawn, drawn_strings = drawn_harp_point_sets(lens, w, h, turns, harp, moved, seed=2 * seed + (g > 0))
        shots += drawn
        strings += drawn_strings
        labels += [g] * len(turns)
    t0 = time.perf_counter()
    plain = fit_distortion(shots, w, h, **SPEC.fit_arguments())
    if not plain:
        return out | {"result": "plain fit failed"}
    rejected = {(r.image, r.line) for r in plain.rejected}
    corrected, truth = [], []
    for i, (shot, drawn_labels) in enumerate(zip(shots, strings, strict=True)):
        keep = [j for j in range(len(shot)) if (i, j) not in rejected]
        corrected.append([plain.model.undistort_points(shot[j]) for j in keep])
        truth.append([drawn_labels[j] for j in keep])
    t1 = time.perf_counter()
    framed = group_frames(corrected, turns + turns, labels, w, h)
    out |= {"frame_s": time.perf_counter() - t1, "fit_s": t1 - t0}
    if not framed:
        return out | {"result": "refused", "reason": framed.reason}
    frames, numbers = framed
    drawn_axes = {g: plain.model.undistort_points(lens.distort_points(a[None, :]))[0] for g, a in axes.items()}
    err = max(float(np.hypot(*(np.asarray(frames[g].centre) - drawn_axes[g]))) for g in (-1, 1))
    result = {"result": "framed", "axis_err_pitches": err / pitch, "axis_off": err > 0.25 * pitch}
    return out | result | numbering(truth, numbers)


def numbering(truth: list[list[int]], numbers: list[list[int]]) -> dict[str, object]:
    """Whether some drawn string carries two numbers or some number two drawn strings."""
    pairs = {(t, n) for ts, ns in zip(truth, numbers, strict=True) for t, n in zip(ts, ns, strict=True)}
    by_true, by_num = defaultdict(set), defaultdict(set)
    for t, n in pairs:
        by_true[t].add(n)
        by_num[n].add(t)
    wrong = {t for t, ns in by_true.items() if len(ns) > 1 or any(len(by_num[n]) > 1 for n in ns)}
    return {"misnumbered": bool(wrong), "wrong_strings": len(wrong), "seen_strings": len(by_true)}


def seeds_arg(text: str) -> list[int]:
    out: list[int] = []
    for part in text.split(","):
        a, _, b = part.partition("-")
        out.extend(range(int(a), int(b) + 1) if b else [int(a)])
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", default="0-239", help="seeds, e.g. 0-239 or 3,7,12")
    ap.add_argument("--size", default="1000x750")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--rows", action="store_true", help="also print every geometry that went wrong")
    ap.add_argument("--groups", action="store_true", help="two places of the turntable axis, no shifts given")
    args = ap.parse_args()
    w, h = (int(v) for v in args.size.split("x"))
    jobs = [(s, w, h, args.groups) for s in seeds_arg(args.seeds)]
    t0 = time.perf_counter()
    if args.workers > 1:
        with ProcessPoolExecutor(args.workers) as pool:
            rows = list(pool.map(one, jobs))
    else:
        rows = [one(j) for j in jobs]
    wall = time.perf_counter() - t0

    def line(name: str, sel: list[dict[str, object]]) -> str:
        n = len(sel)
        framed = [r for r in sel if r["result"] == "framed"]
        refused = sum(r["result"] == "refused" for r in sel)
        other = n - len(framed) - refused
        off = sum(bool(r["axis_off"]) for r in framed)
        mis = sum(bool(r["misnumbered"]) for r in framed)
        bad = sum(bool(r["axis_off"]) or bool(r["misnumbered"]) for r in framed)
        pct = (lambda k: f"{100.0 * k / n:5.1f}") if n else (lambda k: "    -")
        return f"| {name:<22} | {n:4d} | {off:4d} ({pct(off)} %) | {mis:4d} ({pct(mis)} %) | {bad:4d} ({pct(bad)} %) | {refused:4d} | {other:3d} |"

    what = "group_frames (two places, no shifts)" if args.groups else "harp_frame"
    print(f"{what} over {len(rows)} geometries ({args.size}), {wall:.0f} s wall with {args.workers} workers")
    print()
    print(
        "| geometries             |    n | axis > p/4 off   | misnumbered      | either (wrong)   | refused | other |"
    )
    print(
        "|------------------------|------|------------------|------------------|------------------|---------|-------|"
    )
    print(line("all", rows))
    for kind in PLANS:
        print(line(f"plan {kind}", [r for r in rows if r["plan"] == kind]))
    for lo, hi in ((3, 3), (4, 5), (6, 8), (9, 12)):
        print(line(f"{lo}-{hi} shots" if hi > lo else f"{lo} shots", [r for r in rows if lo <= int(r["shots"]) <= hi]))
    for lo, hi in (
        ((0.0, 1.0), (1.0, 2.0), (2.0, 3.0), (3.0, 4.0))
        if args.groups
        else ((0.0, 0.5), (0.5, 1.0), (1.0, 1.5), (1.5, 2.0))
    ):
        sel = [r for r in rows if lo <= float(r["axis_off_pitches"]) < hi]
        print(line(f"axis {lo:.1f}-{hi:.1f} p off centre", sel))
    for lo, hi in ((30, 60), (60, 90), (90, 120)):
        print(line(f"pitch {lo}-{hi} px", [r for r in rows if lo <= float(r["pitch"]) < hi]))
    frame_s = [float(r["frame_s"]) for r in rows if "frame_s" in r]
    if frame_s:
        print()
        print(f"{what} time: median {1e3 * np.median(frame_s):.0f} ms, max {1e3 * max(frame_s):.0f} ms")
    pitch_err = np.abs([float(r["pitch_err_pct"]) for r in rows if "pitch_err_pct" in r])
    if len(pitch_err):
        print(
            f"frame pitch against the drawn pitch ({len(pitch_err)} framed): median |error| "
            f"{np.median(pitch_err):.2f} %, 90th percentile {np.percentile(pitch_err, 90):.2f} %, "
            f"max {pitch_err.max():.2f} %"
        )
    if args.rows:
        print()
        for r in rows:
            if r["result"] != "framed" or r["axis_off"] or r["misnumbered"]:
                keys = ("seed", "plan", "shots", "strings", "pitch", "axis_off_pitches", "result")
                desc = " ".join(f"{k}={r[k]:.2f}" if isinstance(r[k], float) else f"{k}={r[k]}" for k in keys)
                extra = r.get("reason") or (
                    f"axis err {float(r['axis_err_pitches']):.2f} p, {r['wrong_strings']}/{r['seen_strings']} strings wrong"
                    if r["result"] == "framed"
                    else ""
                )
                print(f"  {desc}: {extra}")


if __name__ == "__main__":
    main()
