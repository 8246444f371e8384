r"""What the lens does to the image besides distortion: field-dependent blur and vignetting.

Both are in *sensor* coordinates (they belong to the camera, not to the harp), with
:math:`\rho` the distance to the image centre over the half-diagonal (1 at the corners),
:math:`\hat r` the unit vector from the centre and :math:`\hat t` the one perpendicular
to it.

Field-dependent blur
--------------------
The point-spread function is a Gaussian whose covariance is the sum of an isotropic
part (diffraction, residual aberrations, the sensor's anti-aliasing filter) and an
astigmatic defocus that grows to the corners:

.. math::
    \Sigma(x) = \sigma_0^2 I + \delta_t(x)^2\,\hat r\hat r^T + \delta_s(x)^2\,\hat t\hat t^T,
    \qquad \delta_{t,s}(x) = c_{t,s}\,\rho^2 + c_{tilt}\,\ell(x)

An edge with unit normal :math:`n` is blurred by the standard deviation
:math:`\sigma_n = \sqrt{n^T\Sigma n}` (:meth:`FieldBlur.variance_along`): strings
perpendicular to the radius see :math:`\delta_t` (the tangential focal surface), strings
along it :math:`\delta_s` (the sagittal one).

Derivation and magnitudes. The sagittal and tangential focal surfaces of a lens lie
:math:`z_{s,t}(\rho) \approx z_{s,t}(1)\,\rho^2` away from the sensor (field curvature
and astigmatism are both quadratic in the image height to third order, Seidel); a
focus error :math:`z` at f-number :math:`N` blurs a point into a disc of radius
:math:`|z|/2N`, whose standard deviation along any direction is half its radius,
replaced by the Gaussian of that standard deviation: :math:`c = z(1)/(4N)`. With the
focus set on the centre of the field, typical corner focus errors of 30–200 µm (the
distance between a normal lens's sagittal and tangential best-focus curves in its MTF
data) give at f/8 1–6 µm, i.e. ``corner_*_px`` of 0.1–0.8 px on 8–12 µm output pixels. A
tilted sensor or lens adds a defocus linear across the field, :math:`\ell(x) = (\xi\cos\tau
+ \eta\sin\tau)` (``tilt_px`` at the corner in direction ``tilt_deg``; 10 µm of tilt over the
half-diagonal at f/8 is 0.3 µm). The isotropic part: diffraction at f/8 and 550 nm is
:math:`\approx 0.42\lambda N = 1.8` µm (the Airy core's Gaussian), an anti-aliasing filter
splits each ray by about one native pixel (:math:`\sigma \approx 0.35`–0.5 native px):
``sigma_px`` of 0.35–0.7 output px.

The PSF is applied in the renderer as a Gaussian blur of the ideal scene along the
string's normal, with :math:`\sigma_n` taken at each pixel's own position (the
local approximation of a spatially varying convolution, exact where :math:`\Sigma` is
constant over the PSF's extent); the half-level crossing of an isolated edge stays on
the geometric edge, while the gradient maxima of a 3 px string move outwards by
:func:`pipeline.render.edge_peak_offset` of the *local* :math:`\sigma_n`: a string's
measured width grows towards the corners.

Vignetting
----------
:class:`Vignetting` is the cos\ :sup:`4`-like fall-off :math:`V = (1 + a\rho^2)^{-2}` of the
clean renderer (:mod:`pipeline.render`), :math:`a` chosen so that :math:`V = 1 - v` at the
corners. The cos\ :sup:`4` law alone gives :math:`v = 1 - \cos^4\beta` at the corner field
angle :math:`\beta` (0.29 at 23.4°, a normal lens on its format; 0.15 at 16°); mechanical
vignetting adds a little at f/8: ``corner`` of 0.15–0.45.

References
----------
.. [1] W. J. Smith, *Modern Optical Engineering*, 4th ed., McGraw-Hill, 2008, Ch. 3 and 6
   (Seidel field curvature and astigmatism; depth of focus, blur disc :math:`z/N`).
.. [2] M. Born, E. Wolf, *Principles of Optics*, 7th ed., Cambridge, 1999, Sect. 8.5
   (the Airy pattern).
.. [3] M. Aggarwal, H. Hua, N. Ahuja, "On cosine-fourth and vignetting effects in real
   lenses", ICCV 2001.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

PIXEL_BOX_VARIANCE = 1.0 / 12.0
"""Variance (px^2, along any direction) of the integration over a square pixel of side 1."""


@dataclass(frozen=True)
class FieldBlur:
    """The PSF over the field (module docstring); lengths in output pixels.

    Parameters
    ----------
    sigma_px : :math:`\\sigma_0`, the isotropic PSF (standard deviation).
    corner_tangential_px : :math:`c_t`, the defocus standard deviation at the corners along
        the radius (the tangential focal surface: blurs strings perpendicular to the radius).
    corner_sagittal_px : :math:`c_s`, the same across the radius.
    tilt_px, tilt_deg : :math:`c_{tilt}` and the direction :math:`\\tau` of a tilt's linear defocus.
    """

    sigma_px: float = 0.7
    corner_tangential_px: float = 0.0
    corner_sagittal_px: float = 0.0
    tilt_px: float = 0.0
    tilt_deg: float = 0.0

    def __post_init__(self) -> None:
        if not (self.sigma_px >= 0 and self.corner_tangential_px >= 0 and self.corner_sagittal_px >= 0):
            raise ValueError("FieldBlur: sigma_px and the corner defocus must be >= 0")

    @property
    def uniform(self) -> bool:
        """True when the PSF is the same everywhere (no defocus term)."""
        return self.corner_tangential_px == 0 and self.corner_sagittal_px == 0 and self.tilt_px == 0

    def max_variance(self) -> float:
        """An upper bound of :meth:`variance_along` over the image and every direction (px^2)."""
        d = max(self.corner_tangential_px, self.corner_sagittal_px) + abs(self.tilt_px)
        return self.sigma_px**2 + d * d

    def variance_along(
        self, x: np.ndarray, y: np.ndarray, normal: tuple[float, float], width: int, height: int
    ) -> np.ndarray:
        """:math:`n^T\\Sigma n` (px^2, optics only: add the pixel's box) at sensor points ``(x, y)``."""
        x = np.asarray(x, np.float64)
        y = np.asarray(y, np.float64)
        base = np.full(np.broadcast(x, y).shape, self.sigma_px**2)
        if self.uniform:
            return base
        cx, cy = (width - 1) / 2.0, (height - 1) / 2.0
        r0 = 0.5 * math.hypot(width, height)
        xi, eta = (x - cx) / r0, (y - cy) / r0
        rho2 = xi * xi + eta * eta
        t = math.radians(self.tilt_deg)
        tilt = self.tilt_px * (xi * math.cos(t) + eta * math.sin(t))
        d_t = self.corner_tangential_px * rho2 + tilt
        d_s = self.corner_sagittal_px * rho2 + tilt
        rho = np.sqrt(rho2)
        safe = np.where(rho > 0, rho, 1.0)
        nr = (normal[0] * xi + normal[1] * eta) / safe  # n . r_hat
        nr2 = np.where(rho > 0, nr * nr, 0.5)
        out: np.ndarray = base + d_t * d_t * nr2 + d_s * d_s * (1.0 - nr2)
        return out

    def sigma_along(
        self, x: np.ndarray, y: np.ndarray, normal: tuple[float, float], width: int, height: int
    ) -> np.ndarray:
        """:math:`\\sigma_n = \\sqrt{n^T\\Sigma n}` at sensor points (px, optics only)."""
        out: np.ndarray = np.sqrt(self.variance_along(x, y, normal, width, height))
        return out


@dataclass(frozen=True)
class Vignetting:
    """cos^4-like fall-off to ``1 - corner`` at the image corners (module docstring)."""

    corner: float = 0.3

    def __post_init__(self) -> None:
        if not 0 <= self.corner < 1:
            raise ValueError(f"vignetting corner fall-off must be in [0, 1), got {self.corner}")

    def at(self, x: np.ndarray, y: np.ndarray, width: int, height: int) -> np.ndarray:
        """The relative illumination :math:`V` at sensor points ``(x, y)``."""
        cx, cy = (width - 1) / 2.0, (height - 1) / 2.0
        a = ((1.0 - self.corner) ** -0.5 - 1.0) / (cx * cx + cy * cy)
        v = 1.0 + a * ((np.asarray(x, np.float64) - cx) ** 2 + (np.asarray(y, np.float64) - cy) ** 2)
        out: np.ndarray = 1.0 / (v * v)
        return out
