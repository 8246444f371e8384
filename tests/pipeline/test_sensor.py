"""The sensor and the raw conversion: noise statistics, the colour filter array against
OpenCV's demosaicing, tone curves, and what Bayer and JPEG do to the edges of straight
strings, measured against their exact traced curves (``tests/pipeline/_harp_truth.py``)."""

from __future__ import annotations

import math
from functools import cache

import numpy as np
import pytest

from pipeline.harp_scene import Harp, HarpMount
from pipeline.measure import measure_image
from pipeline.models.radial import RadialModel
from pipeline.realism import Effects, render_shot
from pipeline.sensor import LUMA, Development, Sensor, develop, expose, jpeg_roundtrip, shot_noise_snr, tone_curve
from tests.pipeline import _harp_truth as truth


@pytest.mark.parametrize("irradiance", [0.5, 0.015])  # 10000 e- (drawn as a Gaussian) and 300 e- (Poisson)
def test_shot_noise_variance_is_the_mean_in_electrons(irradiance):
    sensor = Sensor(exposure=0.8, shot_noise=True, full_well_e=25000.0, adc_bits=16)
    raw = expose(np.full((400, 500), irradiance), sensor, np.random.default_rng(4))
    electrons = raw * sensor.full_well_e / sensor.full_scale
    mean = irradiance * 0.8 * 25000.0
    assert electrons.mean() == pytest.approx(mean, rel=2e-3)
    # variance = mean (+ the ADC's rounding, 1/12 code^2)
    assert electrons.var() == pytest.approx(mean + (25000.0 / 65535.0) ** 2 / 12, rel=0.02)


def test_read_noise_adds_in_quadrature_and_nothing_is_random_without_noise():
    sensor = Sensor(exposure=0.5, shot_noise=True, full_well_e=20000.0, read_noise_e=30.0, adc_bits=16)
    raw = expose(np.full((400, 400), 1.0), sensor, np.random.default_rng(1))
    e = raw * 20000.0 / sensor.full_scale
    assert e.var() == pytest.approx(10000.0 + 900.0, rel=0.02)
    assert shot_noise_snr(sensor) == pytest.approx(10000.0 / math.sqrt(10900.0))
    quiet = expose(np.full((10, 10), 0.3), Sensor(), np.random.default_rng(1))
    assert np.all(quiet == np.rint(0.3 * 0.8 * 16383))


@pytest.mark.parametrize("pattern", ["RGGB", "BGGR", "GRBG", "GBRG"])
@pytest.mark.parametrize("demosaic", ["bilinear", "ea", "half-size"])
def test_the_cfa_and_opencvs_demosaicing_agree_on_the_pattern(pattern, demosaic):
    response = (0.5, 1.0, 0.7)
    sensor = Sensor(exposure=0.6, cfa=pattern, channel_response=response)
    raw = expose(np.ones((40, 60)), sensor, np.random.default_rng(0))
    # the raw holds each pixel's own channel, where the pattern says
    names = {"R": 0, "G": 1, "B": 2}
    for r in (0, 1):
        for c in (0, 1):
            want = np.rint(0.6 * response[names[pattern[2 * r + c]]] * 16383)
            assert np.all(raw[r::2, c::2] == want)
    # without white balance every demosaiced channel is its response: the colours land where they belong
    flat = develop(raw, sensor, Development(demosaic=demosaic, white_balance=False, bit_depth=16)) / 65535.0
    grey = 0.6 * sum(w * g for w, g in zip(LUMA, response))
    assert np.abs(flat[4:-4, 4:-4] - grey).max() < 2e-4
    balanced = develop(raw, sensor, Development(demosaic=demosaic, bit_depth=16)) / 65535.0
    assert np.abs(balanced[4:-4, 4:-4] - 0.6).max() < 2e-4
    assert balanced.shape == ((20, 30) if demosaic == "half-size" else (40, 60))


def test_tone_curves_are_the_standards():
    x = np.array([0.0, 0.01, 0.018, 0.5, 1.0])
    bt = tone_curve(x, "bt709")
    assert bt == pytest.approx([0.0, 0.045, 1.099 * 0.018**0.45 - 0.099, 1.099 * 0.5**0.45 - 0.099, 1.0], abs=1e-12)
    assert tone_curve(np.array([0.5]), "srgb") == pytest.approx([1.055 * 0.5 ** (1 / 2.4) - 0.055])
    assert tone_curve(np.array([0.0031308]), "srgb")[0] == pytest.approx(12.92 * 0.0031308)
    assert np.array_equal(tone_curve(x, "linear"), x)
    with pytest.raises(ValueError, match="tone"):
        Development(tone="log")
    with pytest.raises(ValueError, match="jpeg_quality"):
        Development(jpeg_quality=90, bit_depth=16)


