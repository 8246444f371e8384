"""Focus interpolation of the correction field (pipeline/interpolate.py)."""

import json

import numpy as np
import pytest

from drivers.sim.lens import lens_for_focus
from pipeline.compare import compare_models
from pipeline.interpolate import FocusInterpolator, interpolate_correction, leave_one_out_error
from pipeline.model_file import load_model, model_file_text
from pipeline.models import model_from_dict
from pipeline.models.grid_field import GridFieldModel
from pipeline.models.homography import HomographyModel
from pipeline.models.radial import RadialModel

W, H = 640, 480


def curved_lens(f: float) -> RadialModel:
    """Demo lens whose k2 varies *quadratically* with focus (linear interpolation is not exact)."""
    base = lens_for_focus(0.0, W, H)
    k = list(base.k)
    k[2] = 0.004 * (1 - 0.6 * f * f)
    return RadialModel(center=base.center, k=tuple(k), scale=base.scale, tangential=base.tangential)


def test_demo_lens_interpolates_to_its_true_correction():
    models = {f: lens_for_focus(f, W, H) for f in (0.0, 0.5, 1.0)}
    interp = FocusInterpolator(models, W, H)
    for f in (0.2, 0.5, 0.9):
        c = compare_models(interp.at(f), lens_for_focus(f, W, H), W, H)
        # the demo lens is linear in focus: only the bicubic grid error is left
        assert c.max < 1e-4, (f, c)
    # the true distortion is not small: the interpolated field is not just the identity
    assert compare_models(interp.at(0.2), lens_for_focus(1.0, W, H), W, H).max > 0.1
    (loo,) = leave_one_out_error(models, W, H)
    assert loo.focus == 0.5 and loo.rms_px < 1e-4 and loo.max_px < 1e-3


@pytest.mark.parametrize("method", ["linear", "pchip", "cubic"])
def test_leave_one_out_measures_the_true_interpolation_error(method):
    focus = (0.0, 0.25, 0.5, 0.75, 1.0)
    models = {f: curved_lens(f) for f in focus}
    loo = leave_one_out_error(models, W, H, method=method)
    assert [r.focus for r in loo] == [0.25, 0.5, 0.75]
    for f, rms, mx in loo:
        # independently: interpolate without f, compare with the truth there
        others = {g: m for g, m in models.items() if g != f}
        truth = compare_models(interpolate_correction(others, f, W, H, method=method), curved_lens(f), W, H)
        assert rms == pytest.approx(truth.rms, rel=1e-6, abs=1e-9)
        assert mx == pytest.approx(truth.max, rel=1e-6, abs=1e-9)
    worst = max(r.max_px for r in loo)
    if method == "linear":
        # a field quadratic in f: the linear error is the k2 curvature term, computed here in closed form:
        # the mid-point of a linear interpolation over [f-h, f+h] is off by 0.6*0.004*h^2 in k2
        h = 0.25
        dk2 = 0.004 * 0.6 * h * h
        base = lens_for_focus(0.0, W, H)
        k_lo = list(base.k)
        k_lo[2] = 0.004 * (1 - 0.6 * 0.5**2) - dk2
        expected = compare_models(
            RadialModel(center=base.center, k=tuple(k_lo), scale=base.scale, tangential=base.tangential),
            curved_lens(0.5),
            W,
            H,
        )
        mid = loo[1]
        assert mid.rms_px == pytest.approx(expected.rms, rel=0.02)
        assert worst > 0.01
    elif method == "cubic":
        assert worst < 1e-3  # not-a-knot cubic reproduces a quadratic
    else:
        assert worst < 0.5 * max(r.max_px for r in leave_one_out_error(models, W, H, method="linear"))


def test_fields_are_compared_in_a_common_gauge():
    # the fit at f=1 came out in another homography gauge (projective part included)
    g = np.array([[1.02, 0.01, 3.0], [-0.008, 0.99, -2.0], [1.5e-4, -1e-4, 1.0]])
    models = {
        0.0: lens_for_focus(0.0, W, H),
        1.0: HomographyModel(base=lens_for_focus(1.0, W, H), homography=tuple(map(tuple, g))),
    }
    for gauge in ("lsq", "corners"):
        m = interpolate_correction(models, 0.5, W, H, gauge=gauge)
        assert compare_models(m, lens_for_focus(0.5, W, H), W, H).max < 1e-3, gauge
    # averaging the raw fields instead would be off by far more: the test can tell
    yy, xx = np.mgrid[0:H:10, 0:W:10]
    p = np.stack([xx.ravel(), yy.ravel()], axis=1).astype(float)
    raw = 0.5 * (models[0.0].undistort_points(p) + models[1.0].undistort_points(p))
    from pipeline.compare import fit_homography

    _, res = fit_homography(raw, lens_for_focus(0.5, W, H).undistort_points(p))
    assert np.hypot(res[:, 0], res[:, 1]).max() > 0.05


def test_extrapolation_and_bad_input_are_refused():
    models = {0.2: lens_for_focus(0.2, W, H), 0.8: lens_for_focus(0.8, W, H)}
    for f in (0.1, 0.9, float("nan")):
        with pytest.raises(ValueError, match="outside the calibrated range"):
            interpolate_correction(models, f, W, H)
    # the ends themselves are inside
    assert compare_models(interpolate_correction(models, 0.8, W, H), models[0.8], W, H).max < 1e-4
    with pytest.raises(ValueError, match="at least 2"):
        interpolate_correction({0.5: lens_for_focus(0.5, W, H)}, 0.5, W, H)
    with pytest.raises(ValueError, match="distinct"):
        interpolate_correction([(0.5, models[0.2]), (0.5, models[0.8])], 0.5, W, H)
    with pytest.raises(ValueError, match="unknown interpolation method"):
        interpolate_correction(models, 0.5, W, H, method="spline")
    assert leave_one_out_error(models, W, H) == []  # nothing to leave out without extrapolating


def test_grid_field_model_round_trip_and_inverse(tmp_path):
    m = interpolate_correction({0.0: lens_for_focus(0.0, W, H), 1.0: lens_for_focus(1.0, W, H)}, 0.3, W, H)
    assert isinstance(m, GridFieldModel) and m.info["interpolated_focus"] == 0.3
    back = model_from_dict(json.loads(json.dumps(m.to_dict())))
    pts = np.array([[0.0, 0.0], [W - 1.0, H - 1.0], [123.4, 321.9]])
    np.testing.assert_array_equal(back.undistort_points(pts), m.undistort_points(pts))
    (tmp_path / "m.yaml").write_text(model_file_text(m, width=W, height=H))
    np.testing.assert_allclose(
        load_model(tmp_path / "m.yaml").undistort_points(pts), m.undistort_points(pts), atol=1e-12
    )
    np.testing.assert_allclose(m.undistort_points(m.distort_points(pts)), pts, atol=1e-8)
    with pytest.raises(ValueError, match="non-finite"):
        GridFieldModel(origin=(0, 0), step=10, dx=np.full((5, 5), np.nan), dy=np.zeros((5, 5)), width=40, height=40)
