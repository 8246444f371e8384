"""Does the residual field help where the lens has structure the radial model lacks, and never hurt?

Usage::

    .venv/bin/python benchmarks/residual_field.py [--lenses 10] [--shots 5] [--workers 2]
        [--field-rms 0.005,0.04]

Issue 19 item 3. For each seed a lens of :func:`pipeline.lens_population.lens_population` (designs
drawn, manufacturing spread) twice: with its non-parametric field (RMS drawn in ``--field-rms``, the
population's documented range by default) and without it (the same radial + tangential + prism lens).
Each is photographed by the realistic simulator (:func:`pipeline.realism.realistic_session`: bent
strings fixed to the harp, field-dependent blur, vignetting, back-light, shot noise, Bayer sensor and
demosaicing, 8 bits; 1000x750, pitch 60-80 px) at ``--shots`` turntable angles 180/shots apart, the
shots measured (:func:`pipeline.measure.measure_image`, t = 30) and the choice made among
``radial4+tangential+prism`` and that model with each field of
:func:`pipeline.select.field_candidates` (8x6 and 12x9 control points, penalties 1e-4, 1e-3, 1e-2) by
:func:`pipeline.select.select_model`. Figures: the field error modulo homography against the exact
lens (:func:`pipeline.compare.compare_models`, RMS over a 10 px grid) of the radial model fitted on all
shots and of the choice, and the leave-one-shot-out CV d of both.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from pipeline.compare import compare_models
from pipeline.fitspec import parse
from pipeline.select import field_candidates, select_model

W, H = 1000, 750
BASE = parse("radial4+tangential+prism")


def session(args: tuple[int, bool, int, tuple[float, float]]) -> dict[str, object]:
    """Render, measure, choose and compare one lens (module docstring)."""
    import threadpoolctl

    from pipeline.lens_population import lens_population
    from pipeline.measure import measure_image
    from pipeline.realism import realistic_session, render_shots

    seed, field, n_shots, rms = args
    t0 = time.perf_counter()
    with threadpoolctl.threadpool_limits(1):
        lens = lens_population(2026, seed + 1, W, H, field=field, field_rms_px=rms)[seed]
        s = realistic_session(seed, W, H, spacing_px=(60.0, 80.0), string_width_px=(2.5, 3.0))
        turntable = [k * 180.0 / n_shots for k in range(n_shots)]
        shots = render_shots(lens.model, s.harp, s.mount, turntable, W, H, s.effects, seed=seed)
        lines = [[ln.points for ln in measure_image(sh.image, t=30).lines] for sh in shots]
        sel = select_model(lines, W, H, candidates=field_candidates(BASE))
    rows = {r.candidate: r for r in sel.table}
    base, chosen = rows[BASE], rows[sel.choice]
    assert base.full_fit is not None and chosen.full_fit is not None
    return {
        "seed": seed,
        "field": field,
        "field_rms": lens.field_rms_px,
        "design": lens.design,
        "choice": sel.choice.label.replace(BASE.label, "base"),
        "cv_base": base.cv_d,
        "cv_choice": chosen.cv_d,
        "err_base": compare_models(base.full_fit.model, lens.model, W, H).rms,
        "err_choice": compare_models(chosen.full_fit.model, lens.model, W, H).rms,
        "seconds": time.perf_counter() - t0,
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--lenses", type=int, default=10)
    ap.add_argument("--shots", type=int, default=5)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--field-rms", default="0.005,0.04")
    a = ap.parse_args(argv)
    lo, hi = (float(v) for v in a.field_rms.split(","))
    jobs = [(seed, field, a.shots, (lo, hi)) for field in (True, False) for seed in range(a.lenses)]
    print(f"# {os.uname().nodename}: load average {os.getloadavg()[0]:.1f} at start, {a.workers} workers")
    print(f"# base = {BASE.label}; {a.shots} shots per lens, 1000x750, field RMS {lo:g}-{hi:g} px")
    print()
    print("| lens | design | field RMS px | choice | CV d base px | CV d choice px | field err base px "
          "| field err choice px | choice / base | s |")  # fmt: skip
    print("|---:|---|---:|---|---:|---:|---:|---:|---:|---:|")
    with ProcessPoolExecutor(a.workers) as pool:
        out = list(pool.map(session, jobs))
    for r in out:
        ratio = float(r["err_choice"]) / float(r["err_base"])  # type: ignore[arg-type]
        print(
            f"| {r['seed']} | {r['design']} | {r['field_rms']:.4f} | {r['choice']} | {r['cv_base']:.4f} "
            f"| {r['cv_choice']:.4f} | {r['err_base']:.4f} | {r['err_choice']:.4f} | {ratio:.2f} | {r['seconds']:.0f} |"
        )
    print()
    for field in (True, False):
        sub = [r for r in out if r["field"] is field]
        eb = np.array([r["err_base"] for r in sub], float)
        ec = np.array([r["err_choice"] for r in sub], float)
        n_field = sum(1 for r in sub if r["choice"] != "base")
        kind = "with a field" if field else "without a field"
        print(
            f"lenses {kind}: field chosen for {n_field} of {len(sub)}; field error median base {np.median(eb):.4f} "
            f"-> choice {np.median(ec):.4f} px; lower for {int(np.sum(ec < eb))}, equal for {int(np.sum(ec == eb))}, "
            f"higher for {int(np.sum(ec > eb))} (worst ratio {np.max(ec / eb):.2f})"
        )
    print(f"# load average at end {os.getloadavg()[0]:.1f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
