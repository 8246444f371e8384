"""Stacking instead of choosing: a cross-validated weighted average of the candidates' corrections.

Usage::

    .venv/bin/python benchmarks/stacking.py [--real DIR] [--skip-real] [--lenses 20] [--first-seed 0]
        [--fit-shots 3,4,6] [--workers 2] [--cache DIR]

Issue 19 item 2 asks for a correction that holds on unseen shots; :func:`pipeline.select.select_model` chooses
one candidate. Stacking [1]_ [2]_ keeps them all: the correction is :math:`U_w(x) = \\sum_c w_c U_c(x)`
(:math:`w_c \\ge 0`, :math:`\\sum_c w_c = 1`), the weights chosen on the cross-validation folds. Every
correction is defined up to a homography only (:mod:`pipeline.compare`), so each candidate's correction is first
moved onto a reference's (:data:`pipeline.cross_validation.FALLBACK`, else the first candidate) by the
least-squares homography over an image grid (:func:`pipeline.compare.fit_homography`), in every fold and for the
fits on all shots alike.

The TLS residual of a point is, to first order in the corrections' differences, linear in the points: with
each held-out edge's normal :math:`n_e` and positions :math:`a_i` along it taken from the reference's corrected
points, :math:`\\rho_{c,i} = n_e \\cdot (P_{c,i} - \\bar P_{c,e})` and :math:`r_{c,i} = \\rho_{c,i} - a_i
\\sum_j a_j \\rho_{c,j} / \\sum_j a_j^2` (the line's small turn removed), the held-out residual of the blend is
:math:`\\sum_c w_c r_c`, and its mean square over
the folds is :math:`w^T G w / N`, :math:`G = R^T R`. The weights minimise it on the simplex (NNLS with the
sum-to-one row weighted 1e6, [1]_'s non-negative stacking; no target: a straight edge is zero residual). The
TLS line of the blend is the best line, so the exact held-out figure is at most the linear one: both are
printed for the folds (``linear`` vs ``exact``).

Fold fits are :mod:`pipeline.cross_validation`'s (warm-started Gauss-Newton from the fit on all shots, the full
fit's outlier edges left out; its final pass when that does not converge). Candidates: the ones the choice's
table cross-validated to the end (finite CV d; stopped and failed ones left out). Variants:

* **loso**: weights from the leave-one-shot-out folds (3 shots or more);
* **strings**: from the alternate-string folds (every orientation in each fit; the only folds with 2 shots);
* **both**: from both, each fold set's mean square weighted equally;
* **both, half to the rule**: ``0.5 w_both + 0.5 e_choice`` (shrinkage toward the rule's choice);
* **strings, tier 1's candidates only**: the rule's two tiers with tier 2 blending instead of picking: weights
  from the alternate-string folds over the candidates that tier 1 found to generalise to an unseen orientation;
* and, as the ceiling of any blend of these fits, the weights fitted on the unseen shots themselves.

Measured as ``benchmarks/model_choice.py`` measures the choice: on the real photographs' 2+1 splits (held-out
d of the third shot, whole strings and interior only) and on its point-set population (``nfit`` shots fitted, 3
unseen: held-out d over the best single candidate's, and field error against the exact lens over the least of
any candidate, :func:`pipeline.compare.compare_models`, grid step 40 px).

References
----------
.. [1] L. Breiman, "Stacked regressions", Machine Learning 24(1), 49-64, 1996.
.. [2] D. H. Wolpert, "Stacked generalization", Neural Networks 5(2), 241-259, 1992.
"""

from __future__ import annotations

import argparse
import os
import pickle
import sys
import time
from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from scipy.optimize import nnls

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from model_choice import H_PT, REAL, W_PT, held_d, point_session

from pipeline.compare import compare_models, fit_homography, image_grid
from pipeline.cross_validation import FALLBACK, _gauss_newton_fold, cv_folds
from pipeline.edgeset import FitResult, held_out_edges, held_out_residuals, tls
from pipeline.fit import fit_distortion
from pipeline.fitspec import FitSpec
from pipeline.models.homography import apply_homography
from pipeline.select import select_model

