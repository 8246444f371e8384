"""The automatic choice on the realistic simulator, judged by what a session stores: rules against an oracle.

Usage::

    .venv/bin/python benchmarks/choice_realistic.py [--seeds 0:60] [--workers 2] [--cache DIR] [--tables DIR] [--lens-field]

For each lens of ``benchmarks/lens_limits.py``'s realistic population (seeds, 1000x750, six shots 30 degrees
apart, the measured edges of ``lens_limits.realistic_measured``, kept in ``--cache``), the two cross-validation
tables a session can choose on are computed once: the plain folds (:func:`pipeline.select.select_model`, the
leave-one-shot-out table and the alternate-string table of tier 2) and the folds with the strings separated
(``select_model(..., turntable_deg=...)``: each fold fitted with every string's bend separated, the held-out shot
judged with the bends that fold fitted removed). Every candidate either table cross-validated to the end is then
fitted as a session stores it (``pipeline.strings: separate-kinks``, the default: the joint fit with every string's
bend and kinks, :func:`pipeline.harp_shape.fit_harp_shape`) and judged by its field error against the exact lens
(RMS modulo homography, 20 px grid, :func:`pipeline.compare.compare_models`). The rules are applied to the same
tables (``--tables`` keeps them, one pickle per seed):

* **plain, two tiers**: what a session chooses with ``pipeline.model: auto`` (``pipeline.choice_folds: plain``),
  tier 2 by the lowest alternate-string CV d (now) or by the fewest parameters within one paired standard
  error (before 2026-12-06), or the most parameters within it (``choice_rules.choose`` on the stored tables);
* **strings separated**: ``pipeline.choice_folds: strings-separated``, the lowest CV d of the separated folds
  (now) or the fewest parameters within ``n`` paired standard errors of it (before: ``n`` = 1), a free
  polynomial only when it is ahead of every radial candidate by more than 2 SE
  (:data:`pipeline.select.FLEXIBLE_MARGIN_SE`);
* **fixed** radial4+tangential+prism, radial6+tangential+prism, and radial4 (what a session fitted when its configuration named no
  model, before 2026-12-06);
* **a residual field on top** (``pipeline.field: auto``, :func:`pipeline.select.select_field`): the plain choice's
  model against it with each field of :func:`pipeline.select.field_candidates`, by the plain folds or by the folds
  with the strings separated (what a session does);
* **oracle**: the candidate with the least field error, which no rule can beat, among the parametric candidates
  or among those and the field stage's.

``--lens-field`` gives every lens the smooth non-parametric field of :mod:`pipeline.lens_population` (RMS drawn in
0.005-0.04 px; the same parametric lens otherwise, its renders and tables kept apart, ``..._field``): the structure
a real lens has that no parametric term expresses (``benchmarks/RESULTS-realism.md``).

The issue's target (issue 19 item 5) is a field error at or below 0.005 px RMS.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import pickle
import sys
import time
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from choice_rules import choose, most_within
from lens_limits import FITTED, SPEC, SPEC6, field, realistic_measured, seed_lens

from pipeline.cross_validation import CVRow
from pipeline.fitspec import FitSpec
from pipeline.resample import DEFAULT_T
from pipeline.select import (
    FIELD_MARGIN_SE,
    FLEXIBLE_MARGIN_SE,
    _fewest_within,
    _flexible_margin,
    is_flexible,
    lowest_radial,
    select_field,
    select_model,
)

W, H = 1000, 750


def _light(rows: Sequence[CVRow]) -> tuple[CVRow, ...]:
    return tuple(dataclasses.replace(r, full_fit=None) for r in rows)


RADIAL4 = FitSpec("radial", 4, False, False)
"""What a session fits when its configuration names no model (``pipeline.model: radial``)."""


def field_stage(t: dict[str, Any], fitted: list[list], lens: Any, separated: bool = False) -> dict[str, Any]:
    """The residual field chosen on top of the plain choice (``pipeline.field: auto``): the plain two tiers'
    model (tier 2 by the lowest CV d) and that model with each field of :func:`pipeline.select.field_candidates`,
    cross-validated by :func:`pipeline.select.select_field` with the plain folds or (``separated``) with the
    strings' bends and kinks separated in each fold (``turntable_deg``, ``kink_t``, as a session does; the folds
    modelled the bends only before 2026-12-06's second change, and the stored tables of
    ``benchmarks/RESULTS-residual-field.md`` were made so; a polynomial choice weighed against the plain table's
    best radial candidate with each field); each candidate's stored field error is added to ``t["fields"]``."""
    base = plain(t, "lowest")
    radial = lowest_radial(t["plain_table"])
    t0 = time.perf_counter()
    sel = select_field(
        fitted, W, H, base, turntable_deg=FITTED if separated else None, kink_t=DEFAULT_T if separated else None,
        radial=None if radial is None else radial.candidate,
    )  # fmt: skip
    seconds = time.perf_counter() - t0
    full = {r.candidate: r.full_fit for r in sel.table if r.full_fit is not None}
    for r in sel.table:
        if r.candidate not in t["fields"]:
            t["fields"][r.candidate] = field(fitted, lens, W, H, r.candidate, plain=full.get(r.candidate), kinks=True)
    return {"base": base, "choice": sel.choice, "table": _light(sel.table), "seconds": seconds}


