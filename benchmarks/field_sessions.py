"""Whole simulated sessions on lenses with and without a residual field: what ``pipeline.field`` stores.

Usage::

    .venv/bin/python benchmarks/field_sessions.py [--seeds 0,1,2,3] [--size 1000x750] [--workers 2] [--places 2]
        [--runs "with a field, field auto;..."]

``benchmarks/choice_realistic.py`` emulates a session's choice and field stage on rendered shots. This runs the
sessions themselves: ``harp session run`` on the simulated station of ``configs/demo.yaml`` with the realistic
camera (``realism_seed``: bent and kinked strings, field blur, back-light, vignetting, noise, Bayer; one frame per
orientation, twelve turntable angles 0..165 by 15, one focus setting, 0.5), a unit of the demo lens drawn from
each serial (``simulation.lens_spread: 1``) and the session's own defaults for everything the pipeline does
(``model: auto``, ``strings: separate-kinks``, ``field: auto``, ``choice_folds: plain``) but the bootstrap (0).

Per seed (realism seed and lens serial ``FIELD-<seed>``), two lenses, each measured twice:

* **with a field**: the unit with a residual field (``simulation.lens_field_px``, :func:`drivers.sim.lens.lens_field`)
  of an RMS drawn uniformly in 0.005-0.04 px from the seed (as :mod:`pipeline.lens_population` draws it);
* **without**: the same unit without it;

each with ``pipeline.field: auto`` (the default) and ``none`` (``--runs``: some of these four). ``--places 2``:
six angles 0..150 by 30 at each of two linear-stage positions instead (``benchmarks/two_place_sessions.py``'s
two places, 240 px apart). The table gives each session's stored model and its
field error against the exact lens (the unit at that focus with its field; ``pipeline.compare.compare_models``,
modulo homography, 20 px grid), for a field the stage took its lead over the model in the folds (paired standard
errors, ``+x.x SE``; :data:`pipeline.select.FIELD_MARGIN_SE` is the bar), the QA checks the session failed
(``QA fails string_bend_max``: the harp's self-check found a string bent beyond its limit) and its wall time (a
whole process; two sessions run at once with ``--workers 2``); below it, the range of the stored corrections'
linear scale over the image against the exact lens's (``pipeline.fit.correction_scale``).
"""

from __future__ import annotations

import argparse
import os
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from benchmarks.two_place_sessions import ONE, TWO, cell, run_session  # noqa: E402

FIELD_RMS_PX = (0.005, 0.04)
RUNS = ("with a field, field auto", "with a field, field none", "without, field auto", "without, field none")


def lens_field_px(seed: int) -> float:
    """The RMS of seed ``seed``'s residual field, drawn uniformly in :data:`FIELD_RMS_PX`."""
    return float(np.random.default_rng([seed, 0xF1E1D]).uniform(*FIELD_RMS_PX))


def run(job: tuple[int, str, int, int, int]) -> dict[str, Any]:
    seed, name, w, h, places = job
    rms = lens_field_px(seed) if name.startswith("with a field") else 0.0
    field = name.rsplit(" ", 1)[1]
    capture = ONE if places == 1 else TWO
    out = run_session(seed, capture, {"field": field}, w, h, serial=f"FIELD-{seed}", lens_field_px=rms, defaults=True)
    return {**out, "run": name, "rms": rms}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="0,1,2,3")
    ap.add_argument("--size", default="1000x750")
    ap.add_argument("--workers", type=int, default=2, help="sessions run at once")
    ap.add_argument("--places", type=int, choices=(1, 2), default=1, help="turntable-axis places (module doc)")
    ap.add_argument("--runs", default=";".join(RUNS), help="the runs, by name, separated by ;")
    args = ap.parse_args(argv)
    runs = [r for r in RUNS if r in args.runs.split(";")]
    if not runs:
        ap.error(f"--runs: none of {args.runs!r} is a run ({'; '.join(RUNS)})")
    w, h = (int(v) for v in args.size.split("x"))
    seeds = [int(s) for s in args.seeds.split(",")]
    where = "twelve angles about one place" if args.places == 1 else "six angles at each of two places"
    print(
        f"# Whole simulated sessions, lenses with and without a residual field: field error of the stored lens, "
        f"{w}x{h}, focus 0.5, {where} ({os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.1f} at start; "
        f"`benchmarks/field_sessions.py {' '.join(argv if argv is not None else sys.argv[1:])}`)"
    )
    print()
    jobs = [(s, name, w, h, args.places) for s in seeds for name in runs]
    print("| seed | lens field px | " + " | ".join(f"{name}: stored model, field px (wall s)" for name in runs) + " |")
    print("|---:|---:|" + "---|" * len(runs), flush=True)
    results = []
    with ThreadPoolExecutor(max(1, args.workers)) as pool:
        for r in pool.map(run, jobs):  # in order: a seed's row as soon as its runs are in
            results.append(r)
            if len(results) % len(runs) == 0:
                row = results[-len(runs) :]
                print(
                    f"| {r['seed']} | {lens_field_px(r['seed']):.4f} | " + " | ".join(map(cell, row)) + " |", flush=True
                )
    by = {(r["seed"], r["run"]): r for r in results}
    print()
    f = {name: np.array([by[(s, name)].get("field", np.nan) for s in seeds]) for name in runs}
    for name in runs:
        walls = [by[(s, name)]["wall"] for s in seeds]
        print(
            f"{name}: at or below 0.005 px {int(np.sum(f[name] <= 0.005))} of {len(seeds)}, median "
            f"{np.nanmedian(f[name]):.4f} px, worst {np.nanmax(f[name]):.4f} px; median wall {np.median(walls):.0f} s"
        )
    for lens in ("with a field", "without"):
        if f"{lens}, field auto" not in f or f"{lens}, field none" not in f:
            continue
        auto, none = f[f"{lens}, field auto"], f[f"{lens}, field none"]
        apart = (np.abs(auto - none) > 0.2 * none) & (np.abs(auto - none) > 0.001)
        better, worse = int(np.sum(apart & (auto < none))), int(np.sum(apart & (auto > none)))
        print(
            f"{lens}: field auto against none, more than 20 % and 0.001 px apart: {better} better, {worse} worse "
            f"of {len(seeds)}"
        )
    scales = np.array([r["scale"] for r in results if "scale" in r])
    if len(scales):
        print(
            f"stored correction's scale over the image against the exact lens's: {scales.min():.4f} to "
            f"{scales.max():.4f} ({len(scales)} sessions)"
        )
    print(f"(load average at end {os.getloadavg()[0]:.1f})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
