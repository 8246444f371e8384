"""How close can any choice rule get to the best candidate on unseen shots? Rule variants and an oracle.

Usage::

    .venv/bin/python benchmarks/choice_rules.py [--seeds 0:20] [--fit-shots 4,6] [--cache DIR]

On the point-set population of ``benchmarks/model_choice.py`` (:func:`model_choice.point_session`: an exact
lens, a harp with its own string bends, every shot moved by a smooth field of its own), each lens's
leave-one-shot-out table and alternate-string table of every radial candidate are computed once
(:func:`pipeline.cross_validation.cross_validate`), with each candidate's held-out d on the three unseen
shots and its field error against the exact lens (:func:`pipeline.compare.compare_models`). Then the
rules are applied to the same tables:

* **now**: the two tiers of :func:`pipeline.select.select_model` (tier 1: n_se 1, orientation tolerance 0.5,
  flexible margin 2 SE; tier 2: the lowest alternate-string CV d, since 2026-12-06) — :func:`choose` mirrors
  them on stored tables; its figures equal ``benchmarks/model_choice.py``'s "two tiers (now)" rows for the same
  seeds;
* **before**: tier 2 by the fewest parameters within one paired standard error (the rule until 2026-12-06);
* variants: tier 2 within 0.5 SE, the most parameters within 1 SE, tier 1 tolerance 0.2 or 0.1 (tier 2 as
  before), and ranking by the sum of both CV figures;
* **fixed** radial4+tangential+prism and radial6+tangential+prism (no choice);
* **oracle**: the candidate whose correction is nearest the exact lens (least field error), which no rule
  can beat on average: where it is itself more than 5 % worse than the best candidate on the unseen
  shots, the unseen shots' own errors (each shot's field, the strings' bends) decide which candidate
  looks best on them, and the 5 % target measures that noise.

The ratio is the rule's candidate's held-out d on the unseen shots over the best candidate's
(issue 19 item 2), and, in a second table, its field error over the least field error.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import pickle
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from model_choice import H_PT, W_PT, held_d, point_session

from pipeline.compare import compare_models
from pipeline.cross_validation import DEFAULT_CANDIDATES, STOP_FACTOR, CVRow, cross_validate
from pipeline.fit import fit_distortion
from pipeline.fitspec import FitSpec
from pipeline.select import (
    FLEXIBLE_MARGIN_SE,
    ORIENTATION_TOLERANCE,
    _flexible_margin,
    _within,
    is_flexible,
    lowest_radial,
)

Tables = dict[str, Any]


def tables(seed: int, nfit: int, cache: Path | None) -> Tables:
    """Lens ``seed``'s CV tables with ``nfit`` shots, each candidate's unseen held-out d and field error."""
    f = None if cache is None else cache / f"d_{seed}_{nfit}.pkl"
    if f is not None and f.exists():
        with open(f, "rb") as fh:
            out: Tables = pickle.load(fh)
        return out
    lens, fs, ts = point_session(seed, nfit)
    loso, _ = cross_validate(fs, W_PT, H_PT, DEFAULT_CANDIDATES, "images", stop_factor=STOP_FACTOR)
    radial = [r for r in loso if not is_flexible(r.candidate)]
    fits = {r.candidate: r.full_fit for r in radial if r.full_fit is not None}
    edges, _ = cross_validate(fs, W_PT, H_PT, [r.candidate for r in radial], "edges", stop_factor=None, full_fits=fits)
    unseen, field = {}, {}
    held = [p for s in ts for p in s]
    for r in loso:
        fit = r.full_fit or fit_distortion(fs, W_PT, H_PT, **r.candidate.fit_arguments())
        unseen[r.candidate] = held_d(fit.model, held) if fit else float("nan")
        field[r.candidate] = float(compare_models(fit.model, lens, W_PT, H_PT, step=40).rms) if fit else float("nan")
    out = {
        "loso": [dataclasses.replace(r, full_fit=None) for r in loso],
        "edges": [dataclasses.replace(r, full_fit=None) for r in edges],
        "unseen": unseen,
        "field": field,
    }
    if f is not None:
        with open(f, "wb") as fh:
            pickle.dump(out, fh)
    return out


def _ok(rows: list[CVRow]) -> list[CVRow]:
    return [r for r in rows if np.isfinite(r.cv_d)]


def most_within(rows: list[CVRow], n_se: float) -> FitSpec | None:
    """Of the radial (not flexible) rows within ``n_se`` paired standard errors of the best radial CV d, the one
    with the most parameters (ties: the lower CV d): parsimony the other way round."""
    ok = [r for r in rows if np.isfinite(r.cv_d) and not is_flexible(r.candidate)]
    if not ok:
        return None
    near = _within(ok, min(ok, key=lambda r: r.cv_d), n_se, 0.0)
    return max(near, key=lambda r: (r.n_params, -r.cv_d)).candidate


def choose(t: Tables, n_se2: float = 1.0, tolerance: float = ORIENTATION_TOLERANCE, pick: str = "lowest") -> FitSpec:
    """:func:`pipeline.select.select_model`'s two tiers on stored tables, with tier 1's ``tolerance`` and tier 2's
    pick: the 'lowest' CV d (now, :data:`pipeline.select.TIER2_RULE`), the 'fewest' parameters within ``n_se2``
    SE of the best (the rule before 2026-12-06), the 'most' parameters within them, or 'sum' (the lowest
    leave-one-shot-out plus alternate-string CV d)."""
    rows = _ok(t["loso"])
    best = min(rows, key=lambda r: r.cv_d)
    first = min(_within(rows, best, 1.0, 0.0), key=lambda r: (r.n_params, r.cv_d))
    radial = [r for r in rows if not is_flexible(r.candidate)]
    best_radial = lowest_radial(rows)
    if is_flexible(first.candidate) and _flexible_margin(first, best_radial) > FLEXIBLE_MARGIN_SE:
        return first.candidate
    general = {r.candidate: r for r in _within(radial, best_radial, 1.0, tolerance)}
    e = [r for r in _ok(t["edges"]) if r.candidate in general]
    best2 = min(e, key=lambda r: r.cv_d)
    if pick == "lowest":
        return best2.candidate
    if pick == "most":
        return most_within(e, n_se2) or best2.candidate  # e: radial rows with a finite CV d, never empty
    if pick == "sum":
        return min(e, key=lambda r: general[r.candidate].cv_d + r.cv_d).candidate
    return min(_within(e, best2, n_se2, 0.0), key=lambda r: (r.n_params, r.cv_d)).candidate


def _fixed(label: str) -> Callable[[Tables], FitSpec]:
    return lambda t: next(k for k in t["unseen"] if k.label == label)


RULES: dict[str, Callable[[Tables], FitSpec]] = {
    "two tiers, tier 2 lowest CV d (now)": choose,
    "tier 2 fewest parameters within 1 SE (before)": lambda t: choose(t, pick="fewest"),
    "tier 2 within 0.5 SE": lambda t: choose(t, n_se2=0.5, pick="fewest"),
    "tier 1 tolerance 0.2": lambda t: choose(t, tolerance=0.2, pick="fewest"),
    "tier 1 tolerance 0.1": lambda t: choose(t, tolerance=0.1, pick="fewest"),
    "sum of both CV d": lambda t: choose(t, pick="sum"),
    "tier 2 most parameters within 1 SE": lambda t: choose(t, pick="most"),
    "fixed radial4+tangential+prism": _fixed("radial4+tangential+prism"),
    "fixed radial6+tangential+prism": _fixed("radial6+tangential+prism"),
    "oracle: least field error": lambda t: min(
        (k for k, v in t["field"].items() if np.isfinite(v)), key=t["field"].get
    ),
}


def report(all_tables: dict[int, list[Tables]], seeds: range, metric: str, title: str) -> None:
    print(f"## {title} (seeds {seeds.start}..{seeds.stop - 1})")
    print()
    print("| shots fitted | rule | worst ratio | mean ratio | lenses > 1.05 |")
    print("|---:|---|---:|---:|---:|")
    for nfit, ts in all_tables.items():
        for name, rule in RULES.items():
            ratios = []
            for t in ts:
                v = t[metric]
                ratios.append(v[rule(t)] / min(x for x in v.values() if np.isfinite(x)))
            a = np.array(ratios)
            print(f"| {nfit} | {name} | {a.max():.3f} | {a.mean():.3f} | {int(np.sum(a > 1.05))} / {len(a)} |")
    print()


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="0:20", help="first:stop")
    ap.add_argument("--fit-shots", default="4,6")
    ap.add_argument("--cache", type=Path, default=None, help="keep each lens's tables here (pickles)")
    args = ap.parse_args(argv)
    a, b = (int(v) for v in args.seeds.split(":"))
    seeds = range(a, b)
    print(
        f"# Choice rules against an oracle ({os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.1f} at start; "
        f"`benchmarks/choice_rules.py {' '.join(argv if argv is not None else sys.argv[1:])}`)"
    )
    print()
    t0 = time.perf_counter()
    if args.cache is not None:
        args.cache.mkdir(parents=True, exist_ok=True)
    all_tables = {int(n): [tables(s, int(n), args.cache) for s in seeds] for n in args.fit_shots.split(",")}
    report(all_tables, seeds, "unseen", "Held-out d on 3 unseen shots over the best candidate's")
    report(all_tables, seeds, "field", "Field error over the least field error of any candidate")
    print(f"({time.perf_counter() - t0:.0f} s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
