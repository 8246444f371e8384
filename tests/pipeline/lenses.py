r"""Exact closed-form lens maps for rendering test shots (test helper).

Each lens is a closed-form map :math:`U` from *distorted* pixel coordinates
(what the camera records) to *ideal* (pin-hole) ones, the direction the
renderer (:func:`pipeline.render.render_harp`) evaluates per pixel. Nothing
here is fitted, nothing comes from :mod:`pipeline.models`: the truth of a
test (:mod:`tests.pipeline._harp_truth`) is the exact image of each ideal
string edge under these maps.

With :math:`c` the distortion centre, :math:`v = x - c`, :math:`R_0` the
half-diagonal of the image, :math:`\rho = |v| / R_0` and
:math:`(\xi, \eta) = v / R_0`:

.. math::
    U(x) = c + g(\rho)\,v + R_0\,\bigl(T(\xi, \eta) + P(\rho)\bigr)

* radial factor :math:`g`: polynomial :math:`1 + k_1\rho^2 + k_2\rho^4 + k_3\rho^6`,
  or division :math:`1 / (1 + \lambda\rho^2)`, or the equidistant fisheye seen
  as a pin-hole image, :math:`g = \tan(\rho R_0 / f) / (\rho R_0 / f)`;
* decentering (Brown-Conrady) :math:`T = (2p_1\xi\eta + p_2(\rho^2 + 2\xi^2),\;
  p_1(\rho^2 + 2\eta^2) + 2p_2\xi\eta)`;
* thin prism :math:`P = (s_1\rho^2 + s_2\rho^4,\; s_3\rho^2 + s_4\rho^4)`.

References
----------
.. [1] D. C. Brown, "Decentering distortion of lenses", Photogrammetric
   Engineering 32(3), 1966, pp. 444-462.
.. [2] A. W. Fitzgibbon, "Simultaneous linear estimation of multiple view
   geometry and lens distortion", CVPR 2001 (the division model).
.. [3] J. Weng, P. Cohen, M. Herniou, "Camera calibration with distortion
   models and accuracy evaluation", IEEE TPAMI 14(10), 1992 (thin prism).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class ExactLens:
    """A closed-form distorted -> ideal map (module docstring); pixels."""

    name: str
    width: int
    height: int
    center: tuple[float, float] | None = None
    k: tuple[float, ...] = ()
    division: float = 0.0
    fisheye_f: float | None = None
    tangential: tuple[float, float] = (0.0, 0.0)
    prism: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)

    @property
    def c(self) -> np.ndarray:
        if self.center is None:
            return np.array([(self.width - 1) / 2.0, (self.height - 1) / 2.0])
        return np.asarray(self.center, np.float64)

    @property
    def r0(self) -> float:
        return 0.5 * float(np.hypot(self.width, self.height))

    def undistort_points(self, xy: np.ndarray) -> np.ndarray:
        """``U(x)`` for ``(N, 2)`` distorted points."""
        v = np.asarray(xy, np.float64).reshape(-1, 2) - self.c
        r0 = self.r0
        xi, eta = v[:, 0] / r0, v[:, 1] / r0
        rho2 = xi * xi + eta * eta
        if self.fisheye_f is not None:
            a = np.sqrt(rho2) * r0 / self.fisheye_f
            g = np.where(a > 1e-8, np.tan(a) / np.where(a > 1e-8, a, 1.0), 1.0 + a * a / 3.0)
        elif self.division:
            g = 1.0 / (1.0 + self.division * rho2)
        else:
            g = np.ones_like(rho2)
            p = rho2.copy()
            for kk in self.k:
                g = g + kk * p
                p = p * rho2
        p1, p2 = self.tangential
        s1, s2, s3, s4 = self.prism
        dx = 2 * p1 * xi * eta + p2 * (rho2 + 2 * xi * xi) + s1 * rho2 + s2 * rho2 * rho2
        dy = p1 * (rho2 + 2 * eta * eta) + 2 * p2 * xi * eta + s3 * rho2 + s4 * rho2 * rho2
        return self.c + g[:, None] * v + r0 * np.column_stack([dx, dy])

    def corner_shift(self) -> float:
        """Largest ``|U(x) - x|`` over the four image corners, pixels."""
        w, h = self.width - 1.0, self.height - 1.0
        corners = np.array([[0.0, 0.0], [w, 0.0], [0.0, h], [w, h]])
        return float(np.max(np.hypot(*(self.undistort_points(corners) - corners).T)))


def mild_lenses(width: int, height: int) -> dict[str, ExactLens]:
    """The six mild families of issue 8 (corner shifts of about 8-25 px on 1000x750)."""
    w, h = width, height
    c = ((w - 1) / 2.0, (h - 1) / 2.0)
    return {
        "barrel": ExactLens("barrel", w, h, k=(0.035, 0.004)),
        "pincushion": ExactLens("pincushion", w, h, k=(-0.03, -0.003)),
        "mustache": ExactLens("mustache", w, h, center=(c[0] + 23.0, c[1] - 17.0), k=(0.06, -0.05)),
        "division": ExactLens("division", w, h, division=-0.035),
        "tangential": ExactLens(
            "tangential", w, h, center=(c[0] - 15.0, c[1] + 9.0), k=(0.02,), tangential=(0.002, -0.0015)
        ),
        "prism": ExactLens("prism", w, h, k=(0.025,), prism=(0.0015, 0.0, -0.001, 0.0)),
    }


def wide_lenses(width: int, height: int) -> dict[str, ExactLens]:
    """Wide-angle lenses: about 25-30 % of the half-diagonal at the corners."""
    w, h = width, height
    c = ((w - 1) / 2.0, (h - 1) / 2.0)
    r0 = 0.5 * float(np.hypot(w, h))
    return {
        # division: corner radius r0 -> r0 / (1 + lam) ~ 1.3 r0
        "wide-division": ExactLens("wide-division", w, h, division=-0.23),
        # equidistant fisheye as a pin-hole image: tan(a)/a = 1.3 at the corner (a ~ 0.81 rad)
        "wide-fisheye": ExactLens("wide-fisheye", w, h, center=(c[0] + 12.0, c[1] - 8.0), fisheye_f=r0 / 0.81),
    }
