import numpy as np
import pytest

from pipeline.compare import compare_models, corner_homography, corner_normalised, fit_homography, image_grid
from pipeline.edgeset import straightness_of
from pipeline.models import HomographyModel, PolynomialModel, RadialModel
from pipeline.models.homography import apply_homography

W, H = 1000, 750
LENS = RadialModel.for_image(W, H, k=(1.0, 0.0, 0.03, 0.0, 0.005), center=(520, 360), tangential=(0.001, 0.0))
HOM = np.array([[1.02, 0.01, -4.0], [-0.005, 0.98, 6.0], [2e-5, -1e-5, 1.0]])


def test_grid_covers_the_image_with_corners():
    g = image_grid(W, H, 10.0)
    assert g.min(axis=0).tolist() == [0.0, 0.0] and g.max(axis=0).tolist() == [W - 1.0, H - 1.0]
    assert len(g) == 101 * 76


def test_same_correction_up_to_a_homography_compares_equal():
    b = HomographyModel(LENS, tuple(map(tuple, HOM)))
    c = compare_models(LENS, b, W, H)
    assert c.rms < 1e-9 and c.max < 1e-8
    assert np.allclose(c.homography / c.homography[2, 2], HOM / HOM[2, 2], atol=1e-10)


def test_different_corrections_leave_the_expected_field():
    # k2 differs by 0.001: the field differs by 0.001 * s * rho^3 minus what a homography absorbs
    other = RadialModel(LENS.center, (1.0, 0.0, 0.031, 0.0, 0.005), LENS.scale, LENS.tangential)
    c = compare_models(LENS, other, W, H)
    assert 0.01 < c.rms < 0.001 * LENS.scale
    assert c.max > c.rms
    # the comparison is symmetric in size
    assert compare_models(other, LENS, W, H).rms == pytest.approx(c.rms, rel=0.05)


def test_fit_homography_recovers_exact_map():
    rng = np.random.default_rng(0)
    src = rng.uniform(0, 1000, (200, 2))
    h, res = fit_homography(src, apply_homography(HOM, src))
    assert np.abs(res).max() < 1e-9
    assert np.allclose(h, HOM, atol=1e-12 + 1e-9 * np.abs(HOM))


def test_corner_normalisation_keeps_corners_and_straightness():
    n = corner_normalised(LENS, W, H)
    corners = np.array([[0.0, 0.0], [W - 1.0, 0.0], [W - 1.0, H - 1.0], [0.0, H - 1.0]])
    assert np.abs(n.undistort_points(corners) - corners).max() < 1e-9
    assert np.allclose(n.matrix, corner_homography(LENS, W, H))
    # a homography keeps lines straight: points on a line corrected by LENS stay on a line
    line = LENS.distort_points(np.stack([np.linspace(50, 950, 40), np.linspace(60, 700, 40)], 1))
    assert straightness_of([n.undistort_points(line)])[0] < 1e-9
    assert compare_models(n, LENS, W, H).rms < 1e-9


def test_identity_vs_distortion_is_large():
    c = compare_models(PolynomialModel.identity(W, H, 3), LENS, W, H, step=25)
    assert c.rms > 1.0
