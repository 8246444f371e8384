"""Does moving the harp (with its turntable) between shots separate the strings' bends from the lens?

Usage::

    .venv/bin/python benchmarks/axis_positions.py [--seeds 38,26,0,16,27,39] [--first-seed 0 --count 20]
        [--shift 150] [--workers 2]

Turning the harp about one axis cannot tell a radial correction about that axis from string bends
depending on the strings' distances from it (``pipeline.harp_shape``'s docstring): when the axis is near
the distortion centre that part goes to the lens by a gauge, right or wrong. Seen about two axes, a
string keeps its distance from the turntable axis while its distance from the distortion centre changes,
so the shots tell them apart. For each seeded lens of ``benchmarks/lens_limits.py`` (its realistic
session's lens, harp with drawn string shapes and mount), the exact edges (no rendering: the strings'
shapes are the only error) are traced for plans of equal shot counts:

* six shots at 0..150 by 30 about the drawn axis, against six in two groups of three (0, 60, 120 with
  the axis moved by ``-shift`` px in x and half that in y; 30, 90, 150 moved by ``+shift``);
* twelve shots at 0..165 by 15 about the drawn axis, against 0..150 by 30 about each moved axis.

The two-axis plans are fitted twice: with each group's shift given 2 % off (``axis_shifts``, what a linear
stage's travel and a rough image scale tell) and with each group's axis searched on its own shots (no
shift given; three shots 60 degrees apart cannot place an axis for a harp of uniform pitch, see
``pipeline.harp_frame.group_frames``, which refuses it: "nan (refused)"). "(axis wrong)": a group's axis (or the
one axis) was found more than a third of a pitch from where it was drawn (its strings misnumbered). A two-axis cell has a third
figure: the strings separated with a ridge ten times weaker (``LOW_RIDGE``) than the default
(``pipeline.harp_shape.STRING_RIDGE``, 0.02).

Every plan uses the harp widened by copies of its strings (``lens_limits.widened``) so that it fills the
image wherever the axis is. ``radial4+tangential+prism`` is fitted alone (``pipeline.fit.fit_distortion``)
and with the strings separated (``pipeline.harp_shape.fit_harp_shape``; for the moved plans with
``axis_groups``, each group's axis found by the search, the shift not given); the table gives the field
error against the exact lens (``pipeline.compare.compare_models``, 20 px grid), "alone / separated", px.
The summary compares the separated figures (the default ridge) with the one-axis plan's.

``--realistic``: the same plans on shots rendered with every effect of the seed's realistic session (blur,
noise, Bayer, vignetting, the strings' kinks; ``pipeline.realism.render_shots``, JPEG off as in
``benchmarks/lens_limits.py``) and measured as ``harp measure`` does, instead of the exact edges.

``--stored``: what a session would store from each plan of shots (realistic renders only; kept in ``--cache
DIR``, one file per seed and shift, when given): the model ``pipeline.select.select_model`` chooses on the
plan's shots (plain folds, the session default ``pipeline.choice_folds``), fitted with the strings' bends and
kinks separated (the default ``pipeline.strings: separate-kinks``; the two-axis plans with ``axis_groups`` and
the shift given), beside radial4+tangential+prism fitted the same way; field error against the exact lens.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import pickle
import sys
import time
from collections.abc import Hashable
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from lens_limits import SPEC, seed_lens, widened

from pipeline.compare import compare_models
from pipeline.fit import fit_distortion
from pipeline.harp_scene import Harp, HarpMount
from pipeline.harp_shape import STRING_RIDGE, fit_harp_shape
from pipeline.measure import measure_image
from pipeline.realism import Session, render_shots, shot_edges
from pipeline.render import visible_edges
from pipeline.select import select_model

W, H = 1000, 750
SIX = tuple((float(a), -1 if a % 60 == 0 else 1) for a in range(0, 180, 30))
TWELVE = tuple((float(a), g) for g in (-1, 1) for a in range(0, 180, 30))
# plan name -> ((turntable angle, axis group: -1 moved by -shift, 0 not moved, +1 moved by +shift) per shot,
# how the fit is told the groups' shifts: None (one axis), "given" or "searched")
PLANS: dict[str, tuple[tuple[tuple[float, int], ...], str | None]] = {
    "6 shots, one axis": (tuple((float(a), 0) for a in range(0, 180, 30)), None),
    "6 shots, two axes, shift given": (SIX, "given"),
    "6 shots, two axes, searched": (SIX, "searched"),
    "12 shots, one axis": (tuple((float(a), 0) for a in range(0, 180, 15)), None),
    "12 shots, two axes, shift given": (TWELVE, "given"),
    "12 shots, two axes, searched": (TWELVE, "searched"),
}
LOW_RIDGE = 0.1 * STRING_RIDGE
"""The weaker ridge tried on the two-axis plans (module docstring)."""
SHIFT_ERROR = 1.02
"""A given shift is the true one times this (known roughly: a stage's travel times an image scale, from the harp's
pitch in mm and in px)."""


def moved(ses: Session, shift: float, group: int) -> tuple[Harp, HarpMount]:
    """The widened harp and the mount with its axis moved by ``group * (shift, shift / 2)``."""
    harp = widened(ses.harp, int(np.hypot(shift, shift / 2) // ses.harp.spacing_px) + 1)
    c = ses.mount.centre
    return harp, dataclasses.replace(ses.mount, centre=(c[0] + group * shift, c[1] + group * shift / 2))


def exact_shots(seed: int, shift: float) -> dict[tuple[float, int], list[Any]]:
    """The exact edges of every (angle, group) shot the plans take, traced through the exact lens every 2 px."""
    lens, ses, _ = seed_lens(seed, W, H)
    out = {}
    for a, g in dict.fromkeys(shot for plan, _ in PLANS.values() for shot in plan):
        harp, mount = moved(ses, shift, g)
        edges = shot_edges(lens, harp, mount.pose(a), W, H)
        out[(a, g)] = [p for _, p in visible_edges(edges, lens, W, H, step=2.0)]
    return out


def rendered_shots(seed: int, shift: float) -> dict[tuple[float, int], list[Any]]:
    """Every (angle, group) shot the plans take rendered with all of the seed's realistic effects
    (``pipeline.realism.render_shots``, group ``g``'s shots seeded ``3 seed + g + 1``) and measured as
    ``harp measure`` does."""
    lens, ses, _ = seed_lens(seed, W, H)
    shots = list(dict.fromkeys(shot for plan, _ in PLANS.values() for shot in plan))
    out = {}
    for g in sorted({g for _, g in shots}):
        harp, mount = moved(ses, shift, g)
        angles = [a for a, h in shots if h == g]
        for a, im in zip(angles, render_shots(lens, harp, mount, angles, W, H, ses.effects, seed=3 * seed + g + 1)):
            out[(a, g)] = [ln.points for ln in measure_image(im.image).lines]
    return out


def cached_rendered(seed: int, shift: float, cache: Path | None) -> dict[tuple[float, int], list[Any]]:
    """:func:`rendered_shots`, kept in ``cache`` (a directory; one pickle per seed and shift) when given."""
    path = None if cache is None else cache / f"axis_rendered_{seed}_{shift:g}_{W}x{H}.pkl"
    if path is not None and path.exists():
        with open(path, "rb") as f:
            out: dict[tuple[float, int], list[Any]] = pickle.load(f)
        return out
    out = rendered_shots(seed, shift)
    if path is not None:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(".tmp")
        with open(tmp, "wb") as f:
            pickle.dump(out, f)
        os.replace(tmp, path)
    return out


STORED_PLANS = (
    "6 shots, one axis",
    "6 shots, two axes, shift given",
    "12 shots, one axis",
    "12 shots, two axes, shift given",
)
"""The plans ``--stored`` compares (a session's two-axis capture gives the fit the stage's shift)."""


Inputs = tuple[list[Any], list[float], list[Hashable] | None, dict[Hashable, tuple[float, float]] | None]


def plan_inputs(store: dict[tuple[float, int], list[Any]], name: str, shift: float) -> Inputs:
    """Plan ``name``'s shots from ``store``: their edges, turntable angles, axis groups and the groups' shifts
    as a session's stage gives them (:data:`SHIFT_ERROR` off; None for the one-axis plans)."""
    plan, mode = PLANS[name]
    lines = [store[shot] for shot in plan]
    angles = [a for a, _ in plan]
    groups: list[Hashable] | None = [g for _, g in plan] if mode else None
    shifts = {g: (SHIFT_ERROR * g * shift, SHIFT_ERROR * g * shift / 2) for g in (-1, 1)} if mode else None
    return lines, angles, groups, shifts  # type: ignore[return-value]


def stored_field(inputs: Inputs, sel: Any, spec: Any, lens: Any) -> float:
    """Field error of ``spec`` as a session stores it: its fit of the choice ``sel`` (or fitted now), with the
    strings' bends and kinks separated about the plan's axis groups."""
    lines, angles, groups, shifts = inputs
    full = next((r.full_fit for r in sel.table if r.candidate == spec and r.full_fit), None)
    full = full or fit_distortion(lines, W, H, **spec.fit_arguments())
    if not full:
        return float("nan")
    sep = fit_harp_shape(lines, angles, W, H, spec, plain=full, axis_groups=groups, axis_shifts=shifts, kinks=True)
    return float(compare_models(sep.model, lens, W, H, step=20).rms) if sep else float("nan")


def stored_row(args: tuple[int, float, Path | None]) -> dict[str, Any]:
    """Per plan of :data:`STORED_PLANS`: the chosen candidate and the field errors of the chosen and of
    radial4+tangential+prism, each fitted with the strings' bends and kinks separated (``--stored``)."""
    seed, shift, cache = args
    lens, _, start = seed_lens(seed, W, H)
    store = cached_rendered(seed, shift, cache)
    out: dict[str, Any] = {"seed": seed, "lens": start["lens"], "strings": start["strings"]}
    t0 = time.perf_counter()
    for name in STORED_PLANS:
        inputs = plan_inputs(store, name, shift)
        sel = select_model(inputs[0], W, H)
        out[name] = (sel.choice.label, *(stored_field(inputs, sel, spec, lens) for spec in (sel.choice, SPEC)))
    out["t"] = time.perf_counter() - t0
    return out


SEPARATED_PLAN = "12 shots, two axes, shift given"
"""The plan ``--separated-choice`` compares the choices on (each fold keeps five shots of one group)."""


def separated_row(args: tuple[int, float, Path | None]) -> dict[str, Any]:
    """The plain-fold and the separated-fold choices on :data:`SEPARATED_PLAN`, each stored with the strings'
    bends and kinks separated; radial4+tangential+prism the same way (``--separated-choice``)."""
    seed, shift, cache = args
    lens, _, start = seed_lens(seed, W, H)
    store = cached_rendered(seed, shift, cache)
    out: dict[str, Any] = {"seed": seed, "lens": start["lens"], "strings": start["strings"]}
    inputs = plan_inputs(store, SEPARATED_PLAN, shift)
    lines, angles, groups, shifts = inputs
    for name, kw in (
        ("plain", {}),
        ("separated", {"turntable_deg": angles, "axis_groups": groups, "axis_shifts": shifts}),
    ):
        t0 = time.perf_counter()
        sel = select_model(lines, W, H, **kw)  # type: ignore[arg-type]
        out[name] = (sel.choice.label, stored_field(inputs, sel, sel.choice, lens))
        if name == "plain":
            out["fixed"] = (SPEC.label, stored_field(inputs, sel, SPEC, lens))
        out[f"t {name}"] = time.perf_counter() - t0
    return out


def print_separated(results: list[dict[str, Any]]) -> None:
    print(
        "| seed | lens | strings | chosen, plain folds: px | chosen, strings separated in the folds: px | radial4+tangential+prism px | s (plain / separated) |"
    )
    print("|---:|---|---|---|---|---:|---:|")
    for r in results:
        print(
            f"| {r['seed']} | {r['lens']} | {r['strings']} | {r['plain'][0]} {r['plain'][1]:.4f} | "
            f"{r['separated'][0]} {r['separated'][1]:.4f} | {r['fixed'][1]:.4f} | {r['t plain']:.0f} / {r['t separated']:.0f} |",
            flush=True,
        )
    print()
    a, b, f = (np.array([r[k][1] for r in results]) for k in ("plain", "separated", "fixed"))
    print(
        f"{SEPARATED_PLAN}: at or below 0.005 px: plain folds {int(np.sum(a <= 0.005))}, strings separated "
        f"{int(np.sum(b <= 0.005))}, radial4+tangential+prism {int(np.sum(f <= 0.005))} of {len(a)}; median "
        f"{np.median(a):.4f} / {np.median(b):.4f} / {np.median(f):.4f} px; separated against plain: lower (< 0.95x) "
        f"for {int(np.sum(b < 0.95 * a))}, higher (> 1.05x) for {int(np.sum(b > 1.05 * a))}, worst "
        f"{np.nanmax(b / a):.2f}x; over the least of the three: "
        f"separated worst {np.nanmax(b / np.minimum(a, f)):.2f}x, plain worst {np.nanmax(a / np.minimum(b, f)):.2f}x"
    )


def print_stored(results: list[dict[str, Any]]) -> None:
    print("| seed | lens | strings | " + " | ".join(f"{p}: chosen, px (fixed px)" for p in STORED_PLANS) + " | s |")
    print("|---:|---|---|" + "---|" * len(STORED_PLANS) + "---:|")
    for r in results:
        cells = [f"{r[p][0]} {r[p][1]:.4f} ({r[p][2]:.4f})" for p in STORED_PLANS]
        print(f"| {r['seed']} | {r['lens']} | {r['strings']} | " + " | ".join(cells) + f" | {r['t']:.0f} |", flush=True)


def stored_summary(results: list[dict[str, Any]]) -> list[str]:
    out = []
    for one, two in ((STORED_PLANS[0], STORED_PLANS[1]), (STORED_PLANS[2], STORED_PLANS[3])):
        for i, who in ((1, "the chosen model"), (2, "radial4+tangential+prism")):
            a = np.array([r[one][i] for r in results])
            b = np.array([r[two][i] for r in results])
            ratio = b / a
            out.append(
                f"{two} against {one}, {who}: at or below 0.005 px {int(np.sum(a <= 0.005))} -> "
                f"{int(np.sum(b <= 0.005))} of {len(a)}; median {np.median(a):.4f} -> {np.median(b):.4f} px; "
                f"lower (< 0.95x) for {int(np.sum(ratio < 0.95))}, higher (> 1.05x) for {int(np.sum(ratio > 1.05))}, "
                f"worst {np.nanmax(ratio):.2f}x"
            )
    return out


def row(args: tuple[int, float, bool]) -> str:
    seed, shift, realistic = args
    lens, ses, start = seed_lens(seed, W, H)
    cells = [str(seed), str(start["lens"]), str(start["strings"])]
    store = rendered_shots(seed, shift) if realistic else exact_shots(seed, shift)
    for plan, mode in PLANS.values():
        lines = [store[shot] for shot in plan]
        angles = [a for a, _ in plan]
        groups = [g for _, g in plan] if mode else None
        given: dict[Hashable, tuple[float, float]] = {
            g: (SHIFT_ERROR * g * shift, SHIFT_ERROR * g * shift / 2) for g in (-1, 1)
        }
        plain = fit_distortion(lines, W, H, **SPEC.fit_arguments())
        shifts = given if mode == "given" else None
        fits = [
            fit_harp_shape(lines, angles, W, H, SPEC, plain=plain, axis_groups=groups, axis_shifts=shifts, ridge=r)
            if plain
            else None
            for r in ((STRING_RIDGE, LOW_RIDGE) if mode else (STRING_RIDGE,))
        ]
        sep = fits[0]
        alone = compare_models(plain.model, lens, W, H, step=20).rms if plain else np.nan
        both = " / ".join(f"{compare_models(f.model, lens, W, H, step=20).rms:.4f}" if f else "nan" for f in fits)
        # a group's axis found more than a third of a pitch from where it was drawn: the strings misnumbered
        c = ses.mount.centre
        drawn: dict[Hashable, tuple[float, float]] = {g: (c[0] + g * shift, c[1] + g * shift / 2) for g in (-1, 0, 1)}
        wrong = sep and any(
            np.hypot(f.centre[0] - drawn[g][0], f.centre[1] - drawn[g][1]) > f.pitch_px / 3
            for g, f in (sep.axis_groups or ((0, sep.frame),))
        )
        cells.append(f"{alone:.4f} / {both}" + (" (axis wrong)" if wrong else "" if sep or not plain else " (refused)"))
    return "| " + " | ".join(cells) + " |"


def summary(rows: list[str]) -> list[str]:
    """Per two-axis plan against the one-axis plan of its shot count: how often the separated field error
    drops, rises, stays."""
    cells = [[c.split(" (")[0] for c in r.strip("| ").split(" | ")[3:]] for r in rows]
    sep = np.array([[float(c.split("/")[1]) for c in r] for r in cells])
    alone = np.array([[float(c.split("/")[0]) for c in r] for r in cells])
    out = []
    names = list(PLANS)
    for i, j in ((0, 1), (0, 2), (3, 4), (3, 5)):
        one, two = sep[:, i], sep[:, j]
        ratio = two / one
        refused = int(np.sum(~np.isfinite(two)))
        if refused == len(two):
            out.append(f"{names[j]}: refused for all {len(two)}")
            continue
        out.append(
            f"{names[j]} against {names[i]}, separated: lower (< 0.95x) for {int(np.sum(ratio < 0.95))}, "
            f"within 5 % for {int(np.sum((ratio >= 0.95) & (ratio <= 1.05)))}, higher for {int(np.sum(ratio > 1.05))} of "
            f"{len(ratio)}{f' (refused {refused})' if refused else ''}; median ratio {np.nanmedian(ratio):.2f}, worst "
            f"{np.nanmax(ratio):.2f}; median field {np.median(one):.4f} -> {np.nanmedian(two):.4f} px; at or below "
            f"0.005 px {int(np.sum(one <= 0.005))} -> {int(np.sum(two <= 0.005))}; lens alone median "
            f"{np.median(alone[:, i]):.4f} -> {np.median(alone[:, j]):.4f} px"
        )
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="38,26,0,16,27,39", help="comma-separated seeds")
    ap.add_argument("--first-seed", type=int, default=None, help="a population instead: seeds first..first+count-1")
    ap.add_argument("--count", type=int, default=20)
    ap.add_argument("--shift", type=float, default=150.0, help="axis shift in x, px (half that in y)")
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--realistic", action="store_true", help="rendered and measured shots instead of exact edges")
    ap.add_argument("--stored", action="store_true", help="what a session stores from each plan (realistic renders)")
    ap.add_argument("--cache", type=Path, default=None, help="--stored: keep the rendered, measured shots here")
    ap.add_argument(
        "--separated-choice", action="store_true", help="--stored: plain against strings-separated choice folds"
    )
    args = ap.parse_args(argv)
    seeds = (
        list(range(args.first_seed, args.first_seed + args.count))
        if args.first_seed is not None
        else [int(s) for s in args.seeds.split(",")]
    )
    if args.stored:
        return main_stored(seeds, args.shift, args.workers, args.cache, argv, args.separated_choice)
    print(
        f"# One turntable axis or two: field error, radial4+tangential+prism alone / strings separated, "
        f"{'realistic renders' if args.realistic else 'exact edges'}, {W}x{H}, axis moved by +-({args.shift:.0f}, {args.shift / 2:.0f}) px ({os.cpu_count()} CPUs, "
        f"load average {os.getloadavg()[0]:.1f} at start; "
        f"`benchmarks/axis_positions.py {' '.join(argv if argv is not None else sys.argv[1:])}`)"
    )
    print()
    print("| seed | lens | strings | " + " | ".join(PLANS) + " |")
    print("|---:|---|---|" + "---:|" * len(PLANS))
    t0 = time.perf_counter()
    rows = []
    jobs = [(s, args.shift, args.realistic) for s in seeds]
    with ProcessPoolExecutor(max(1, args.workers)) as pool:
        for r in pool.map(row, jobs):
            rows.append(r)
            print(r, flush=True)
    print()
    for line in summary(rows):
        print(line)
    print()
    print(f"({time.perf_counter() - t0:.0f} s, load average at end {os.getloadavg()[0]:.1f})")
    return 0


def main_stored(
    seeds: list[int], shift: float, workers: int, cache: Path | None, argv: list[str] | None, separated: bool = False
) -> int:
    print(
        f"# One turntable axis or two, what a session stores: the chosen model (plain folds) and "
        f"radial4+tangential+prism, strings' bends and kinks separated, field error against the exact lens, "
        f"realistic renders, {W}x{H}, axis moved by +-({shift:.0f}, {shift / 2:.0f}) px ({os.cpu_count()} CPUs, "
        f"load average {os.getloadavg()[0]:.1f} at start; "
        f"`benchmarks/axis_positions.py {' '.join(argv if argv is not None else sys.argv[1:])}`)"
    )
    print()
    t0 = time.perf_counter()
    with ProcessPoolExecutor(max(1, workers)) as pool:
        results = list(pool.map(separated_row if separated else stored_row, [(s, shift, cache) for s in seeds]))
    if separated:
        print_separated(results)
    else:
        print_stored(results)
        print()
        for line in stored_summary(results):
            print(line)
    print()
    print(f"({time.perf_counter() - t0:.0f} s, load average at end {os.getloadavg()[0]:.1f})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
