"""The exact derivatives the OpenCV pin-hole fits use once forward differences crawl
(pipeline/exports/opencv_jacobian.py, pole_free.radial_penalty_jacobian): equal to central differences
of the projection (OpenCVModel.distort_points, numpy's closed form, and cv2.projectPoints with tilt), of
the homography's action and of the pole-free penalty."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.exports.opencv_jacobian import homography_jacobian, projection_jacobian
from pipeline.exports.pole_free import radial_penalty, radial_penalty_jacobian
from pipeline.models.homography import apply_homography
from pipeline.models.opencv_model import OpenCVModel


def _central(f, x: np.ndarray, h: float) -> np.ndarray:
    return np.stack([(f(x + h * e) - f(x - h * e)) / (2 * h) for e in np.eye(len(x))], axis=-1)


@pytest.mark.parametrize("n", [4, 5, 8, 12, 14])
def test_the_projection_jacobian_is_the_central_difference_one(n):
    rng = np.random.default_rng(n)
    dist = rng.normal(0, [0.1, 0.02, 1e-3, 1e-3, 0.01, 0.05, 0.01, 0.005, 1e-3, 1e-4, 1e-3, 1e-4, 1e-3, 1e-3])[:n]
    fx, fy, cx, cy = 500.0, 510.0, 321.0, 238.0
    ideal = rng.uniform([0, 0], [640, 480], (40, 2))

    def project(p: np.ndarray) -> np.ndarray:
        return OpenCVModel(fx=fx, fy=fy, cx=p[0], cy=p[1], dist=tuple(p[2:])).distort_points(ideal)

    j_par, j_ideal = projection_jacobian(OpenCVModel(fx=fx, fy=fy, cx=cx, cy=cy, dist=tuple(dist)), ideal)
    num = _central(project, np.r_[cx, cy, dist], 1e-6)
    assert np.allclose(j_par, num, rtol=1e-5, atol=1e-5)
    m = OpenCVModel(fx=fx, fy=fy, cx=cx, cy=cy, dist=tuple(dist))
    for k in range(2):
        step = np.zeros(2)
        step[k] = 1e-4
        d = (m.distort_points(ideal + step) - m.distort_points(ideal - step)) / 2e-4
        assert np.allclose(j_ideal[:, :, k], d, rtol=1e-6, atol=1e-6)


def test_the_homography_jacobian_is_the_central_difference_one():
    rng = np.random.default_rng(1)
    s, c = 400.0, np.array([319.5, 239.5])
    t = np.array([[1 / s, 0, -c[0] / s], [0, 1 / s, -c[1] / s], [0, 0, 1.0]])
    tinv = np.linalg.inv(t)
    h8 = np.array([1.02, 0.01, 0.003, -0.02, 0.97, 0.002, 0.03, -0.04])
    u = rng.uniform([0, 0], [640, 480], (30, 2))

    def act(h: np.ndarray) -> np.ndarray:
        return apply_homography(tinv @ np.append(h, 1.0).reshape(3, 3) @ t, u)

    assert np.allclose(homography_jacobian(tinv, h8, t, u), _central(act, h8, 1e-7), rtol=1e-6, atol=1e-5)


def test_the_penalty_jacobian_is_the_central_difference_one_where_the_margins_bite():
    rng = np.random.default_rng(2)
    active = 0
    for _ in range(40):
        dist = rng.normal(0, 1.5, 8)
        r_max = 0.6 + rng.random()
        active += int(np.any(radial_penalty(dist, r_max) > 0))
        jd, jr = radial_penalty_jacobian(dist, r_max)
        scale = max(1.0, float(np.abs(jd).max()), float(np.abs(jr).max()))
        assert np.allclose(jd, _central(lambda d: radial_penalty(d, r_max), dist, 1e-7), atol=1e-5 * scale)
        assert np.allclose(jr, (radial_penalty(dist, r_max + 1e-7) - radial_penalty(dist, r_max - 1e-7)) / 2e-7,
                           atol=1e-5 * scale)  # fmt: skip
    assert active >= 20  # the margins are crossed in most draws: the hinge terms are checked