def field_pick(stage: dict[str, Any], bar: float) -> FitSpec:
    """The field stage's choice with the strings separated, a field taken when it is more than ``bar`` paired
    standard errors ahead of the model (0: the lowest CV d, :data:`pipeline.select.FIELD_MARGIN_SE`), on the stored
    table (:func:`pipeline.select._select_separated`'s rule)."""
    ok = [r for r in stage["table"] if np.isfinite(r.cv_d)]
    base = [r for r in ok if not is_flexible(r.candidate)]
    if not ok or not base:
        return stage["choice"]  # type: ignore[no-any-return]
    best = min(ok, key=lambda r: r.cv_d)
    if is_flexible(best.candidate) and _flexible_margin(best, base[0]) <= bar:
        return base[0].candidate
    return best.candidate


def tables(seed: int, cache: Path | None, keep: Path | None, lens_field: bool = False) -> dict[str, Any]:
    """Seed ``seed``'s two choices' tables, the field stage's (:func:`field_stage`) and each candidate's stored
    field error (module docstring); ``lens_field``: the lens with its non-parametric field."""
    f = None if keep is None else keep / f"choice_{seed}{'_field' if lens_field else ''}.pkl"
    if f is not None and f.exists():
        t: dict[str, Any] = pickle.loads(f.read_bytes())
        changed = False
        if RADIAL4 not in t["fields"]:  # tables kept before the default model's row was added
            lens, _, _ = seed_lens(seed, W, H, lens_field)
            fitted = realistic_measured(seed, W, H, cache, lens_field)[0]
            t["fields"][RADIAL4] = field(fitted, lens, W, H, RADIAL4, kinks=True)
            changed = True
        for key, separated in (("field_stage", False), ("field_stage_sep", True)):
            # kept before the field stage was added, or before a polynomial choice was weighed against the best
            # radial candidate with a field
            poly_unweighed = separated and key in t and t[key]["base"].kind == "poly" and not t[key]["table"]
            if key not in t or poly_unweighed:
                lens, _, _ = seed_lens(seed, W, H, lens_field)
                fitted = realistic_measured(seed, W, H, cache, lens_field)[0]
                t[key] = field_stage(t, fitted, lens, separated)
                changed = True
        if changed:
            tmp = f.with_suffix(".tmp")
            tmp.write_bytes(pickle.dumps(t))
            os.replace(tmp, f)
        return t
    lens, _, row = seed_lens(seed, W, H, lens_field)
    fitted, _, _ = realistic_measured(seed, W, H, cache, lens_field)
    t0 = time.perf_counter()
    plain = select_model(fitted, W, H)
    t_plain = time.perf_counter() - t0
    t0 = time.perf_counter()
    sep = select_model(fitted, W, H, turntable_deg=FITTED, kink_t=DEFAULT_T)
    t_sep = time.perf_counter() - t0
    full = {r.candidate: r.full_fit for r in (*plain.table, *sep.table) if r.full_fit is not None}
    wanted = {r.candidate for r in (*plain.table, *plain.strings_table, *sep.table) if np.isfinite(r.cv_d)}
    fields = {c: field(fitted, lens, W, H, c, plain=full.get(c), kinks=True) for c in wanted | {SPEC, RADIAL4}}
    out = {
        **row,
        "plain": plain.choice,
        "plain_table": _light(plain.table),
        "strings_table": _light(plain.strings_table),
        "sep": sep.choice,
        "sep_table": _light(sep.table),
        "fields": fields,
        "t_plain": t_plain,
        "t_sep": t_sep,
    }
    out["field_stage"] = field_stage(out, fitted, lens)
    out["field_stage_sep"] = field_stage(out, fitted, lens, separated=True)
    if f is not None:
        f.parent.mkdir(parents=True, exist_ok=True)
        tmp = f.with_suffix(".tmp")
        tmp.write_bytes(pickle.dumps(out))
        os.replace(tmp, f)
    return out


