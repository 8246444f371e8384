r"""Exact per-channel lens maps with lateral chromatic aberration (test helper).

A channel's map is the green lens's after an exact closed-form shift from the
channel's pixels to green's (nothing here is fitted, nothing comes from
:mod:`pipeline.models.tca_model`): with :math:`c_t` the TCA's own centre (decentred
from the image centre), :math:`R_0` the half diagonal, :math:`\rho = |x - c_t| / R_0`,

.. math::
    \Delta(x) = (x - c_t)\,(\alpha_0 + \alpha_1 \rho + \alpha_2 \rho^2) + \delta,
    \qquad U_c(x) = U_g\bigl(x + \Delta(x)\bigr)

(:math:`\alpha_0` a relative magnification, :math:`\alpha_1, \alpha_2` its change
with the radius, :math:`\delta` a lateral shift). :math:`\Delta` is the true field a
TCA fit must find.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache

import numpy as np

from tests.pipeline.lenses import ExactLens, mild_lenses


@dataclass(frozen=True)
class ExactTca:
    """The closed-form channel -> green shift of the module docstring (pixels)."""

    width: int
    height: int
    alpha: tuple[float, float, float] = (0.0, 0.0, 0.0)
    center: tuple[float, float] | None = None
    shift: tuple[float, float] = (0.0, 0.0)

    def displacement(self, xy: np.ndarray) -> np.ndarray:
        p = np.asarray(xy, np.float64).reshape(-1, 2)
        c = np.array(self.center if self.center is not None else ((self.width - 1) / 2, (self.height - 1) / 2))
        r0 = 0.5 * float(np.hypot(self.width, self.height))
        v = p - c
        rho = np.hypot(v[:, 0], v[:, 1]) / r0
        a0, a1, a2 = self.alpha
        return v * (a0 + a1 * rho + a2 * rho * rho)[:, None] + np.asarray(self.shift)

    def to_reference(self, xy: np.ndarray) -> np.ndarray:
        p = np.asarray(xy, np.float64).reshape(-1, 2)
        return p + self.displacement(p)


@dataclass(frozen=True)
class ChannelLens:
    """``U_c = U_g(x + Delta(x))``: distorted channel pixels -> ideal."""

    green: ExactLens
    tca: ExactTca

    def undistort_points(self, xy: np.ndarray) -> np.ndarray:
        return self.green.undistort_points(self.tca.to_reference(xy))


def colour_lens(width: int, height: int, family: str = "barrel", strength: float = 1.0) -> dict:
    """``{"R": ..., "G": ..., "B": ...}`` lens maps and ``{"R": ExactTca, "B": ExactTca}``: a realistic TCA.

    Red magnified by about 0.9 px at the corners of 1000x750 relative to green, blue
    shrunk by about 0.7 px, each with a radius-dependent part, a decentred centre and a
    small lateral shift (a decentred element); ``strength`` scales them.
    """
    green = mild_lenses(width, height)[family]
    c = ((width - 1) / 2.0, (height - 1) / 2.0)
    s = float(strength)
    tca = {
        "R": ExactTca(
            width, height, (-1.1e-3 * s, -0.5e-3 * s, 0.3e-3 * s), (c[0] + 14.0, c[1] - 9.0), (0.06 * s, -0.04 * s)
        ),
        "B": ExactTca(
            width, height, (0.8e-3 * s, 0.6e-3 * s, -0.2e-3 * s), (c[0] - 11.0, c[1] + 7.0), (-0.05 * s, 0.03 * s)
        ),
    }
    lenses = {"R": ChannelLens(green, tca["R"]), "G": green, "B": ChannelLens(green, tca["B"])}
    return {"lenses": lenses, "tca": tca}


COLOUR_SIZE = (640, 480)
COLOUR_ANGLES = (5.0, 50.0, 95.0, 140.0)
GAINS = {"R": 0.6, "G": 1.0, "B": 0.5}


@cache
def measured_colour_shots(width: int = COLOUR_SIZE[0], height: int = COLOUR_SIZE[1], angles=COLOUR_ANGLES) -> tuple:
    """Rendered RGGB mosaics of :func:`colour_lens` (8 px strings, blur 1 px, noise 1.5) measured per CFA plane."""
    from pipeline.cfa import measure_mosaic
    from pipeline.render import HarpScene
    from pipeline.render_colour import render_mosaic

    lens = colour_lens(width, height)
    out = []
    for i, ang in enumerate(angles):
        scene = HarpScene(angle_deg=ang, spacing_px=40.0, string_width_px=8.0, phase_px=7.0 * i, blur_px=1.0)
        r = render_mosaic(width, height, scene, lens["lenses"], gains=GAINS, seed=20 + i)
        out.append(measure_mosaic(r.image, "RGGB", t=30))
    return tuple(out)
