"""Fitted correction against the true lens, per lens family: field error modulo homography.

Usage::

    .venv/bin/python benchmarks/field_error.py [--families barrel,wide-fisheye,...]

For each family of exact closed-form lenses (``tests/pipeline/lenses.py``: six mild
families on 1000x750, two wide-angle ones, about 300 px at the corners of 1600x1200),
six orientations of a harp (3 px dark strings, noise 1.5) are rendered, measured
(``pipeline.measure.measure_image``, ends kept) and the model is chosen by the
cross-validation of ``harp calibrate`` (``pipeline.select.select_model``, default
candidates, leave one shot out). The chosen spec is fitted on all six shots and compared
with the true lens over the whole image, borders included (``pipeline.compare.compare_models``,
grid step 10 px, corners included): RMS and max of what is left after the best homography.
The old default ``radial4+tangential+prism`` is shown beside it. Targets (issue 8): mild
<= 0.005 px RMS / <= 0.02 px max, wide-angle <= 0.01 / <= 0.05.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from pipeline.compare import compare_models
from pipeline.edgeset import straightness_of
from pipeline.fit import fit_distortion
from pipeline.fitspec import parse
from pipeline.select import select_model
from tests.pipeline.rendered_shots import exact_lens, exact_shots

FAMILIES = ("barrel", "pincushion", "mustache", "division", "tangential", "prism", "wide-division", "wide-fisheye")


def row(family: str) -> str:
    lens = exact_lens(family)
    w, h = lens.width, lens.height
    t0 = time.perf_counter()
    shots = exact_shots(family)
    t_meas = time.perf_counter() - t0
    d_before, _ = straightness_of([p for s in shots for p in s])
    t0 = time.perf_counter()
    sel = select_model(shots, w, h)
    t_cv = time.perf_counter() - t0
    cv = {r.candidate: r for r in sel.table}[sel.choice].cv_d
    fit = fit_distortion(shots, w, h, **sel.choice.fit_arguments())
    cmp = compare_models(fit.model, lens, w, h)
    old = fit_distortion(shots, w, h, **parse("radial4+tangential+prism").fit_arguments())
    cmp_old = compare_models(old.model, lens, w, h)
    wide = family.startswith("wide")
    target = (0.01, 0.05) if wide else (0.005, 0.02)
    ok = cmp.rms <= target[0] and cmp.max <= target[1]
    return (
        f"| {family} | {w}x{h} | {lens.corner_shift():.1f} | {sum(len(s) for s in shots)} | {d_before:.3f} | "
        f"{sel.choice.label} | {cv:.4f} | {fit.d_after:.4f} | {cmp.rms:.4f} | {cmp.max:.4f} | "
        f"{target[0]:g} / {target[1]:g} {'yes' if ok else 'NO'} | {cmp_old.rms:.4f} / {cmp_old.max:.4f} | "
        f"{t_meas:.0f} | {t_cv:.0f} |"
    )


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--families", default=",".join(FAMILIES))
    args = ap.parse_args(argv)
    print(
        f"# Field error modulo homography of the cross-validated correction, 6 orientations, noise 1.5 "
        f"({os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.1f} at start)"
    )
    print()
    print(
        "| lens family | image | corner shift px | edges | d before px | CV choice | CV d px | fit d px | "
        "field RMS px | field max px | target RMS / max | radial4+tangential+prism RMS / max px | "
        "render+measure s | CV s |"
    )
    print("|---|---|---:|---:|---:|---|---:|---:|---:|---:|---|---|---:|---:|")
    for fam in args.families.split(","):
        print(row(fam), flush=True)
    print()
    print(f"load average at end: {os.getloadavg()[0]:.1f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
