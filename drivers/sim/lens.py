r"""The demo lens of the simulated camera: a decentred 12 mm-like lens whose distortion depends on focus.

A real lens's distortion changes with the focus setting (that is why a
session locks focus). :func:`lens_for_focus` returns a
:class:`~pipeline.models.radial.RadialModel` (distorted -> ideal pixels) whose
coefficients vary linearly with the focus position :math:`f \in [0, 1]`:

.. math::
    \xi &= (x_d - c_x)/s, \quad \eta = (y_d - c_y)/s, \quad \rho^2 = \xi^2 + \eta^2,
    \quad s = \tfrac12\sqrt{W^2 + H^2} \\
    k_2(f) &= 0.040\,(1 - 0.08 f), \qquad k_4(f) = -0.004\,(1 + 0.1 f) \\
    \xi_u &= (1 + k_2\rho^2 + k_4\rho^4)\,\xi + 2 p_1\xi\eta + p_2(\rho^2 + 2\xi^2) \\
    \eta_u &= (1 + k_2\rho^2 + k_4\rho^4)\,\eta + p_1(\rho^2 + 2\eta^2) + 2 p_2\xi\eta \\
    x_u &= c_x + s\,\xi_u, \quad y_u = c_y + s\,\eta_u

with the decentring (tangential) terms :math:`p_1 = 6\cdot10^{-4}`,
:math:`p_2 = -4\cdot10^{-4}` and the distortion centre off the image centre,
:math:`(c_x, c_y) = ((W-1)/2 + 0.012 s,\ (H-1)/2 - 0.009 s)` (9.6 px right of and
7.2 px above the centre of a 1280 x 960 sensor, s = 800).

:math:`k_2 > 0` is barrel distortion, as in most short focal lengths. On a 1280 x 960
sensor the correction moves the four image corners by 29.0 / 26.0 / 28.5 / 31.6 px
(top-left, top-right, bottom-right, bottom-left: unequal, the lens is decentred and
tangential) at focus 0 and by 26.1 / 23.2 / 25.7 / 28.6 px at focus 1: a few pixels less over the
focus range. Modulo the best homography (what a straight-line method can see,
:func:`station.qa.verdicts.distortion_magnitude`) that is 13.8 px max, 3.5 px RMS at
focus 0 and 12.4 px max, 3.1 px RMS at focus 1. Because the coefficients act on
normalised coordinates, the same lens gives proportionally larger displacements on
a larger sensor.

References
----------
.. [1] D. C. Brown, "Decentering distortion of lenses", Photogrammetric
   Engineering 32(3), 1966.
"""

from __future__ import annotations

import math

from pipeline.models.radial import RadialModel

FOCUS_RANGE = (0.0, 1.0)
"""Focus positions for which the demo lens is defined (a camera refuses others)."""

K2 = (0.040, -0.08)  # k2(f) = K2[0] * (1 + K2[1] f)
K4 = (-0.004, 0.10)  # k4(f) = K4[0] * (1 + K4[1] f)
TANGENTIAL = (6.0e-4, -4.0e-4)
CENTRE_SHIFT = (0.012, -0.009)  # in units of s


def lens_for_focus(focus: float, width: int, height: int) -> RadialModel:
    """The demo lens at focus position ``focus`` (in [0, 1]) for a ``width`` x ``height`` sensor.

    Raises ValueError for a focus outside :data:`FOCUS_RANGE` or a bad size.
    """
    f = float(focus)
    if not (math.isfinite(f) and FOCUS_RANGE[0] <= f <= FOCUS_RANGE[1]):
        raise ValueError(f"focus must be in [{FOCUS_RANGE[0]}, {FOCUS_RANGE[1]}], got {focus}")
    if int(width) < 2 or int(height) < 2:
        raise ValueError(f"sensor size must be at least 2x2, got {width}x{height}")
    s = 0.5 * math.hypot(width, height)
    centre = ((width - 1) / 2.0 + CENTRE_SHIFT[0] * s, (height - 1) / 2.0 + CENTRE_SHIFT[1] * s)
    k2 = K2[0] * (1.0 + K2[1] * f)
    k4 = K4[0] * (1.0 + K4[1] * f)
    return RadialModel.for_image(
        int(width), int(height), k=(1.0, 0.0, k2, 0.0, k4), center=centre, tangential=TANGENTIAL
    )


ZOOM_FOCAL_RANGE_MM = (12.0, 36.0)
"""Focal lengths (mm) of the simulated zoom lens, wide end to long end (a camera refuses others)."""

ZOOM_K2 = (0.045, -0.025)  # k2 at the wide and at the long end (barrel -> pincushion)
ZOOM_K4 = (-0.005, 0.002)


def zoom_lens(focal_mm: float, focus: float, width: int, height: int) -> RadialModel:
    r"""The simulated zoom lens at focal length ``focal_mm`` and focus ``focus`` (in [0, 1]).

    As real zooms do, its distortion goes from barrel at the wide end to pincushion at the long
    end: with :math:`z = (f_{mm} - 12) / (36 - 12) \in [0, 1]` the zoom position,

    .. math::
        k_2(z, f) = \bigl(0.045 (1 - z) - 0.025 z\bigr)(1 - 0.08 f), \qquad
        k_4(z) = -0.005 (1 - z) + 0.002 z

    in the equation of :func:`lens_for_focus` (same normalisation, decentring terms scaled by
    :math:`1 - 0.5 z` and centre shift): :math:`k_2 > 0` (barrel) below :math:`z = 0.64`
    (27.4 mm), :math:`< 0` (pincushion) above. Raises ValueError outside
    :data:`ZOOM_FOCAL_RANGE_MM` or :data:`FOCUS_RANGE`.
    """
    fm, f = float(focal_mm), float(focus)
    lo, hi = ZOOM_FOCAL_RANGE_MM
    if not (math.isfinite(fm) and lo <= fm <= hi):
        raise ValueError(f"focal length must be in [{lo:g}, {hi:g}] mm, got {focal_mm}")
    if not (math.isfinite(f) and FOCUS_RANGE[0] <= f <= FOCUS_RANGE[1]):
        raise ValueError(f"focus must be in [{FOCUS_RANGE[0]}, {FOCUS_RANGE[1]}], got {focus}")
    if int(width) < 2 or int(height) < 2:
        raise ValueError(f"sensor size must be at least 2x2, got {width}x{height}")
    z = (fm - lo) / (hi - lo)
    s = 0.5 * math.hypot(width, height)
    centre = ((width - 1) / 2.0 + CENTRE_SHIFT[0] * s, (height - 1) / 2.0 + CENTRE_SHIFT[1] * s)
    k2 = (ZOOM_K2[0] * (1 - z) + ZOOM_K2[1] * z) * (1.0 + K2[1] * f)
    k4 = ZOOM_K4[0] * (1 - z) + ZOOM_K4[1] * z
    tang = (TANGENTIAL[0] * (1 - 0.5 * z), TANGENTIAL[1] * (1 - 0.5 * z))
    return RadialModel.for_image(int(width), int(height), k=(1.0, 0.0, k2, 0.0, k4), center=centre, tangential=tang)
