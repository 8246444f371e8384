"""The camera matrix with the distortion held fixed, on board shots rendered through an exact lens of known K."""

import numpy as np
import pytest

from pipeline.board import detect_board
from pipeline.intrinsics import Intrinsics, IntrinsicsFailure, fit_intrinsics, view_residual
from pipeline.models import IdentityModel
from tests.pipeline import board_shots as bs


@pytest.fixture(scope="module")
def views():
    out = [detect_board(bs.shot(i), bs.spec(), name=f"view{i}") for i in range(bs.N_VIEWS)]
    assert all(out)
    return out


@pytest.fixture(scope="module")
def fitted(views):
    return fit_intrinsics(views, bs.harp_model(), bs.W, bs.H, source="test")


def test_camera_matrix_within_two_of_its_stated_sigmas(fitted):
    r = fitted
    assert isinstance(r, Intrinsics)
    truth = (bs.K_TRUE[0, 0], bs.K_TRUE[1, 1], bs.K_TRUE[0, 2], bs.K_TRUE[1, 2])
    got = (r.fx, r.fy, r.cx, r.cy)
    print("K error (px):", [f"{g - t:+.3f} (sd {s:.3f})" for g, t, s in zip(got, truth, r.sd)])
    for g, t, s in zip(got, truth, r.sd):
        assert 0 < s < 0.5
        assert abs(g - t) <= 2 * s
    assert r.skew == 0.0 and r.sd[4] == 0.0 and not r.skew_fitted
    assert r.n_views == bs.N_VIEWS and r.rms_px < 0.05
    assert r.holdout_rms_px is not None and r.holdout_rms_px < 0.06 and len(r.holdout_per_view) == bs.N_VIEWS
    assert np.allclose(np.sqrt(np.diag(np.asarray(r.covariance))), r.sd)


def test_a_new_view_is_reprojected_to_its_corner_noise(fitted):
    v = detect_board(bs.shot(0), bs.spec())
    rms, pose = view_residual(fitted, bs.harp_model(), v.object_points, v.image_points)
    assert rms < 0.05
    assert np.allclose(pose[3:], bs.poses()[0].tvec, atol=0.5)  # mm, at ~300 mm


def test_the_held_out_error_sees_a_wrong_distortion(views, fitted):
    wrong = fit_intrinsics(views, IdentityModel(), bs.W, bs.H)  # the lens's 20 px of barrel ignored
    assert wrong.holdout_rms_px > 20 * fitted.holdout_rms_px


def test_skew_is_fitted_when_asked_and_found_zero(views):
    r = fit_intrinsics(views, bs.harp_model(), bs.W, bs.H, skew=True, holdout=False)
    assert r.skew_fitted and r.sd[4] > 0 and abs(r.skew) <= 2 * r.sd[4]
    assert r.holdout_rms_px is None


def test_too_few_views_is_a_failure_with_its_reason(views):
    got = fit_intrinsics(views[:2], bs.harp_model(), bs.W, bs.H)
    assert isinstance(got, IntrinsicsFailure) and not got
    assert got.reason == "a camera matrix needs at least 3 board views, got 2"


def test_record_round_trip_and_bad_records(fitted):
    assert Intrinsics.from_dict(fitted.to_dict()) == fitted
    with pytest.raises(ValueError, match="fx, fy must be finite and > 0"):
        Intrinsics.from_dict({**fitted.to_dict(), "fx": -1.0})
    with pytest.raises(ValueError, match="missing or invalid"):
        Intrinsics.from_dict({"fx": 1.0})