TIER2 = "strings, tier 1's candidates only"
VARIANTS = ("loso", "strings", "both", "both, half to the rule", TIER2)
CEILING = "ceiling: weights fitted on the unseen shots"


@dataclass(frozen=True)
class Blend:
    """The correction ``sum_c w_c H_c(U_c(x))`` (duck-typed as a model: ``undistort_points`` only)."""

    models: tuple[Any, ...]
    homographies: tuple[np.ndarray, ...]
    weights: np.ndarray

    def undistort_points(self, xy: np.ndarray) -> np.ndarray:
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        out = np.zeros_like(xy)
        for m, h, w in zip(self.models, self.homographies, self.weights, strict=True):
            if w > 0:
                out += w * apply_homography(h, m.undistort_points(xy))
        return out


def fold_models(cand: FitSpec, lines: list[list[np.ndarray]], w: int, h: int, full: FitResult, mode: str) -> list:
    """``[(model or None, held lines)]`` of every fold of ``mode``, fitted as :func:`cross_validate` does."""
    outliers = {id(lines[e.image][e.line]) for e in full.rejected if e.reason.startswith("outlier")}
    out = []
    for train, held in cv_folds(lines, mode):
        kept = [[p for p in s if id(p) not in outliers] for s in train]
        step = _gauss_newton_fold(cand, kept, w, h, full.model, {})
        if step is not None:
            out.append((step[0], held))
            continue
        r = fit_distortion(kept, w, h, **cand.fit_arguments(), init=full.model, robust=False)
        out.append((r.model if r else None, held))
    return out


def aligned(models: Sequence[Any], ref: int, grid: np.ndarray) -> list[np.ndarray]:
    """Each model's homography onto model ``ref``'s correction (least squares over ``grid``)."""
    target = models[ref].undistort_points(grid)
    return [
        np.eye(3) if i == ref else fit_homography(m.undistort_points(grid), target)[0] for i, m in enumerate(models)
    ]


def fold_gram(
    per_cand: list[list[tuple[Any, list[np.ndarray]]]], ref: int, grid: np.ndarray
) -> tuple[np.ndarray, int, list[tuple[tuple[Any, ...], tuple[np.ndarray, ...], list[np.ndarray]]]]:
    """``(G, N, folds)``: the Gram matrix of the candidates' linearised held-out residuals summed over the
    folds (module docstring), the number of held-out points, and each fold's (models, homographies, held)."""
    n_c = len(per_cand)
    gram = np.zeros((n_c, n_c))
    total = 0
    folds = []
    for k in range(len(per_cand[0])):
        models = tuple(pc[k][0] for pc in per_cand)
        held = per_cand[0][k][1]
        homs = tuple(aligned(models, ref, grid))
        pts = held_out_edges(held)
        if not pts:
            continue
        counts = np.array([len(p) for p in pts])
        starts = np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(int)
        xy = np.concatenate(pts)
        corr = [apply_homography(hh, m.undistort_points(xy)) for m, hh in zip(models, homs, strict=True)]
        _, along, normal, _, _ = tls(corr[ref], starts, counts)
        a2 = np.repeat(np.add.reduceat(along**2, starts), counts)
        cols = []
        for p in corr:
            mean = np.repeat(np.add.reduceat(p, starts, axis=0) / counts[:, None], counts, axis=0)
            rc = np.sum((p - mean) * normal, axis=1)
            # the line's turn to first order: the part of rc linear in the position along the line
            cols.append(rc - along * np.repeat(np.add.reduceat(along * rc, starts), counts) / a2)
        r = np.stack(cols, axis=1)
        ok = np.all(np.isfinite(r), axis=1)
        gram += r[ok].T @ r[ok]
        total += int(ok.sum())
        folds.append((models, homs, held))
    return gram, total, folds


def simplex_weights(gram: np.ndarray) -> np.ndarray:
    """``argmin w^T G w`` over ``w >= 0, sum w = 1`` (NNLS with a heavily weighted sum-to-one row)."""
    vals, vecs = np.linalg.eigh(gram / np.trace(gram))
    a = (vecs * np.sqrt(np.clip(vals, 0, None))).T
    lam = 1e3
    a = np.vstack([a, lam * np.ones(len(gram))])
    b = np.zeros(len(a))
    b[-1] = lam
    w = nnls(a, b, maxiter=50 * len(gram))[0]
    return w / w.sum()


