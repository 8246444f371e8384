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


def test_each_views_tilt_is_recorded_and_views_facing_the_camera_are_warned_of(views, fitted):
    from pipeline.board import parse_board
    from pipeline.board_render import BoardPose, render_board

    # the rendered poses' tilts (15-45 degrees, drawn in tests/pipeline/board_shots.py), recomputed here
    truth = [float(np.degrees(np.arccos(abs(p.rotation()[2, 2])))) for p in bs.poses()]
    assert np.allclose(fitted.extra["view_tilts_deg"], truth, atol=0.2)
    assert not any("facing the camera" in w for w in fitted.warnings)
    # three views of a board facing the camera, moved about: the focal length is barely seen
    spec = parse_board(bs.BOARD)
    flat = []
    for i, (x, y) in enumerate([(-140.0, -90.0), (-60.0, -40.0), (-100.0, -70.0)]):
        pose = BoardPose((0.02 * i, -0.03, 0.1 * i), (x, y, 380.0 + 20 * i))
        img = render_board(
            spec,
            bs.K_TRUE,
            pose,
            bs.LENS.undistort_points,
            bs.W,
            bs.H,
            seed=50 + i,
        )
        flat.append(detect_board(img, spec))
    assert all(flat)
    r = fit_intrinsics(flat, bs.harp_model(), bs.W, bs.H, holdout=False)
    assert any("facing the camera" in w for w in r.warnings)


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
