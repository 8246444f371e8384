r"""The demo lens of the simulated camera: its distortion depends on focus.

A real lens's distortion changes with the focus setting (that is why a
session locks focus). :func:`lens_for_focus` returns a
:class:`~pipeline.models.radial.RadialModel` (distorted -> ideal pixels) whose
coefficients vary linearly with the focus position :math:`f \in [0, 1]`:

.. math::
    \xi &= (x_d - c_x)/s, \quad \eta = (y_d - c_y)/s, \quad \rho^2 = \xi^2 + \eta^2,
    \quad s = \tfrac12\sqrt{W^2 + H^2} \\
    k_2(f) &= 0.0040\,(1 - 0.25 f), \qquad k_4(f) = -0.0006\,(1 + 0.2 f) \\
    \xi_u &= (1 + k_2\rho^2 + k_4\rho^4)\,\xi + 2 p_1\xi\eta + p_2(\rho^2 + 2\xi^2) \\
    \eta_u &= (1 + k_2\rho^2 + k_4\rho^4)\,\eta + p_1(\rho^2 + 2\eta^2) + 2 p_2\xi\eta \\
    x_u &= c_x + s\,\xi_u, \quad y_u = c_y + s\,\eta_u

with the decentring (tangential) terms :math:`p_1 = 1.5\cdot10^{-4}`,
:math:`p_2 = -1.0\cdot10^{-4}` and the distortion centre
:math:`(c_x, c_y) = ((W-1)/2 + 0.004 s,\ (H-1)/2 - 0.003 s)`.

:math:`k_2 > 0` is barrel distortion: a corner point (:math:`\rho \approx 1`) is
imaged :math:`s(k_2 + k_4)` pixels closer to the centre than a pin-hole would
put it: 2.7 px at focus 0 and 1.8 px at focus 1 on a 1280 x 960 sensor
(s = 800; a third less over the focus range). The tangential terms move a
corner by about 0.3 px. Because the coefficients act on normalised
coordinates, the same lens gives proportionally larger pixel displacements on
a larger sensor (about 10 px at the corners of a 24 MP 6000 x 4000 sensor).

References
----------
.. [1] D. C. Brown, "Decentering distortion of lenses", Photogrammetric
   Engineering 32(3), 1966.
"""

from __future__ import annotations

import math

from pipeline.models.radial import RadialModel

FOCUS_RANGE = (0.0, 1.0)
"""Focus positions for which the demo lens is defined (a camera clamps to it)."""

K2 = (0.0040, -0.25)  # k2(f) = K2[0] * (1 + K2[1] f)
K4 = (-0.0006, 0.2)  # k4(f) = K4[0] * (1 + K4[1] f)
TANGENTIAL = (1.5e-4, -1.0e-4)
CENTRE_SHIFT = (0.004, -0.003)  # in units of s


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
