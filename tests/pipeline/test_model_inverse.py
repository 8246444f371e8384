"""The shared safeguarded inverse (pipeline/models/inverse.py): round trips over whole wide-lens
images, and NaN with a reason (never a far-away finite point) where no inverse exists (issue 20 item 9)."""

import numpy as np
import pytest

from pipeline.models import OpenCVModel, RadialModel, RemapModel
from pipeline.models.inverse import INVERSE_REASONS, INVERTED, OUTSIDE_DOMAIN
from pipeline.undistort_maps import fast_undistortion_maps
from tests.pipeline.export_support import wide_radial

W, H = 1280, 960
# a division model fitted by the harp fit (radial degree 4 + d1) to edges of a 115 deg equisolid
# lens: its denominator has a pole at 1.47 half diagonals, the corners correct to 1.63. Before the
# shared inverse, distort(undistort((0, 0))) was (-1845, -1371): Newton found a root beyond the pole.
FITTED_115 = RadialModel(
    center=(642.4999966057003, 477.4999990092887),
    k=(1.0, 0.00037202764554122034, -0.11620654697536938, 0.003103758186395974, -0.008632401950329254),
    scale=800.0,
    division=(-0.4622155588856716,),
)


def whole_image(width, height, step=2):
    """Every ``step``-th pixel of the image, plus every pixel of its border (corners included)."""
    ys, xs = np.mgrid[0:height:step, 0:width:step]
    inner = np.stack([xs.ravel(), ys.ravel()], axis=1)
    c, r = np.arange(width), np.arange(height)
    border = np.concatenate(
        [
            np.stack([c, np.zeros_like(c)], 1),
            np.stack([c, np.full_like(c, height - 1)], 1),
            np.stack([np.zeros_like(r), r], 1),
            np.stack([np.full_like(r, width - 1), r], 1),
        ]
    )
    return np.concatenate([inner, border]).astype(np.float64)


@pytest.mark.parametrize(
    "lens",
    [wide_radial(115.0, W, H), wide_radial(93.0, W, H), FITTED_115],
    ids=["equisolid-115", "equisolid-93", "fitted-division-115"],
)
def test_round_trip_over_the_whole_wide_image(lens):
    p = whole_image(W, H)
    u = lens.undistort_points(p)
    assert np.all(np.isfinite(u))
    back = lens.distort_points(u)
    err = np.hypot(*(back - p).T)
    assert np.all(np.isfinite(err)), lens.distort_inverse(u).summary()
    assert err.max() < 1e-6, err.max()
    corner = lens.distort_points(lens.undistort_points(np.array([[0.0, 0.0]])))
    np.testing.assert_allclose(corner, [[0.0, 0.0]], atol=1e-6)


def test_beyond_the_fold_is_nan_with_a_reason_never_a_far_point():
    """k = (1, 0, -0.3): rho_u = rho - 0.3 rho^3 rises to its fold at rho = sqrt(1/0.9), where it
    is 2/3 sqrt(1/0.9) (both by hand); an ideal radius beyond has no inverse before the fold."""
    lens = RadialModel.for_image(W, H, k=(1.0, 0.0, -0.3))
    fold = np.sqrt(1 / 0.9)
    assert lens.reach == pytest.approx(fold, rel=1e-9)
    top = fold - 0.3 * fold**3
    rng = np.random.default_rng(3)
    rho_u = rng.uniform(0.0, 1.5, 4000)
    ang = rng.uniform(0, 2 * np.pi, 4000)
    c = np.asarray(lens.center)
    t = c + lens.scale * rho_u[:, None] * np.stack([np.cos(ang), np.sin(ang)], 1)
    inv = lens.distort_inverse(t)
    beyond = rho_u > top * (1 + 1e-9)
    assert beyond.sum() > 1000 and (~beyond).sum() > 1000, (beyond.sum(), top)
    assert np.all(np.isnan(inv.points[beyond])) and np.all(inv.reason[beyond] == OUTSIDE_DOMAIN)
    within = rho_u < top * (1 - 1e-6)
    assert np.all(inv.reason[within] == INVERTED)
    assert np.abs(lens.undistort_points(inv.points[within]) - t[within]).max() < 1e-6
    rho = np.hypot(*((inv.points[within] - c) / lens.scale).T)
    assert rho.max() < fold  # the root before the fold, not one beyond it
    assert "fold" in INVERSE_REASONS[OUTSIDE_DOMAIN]
    assert inv.summary() == f"{int(beyond.sum())} {INVERSE_REASONS[OUTSIDE_DOMAIN]}"


def test_opencv_projection_beyond_its_fold_is_nan_with_a_reason():
    """k1 = -0.3: r_d = r - 0.3 r^3 has its largest value 2/3 sqrt(1/0.9) at r = sqrt(1/0.9)."""
    m = OpenCVModel(fx=500.0, fy=500.0, cx=640.0, cy=480.0, dist=(-0.3, 0.0, 0.0, 0.0, 0.0))
    top = 2 / 3 * np.sqrt(1 / 0.9)
    rd = np.array([0.0, 0.3, 0.6, top * 0.999, top * 1.001, 0.9, 2.0])
    q = np.stack([640.0 + 500 * rd, np.full_like(rd, 480.0)], 1)
    inv = m.undistort_inverse(q)
    assert list(inv.ok) == [True, True, True, True, False, False, False]
    assert np.all(inv.reason[~inv.ok] == OUTSIDE_DOMAIN) and np.all(np.isnan(inv.points[~inv.ok]))
    np.testing.assert_allclose(m.distort_points(inv.points[inv.ok]), q[inv.ok], atol=1e-7)


def test_maps_are_not_extrapolated_outside_their_area():
    """A wide lens's maps hold the corrected image [0, W-1] x [0, H-1] only: a distorted point whose
    ideal position (by the lens itself) is outside has no inverse in the maps; inside, the maps
    invert to the lens's own correction."""
    w, h = 320, 240
    lens = wide_radial(115.0, w, h)
    maps = fast_undistortion_maps(lens, w, h, step=8)
    remap = RemapModel(map_x=maps.map_x, map_y=maps.map_y)
    q = whole_image(w, h, step=3)
    u = lens.undistort_points(q)
    margin = 0.5
    inside = (u[:, 0] > margin) & (u[:, 0] < w - 1 - margin) & (u[:, 1] > margin) & (u[:, 1] < h - 1 - margin)
    outside = (u[:, 0] < -margin) | (u[:, 0] > w - 1 + margin) | (u[:, 1] < -margin) | (u[:, 1] > h - 1 + margin)
    assert inside.sum() > 1000 and outside.sum() > 1000
    inv = remap.undistort_inverse(q)
    assert np.all(inv.reason[outside] == OUTSIDE_DOMAIN) and np.all(np.isnan(inv.points[outside]))
    assert np.all(inv.ok[inside])
    assert np.abs(inv.points[inside] - u[inside]).max() < 1e-3  # float32 maps, bicubic nodes