def exact_fold_ms(folds: list, weights: np.ndarray) -> float:
    """The blend's exact held-out mean square over ``folds`` (TLS lines refitted)."""
    ss, n = 0.0, 0
    for models, homs, held in folds:
        r = held_out_residuals(Blend(models, homs, weights), held)
        r = r[np.isfinite(r)]
        ss += float(np.sum(r**2))
        n += len(r)
    return ss / max(n, 1)


def stack(
    lines: list[list[np.ndarray]], w: int, h: int
) -> tuple[Any, list[FitSpec], dict[FitSpec, Any], dict[str, np.ndarray], dict[str, tuple[float, float]], tuple]:
    """The rule's selection, the stacked candidates, their fits on all shots, each variant's weights, each
    variant's (linear, exact) CV mean square, and the aligned full models ``(models, homographies)``."""
    sel = select_model(lines, w, h)
    rows = [r for r in sel.table if np.isfinite(r.cv_d) and r.full_fit]
    cands = [r.candidate for r in rows]
    fulls = {r.candidate: r.full_fit for r in rows}
    ref = cands.index(FALLBACK) if FALLBACK in cands else 0
    grid = image_grid(w, h, step=40)
    grams: dict[str, tuple[np.ndarray, int, list]] = {}
    modes = ["images", "edges"] if len(lines) >= 3 else ["edges"]
    for mode in modes:
        per = [fold_models(c, lines, w, h, fulls[c], mode) for c in cands]
        # a candidate whose fold failed cannot be stacked: its column is left out by the weights (inf)
        bad = [i for i, pc in enumerate(per) if any(m is None for m, _ in pc)]
        if bad:
            for i in bad:
                per[i] = [(per[ref][k][0], held) for k, (_, held) in enumerate(per[i])]
        g, n, folds = fold_gram(per, ref, grid)
        for i in bad:
            g[i, :] = g[:, i] = 0.0
            g[i, i] = 1e6 * np.trace(g)
        grams["loso" if mode == "images" else "strings"] = (g, n, folds)
    weights: dict[str, np.ndarray] = {}
    figures: dict[str, tuple[float, float]] = {}
    for name, (g, _, _) in grams.items():
        weights[name] = simplex_weights(g)
    if "loso" in grams:
        (g1, n1, _), (g2, n2, _) = grams["loso"], grams["strings"]
        weights["both"] = simplex_weights(g1 / n1 + g2 / n2)
    else:
        weights["both"] = weights["strings"]
    e = np.zeros(len(cands))
    e[cands.index(sel.choice)] = 1.0
    weights["both, half to the rule"] = 0.5 * weights["both"] + 0.5 * e
    # tier 1 keeps the candidates that generalise to an unseen orientation; blend those on the strings
    if "loso" in grams:
        kept = {r.candidate for r in sel.strings_table if np.isfinite(r.cv_d)} or {sel.choice}
        idx = [i for i, c in enumerate(cands) if c in kept]
        g = grams["strings"][0]
        weights[TIER2] = np.zeros(len(cands))
        weights[TIER2][idx] = simplex_weights(g[np.ix_(idx, idx)])
    for name, (g, n, folds) in grams.items():
        wv = weights[name]
        figures[name] = (float(wv @ g @ wv / n), exact_fold_ms(folds, wv))
    models = tuple(fulls[c].model for c in cands)
    homs = tuple(aligned(models, ref, grid))
    figures["grams"] = {k: (g, n) for k, (g, n, _) in grams.items()}  # kept in the cache (one_lens), with the models
    return sel, cands, fulls, weights, figures, (models, homs)


