"""Field-dependent blur and vignetting, measured in rendered images.

The blur is measured by an independent least-squares fit of the blurred-string profile
along image rows (:func:`tests.pipeline.scanline_fit.fit_string_profile`); the expected
value is the PSF written out here from its definition (``sigma0^2 + (c rho^2)^2`` along
and across the radius, plus the pixel's 1/12).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from pipeline.harp_scene import Harp, HarpMount
from pipeline.measure import measure_image
from pipeline.optics import FieldBlur, Vignetting
from pipeline.realism import Effects, render_shot
from pipeline.render import edge_peak_offset
from pipeline.sensor import Development
from tests.pipeline.scanline_fit import fit_string_profile

W, H = 480, 360
CX, CY = (W - 1) / 2.0, (H - 1) / 2.0
S = 0.5 * math.hypot(W, H)
BLUR = FieldBlur(sigma_px=0.5, corner_tangential_px=1.0, corner_sagittal_px=0.25)


def _vertical_strings(blur: FieldBlur) -> np.ndarray:
    harp = Harp.straight(11, 45.0, 3.0, 0.0)  # strings at x = CX + 45 k (normal -x)
    eff = Effects(blur=blur, development=Development(bit_depth=16))
    return render_shot(None, harp, HarpMount((CX, CY), 90.0), 0.0, W, H, eff).image.astype(np.float64)


def _expected_sigma(x: float, y: float) -> float:
    xi, eta = (x - CX) / S, (y - CY) / S
    rho2 = xi * xi + eta * eta
    radial = (xi / math.sqrt(rho2)) ** 2 if rho2 > 0 else 0.5  # (n . r_hat)^2 for n = (-1, 0)
    var = 0.5**2 + (1.0 * rho2) ** 2 * radial + (0.25 * rho2) ** 2 * (1 - radial)
    return math.sqrt(var + 1 / 12)


def _fitted_sigma(img: np.ndarray, x_string: float, row: int) -> float:
    pos = np.arange(int(x_string) - 9, int(x_string) + 11).astype(float)
    pos = pos[(pos >= 0) & (pos < W)]
    _, _, s = fit_string_profile(img[row, pos.astype(int)], pos, x_string - 1.5, x_string + 1.5)
    return s


@pytest.mark.parametrize(
    ("k", "row"),
    [(0, int(CY)), (5, int(CY)), (-5, int(CY)), (5, 8), (0, 8), (3, 300), (-4, 40)],
)
def test_the_blur_grows_to_the_corners_as_specified(k, row):
    img = _vertical_strings(BLUR)
    x = CX + 45.0 * k
    assert _fitted_sigma(img, x, row) == pytest.approx(_expected_sigma(x, row), rel=0.02)


def test_astigmatism_blurs_along_the_radius_more_than_across_it():
    img = _vertical_strings(BLUR)
    # at the right edge of the middle row the string's normal is radial: the tangential defocus
    radial = _fitted_sigma(img, CX + 225.0, int(CY))
    # at the top of the middle column it is perpendicular to the radius: the sagittal defocus
    across = _fitted_sigma(img, CX, 2)
    centre = _fitted_sigma(img, CX, int(CY))
    assert centre == pytest.approx(math.sqrt(0.25 + 1 / 12), rel=0.01)
    assert radial > across > centre
    rho2_r, rho2_t = (225.0 / S) ** 2, ((CY - 2) / S) ** 2
    assert radial**2 - centre**2 == pytest.approx((1.0 * rho2_r) ** 2, rel=0.05)
    assert across**2 - centre**2 == pytest.approx((0.25 * rho2_t) ** 2, rel=0.15)


def test_uniform_blur_is_the_clean_renderers():
    img = _vertical_strings(FieldBlur())
    for k, row in [(0, 100), (5, 8), (-5, 350)]:
        assert _fitted_sigma(img, CX + 45.0 * k, row) == pytest.approx(math.sqrt(0.49 + 1 / 12), rel=0.01)
    assert FieldBlur().uniform and not BLUR.uniform
    assert BLUR.max_variance() >= float(
        np.max(BLUR.variance_along(np.array([0.0, W - 1.0]), np.array([0.0, H - 1.0]), (0.6, 0.8), W, H))
    )


def test_a_wider_blur_widens_the_measured_string_as_the_gradient_peaks_predict():
    """The detector (sigma 1) finds each edge of a 3 px string edge_peak_offset(w, sqrt(s^2 + 1))
    outside the geometric edge: the measured width grows towards the corners by twice the
    change of that offset."""
    img = _vertical_strings(FieldBlur(sigma_px=0.5, corner_tangential_px=1.0, corner_sagittal_px=1.0))
    m = measure_image(np.rint(img).astype(np.uint16))
    by: dict[int, dict[int, np.ndarray]] = {}
    for ln in m.lines:
        by.setdefault(ln.string_id, {})[ln.polarity] = ln.raw_points
    widths = {}
    for sides in by.values():
        a, b = (p[np.abs(p[:, 1] - CY) < 15] for p in sides.values())
        widths[round(0.5 * (a[:, 0].mean() + b[:, 0].mean()))] = abs(a[:, 0].mean() - b[:, 0].mean())
    centre = min(widths, key=lambda x: abs(x - CX))
    edge = max(widths, key=lambda x: abs(x - CX))

    def predicted(x: float) -> float:
        return 2 * edge_peak_offset(3.0, math.sqrt(_expected_sigma(x, CY) ** 2 + 1.0))

    growth = widths[edge] - widths[centre]
    assert growth > 0.1
    assert growth == pytest.approx(predicted(edge) - predicted(centre), rel=0.2)


def test_vignetting_reaches_its_corner_value():
    v = Vignetting(0.3)
    corners = v.at(np.array([0.0, W - 1.0, 0.0, W - 1.0]), np.array([0.0, 0.0, H - 1.0, H - 1.0]), W, H)
    assert corners == pytest.approx([0.7] * 4, rel=1e-12)
    assert v.at(np.array([CX]), np.array([CY]), W, H) == pytest.approx([1.0])
    with pytest.raises(ValueError, match="vignetting"):
        Vignetting(1.0)
    with pytest.raises(ValueError, match="FieldBlur"):
        FieldBlur(sigma_px=-1.0)
