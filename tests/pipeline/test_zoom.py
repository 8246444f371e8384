"""Zoom lenses: the simulated zoom goes from barrel to pincushion; corrections at (focal, focus) settings
interpolated in both, never extrapolated, with the leave-one-out error per axis.

Truth: the simulated zoom lens's closed form at the setting asked for (:func:`drivers.sim.lens.zoom_lens`),
compared modulo homography (what a harp can see)."""

import numpy as np
import pytest

from drivers.sim.lens import ZOOM_FOCAL_RANGE_MM, zoom_lens
from pipeline.compare import compare_models
from pipeline.zoom import ZoomInterpolator, leave_one_out_by_axis

W, H = 320, 240
FOCALS = (12.0, 24.0, 36.0)
FOCI = (0.0, 1.0)


@pytest.fixture(scope="module")
def grid():
    return {(z, f): zoom_lens(z, f, W, H) for z in FOCALS for f in FOCI}


def _radial_sign(model):
    """Sign of the correction's radial displacement at the image corner: + barrel (moved out), - pincushion."""
    c = np.array([[0.0, 0.0]])
    centre = np.array([(W - 1) / 2, (H - 1) / 2])
    d = model.undistort_points(c) - c
    return float(np.sign(np.dot(d[0], c[0] - centre)))


def test_zoom_lens_goes_from_barrel_to_pincushion():
    assert _radial_sign(zoom_lens(12.0, 0.5, W, H)) == 1.0
    assert _radial_sign(zoom_lens(36.0, 0.5, W, H)) == -1.0
    with pytest.raises(ValueError, match=r"focal length must be in \[12, 36\] mm"):
        zoom_lens(40.0, 0.5, W, H)
    assert ZOOM_FOCAL_RANGE_MM == (12.0, 36.0)


def test_interpolated_between_settings_close_to_the_lens(grid):
    zi = ZoomInterpolator(grid, W, H)
    for z, f in [(18.0, 0.5), (30.0, 0.25), (24.0, 0.75)]:
        c = compare_models(zi.at(z, f), zoom_lens(z, f, W, H), W, H, step=10.0)
        assert c.rms < 0.15, (z, f, c.rms)
    # at a calibrated setting it is that setting's correction (modulo homography)
    assert compare_models(zi.at(24.0, 1.0), grid[(24.0, 1.0)], W, H, step=10.0).max < 0.01


def test_never_extrapolated(grid):
    zi = ZoomInterpolator(grid, W, H)
    with pytest.raises(ValueError, match=r"focal 40 is outside the calibrated range \[12, 36\]"):
        zi.at(40.0, 0.5)
    partial = {k: v for k, v in grid.items() if not (k[0] == 24.0 and k[1] == 1.0)}
    with pytest.raises(ValueError, match=r"focus 0.5 is outside the range calibrated at focal 24 \(0 only\)"):
        ZoomInterpolator(partial, W, H).at(20.0, 0.5)


def test_leave_one_out_per_axis(grid):
    loo = leave_one_out_by_axis(grid, W, H)
    assert [(r.axis, r.focal, r.focus) for r in loo] == [("focal", 24.0, 0.0), ("focal", 24.0, 1.0)]
    # the simulated zoom's coefficients are linear in the focal length: the middle one is interpolated
    # from the ends to within the gauge's nonlinearity
    print("leave-one-out along the focal (px RMS):", [round(r.rms_px, 4) for r in loo])
    assert all(r.rms_px < 0.05 for r in loo)
    # a middle setting that is not what the ends predict (the 30 mm lens filed as 24 mm) is seen, by
    # about how far the two lenses are apart
    wrong = {**grid, (24.0, 0.0): zoom_lens(30.0, 0.0, W, H)}
    r = next(r for r in leave_one_out_by_axis(wrong, W, H) if r.focus == 0.0)
    apart = compare_models(zoom_lens(24.0, 0.0, W, H), zoom_lens(30.0, 0.0, W, H), W, H, step=10.0).rms
    assert r.rms_px == pytest.approx(apart, rel=0.25) and apart > 0.3
    three_foci = {(z, f): zoom_lens(z, f, W, H) for z in (12.0, 36.0) for f in (0.0, 0.5, 1.0)}
    axes = [(r.axis, r.focal, r.focus) for r in leave_one_out_by_axis(three_foci, W, H)]
    assert axes == [("focus", 12.0, 0.5), ("focus", 36.0, 0.5)]