# ------------------------------------------------------------------------ population
def one_lens(job: tuple[int, int, Path | None]) -> dict[str, Any]:
    seed, nfit, cache = job
    f = None if cache is None else cache / f"s_{seed}_{nfit}.pkl"
    if f is not None and f.exists():
        with open(f, "rb") as fh:
            out: dict[str, Any] = pickle.load(fh)
        if TIER2 in out["weights"] or nfit < 3:  # a cache from before the tier-2 variant is made again
            return out
    t0 = time.perf_counter()
    lens, fs, ts = point_session(seed, nfit)
    sel, cands, _, weights, figures, (models, homs) = stack(fs, W_PT, H_PT)
    held = [p for s in ts for p in s]
    unseen, field = {}, {}
    for r in sel.table:
        fit = r.full_fit or fit_distortion(fs, W_PT, H_PT, **r.candidate.fit_arguments())
        unseen[r.candidate.label] = held_d(fit.model, held) if fit else float("nan")
        field[r.candidate.label] = float(compare_models(fit.model, lens, W_PT, H_PT, step=40).rms) if fit else np.nan
    # the ceiling of any blend: weights fitted on the unseen shots themselves (not a correction one can make)
    ref = cands.index(FALLBACK) if FALLBACK in cands else 0
    g_unseen, n_unseen, _ = fold_gram([[(m, held)] for m in models], ref, image_grid(W_PT, H_PT, step=40))
    weights = {**weights, CEILING: simplex_weights(g_unseen)}
    blend_unseen, blend_field = {}, {}
    for name, wv in weights.items():
        b = Blend(models, homs, wv)
        r = held_out_residuals(b, held)
        blend_unseen[name] = float(np.sqrt(np.mean(r**2)))
        blend_field[name] = float(compare_models(b, lens, W_PT, H_PT, step=40).rms)
    out = {
        "seed": seed,
        "nfit": nfit,
        "choice": sel.choice.label,
        "cands": [c.label for c in cands],
        "weights": weights,
        "figures": figures,
        "unseen": unseen,
        "field": field,
        "blend_unseen": blend_unseen,
        "blend_field": blend_field,
        "t": time.perf_counter() - t0,
        "grams": {**figures.pop("grams"), "unseen": (g_unseen, n_unseen)},
        "models": (models, homs),
    }
    if f is not None:
        with open(f, "wb") as fh:
            pickle.dump(out, fh)
    return out


def _ratio_cells(a: np.ndarray) -> str:
    return f"{a.max():.3f} | {a.mean():.3f} | {int(np.sum(a > 1.05))} / {len(a)}"


def population_part(seeds: range, fit_counts: Sequence[int], workers: int, cache: Path | None) -> list[dict]:
    jobs = [(s, n, cache) for n in fit_counts for s in seeds]
    with ProcessPoolExecutor(workers) as ex:
        results = list(ex.map(one_lens, jobs))
    print(
        f"## Population (point sets, benchmarks/model_choice.py's), seeds {seeds.start}..{seeds.stop - 1}: "
        "held-out d on 3 unseen shots over the best single candidate's, field error over the least of any candidate"
    )
    print()
    print(
        "| shots fitted | correction | unseen d: worst ratio | mean ratio | lenses > 1.05 | field: worst ratio | "
        "mean ratio | lenses > 1.05 | unseen d below the rule's | field below the rule's |"
    )
    print("|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|")
    for nfit in fit_counts:
        rs = [r for r in results if r["nfit"] == nfit]
        best_u = np.array([min(v for v in r["unseen"].values() if np.isfinite(v)) for r in rs])
        best_f = np.array([min(v for v in r["field"].values() if np.isfinite(v)) for r in rs])
        rule_u = np.array([r["unseen"][r["choice"]] for r in rs])
        rule_f = np.array([r["field"][r["choice"]] for r in rs])
        print(
            f"| {nfit} | the rule's choice (now) | {_ratio_cells(rule_u / best_u)} | "
            f"{_ratio_cells(rule_f / best_f)} | | |"
        )
        for name in (*VARIANTS, CEILING):
            if (nfit < 3 and name == "loso") or any(name not in r["blend_unseen"] for r in rs):
                continue
            bu = np.array([r["blend_unseen"][name] for r in rs])
            bf = np.array([r["blend_field"][name] for r in rs])
            print(
                f"| {nfit} | stack: {name} | {_ratio_cells(bu / best_u)} | {_ratio_cells(bf / best_f)} | "
                f"{int(np.sum(bu < rule_u))} / {len(rs)} | {int(np.sum(bf < rule_f))} / {len(rs)} |"
            )
    print()
    print("CV mean square of the blend on its own folds, linear (w^T G w / N) against exact (TLS lines refitted):")
    lin = np.array([v[0] for r in results for k, v in r["figures"].items() if k != "grams"])
    ex_ = np.array([v[1] for r in results for k, v in r["figures"].items() if k != "grams"])
    print(
        f"exact / linear over {len(lin)} (lens, fold set) pairs: min {np.min(ex_ / lin):.6f}, "
        f"max {np.max(ex_ / lin):.6f}"
    )
    nz = [int(np.sum(r["weights"]["both"] > 0.01)) for r in results]
    print(
        f"candidates with weight > 0.01 in 'both': median {np.median(nz):.0f}, max {max(nz)} "
        f"(of {np.median([len(r['cands']) for r in results]):.0f} stacked, median); "
        f"median time per lens {np.median([r['t'] for r in results]):.0f} s"
    )
    print()
    return results