def separated_pick(table: Sequence[CVRow], n_se: float) -> FitSpec | None:
    """:func:`pipeline.select._select_separated`'s pick on ``table`` with ``n_se`` standard errors."""
    ok = [r for r in table if np.isfinite(r.cv_d)]
    if not ok:
        return None
    pick = _fewest_within(ok, min(ok, key=lambda r: r.cv_d), n_se)
    radial = [r for r in ok if not is_flexible(r.candidate)]
    best_radial = lowest_radial(ok)
    if is_flexible(pick.candidate) and best_radial is not None:
        if _flexible_margin(pick, best_radial) <= FLEXIBLE_MARGIN_SE:
            pick = _fewest_within(radial, best_radial, n_se)
    return pick.candidate


def plain(t: dict[str, Any], pick: str) -> FitSpec:
    """The plain two tiers on the stored tables (``choice_rules.choose``) with tier 2's ``pick``."""
    if not t["strings_table"]:  # a flexible model taken in tier 1, or no tier 2 possible: as chosen
        return t["plain"]  # type: ignore[no-any-return]
    return choose({"loso": list(t["plain_table"]), "edges": list(t["strings_table"])}, pick=pick)


RULES: dict[str, Callable[[dict[str, Any]], FitSpec | None]] = {
    "plain, tier 2 fewest parameters within 1 SE (before)": lambda t: plain(t, "fewest"),
    "plain, tier 2 lowest CV d (now; model auto's default)": lambda t: plain(t, "lowest"),
    "plain, tier 2 most parameters within 1 SE": lambda t: plain(t, "most"),
    "strings separated, fewest parameters within 1 SE (before)": lambda t: separated_pick(t["sep_table"], 1.0),
    "strings separated, 0.5 SE": lambda t: separated_pick(t["sep_table"], 0.5),
    "strings separated, lowest CV d (now, the option)": lambda t: separated_pick(t["sep_table"], 0.0),
    "strings separated, most parameters within 1 SE": lambda t: most_within(t["sep_table"], 1.0),
    f"fixed {SPEC.label}": lambda t: SPEC,
    f"fixed {SPEC6.label}": lambda t: SPEC6,
    "fixed radial4 (a session's model when none was named, before)": lambda t: RADIAL4,
    "plain, then a residual field by the plain folds (2 SE ahead)": lambda t: t["field_stage"]["choice"],
    f"plain, then a residual field by the strings-separated folds, {FLEXIBLE_MARGIN_SE:g} SE ahead": lambda t: (
        field_pick(t["field_stage_sep"], FLEXIBLE_MARGIN_SE)
    ),
    "plain, then a residual field by the strings-separated folds, 1 SE ahead": lambda t: field_pick(
        t["field_stage_sep"], 1.0
    ),
    "plain, then a residual field by the strings-separated folds, lowest CV d (now; pipeline.field: auto)": lambda t: (
        field_pick(t["field_stage_sep"], FIELD_MARGIN_SE)
    ),
    "oracle: least field error, no residual field": lambda t: min(
        (c for c in t["fields"] if c.field is None), key=lambda c: t["fields"][c]
    ),
    "oracle: least field error, residual fields too": lambda t: min(t["fields"], key=lambda c: t["fields"][c]),
}


