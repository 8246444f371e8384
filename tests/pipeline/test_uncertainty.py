"""Bootstrap field uncertainty (pipeline/uncertainty.py) on synthetic edges with a known lens."""

import numpy as np
import pytest

from drivers.sim.lens import lens_for_focus
from pipeline.compare import compare_models
from pipeline.edgeset import FitFailure
from pipeline.fit import fit_distortion
from pipeline.fitspec import FitSpec
from pipeline.uncertainty import bootstrap_field_uncertainty
from tests.pipeline.harp_points import harp_point_sets

W, H = 640, 480
LENS = lens_for_focus(0.3, W, H)
ANGLES = [0, 45, 90, 135]
KW = FitSpec("radial", 3, tangential=True)


def shots(noise, spacing=40.0, seed=1, angles=ANGLES):
    return harp_point_sets(LENS, W, H, angles, spacing=spacing, noise=noise, seed=seed)


def test_seeded_and_honest():
    data = shots(0.02)
    a = bootstrap_field_uncertainty(data, W, H, KW, n_boot=12, seed=3)
    b = bootstrap_field_uncertainty(data, W, H, KW, n_boot=12, seed=3)
    c = bootstrap_field_uncertainty(data, W, H, KW, n_boot=12, seed=4)
    np.testing.assert_array_equal(a.std, b.std)
    assert a.rms != c.rms
    assert a.n_boot == 12 and a.n_failed == 0
    assert a.std.shape == (len(a.ys), len(a.xs)) and a.xs[0] == 0 and a.xs[-1] == W - 1
    assert a.max >= a.rms > 0
    # the map is what the fit's actual error (known lens, modulo homography) is like
    err = compare_models(a.model, LENS, W, H)
    assert 1 / 3 < a.rms / err.rms < 3, (a.rms, err.rms)


def test_uncertainty_shrinks_with_less_noise_and_more_edges():
    noisy = bootstrap_field_uncertainty(shots(0.02), W, H, KW, n_boot=12, seed=0)
    clean = bootstrap_field_uncertainty(shots(0.005), W, H, KW, n_boot=12, seed=0)
    dense = bootstrap_field_uncertainty(shots(0.02, spacing=20.0), W, H, KW, n_boot=12, seed=0)
    # a linear estimate: 4x less noise, about 4x less uncertainty
    assert 2.5 < noisy.rms / clean.rms < 6, (noisy.rms, clean.rms)
    # twice the edges: about 1/sqrt(2)
    assert dense.rms < 0.9 * noisy.rms, (dense.rms, noisy.rms)


def test_whole_image_resampling_and_failures():
    data = shots(0.01, angles=[0, 22.5, 45, 67.5, 90, 112.5, 135, 157.5])
    u = bootstrap_field_uncertainty(data, W, H, KW, n_boot=6, seed=0, resample="images")
    assert u.resample == "images" and u.n_boot + u.n_failed == 6 and u.n_boot >= 2
    assert np.isfinite(u.rms)
    # one orientation cannot be fitted at all: a failure with the fit's reason, not a number
    bad = bootstrap_field_uncertainty(shots(0.01, angles=[30]), W, H, KW, n_boot=4)
    assert isinstance(bad, FitFailure) and "full fit failed" in bad.reason
    with pytest.raises(ValueError, match="n_boot"):
        bootstrap_field_uncertainty(data, W, H, KW, n_boot=1)
    # a given full fit is used (and its rejected edges are not resampled)
    full = fit_distortion(data, W, H, **KW.fit_arguments())
    again = bootstrap_field_uncertainty(data, W, H, KW, n_boot=6, seed=0, resample="images", full_fit=full)
    np.testing.assert_array_equal(again.std, u.std)


def test_replicates_run_through_any_map():
    from concurrent.futures import ProcessPoolExecutor

    data = shots(0.01)
    serial = bootstrap_field_uncertainty(data, W, H, KW, n_boot=4, seed=2)
    with ProcessPoolExecutor(max_workers=2) as pool:
        pooled = bootstrap_field_uncertainty(data, W, H, KW, n_boot=4, seed=2, map_fn=pool.map)
    np.testing.assert_array_equal(serial.std, pooled.std)


def test_edge_resampling_draws_whole_strings():
    # measure() lists a string's two edges next to each other (lines 2k, 2k+1); they share the
    # string's own shape, so the bootstrap unit is the string (issue 5: "over strings/shots"),
    # never one side of it drawn independently of the other.
    data = [[q for p in lines for q in (p, p + 0.25)] for lines in shots(0.01)]
    jobs = []

    def spy_map(fn, js):
        js = list(js)
        jobs.extend(js)
        return map(fn, js)

    u = bootstrap_field_uncertainty(data, W, H, KW, n_boot=3, seed=0, map_fn=spy_map)
    assert u.n_boot == 3
    for sample, *_ in jobs:
        for lines in sample:
            assert len(lines) % 2 == 0
            for a, b in zip(lines[0::2], lines[1::2]):
                np.testing.assert_allclose(b - a, 0.25)
