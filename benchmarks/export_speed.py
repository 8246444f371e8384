"""How long the pin-hole exports of wide lenses and of a lens with a residual field take, with what they state.

Run:  .venv/bin/python benchmarks/export_speed.py [--cases eq93:opencv,field:opencv] [--code DIR]
Prints a Markdown table (committed in benchmarks/RESULTS-exports.md): for each lens and export, the
time of ``write_export`` in this process (the fit, its conversion error and the file) and the conversion
error it states (RMS / max modulo homography). ``--code DIR`` imports ``pipeline`` from another checkout
(e.g. a worktree of an earlier commit), so that the same cases time the code before a change.

Lenses: ``eq93`` / ``eq115`` the exact equisolid lenses of ``benchmarks/export_consumers.py`` (93 and 115
degrees diagonal, 640 x 480, decentred, with that benchmark's nominal focal length); ``wr93`` / ``wr115``
the same fields as harp radial models (``tests/pipeline/export_support.wide_radial``, a calibration that
chose a wide-angle model, as ``benchmarks/export_equations.py``); ``field`` the radial model with a
residual B-spline field of ``tests/pipeline/test_radial_field.py`` (1000 x 750, 0.3 px coefficients).
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time
from pathlib import Path

import numpy as np

EXPORTS = {  # label: (format, coeffs)
    "opencv": ("opencv", None),
    "opencv8": ("opencv", 8),
    "opencv5": ("opencv", 5),
    "ros": ("ros", None),
    "mrcal": ("mrcal", None),
    "colmap": ("colmap", None),
    "kalibr": ("kalibr", None),
    "metashape": ("metashape", None),
    "auto": ("auto", None),
}
DEFAULT = [f"{lens}:{e}" for lens in ("eq93", "eq115", "wr93", "wr115") for e in EXPORTS] + [
    f"field:{e}" for e in ("opencv", "ros", "mrcal", "colmap")
]


def source(name: str):  # the checkout's own ExportSource
    from pipeline.exports.lens import LensInfo
    from pipeline.exports.source import ExportSource
    from tests.pipeline.export_support import EquisolidLens, wide_radial

    if name.startswith("eq"):  # as benchmarks/export_consumers.py
        fov = float(name[2:])
        f = 0.5 * math.hypot(639, 479) / (2 * math.sin(math.radians(fov / 4)))
        lens = LensInfo(
            lens_maker="Sim", lens_model=f"Wide {fov:g}", camera_maker="Sim", camera_model="Cam",
            focal_mm=round(f * 3e-3, 4), pixel_pitch_um=3.0,
        )  # fmt: skip
        return ExportSource(EquisolidLens(f=f, cx=322.0, cy=236.5), 640, 480, lens=lens)
    if name.startswith("wr"):  # as benchmarks/export_equations.py
        return ExportSource(wide_radial(float(name[2:]), 640, 480), 640, 480, wide_angle=True)
    if name == "field":  # as tests/pipeline/test_radial_field.py
        from pipeline.models import RadialFieldModel, RadialModel
        from pipeline.models.radial_field import field_bounds

        w, h = 1000, 750
        rng = np.random.default_rng(3)
        base = RadialModel.for_image(w, h, k=(1.0, 0.0, 0.02), center=(505.0, 370.0), tangential=(1e-3, -5e-4))
        m = RadialFieldModel(base, field_bounds(w, h), rng.normal(0, 0.3, (6, 8)), rng.normal(0, 0.3, (6, 8)))
        return ExportSource(m, w, h, holdout_d=0.005)
    raise SystemExit(f"unknown lens {name!r}")


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--cases", default=",".join(DEFAULT), help="lens:export, comma-separated")
    ap.add_argument("--code", type=Path, default=Path(__file__).resolve().parents[1], help="checkout to time")
    args = ap.parse_args()
    sys.path.insert(0, str(args.code.resolve()))
    from pipeline.exports.registry import write_export
    from pipeline.exports.source import ExportOptions

    print(f"# Pin-hole exports of wide lenses and of a field — {os.cpu_count()} CPUs, load average "
          f"{os.getloadavg()[0]:.1f}\n")  # fmt: skip
    print("| lens | export | written as | stated RMS / max mod H (px) | time (s) |\n|---|---|---|---|---|")
    for case in args.cases.split(","):
        lens, label = case.split(":")
        fmt, coeffs = EXPORTS[label]
        src = source(lens)
        t0 = time.perf_counter()
        try:
            ex = write_export(fmt, src, ExportOptions(coeffs=coeffs))
        except ValueError as exc:
            print(f"| {lens} | {label} | refused: {str(exc).split(';')[0]} | | {time.perf_counter() - t0:.1f} |")
            continue
        dt = time.perf_counter() - t0
        note = next((n for n in ex.notes if n.startswith(f"{ex.format}: ")), None)
        written = ex.format + (" → " + note[len(ex.format) + 2 :].split()[0].rstrip(",:") if note else "")
        e = ex.error
        stated = "-" if e is None else f"{e.rms_mod_h_px:.4f} / {e.max_mod_h_px:.4f}"
        print(f"| {lens} | {label} | {written} | {stated} | {dt:.1f} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
