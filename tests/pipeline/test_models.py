import numpy as np
import pytest

from pipeline.models import MODEL_TYPES, HomographyModel, PolynomialModel, RadialModel, model_from_dict
from pipeline.models.polynomial import monomial_exponents, monomials
from tests.pipeline.rendered_shots import H, W, nonradial_lens


def _grid(step=25.0):
    xx, yy = np.meshgrid(np.arange(0, W, step), np.arange(0, H, step))
    return np.stack([xx.ravel(), yy.ravel()], 1).astype(float)


def test_monomial_order_and_values():
    assert monomial_exponents(2) == [(0, 0), (1, 0), (0, 1), (2, 0), (1, 1), (0, 2)]
    m = monomials(np.array([2.0]), np.array([3.0]), 3)
    assert np.allclose(m[0], [1, 2, 3, 4, 6, 9, 8, 12, 18, 27])


def test_polynomial_identity_is_exact():
    m = PolynomialModel.identity(W, H, 7)
    p = _grid()
    assert np.abs(m.undistort_points(p) - p).max() < 1e-9
    assert np.abs(m.distort_points(p) - p).max() < 1e-9


def test_polynomial_equation_matches_docstring():
    m = nonradial_lens()
    p = np.array([[100.0, 650.0], [900.0, 20.0]])
    xi, eta = (p[:, 0] - m.center[0]) / m.scale, (p[:, 1] - m.center[1]) / m.scale
    xu = m.center[0] + m.scale * (xi + 0.02 * xi**3 + 0.02 * xi * eta**2 + 0.004 * xi**2 * eta + 0.002 * xi**5)
    yu = m.center[1] + m.scale * (eta + 0.02 * xi**2 * eta + 0.02 * eta**3 - 0.003 * xi**3)
    assert np.allclose(m.undistort_points(p), np.stack([xu, yu], 1), atol=1e-9)


@pytest.mark.parametrize(
    "model",
    [
        nonradial_lens(),
        RadialModel.for_image(
            W,
            H,
            k=(1.0, 0.0, 0.03, 0.0, 0.005),
            center=(530, 355),
            tangential=(0.001, -0.0007),
            prism=(0.0005, 0.0, -0.0004, 0.0),
        ),
        RadialModel.for_image(W, H, k=(1.0, 0.0, 0.01), center=(490, 380), tangential=(0.001, 0.0), division=(-0.2,)),
    ],
)
def test_distort_inverts_undistort(model):
    p = _grid()
    u = model.undistort_points(p)
    assert np.abs(u - p).max() > 5.0  # a real distortion
    back = model.distort_points(u)
    assert np.abs(back - p).max() < 1e-8


@pytest.mark.parametrize(
    "model",
    [
        nonradial_lens(),
        HomographyModel(
            RadialModel.for_image(W, H, k=(1.0, 0.0, 0.02)),
            ((1.01, 0.002, -3.0), (0.001, 0.99, 2.0), (1e-6, -2e-6, 1.0)),
        ),
        RadialModel.for_image(W, H, k=(1.0, 0.001, -0.02), division=(-0.25, 0.01), prism=(1e-4, 0, 0, 2e-4)),
    ],
)
def test_dict_round_trip_and_registry(model):
    d = model.to_dict()
    assert model.name in MODEL_TYPES
    back = model_from_dict(d)
    p = _grid(100.0)
    assert np.array_equal(back.undistort_points(p), model.undistort_points(p))
    assert back.to_dict() == d


def test_radial_division_equation_matches_docstring():
    # f = (k0 + k1 rho + k2 rho^2) / (1 + d1 rho^2 + d2 rho^4), then the Brown-Conrady terms
    m = RadialModel.for_image(
        W, H, k=(1.0, 0.01, 0.03), center=(480.0, 390.0), tangential=(0.002, -0.001), division=(-0.2, 0.02)
    )
    p = np.array([[10.0, 700.0], [990.0, 15.0], [480.0, 390.0]])
    xi, eta = (p[:, 0] - 480.0) / m.scale, (p[:, 1] - 390.0) / m.scale
    r2 = xi**2 + eta**2
    f = (1.0 + 0.01 * np.sqrt(r2) + 0.03 * r2) / (1.0 - 0.2 * r2 + 0.02 * r2**2)
    xu = xi * f + 2 * 0.002 * xi * eta - 0.001 * (r2 + 2 * xi**2)
    yu = eta * f + 0.002 * (r2 + 2 * eta**2) - 2 * 0.001 * xi * eta
    assert np.allclose(m.undistort_points(p), np.stack([480.0 + m.scale * xu, 390.0 + m.scale * yu], 1), atol=1e-9)
    assert list(m.params()[-2:]) == [-0.2, 0.02]
    with pytest.raises(ValueError, match="division"):
        RadialModel.for_image(W, H, division=())


def test_homography_model_inverse():
    m = HomographyModel(
        RadialModel.for_image(W, H, k=(1.0, 0.0, 0.02)), ((1.01, 0.002, -3.0), (0.001, 0.99, 2.0), (1e-6, -2e-6, 1.0))
    )
    p = _grid(50.0)
    assert np.abs(m.distort_points(m.undistort_points(p)) - p).max() < 1e-8


def test_polynomial_rejects_bad_parameters():
    with pytest.raises(ValueError, match="coefficients"):
        PolynomialModel((0, 0), 3, (0.0,) * 10, (0.0,) * 9)
    with pytest.raises(ValueError, match="degree"):
        PolynomialModel((0, 0), 0, (0.0,), (0.0,))
    with pytest.raises(ValueError, match="invertible"):
        HomographyModel(PolynomialModel.identity(W, H, 3), ((1, 0, 0), (2, 0, 0), (0, 0, 1)))