def job(args: tuple[int, Path | None, Path | None, bool]) -> dict[str, Any]:
    return tables(*args)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="0:60", help="first:end")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--cache", type=Path, default=None, help="directory keeping the measured edges (npz)")
    ap.add_argument("--tables", type=Path, default=None, help="directory keeping each seed's tables (pickle)")
    ap.add_argument("--rows", action="store_true", help="print each lens's row too")
    ap.add_argument(
        "--lens-field", action="store_true", help="each lens with a non-parametric field (0.005-0.04 px RMS)"
    )
    args = ap.parse_args(argv)
    a, b = (int(v) for v in args.seeds.split(":"))
    cmd = " ".join(argv if argv is not None else sys.argv[1:])
    t0 = time.perf_counter()
    print(
        f"# The choice on the realistic simulator, field error of what a session stores ({os.cpu_count()} CPUs, "
        f"load average {os.getloadavg()[0]:.1f} at start; `benchmarks/choice_realistic.py {cmd}`)"
    )
    print()
    with ProcessPoolExecutor(max(1, args.workers)) as pool:
        ts = list(pool.map(job, [(s, args.cache, args.tables, args.lens_field) for s in range(a, b)]))
    picks = {name: [rule(t) for t in ts] for name, rule in RULES.items()}
    if args.rows:
        names = list(RULES)
        print("| seed | lens | strings | " + " | ".join(names) + " |")
        print("|---:|---|---|" + "---|" * len(names))
        for i, t in enumerate(ts):
            cells = []
            for n in names:
                c = picks[n][i]
                cells.append("-" if c is None else f"{c.label} {t['fields'].get(c, float('nan')):.4f}")
            lens = t["lens"] + (f" (field {t['field_rms']:.3f} px)" if "field_rms" in t else "")
            print(f"| {t['seed']} | {lens} | {t['strings']} | " + " | ".join(cells) + " |")
        print()
    print(
        f"## {len(ts)} lenses (seeds {a}..{b - 1}{', each with a non-parametric field' if args.lens_field else ''}): "
        "field error of the chosen model, stored with the strings separated"
    )
    print()
    print("| rule | at or below 0.005 px | median px | worst px | over the least field error: median | > 1.05 |")
    print("|---|---:|---:|---:|---:|---:|")
    best = np.array([min(t["fields"].values()) for t in ts])
    for name in RULES:
        f = np.array([np.nan if c is None else t["fields"].get(c, np.nan) for c, t in zip(picks[name], ts)])
        r = f / best
        print(
            f"| {name} | {int(np.sum(f <= 0.005))} of {len(f)} | {np.nanmedian(f):.4f} | {np.nanmax(f):.4f} | "
            f"{np.nanmedian(r):.3f} | {int(np.sum(r > 1.05))} |"
        )
    print()
    print(
        f"median choice time plain {np.median([t['t_plain'] for t in ts]):.0f} s, strings separated "
        f"{np.median([t['t_sep'] for t in ts]):.0f} s, the field stage "
        f"{np.median([t['field_stage']['seconds'] for t in ts]):.0f} s (plain folds) / "
        f"{np.median([t['field_stage_sep']['seconds'] for t in ts]):.0f} s (strings separated) "
        f"({time.perf_counter() - t0:.0f} s)"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
