"""Focus interpolation and bootstrap field uncertainty on the demo lens: accuracy and time.

The demo lens (drivers/sim/lens.py, 1280x960) at focus 0, 0.25, ..., 1;
synthetic harp edges (8 orientations, strings every 40 px, points every
30 px, Gaussian noise on the points) fitted with radial degree 4 + tangential.

* Interpolation: fits at the calibrated settings (0, 0.5, 1); the leave-one-out
  error at 0.5 (what ``harp profile show --focus`` / ``harp qa`` report) next to
  the true error of the interpolated correction at 0.25 and 0.75 (vs the true
  lens, modulo homography), and the fit's own error at the calibrated settings.
* Bootstrap (20 replicates, edges resampled within each shot): uncertainty
  RMS / max next to the fit's true error RMS / max, and the time.

Prints markdown tables; ``--write`` saves them to benchmarks/RESULTS-qa.md.

    .venv/bin/python benchmarks/qa_figures.py [--write]
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from drivers.sim.lens import lens_for_focus
from pipeline.compare import compare_models
from pipeline.fit import fit_distortion
from pipeline.fitspec import FitSpec
from pipeline.interpolate import FocusInterpolator, leave_one_out_error
from pipeline.uncertainty import bootstrap_field_uncertainty
from tests.pipeline.harp_points import harp_point_sets

W, H = 1280, 960
ANGLES = [0, 22.5, 45, 67.5, 90, 112.5, 135, 157.5]
SPEC = FitSpec("radial", 4, tangential=True)
KW = SPEC.fit_arguments()


def shots(focus, noise, seed):
    return harp_point_sets(lens_for_focus(focus, W, H), W, H, ANGLES, spacing=40.0, noise=noise, seed=seed)


def interpolation_table(noise) -> list[str]:
    fits = {}
    rows = []
    for i, f in enumerate((0.0, 0.5, 1.0)):
        fits[f] = fit_distortion(shots(f, noise, seed=10 + i), W, H, **KW).model
    t0 = time.perf_counter()
    (loo,) = leave_one_out_error(fits, W, H)
    t_loo = time.perf_counter() - t0
    interp = FocusInterpolator(fits, W, H)
    rows.append(f"| {noise:g} | leave-one-out at 0.5 (from 0, 1) | {loo.rms_px:.4f} | {loo.max_px:.4f} | {t_loo:.2f} |")
    for f in (0.25, 0.75):
        c = compare_models(interp.at(f), lens_for_focus(f, W, H), W, H)
        rows.append(f"| {noise:g} | interpolated at {f:g} vs true lens | {c.rms:.4f} | {c.max:.4f} | |")
    for f in (0.0, 0.5, 1.0):
        c = compare_models(fits[f], lens_for_focus(f, W, H), W, H)
        rows.append(f"| {noise:g} | fit at {f:g} vs true lens | {c.rms:.4f} | {c.max:.4f} | |")
    return rows


def bootstrap_rows(noise) -> list[str]:
    data = shots(0.3, noise, seed=3)
    full = fit_distortion(data, W, H, **KW)
    t0 = time.perf_counter()
    u = bootstrap_field_uncertainty(data, W, H, SPEC, n_boot=20, seed=0, full_fit=full)
    dt = time.perf_counter() - t0
    c = compare_models(full.model, lens_for_focus(0.3, W, H), W, H)
    n_edges = sum(len(s) for s in data)
    return [f"| {noise:g} | {n_edges} | {u.rms:.4f} | {u.max:.4f} | {c.rms:.4f} | {c.max:.4f} | {dt:.1f} |"]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--write", action="store_true", help="save the tables to benchmarks/RESULTS-qa.md")
    args = ap.parse_args()
    out = [
        f"Machine: {platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, "
        f"Python {platform.python_version()}; demo lens {W}x{H}, 8 orientations, radial 4 + tangential.",
        "",
        "### Focus interpolation (calibrated at 0, 0.5, 1; PCHIP in focus, 32 px grid)",
        "",
        "| point noise (px) | what | RMS (px) | max (px) | time (s) |",
        "|---:|:---|---:|---:|---:|",
    ]
    for noise in (0.0, 0.01, 0.03):
        out += interpolation_table(noise)
    out += [
        "",
        "### Bootstrap field uncertainty (20 replicates) vs the fit's true error",
        "",
        "| point noise (px) | edges | unc. RMS | unc. max | true err. RMS | true err. max | time (s) |",
        "|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for noise in (0.005, 0.01, 0.03):
        out += bootstrap_rows(noise)
    text = "\n".join(out) + "\n"
    print(text)
    if args.write:
        (Path(__file__).resolve().parent / "RESULTS-qa.md").write_text(
            "# Focus interpolation and field uncertainty\n\n`.venv/bin/python benchmarks/qa_figures.py --write`"
            "\n\n" + text
        )


if __name__ == "__main__":
    main()
