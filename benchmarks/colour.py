"""Colour and light: TCA field and vignetting from rendered harp shots against their exact truth.

Usage::

    .venv/bin/python benchmarks/colour.py [--quick]

TCA: for each mild lens family of ``tests/pipeline/lenses.py`` (the green lens) with the
realistic TCA of ``tests/pipeline/colour_lenses.py`` (red +0.9 px, blue -0.7 px at the
corners of 1000x750, decentred, a lateral shift; strength 1 and 2), six orientations of a
harp (8 px strings, blur 1 px, noise 1.5 on the 8-bit scale, RGGB mosaic, 16 bits,
white balance R 0.6 / B 0.5) are rendered through the exact per-channel maps, measured per
CFA plane without demosaicing (``pipeline.cfa.measure_mosaic``) and each channel's field
fitted against both green planes (``pipeline.tca.fit_tca``, degree 3). Printed: the field
error against the exact field over the whole image (RMS, max; grid step 8 px, corners
included) and the conversion error of lensfun's linear and poly3 TCA models. Target (issue
24): per-channel field error <= 0.01 px.

Vignetting: six grey shots at 1000x750 through the barrel lens, cos^4 vignetting
(f = 900 px: 0.49 at the corners), back-lights: uneven (a gradient and an ellipse, 23 %),
lamp off to one side (Gaussian hot spot, 30 %), and centred (brighter in the middle by
8 %: symmetric about the turntable axis, which no rotation separates: it is measured as
vignetting, shown to say so). Printed: the relative-illumination error over the image
(RMS, max) and lensfun pa's conversion error. Target: <= 1 % over the image.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np

from pipeline.cfa import measure_mosaic
from pipeline.measure import measure_image
from pipeline.render import HarpScene
from pipeline.render_colour import backlit_shading, render_mosaic, render_shaded
from pipeline.tca import channel_pairs, field_difference, fit_tca, lensfun_tca
from pipeline.vignetting import backlit_samples, fit_vignetting, lensfun_pa
from tests.pipeline.colour_lenses import colour_lens
from tests.pipeline.lenses import mild_lenses

W, H = 1000, 750
ANGLES = (2.0, 32.0, 62.0, 92.0, 122.0, 152.0)


def tca_rows(families: list[str], strengths: list[float]) -> list[str]:
    out = []
    for fam in families:
        for s in strengths:
            cl = colour_lens(W, H, fam, s)
            t0 = time.perf_counter()
            shots = []
            for i, a in enumerate(ANGLES):
                scene = HarpScene(angle_deg=a, spacing_px=50.0, string_width_px=8.0, phase_px=11.0 * i, blur_px=1.0)
                r = render_mosaic(W, H, scene, cl["lenses"], gains={"R": 0.6, "B": 0.5}, seed=100 + i)
                shots.append(measure_mosaic(r.image, "RGGB", t=30))
            t1 = time.perf_counter()
            fits = {ch: fit_tca(*channel_pairs(shots, ch), W, H, channel=ch) for ch in "RB"}
            t2 = time.perf_counter()
            lf = {k: lensfun_tca({c: f.field for c, f in fits.items()}, k) for k in ("linear", "poly3")}
            for ch, f in fits.items():
                truth = cl["tca"][ch]
                e = field_difference(f.field.to_reference, truth.to_reference, W, H)
                size = field_difference(truth.to_reference, lambda g: g, W, H).max
                out.append(
                    f"| {fam} | {s:g} | {ch} | {size:.2f} | {f.n_edges} | {f.residual_rms:.4f} | {e.rms:.4f} | {e.max:.4f} "
                    f"| {lf['linear'].error[ch].max:.3f} | {lf['poly3'].error[ch].max:.3f} | {t1 - t0:.1f} / {t2 - t1:.1f} |"
                )
            print("\n".join(out[-2:]), flush=True)
    return out


def cos4(x: np.ndarray) -> np.ndarray:
    c = np.array([(W - 1) / 2.0, (H - 1) / 2.0])
    return np.asarray(np.cos(np.arctan(np.hypot(*(np.asarray(x) - c).T) / 900.0)) ** 4)


R = 0.5 * float(np.hypot(W - 1, H - 1))
BACKLIGHTS = {
    "uneven (gradient + ellipse)": lambda h: (
        (1 + 0.10 * h[:, 0] / R + 0.06 * h[:, 1] / R)
        * (1 + 0.05 * ((h[:, 0] / R) ** 2 - (h[:, 1] / R) ** 2) + 0.04 * h[:, 0] * h[:, 1] / R**2)
    ),
    "lamp to one side (hot spot)": lambda h: (
        1 + 0.3 * np.exp(-((h[:, 0] - 0.6 * R) ** 2 + (h[:, 1] + 0.2 * R) ** 2) / (2 * (0.5 * R) ** 2))
    ),
    "centred (symmetric, not separable)": lambda h: (
        1 + 0.08 * np.exp(-(h[:, 0] ** 2 + h[:, 1] ** 2) / (2 * (0.6 * R) ** 2))
    ),
}


def vignetting_rows() -> list[str]:
    lens = mild_lenses(W, H)["barrel"]
    yy, xx = np.mgrid[0:H:4, 0:W:4]
    g = np.vstack(
        [np.column_stack([xx.ravel(), yy.ravel()]).astype(float), [[0, 0], [W - 1, 0], [0, H - 1], [W - 1, H - 1]]]
    )
    out = []
    for name, back in BACKLIGHTS.items():
        t0 = time.perf_counter()
        samples = []
        for i, a in enumerate(ANGLES):
            scene = HarpScene(angle_deg=a, spacing_px=50.0, string_width_px=8.0, phase_px=11.0 * i, blur_px=1.0)
            r = render_shaded(W, H, scene, lens, backlit_shading(W, H, cos4, back, a, lens), seed=i, shot_noise=True)
            m = measure_image(r.image, t=30)
            samples.append(backlit_samples(r.image, [ln.raw_points for ln in m.lines]))
        t1 = time.perf_counter()
        fit = fit_vignetting(samples, ANGLES, W, H, lens=lens)
        t2 = time.perf_counter()
        assert fit, fit
        rel = fit.relative_illumination(g) / cos4(g) - 1
        pa = lensfun_pa(fit)
        span = back(g - [(W - 1) / 2, (H - 1) / 2])
        out.append(
            f"| {name} | {span.max() / span.min() - 1:.0%} | {fit.n_samples} | {np.sqrt(np.mean(rel**2)):.4f} "
            f"| {np.abs(rel).max():.4f} | {pa.error_max:.4f} | {t1 - t0:.1f} / {t2 - t1:.2f} |"
        )
        print(out[-1], flush=True)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="one lens family, strength 1")
    a = ap.parse_args()
    fams = ["barrel"] if a.quick else ["barrel", "mustache", "tangential"]
    strengths = [1.0] if a.quick else [1.0, 2.0]
    print("TCA, per channel (pixels; times: render + measure / fit, s)\n")
    print(
        "| green lens | TCA strength | channel | TCA max | edges | residual RMS | field error RMS | field error max | lensfun linear max | lensfun poly3 max | time |"
    )
    print("| --- | ---: | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |")
    tca_rows(fams, strengths)
    print("\nVignetting (relative illumination; times: render + measure + samples / fit, s)\n")
    print("| back-light | its unevenness | samples | error RMS | error max | lensfun pa conversion max | time |")
    print("| --- | ---: | ---: | ---: | ---: | ---: | ---: |")
    vignetting_rows()


if __name__ == "__main__":
    main()