def test_jpeg_roundtrip_at_high_quality_is_close():
    img = (np.add.outer(np.arange(64), np.arange(80)) * 2 % 256).astype(np.uint8)
    back = jpeg_roundtrip(img, 95)
    assert back.shape == img.shape and back.dtype == np.uint8
    assert 0 < np.abs(back.astype(int) - img).mean() < 2.0


# ------------------------------------------------------------------ edges of straight strings
W, H = 512, 384
LENS = RadialModel.for_image(W, H, k=(1.0, 0.0, 0.03), center=(W / 2 + 9, H / 2 - 6), tangential=(0.001, -0.0005))
HARP = Harp.straight(17, 40.0, 3.0, 7.0)
CFA = Sensor(cfa="RGGB", channel_response=(0.5, 1.0, 0.7))
CASES = {
    "clean": Effects(development=Development(bit_depth=16)),
    "bilinear": Effects(sensor=CFA, development=Development(bit_depth=16)),
    "ea": Effects(sensor=CFA, development=Development(demosaic="ea", bit_depth=16)),
    "half-size": Effects(sensor=CFA, development=Development(demosaic="half-size", bit_depth=16)),
    "jpeg95": Effects(development=Development(jpeg_quality=95)),
}


@cache
def _edges(case: str, angle: float) -> dict[tuple[int, int], tuple[float, float, np.ndarray]]:
    """Per true edge: (median outward offset of the measured points from the exact curve, d
    measured, the measured points' offsets less that median), along the edge's ideal normal."""
    shot = render_shot(LENS, HARP, HarpMount(((W - 1) / 2, (H - 1) / 2), angle), 0.0, W, H, CASES[case], seed=3)
    m = measure_image(shot.image)
    c = truth.compare(shot, m)
    out = {}
    for mt in c.matches:
        te = c.truths[mt.truth]
        # distance along the ideal normal, positive outwards (to first order: the lens scale is ~1)
        s = te.edge.level(LENS.undistort_points(m.lines[mt.line].points)) * te.edge.side
        out[(te.edge.string_index, te.edge.side)] = (float(np.median(s)), m.d, s - np.median(s))
    assert len(out) >= 20 and all(te.length < 100 for te in c.missing)  # a short corner piece may go unmeasured
    return out


@pytest.mark.parametrize("angle", [3.0, 37.0, 88.0])
@pytest.mark.parametrize("case", ["bilinear", "ea", "half-size", "jpeg95"])
def test_bayer_and_jpeg_leave_the_string_centre_lines_and_straightness_unbiased(case, angle):
    """Against the clean image of the same strings: the centre line of each string (mean of its two
    edges) does not move (half-size: by the luma-weighted centroid of the 2x2 quad, -(0.046, 0.046)
    px, a constant shift), the edges stay straight within the stated RMS, d does not change;
    demosaicing widens a 3 px string by a constant (bilinear 0.07-0.11 px per edge, edge-aware
    0.03-0.09), JPEG at quality 95 by nothing."""
    clean, other = _edges("clean", angle), _edges(case, angle)
    n = np.array([-math.sin(math.radians(angle)), math.cos(math.radians(angle))])
    centroid = 0.25 * np.array([-LUMA[0] + LUMA[2], -LUMA[0] + LUMA[2]])  # R at (-1/4, -1/4), B at (+1/4, +1/4)
    shift = -(centroid @ n) if case == "half-size" else 0.0
    centre_moves, widening, rms = [], [], []
    for k in {key[0] for key in clean}:
        if not all((k, s) in clean and (k, s) in other for s in (-1, 1)):
            continue
        # outward offsets: side -1's is along -n, side +1's along +n
        centre_moves.append(0.5 * ((other[k, 1][0] - clean[k, 1][0]) - (other[k, -1][0] - clean[k, -1][0])))
        widening.append(0.5 * ((other[k, 1][0] - clean[k, 1][0]) + (other[k, -1][0] - clean[k, -1][0])))
        rms += [np.sqrt(np.mean(other[k, s][2] ** 2)) for s in (-1, 1)]
    assert len(centre_moves) >= 8
    assert np.abs(np.array(centre_moves) - shift).max() < 0.004
    bounds = {"bilinear": (0.06, 0.12), "ea": (0.025, 0.09), "half-size": (-0.005, 0.005), "jpeg95": (-0.003, 0.003)}
    lo, hi = bounds[case]
    assert lo < float(np.mean(widening)) < hi
    limit = {"bilinear": 0.02, "ea": 0.02, "half-size": 0.006, "jpeg95": 0.006}[case]
    assert float(np.sqrt(np.mean(np.square(rms)))) < limit
    d_clean, d_other = next(iter(clean.values()))[1], next(iter(other.values()))[1]
    assert d_other == pytest.approx(d_clean, rel=3e-3)


def test_the_clean_image_measures_on_the_exact_curves():
    for angle in (3.0, 37.0, 88.0):
        edges = _edges("clean", angle)
        assert max(float(np.sqrt(np.mean(v[2] ** 2))) for v in edges.values()) < 0.006
