"""A string's kink modelled in the joint fit of lens and strings (issue 19 items 4-5, ``pipeline.harp_kinks``):
shots of a turning harp whose strings carry cusps drawn at known places, traced through an exact lens and
smoothed along the edge as ``harp measure`` does (``tests.pipeline.harp_points.kinked_harp_point_sets``);
truth from that geometry (the drawn place ``a_k`` and area ``2 h lambda``) and the exact lens map."""

import numpy as np
import pytest

from pipeline.compare import compare_models
from pipeline.fit import fit_distortion
from pipeline.fitspec import FitSpec
from pipeline.harp_shape import fit_harp_shape
from pipeline.models import RadialModel
from pipeline.resample import equivalent_kernel, smooth_subsample
from tests.pipeline.harp_points import kinked_harp_point_sets

W, H = 1000, 750
LENS = RadialModel.for_image(
    W, H, k=(1.0, 0.0, 0.03, 0.0, 0.004), center=(512, 366), tangential=(8e-4, -5e-4), prism=(4e-4, 0.0, -3e-4, 0.0)
)
SPEC = FitSpec("radial", 4, True, True)
TURNS = (0, 30, 60, 90, 120, 150)
KINKS = {2: (120.0, 0.3, 10.0), 4: (-200.0, 0.3, 10.0), 6: (-80.0, -0.25, 8.0), 8: (40.0, 0.3, 12.0)}
"""string -> (a_k, h, lambda): harp px along the string from the axis, cusp height and length (px)."""


def _fits(kinks):
    shots, _ = kinked_harp_point_sets(LENS, W, H, TURNS, 11, kinks, axis=(497, 378), seed=4, noise=0.008)
    plain = fit_distortion(shots, W, H, **SPEC.fit_arguments())
    without = fit_harp_shape(shots, TURNS, W, H, SPEC, plain=plain)
    with_kinks = fit_harp_shape(shots, TURNS, W, H, SPEC, plain=plain, kinks=True)
    assert without and with_kinks
    err = [compare_models(f.model, LENS, W, H, step=25).rms for f in (without, with_kinks)]
    return with_kinks, err


def test_drawn_kinks_are_found_where_drawn_and_the_lens_is_freed_of_them():
    fit, (err_without, err_with) = _fits(KINKS)
    assert fit.frame.sign == 1 and abs(fit.frame.angle0_deg - 20.0) < 0.2  # a along the drawn direction
    found = {k.string: k for k in fit.kinks}
    assert sorted(found) == sorted(KINKS)  # one each, and none on the seven straight strings
    for s, (at, h, lam) in KINKS.items():
        k = found[s]
        assert abs(k.at_px - at) < 4.0, (s, k.at_px, at)
        assert k.area_px2 == pytest.approx(2.0 * h * lam, rel=0.3), (s, k.area_px2)
        assert k.shots >= 2 and abs(k.z) > 10
    assert err_with < 0.5 * err_without, (err_with, err_without)
    assert fit.to_dict()["kinks"][0]["string"] == fit.kinks[0].string


def test_a_harp_without_kinks_gets_none_and_the_same_lens():
    fit, (err_without, err_with) = _fits({})
    assert fit.kinks == ()
    assert err_with == pytest.approx(err_without, rel=1e-9)


def test_the_kink_template_is_the_smoothers_own_response():
    """A narrow bump of area A on a straight edge, smoothed by ``harp measure``'s smoother, leaves A l(s)."""
    x = np.arange(0.0, 601.0)
    y = np.where(x == 300.0, 1e-3, 0.0)  # area 1e-3 px x px, on one sample
    sm = smooth_subsample(np.column_stack([x, y]), t=30)
    inner = (sm[:, 0] > 80) & (sm[:, 0] < 520)
    expected = 1e-3 * equivalent_kernel(sm[inner, 0] - 300.0)
    peak = np.abs(expected).max()  # within 3 % of the peak (the window is centred on the nearest sample)
    assert peak > 1e-5 and np.allclose(sm[inner, 1], expected, atol=0.03 * peak)
    assert equivalent_kernel(np.arange(-80, 81)).sum() == pytest.approx(1.0)
