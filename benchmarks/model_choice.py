"""Does the model choice hold on unseen shots? Held-out d of every candidate and of the choice.

Usage::

    .venv/bin/python benchmarks/model_choice.py [--real DIR] [--lenses 20] [--fit-shots 3,4,6]
        [--population points] [--skip-real] [--separated]

Two parts (issue 19 items 2 and 5):

* **The real photographs** (``../shared/data/real-harp`` or ``$HARP_REAL_DATA``): every split of the
  three shots into two fitted and one held out. For each candidate of ``harp calibrate``
  (:data:`pipeline.cross_validation.DEFAULT_CANDIDATES`) fitted on the two, the held-out shot's d, measured
  on whole strings (the measurement of ``harp measure``, ends kept) and on the paper's interior-only
  points (``smoothing="gaussian"``: 3 sigma = 72 px dropped at both ends of every piece); the choice
  made on the two shots (:func:`pipeline.select.select_model`) and its ratio to the best candidate on
  the held-out shot. Then the choice on all three shots (leave-one-shot-out and alternate-string tables).
* **A seeded population of lenses**: for each lens, ``n`` shots to fit and three unseen shots at other
  orientations; the choice made on the ``n`` shots against the best candidate on the unseen ones
  (held-out d, whole strings) and the old rule (leave-one-shot-out alone, one standard error); then the same
  on twelve unseen shots (the three and :data:`EXTRA_UNSEEN` more at seeded random angles), where each unseen
  shot's own field and bends weigh less in which candidate looks best. With
  ``--population points`` the shots are point sets: ideal strings of a harp of 15 strings 125 px
  apart on 1761x1174 mapped through an exact lens (radial k1..k3, decentering, thin prism, centre up to
  30 px off), each string bent by its own Legendre P2..P4 terms (harp-fixed, 0.015 px each) plus a
  bend of its own in every shot (0.015 px), every shot moved by a smooth field of its own (quadratic
  and cubic terms, 0.04 px each: an orientation's own measurement bias), raw points every pixel with
  0.06 px noise smoothed as the measurement does (``smooth_subsample``, t = 30). With ``--separated`` also the
  choice with the turntable angles known (``select_model(..., turntable_deg=...)``, :mod:`pipeline.separated_cv`)
  against the two tiers, every candidate fitted with the strings separated: its d on the unseen shots with their
  strings' fitted bends removed and its field error against the exact lens, over the best candidate's.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from pipeline.compare import compare_models
from pipeline.cross_validation import DEFAULT_CANDIDATES, FALLBACK, CVRow, paired_difference
from pipeline.edgeset import held_out_residuals
from pipeline.fit import fit_distortion
from pipeline.fitspec import FitSpec
from pipeline.harp_shape import fit_harp_shape
from pipeline.models import RadialModel
from pipeline.resample import point_sigma, sample_noise, smooth_subsample
from pipeline.select import SEPARATED_FOLDS, select_model
from pipeline.separated_cv import held_out_without_strings

REAL = Path(os.environ.get("HARP_REAL_DATA", Path(__file__).resolve().parents[2] / "shared" / "data" / "real-harp"))


def held_d(model, lines: Sequence[np.ndarray]) -> float:
    r = held_out_residuals(model, lines)
    return float(np.sqrt(np.mean(r**2))) if len(r) else float("nan")


def old_rule(table: Sequence[CVRow]) -> FitSpec:
    """The choice before issue 19: leave-one-shot-out alone, fewest parameters within one SE."""
    ok = [r for r in table if np.isfinite(r.cv_d)]
    best = min(ok, key=lambda r: r.cv_d)
    good = [r for r in ok if r is best or (lambda d: np.isfinite(d[0]) and d[0] <= d[1])(paired_difference(r, best))]
    return min(good, key=lambda r: (r.n_params, r.cv_d)).candidate


# ------------------------------------------------------------------------ real photographs
def real_part(directory: Path) -> None:
    from real_photos import real_points

    measured = real_points(directory)
    if measured is None:
        return
    names, whole, interior, (w, h) = measured
    print(f"## Real photographs ({directory.name}: {', '.join(names)}), {w}x{h}")
    print()
    for held in names:
        fit_on = [n for n in names if n != held]
        t0 = time.perf_counter()
        sel = select_model([whole[n] for n in fit_on], w, h)
        t_sel = time.perf_counter() - t0
        rows = []
        for c in DEFAULT_CANDIDATES:
            f = fit_distortion([whole[n] for n in fit_on], w, h, **c.fit_arguments())
            if not f:
                rows.append((c, float("nan"), float("nan"), float("nan")))
                continue
            rows.append((c, f.d_after, held_d(f.model, whole[held]), held_d(f.model, interior[held])))
        best = min(r[2] for r in rows if np.isfinite(r[2]))
        best_i = min(r[3] for r in rows if np.isfinite(r[3]))
        print(f"### fitted on {' + '.join(fit_on)}, {held} held out (choice in {t_sel:.1f} s)")
        print()
        print("| candidate | fit d px | held-out d, whole strings px | held-out d, interior only px | choice |")
        print("|---|---:|---:|---:|---|")
        for c, fd, hd, hi in rows:
            mark = "**chosen**" if c == sel.choice else ""
            print(f"| {c.label} | {fd:.4f} | {hd:.4f} | {hi:.4f} | {mark} |")
        ch = next(r for r in rows if r[0] == sel.choice)
        print()
        print(
            f"choice {sel.choice.label}: held-out d {ch[2]:.4f} px whole ({ch[2] / best:.3f}x the best "
            f"{best:.4f}), {ch[3]:.4f} px interior ({ch[3] / best_i:.3f}x the best {best_i:.4f})"
        )
        print(f"reason: {sel.reason}")
        print()
    sel = select_model([whole[n] for n in names], w, h)
    print("### all three shots: the choice")
    print()
    print(f"{sel.choice.label}: {sel.reason}")
    print()
    strings = {r.candidate: r for r in sel.strings_table}
    print("| candidate | params | leave-one-shot-out CV d px | per fold | alternate-string CV d px (tier 2) |")
    print("|---|---:|---:|---|---:|")
    for r in sel.table:
        s = strings.get(r.candidate)
        folds = " ".join(f"{v:.4f}" for v in r.fold_d)
        cv = f"{r.cv_d:.4f}" if np.isfinite(r.cv_d) else f">= {r.cv_d_bound:.4f} (stopped)"
        print(f"| {r.candidate.label} | {r.n_params} | {cv} | {folds} | {'' if s is None else f'{s.cv_d:.4f}'} |")
    print()


# ------------------------------------------------------------------------ point population
W_PT, H_PT = 1761, 1174


def _legendre_bend(u: np.ndarray, c: np.ndarray) -> np.ndarray:
    return c[0] * 0.5 * (3 * u**2 - 1) + c[1] * 0.5 * (5 * u**3 - 3 * u) + c[2] * (35 * u**4 - 30 * u**2 + 3) / 8


def point_lens(seed: int) -> RadialModel:
    rng = np.random.default_rng(seed)
    c = ((W_PT - 1) / 2 + rng.normal(0, 15), (H_PT - 1) / 2 + rng.normal(0, 15))
    return RadialModel.for_image(
        W_PT,
        H_PT,
        k=(1.0, 0.0, rng.uniform(-0.06, 0.08), 0.0, rng.normal(0, 0.02), 0.0, rng.normal(0, 0.005)),
        center=c,
        tangential=tuple(rng.normal(0, 8e-4, 2)),
        prism=(rng.normal(0, 6e-4), 0.0, rng.normal(0, 6e-4), 0.0),
    )


def point_shot(
    lens: RadialModel, harp_bends: np.ndarray, angle: float, seed: int, sigma_out: list[np.ndarray] | None = None
) -> list[np.ndarray]:
    """One shot's smoothed edges; with ``sigma_out``, each edge's point sigmas appended to it
    (``pipeline.resample.point_sigma``, the edge's noise from ``sample_noise``; benchmarks/point_weights.py)."""
    rng = np.random.default_rng(seed)
    field = rng.normal(0, 0.04, (2, 6))
    t = np.radians(angle)
    d, n = np.array([np.cos(t), np.sin(t)]), np.array([-np.sin(t), np.cos(t)])
    c0 = np.array([(W_PT - 1) / 2, (H_PT - 1) / 2])
    half = 0.5 * np.hypot(W_PT, H_PT) * 1.15
    lines = []
    for k, hb in enumerate(harp_bends):
        q = (k - (len(harp_bends) - 1) / 2) * 125.0
        own = rng.normal(0, 0.015, 3)
        s = np.arange(-half, half, 1.0)
        dev = _legendre_bend(s / half, hb) + _legendre_bend(s / half, own)
        for side in (-1.4, 1.4):
            p = lens.distort_points(c0 + (q + side + dev)[:, None] * n + s[:, None] * d)
            xn, yn = (p[:, 0] - W_PT / 2) / (W_PT / 2), (p[:, 1] - H_PT / 2) / (H_PT / 2)
            basis = np.stack([xn * xn, xn * yn, yn * yn, xn**3, xn * yn * yn, yn**3])
            p = p + np.column_stack([field[0] @ basis, field[1] @ basis])
            ok = np.all(np.isfinite(p), 1) & np.all((p > 5) & (p < [W_PT - 6, H_PT - 6]), 1)
            idx = np.flatnonzero(ok)
            if len(idx) < 100:
                continue
            runs = np.split(idx, np.flatnonzero(np.diff(idx) > 1) + 1)
            idx = max(runs, key=len)
            raw = p[idx] + rng.normal(0, 0.06, (len(idx), 2))
            lines.append(smooth_subsample(raw, 30))
            if sigma_out is not None:
                sigma_out.append(point_sigma(raw, sample_noise(raw), 30))
    return lines


def point_angles(seed: int, nfit: int) -> tuple[np.ndarray, list[float], list[float]]:
    """Lens ``seed``'s harp (each string's P2..P4 bend, px), the turntable angles of its ``nfit`` fitted shots and
    of its 3 unseen ones (degrees: the strings' direction in the image, :func:`point_shot`)."""
    rng = np.random.default_rng(seed + 7)
    harp = rng.normal(0, 0.015, (15, 3))
    base = rng.uniform(0, 180)
    fa = [(base + 180 * i / nfit + rng.normal(0, 5)) % 180 for i in range(nfit)]
    ta = [(base + 90 / nfit + 60 * i + rng.normal(0, 5)) % 180 for i in range(3)]
    return harp, fa, ta


def point_session(
    seed: int, nfit: int, sigmas: list[list[np.ndarray]] | None = None
) -> tuple[RadialModel, list[list[np.ndarray]], list[list[np.ndarray]]]:
    """Lens ``seed`` of the point-set population, its ``nfit`` shots to fit (spread over 180 degrees) and 3
    unseen shots between them, one harp (15 strings with their own bends) in all; with ``sigmas``, each
    fitted shot's point sigmas appended to it (:func:`point_shot`)."""
    lens = point_lens(seed)
    harp, fa, ta = point_angles(seed, nfit)
    fs = []
    for i, a in enumerate(fa):
        out: list[np.ndarray] | None = None if sigmas is None else []
        fs.append(point_shot(lens, harp, a, seed * 100 + i, out))
        if sigmas is not None and out is not None:
            sigmas.append(out)
    ts = [point_shot(lens, harp, a, seed * 100 + 50 + i) for i, a in enumerate(ta)]
    return lens, fs, ts


EXTRA_UNSEEN = 9
"""Unseen shots added to each lens's three (at seeded random angles) for the second measure of the population:
the held-out d on twelve unseen shots, where each shot's own field and bends weigh less in which candidate
looks best."""


def extra_unseen(seed: int, lens: RadialModel, n: int = EXTRA_UNSEEN) -> list[list[np.ndarray]]:
    """``n`` more unseen shots of lens ``seed``'s harp (:func:`point_session`'s harp and shots, other angles)."""
    harp, _, _ = point_angles(seed, 3)  # the harp does not depend on the number of fitted shots
    angles = np.random.default_rng(seed + 1000).uniform(0, 180, n)
    return [point_shot(lens, harp, float(a), seed * 100 + 53 + i) for i, a in enumerate(angles)]


def population_part(n_lenses: int, fit_counts: Sequence[int], first_seed: int = 0, separated: bool = False) -> None:
    print(
        "## Population (point sets): chosen model's held-out d on unseen shots over the best candidate's "
        f"({n_lenses} seeded lenses per row, seeds {first_seed}..{first_seed + n_lenses - 1}): on each lens's 3 "
        f"unseen shots, and on those and {EXTRA_UNSEEN} more at random angles"
    )
    print()
    print(
        "| shots fitted | rule | worst ratio | mean ratio | lenses > 1.05 | median best held-out d px "
        f"| {3 + EXTRA_UNSEEN} unseen: worst ratio | mean ratio | lenses > 1.05 |"
    )
    print("|---:|---|---:|---:|---:|---:|---:|---:|---:|")
    sep_rows: list[tuple[int, dict[str, list[float]]]] = []
    for nfit in fit_counts:
        sep: dict[str, list[float]] = {}
        sep_rows.append((nfit, sep))
        rules = ("two tiers (now)", "leave-one-shot-out alone (before)")
        ratios: dict[str, list[float]] = {rule: [] for rule in rules}
        ratios12: dict[str, list[float]] = {rule: [] for rule in rules}
        bests = []
        for seed in range(first_seed, first_seed + n_lenses):
            lens, fs, ts = point_session(seed, nfit)
            ts12 = ts + extra_unseen(seed, lens)
            sel = select_model(fs, W_PT, H_PT)
            unseen, unseen12 = {}, {}
            for r in sel.table:
                f = r.full_fit or fit_distortion(fs, W_PT, H_PT, **r.candidate.fit_arguments())
                if f:
                    unseen[r.candidate] = held_d(f.model, [p for s in ts for p in s])
                    unseen12[r.candidate] = held_d(f.model, [p for s in ts12 for p in s])
            best, best12 = min(unseen.values()), min(unseen12.values())
            bests.append(best)
            for rule, spec in zip(rules, (sel.choice, old_rule(sel.table)), strict=True):
                ratios[rule].append(unseen[spec] / best)
                ratios12[rule].append(unseen12[spec] / best12)
            if separated:
                for k, v in separated_ratios(seed, nfit, lens, fs, ts, sel.choice).items():
                    sep.setdefault(k, []).append(v)
        for rule, v in ratios.items():
            a, b = np.array(v), np.array(ratios12[rule])
            print(
                f"| {nfit} | {rule} | {a.max():.3f} | {a.mean():.3f} | {int(np.sum(a > 1.05))} / {len(a)} | "
                f"{np.median(bests):.4f} | {b.max():.3f} | {b.mean():.3f} | {int(np.sum(b > 1.05))} / {len(b)} |"
            )
    print()
    if separated:
        print_separated(sep_rows, n_lenses, first_seed)


COMPARED = (
    "for comparison: lowest CV d of the separated folds",
    f"for comparison: no choice ({FALLBACK.label})",
)
"""Two rules that are not the pipeline's, printed beside the choice with the strings separated (``--separated``)."""

SEPARATED_MEASURES = (
    ("unseen", "unseen d, strings removed"),
    ("field", "field error"),
)


def separated_ratios(
    seed: int, nfit: int, lens: RadialModel, fs: list[list[np.ndarray]], ts: list[list[np.ndarray]], plain: FitSpec
) -> dict[str, float]:
    """The choice with the turntable angles known (``select_model(..., turntable_deg=...)``) against the plain
    choice ``plain``, every candidate fitted with the strings separated (what a session stores): each one's
    d on the unseen shots with their strings' fitted bends removed (the unseen shots' angles known) and its
    field error against the exact lens, both over the best candidate's (``--separated``)."""
    _, fa, ta = point_angles(seed, nfit)
    t0 = time.perf_counter()
    sel = select_model(fs, W_PT, H_PT, turntable_deg=fa)
    elapsed = time.perf_counter() - t0
    unseen, field = {}, {}
    for r in sel.table:
        plain_fit = r.full_fit or fit_distortion(fs, W_PT, H_PT, **r.candidate.fit_arguments())
        joint = fit_harp_shape(fs, fa, W_PT, H_PT, r.candidate, plain=plain_fit) if plain_fit else plain_fit
        if not joint:
            continue
        held = np.concatenate([held_out_without_strings(joint, s, a).residuals for s, a in zip(ts, ta, strict=True)])
        unseen[r.candidate] = float(np.sqrt(np.mean(held**2)))
        field[r.candidate] = float(compare_models(joint.model, lens, W_PT, H_PT, step=20).rms)
    out = {"t": elapsed, "separated folds": float(sel.folds == SEPARATED_FOLDS)}
    lowest = min((r for r in sel.table if np.isfinite(r.cv_d)), key=lambda r: r.cv_d).candidate
    others = ((COMPARED[0], lowest), (COMPARED[1], FALLBACK))
    for name, table in (("unseen", unseen), ("field", field)):
        best = min(table.values())
        out[f"{name} best"] = best
        for rule, spec in (("two tiers (now)", plain), ("strings separated (angles known)", sel.choice), *others):
            out[f"{name} {rule}"] = table.get(spec, float("nan")) / best
    return out


def print_separated(rows: list[tuple[int, dict[str, list[float]]]], n_lenses: int, first_seed: int) -> None:
    print(
        "## Population (point sets), every candidate fitted with the strings separated (what a session stores): "
        f"the choice with and without the turntable angles over the best candidate ({n_lenses} seeded lenses "
        f"per row, seeds {first_seed}..{first_seed + n_lenses - 1})"
    )
    print()
    print(
        "| shots fitted | measure | rule | worst ratio | mean ratio | lenses > 1.05 | median best px | median choice s |"
    )
    print("|---:|---|---|---:|---:|---:|---:|---:|")
    for nfit, sep in rows:
        if not sep:
            continue
        for key, name in SEPARATED_MEASURES:
            for rule in ("two tiers (now)", "strings separated (angles known)", *COMPARED):
                a = np.array(sep[f"{key} {rule}"])
                t = f"{np.median(sep['t']):.0f}" if rule.startswith("strings") else ""
                folds = "" if min(sep["separated folds"]) else " (some folds too few orientations: plain folds)"
                print(
                    f"| {nfit} | {name} | {rule}{folds if rule.startswith('strings') else ''} | {a.max():.3f} | "
                    f"{a.mean():.3f} | {int(np.sum(a > 1.05))} / {len(a)} | {np.median(sep[f'{key} best']):.4f} | {t} |"
                )
    print()


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--real", type=Path, default=REAL)
    ap.add_argument("--skip-real", action="store_true")
    ap.add_argument("--population", choices=("points", "none"), default="points")
    ap.add_argument("--lenses", type=int, default=20)
    ap.add_argument("--first-seed", type=int, default=0, help="seeds first..first+lenses-1 (a fresh population)")
    ap.add_argument("--fit-shots", default="3,4,6")
    ap.add_argument(
        "--separated", action="store_true", help="also the choice with the turntable angles known (strings separated)"
    )
    args = ap.parse_args(argv)
    print(
        f"# Model choice on unseen shots ({os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.1f} at start; "
        f"`benchmarks/model_choice.py {' '.join(argv if argv is not None else sys.argv[1:])}`)"
    )
    print()
    t0 = time.perf_counter()
    if not args.skip_real:
        real_part(args.real)
    if args.population == "points":
        population_part(args.lenses, [int(v) for v in args.fit_shots.split(",")], args.first_seed, args.separated)
    print(f"({time.perf_counter() - t0:.0f} s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
