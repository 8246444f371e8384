"""How far the residual field the folds take leads the model, and what it does to the stored lens.

Usage::

    .venv/bin/python benchmarks/field_leads.py [--seeds 0,3,4] [--runs "without;with a field"] [--no-kinks]
        [--cache DIR]

For each lens of ``benchmarks/lens_limits.py``'s realistic population (seeds, 1000x750), without its
non-parametric field and with it (``--runs``), twelve shots at turntable angles 0..165 by 15 are rendered with the
realistic effects and measured as ``harp measure`` does. A session's choice follows (``pipeline.select.select_model``,
plain folds), then the field stage (``pipeline.select.select_field`` with the turntable angles: each fold fitted with
every string's bend, and with ``kink_t`` its kinks, separated; ``--no-kinks``: bends only, as before 2026-12-06's
second change). Printed per lens: the model and its stored field error (the joint fit with bends and kinks, as a
session stores it, against the exact lens, modulo homography, 20 px grid), the field the stage took and its stored
field error, and for every field candidate its CV d and its lead over the model (CV mean square, paired over the
held-out edges, in standard errors, :func:`pipeline.cross_validation.paired_difference`; and paired over the folds,
with in how many of the twelve folds it was better). The bar on that lead is
:data:`pipeline.select.FIELD_MARGIN_SE`; the field taken is the lowest CV d with the bar at zero. ``--cache`` keeps
the measured edges (one pickle per lens; a render takes a minute).
"""

from __future__ import annotations

import argparse
import pickle
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from lens_limits import field, seed_lens

from pipeline.cross_validation import paired_difference
from pipeline.measure import measure_image
from pipeline.realism import render_shots
from pipeline.resample import DEFAULT_T
from pipeline.select import is_flexible, lowest_radial, select_field, select_model

W, H = 1000, 750
ANGLES = tuple(float(a) for a in range(0, 180, 15))
RUNS = ("without", "with a field")


def measured(seed: int, run: str, cache: Path | None) -> list[list[np.ndarray]]:
    """The measured edges of the twelve shots (:data:`ANGLES`) of ``lens_limits``' lens ``seed`` (``run``: "with
    a field" or "without"), kept in ``cache`` (one pickle per lens) when given and read from there when present."""
    path = None if cache is None else cache / f"leads_{seed}_{run.replace(' ', '_')}.pkl"
    if path is not None and path.exists():
        lines: list[list[np.ndarray]] = pickle.loads(path.read_bytes())
        return lines
    lens, ses, _ = seed_lens(seed, W, H, run == "with a field")
    shots = render_shots(lens, ses.harp, ses.mount, ANGLES, W, H, ses.effects, seed=seed)
    lines = [[ln.points for ln in measure_image(s.image).lines] for s in shots]
    if path is not None:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(pickle.dumps(lines))
    return lines


def job(args: tuple[int, str, bool, Path | None]) -> dict[str, Any]:
    seed, run, kinks, cache = args
    lens, _, _ = seed_lens(seed, W, H, run == "with a field")
    t0 = time.perf_counter()
    lines = measured(seed, run, cache)
    sel = select_model(lines, W, H)
    radial = lowest_radial(sel.table)
    stage = select_field(
        lines, W, H, sel.choice, turntable_deg=list(ANGLES), radial=None if radial is None else radial.candidate,
        kink_t=DEFAULT_T if kinks else None,
    )  # fmt: skip
    rows = [r for r in stage.table if np.isfinite(r.cv_d)]
    out: dict[str, Any] = {"seed": seed, "run": run, "choice": sel.choice.label, "rows": []}
    model = next((r for r in rows if not is_flexible(r.candidate)), None)
    if model is not None:
        out["model"], out["model_cv"] = model.candidate.label, model.cv_d
        for r in rows:
            if r is model:
                continue
            delta, se = paired_difference(model, r)
            fold = np.array(model.fold_d) ** 2 - np.array(r.fold_d) ** 2
            fold_se = fold.std(ddof=1) / np.sqrt(len(fold))
            out["rows"].append(
                (r.candidate.label, r.cv_d, delta / se if se > 0 else np.nan, fold.mean() / fold_se, int((fold > 0).sum()), len(fold))
            )  # fmt: skip
        full = {r.candidate: r.full_fit for r in stage.table if r.full_fit is not None}
        out["model_err"] = field(
            lines, lens, W, H, model.candidate, plain=full.get(model.candidate), kinks=True, angles=ANGLES
        )
        best = min(rows, key=lambda r: r.cv_d)
        out["best"] = best.candidate.label
        if best is not model:
            out["best_err"] = field(
                lines, lens, W, H, best.candidate, plain=full.get(best.candidate), kinks=True, angles=ANGLES
            )
    out["t"] = time.perf_counter() - t0
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="0,3,4")
    ap.add_argument("--runs", default=";".join(RUNS))
    ap.add_argument("--no-kinks", action="store_true", help="folds that separate the strings' bends only")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--cache", type=Path, default=None)
    args = ap.parse_args(argv)
    runs = [r for r in RUNS if r in args.runs.split(";")]
    seeds = [int(s) for s in args.seeds.split(",")]
    print(f"# `benchmarks/field_leads.py {' '.join(argv if argv is not None else sys.argv[1:])}`")
    with ProcessPoolExecutor(args.workers) as pool:
        jobs = [(s, r, not args.no_kinks, args.cache) for s in seeds for r in runs]
        for o in pool.map(job, jobs):
            print(
                f"## seed {o['seed']} {o['run']}: choice {o['choice']}; model {o.get('model', '-')} stored "
                f"{o.get('model_err', np.nan):.4f} px, CV d {o.get('model_cv', np.nan):.5f}; lowest CV d "
                f"{o.get('best', '-')} stored {o.get('best_err', np.nan):.4f} px ({o['t']:.0f} s)",
                flush=True,
            )
            for label, cv, lead, fold_lead, better, n in o["rows"]:
                print(f"   {label:52s} CV d {cv:.5f}  lead {lead:6.2f} SE (edges) {fold_lead:6.2f} SE (folds), better in {better}/{n}")  # fmt: skip
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