# ------------------------------------------------------------------------ real photographs
def real_part(directory: Path) -> None:
    from real_photos import real_points

    measured = real_points(directory)
    if measured is None:
        return
    names, whole, interior, (w, h) = measured
    print(f"## Real photographs ({directory.name}), {w}x{h}: every 2+1 split, held-out d of the third shot (px)")
    print()
    print(
        "| held out | best single (whole / interior) | rule's choice | stack: strings | stack: half to the rule | "
        "weights > 0.01 (strings) |"
    )
    print("|---|---|---|---|---|---|")
    for held in names:
        fit_on = [whole[n] for n in names if n != held]
        sel, cands, fulls, weights, figures, (models, homs) = stack(fit_on, w, h)
        d = {}
        for r in sel.table:  # every candidate, the stopped ones too (benchmarks/model_choice.py's best)
            f = r.full_fit or fit_distortion(fit_on, w, h, **r.candidate.fit_arguments())
            if f:
                d[r.candidate.label] = (held_d(f.model, whole[held]), held_d(f.model, interior[held]))
        bw = min(v[0] for v in d.values())
        bi = min(v[1] for v in d.values())
        rule = d[sel.choice.label]
        cells = []
        for name in ("strings", "both, half to the rule"):
            b = Blend(models, homs, weights[name])
            bd, bdi = held_d(b, whole[held]), held_d(b, interior[held])
            cells.append(f"{bd:.4f} ({bd / bw:.3f}x) / {bdi:.4f} ({bdi / bi:.3f}x)")
        big = ", ".join(f"{c.label} {v:.2f}" for c, v in zip(cands, weights["strings"], strict=True) if v > 0.01)
        print(
            f"| {held} | {bw:.4f} / {bi:.4f} | {sel.choice.label} {rule[0]:.4f} ({rule[0] / bw:.3f}x) / "
            f"{rule[1]:.4f} ({rule[1] / bi:.3f}x) | {cells[0]} | {cells[1]} | {big} |"
        )
    print()


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--real", type=Path, default=REAL)
    ap.add_argument("--skip-real", action="store_true")
    ap.add_argument("--lenses", type=int, default=20)
    ap.add_argument("--first-seed", type=int, default=0)
    ap.add_argument("--fit-shots", default="3,4,6", help="comma-separated; empty: no population")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--cache", type=Path, default=None, help="keep each lens's figures here (pickles)")
    args = ap.parse_args(argv)
    print(
        f"# Stacking the candidates ({os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.1f} at start; "
        f"`benchmarks/stacking.py {' '.join(argv if argv is not None else sys.argv[1:])}`)"
    )
    print()
    t0 = time.perf_counter()
    if not args.skip_real:
        real_part(args.real)
    if args.fit_shots:
        if args.cache is not None:
            args.cache.mkdir(parents=True, exist_ok=True)
        seeds = range(args.first_seed, args.first_seed + args.lenses)
        population_part(seeds, [int(v) for v in args.fit_shots.split(",")], args.workers, args.cache)
    print(f"({time.perf_counter() - t0:.0f} s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
