"""pipeline/evaluate.py: a correction defined on part of the image (maps) is not extrapolated."""

import numpy as np

from pipeline.evaluate import corrected_edges
from pipeline.exports.maps import corners_ideal, map_accuracy, maps_npz_bytes, read_maps_npz
from pipeline.models import RemapModel
from pipeline.models.homography import apply_homography
from pipeline.normalise import corner_homography, image_corners
from pipeline.undistort_maps import fast_undistortion_maps
from tests.pipeline.export_support import wide_radial

W, H = 320, 240
LENS = wide_radial(115.0, W, H)


def _maps():
    return fast_undistortion_maps(LENS, W, H, step=8)


def test_maps_file_keeps_the_corrected_corners_and_normalises_like_the_lens():
    maps = _maps()
    data = maps_npz_bytes(maps, map_accuracy(LENS, maps.map_x, maps.map_y), corners=corners_ideal(LENS, W, H))
    m = read_maps_npz(data, "m.npz")
    corners = LENS.undistort_points(image_corners(W, H))  # outside the maps: x < 0 at the left corners
    assert corners[0, 0] < -50
    np.testing.assert_allclose(np.asarray(m.corners_ideal), corners, atol=1e-9)
    np.testing.assert_allclose(corner_homography(m, W, H), corner_homography(LENS, W, H), atol=1e-12)


def test_without_stored_corners_the_maps_own_corners_normalise_and_outside_points_are_counted():
    maps = _maps()
    m = RemapModel(map_x=maps.map_x, map_y=maps.map_y)
    hc = corner_homography(m, W, H)
    c = image_corners(W, H)
    np.testing.assert_allclose(apply_homography(hc, c), m.distort_points(c), atol=1e-9)
    # a distorted row through the image: its ends are corrected to outside the corrected image
    row = np.stack([np.linspace(0, W - 1, 200), np.full(200, 20.0)], axis=1)
    u = LENS.undistort_points(row)
    outside = (u[:, 0] < 0) | (u[:, 0] > W - 1) | (u[:, 1] < 0) | (u[:, 1] > H - 1)
    assert 10 < outside.sum() < 190
    ce = corrected_edges([row], m, W, H)
    assert ce.n_points == 200 and abs(ce.n_excluded - int(outside.sum())) <= 1 and ce.kept == [0]
    assert np.all(np.isfinite(ce.points[0])) and len(ce.points[0]) == 200 - ce.n_excluded
