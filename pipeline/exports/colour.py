r"""Colour and light in an export: the channels' TCA and the lens's vignetting beside the distortion.

A harp export is made from a distortion model (green's, the reference channel); the same
shots give the red and blue channels' TCA fields (:mod:`pipeline.tca`, ``harp tca``) and
the lens's relative illumination (:mod:`pipeline.vignetting`, ``harp vignetting``).
:class:`ColourCorrection` holds them for the export; :func:`lensfun_colour` converts them
to lensfun's ``<tca>`` and ``<vignetting>`` models about the ``<center>`` the distortion is
written with (liblensfun applies all three about it), each with its conversion error.

OpenCV has no TCA model: :func:`opencv_channels` fits each of red and blue its own
camera matrix (green's focal lengths, its own principal point: a TCA's lateral shift) and
distortion coefficients, so that ``cv2.initUndistortRectifyMap(K_c, D_c, R, newK, ...)``
with the file's ``R`` and ``newK`` (or ``cv2.undistort(channel, K_c, D_c, None, newK)``)
puts every channel where green's correction puts green. The channel's target is green's
OpenCV correction after the channel's field, :math:`U^{cv}_g \circ T_c`
(:class:`~pipeline.models.tca_model.ChannelModel`), in green's normalised ideal frame (no
homography: the channels must coincide, not just be straight).

References
----------
.. [1] Lensfun, the lens database format (``<tca>``, ``<vignetting>``),
   https://lensfun.github.io/manual/latest/
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, replace

import numpy as np

from pipeline.exports.conversion_error import image_grid as fit_grid
from pipeline.models.opencv_model import OpenCVModel
from pipeline.models.tca_model import ChannelModel, TcaField
from pipeline.tca import LensfunTcaFit, lensfun_tca
from pipeline.vignetting import LensfunVignetting, VignettingFit, lensfun_pa

DEFAULT_DISTANCE_M = 1000.0
"""Focus distance (m) a ``<vignetting>`` element is filed under when none is given (lensfun: infinity)."""


@dataclass(frozen=True)
class ColourCorrection:
    """The TCA fields and the vignetting an export carries beside the distortion (either may be None).

    ``tca``: ``{"R": field, "B": field}``, channel -> green (:class:`TcaField`);
    ``vignetting``: the fitted relative illumination; ``aperture`` (f-number) and
    ``distance`` (m): the setting the vignetting was measured at (lensfun files it under them).
    """

    tca: Mapping[str, TcaField] | None = None
    vignetting: VignettingFit | None = None
    aperture: float | None = None
    distance: float = DEFAULT_DISTANCE_M

    def size_problem(self, width: int, height: int) -> str | None:
        """What is for another image size than ``width`` x ``height`` (None: all fit)."""
        for what, size in (
            ("the TCA", None if self.tca is None else (self.tca["R"].width, self.tca["R"].height)),
            ("the vignetting", None if self.vignetting is None else (self.vignetting.width, self.vignetting.height)),
        ):
            if size is not None and size != (width, height):
                return f"{what} is for {size[0]}x{size[1]} images, the model for {width}x{height}"
        return None


@dataclass(frozen=True)
class LensfunColour:
    """Lensfun's TCA and ``pa`` vignetting of a :class:`ColourCorrection`, and their conversion errors."""

    tca: LensfunTcaFit | None
    vignetting: LensfunVignetting | None

    def lines(self) -> list[str]:
        out = [] if self.tca is None else self.tca.lines()
        if self.vignetting is not None:
            v = self.vignetting
            out.append(
                f"vignetting pa: conversion error RMS {100 * v.error_rms:.3f} %, max {100 * v.error_max:.3f} % "
                "of the relative illumination"
            )
        return out


def lensfun_colour(
    colour: ColourCorrection, center: tuple[float, float] = (0.0, 0.0), tca_kind: str = "poly3"
) -> LensfunColour:
    """Lensfun's ``tca_kind`` TCA and ``pa`` vignetting closest to ``colour``, about the lens's ``center``.

    ``center`` is the ``<center>`` of the lens element (lensfun's normalised units).
    ValueError when the vignetting has no aperture (lensfun files a ``<vignetting>`` under one).
    """
    tca = None if colour.tca is None else lensfun_tca(colour.tca, tca_kind, center=center)
    pa = None
    if colour.vignetting is not None:
        if colour.aperture is None:
            raise ValueError(
                "lensfun: a <vignetting> element is filed under the f-number the shots were taken at: give --aperture"
            )
        pa = lensfun_pa(colour.vignetting, center=center)
    return LensfunColour(tca, pa)


CHANNEL_NAMES = {"R": "red", "B": "blue"}
"""The channels an OpenCV file holds besides green's, and the suffix of their nodes."""


@dataclass(frozen=True)
class OpenCVChannel:
    """One channel's OpenCV camera (green's focal lengths, its own principal point) and distortion, and
    its conversion error, pixels."""

    channel: str
    model: OpenCVModel
    rms_px: float
    max_px: float

    @property
    def name(self) -> str:
        return CHANNEL_NAMES[self.channel]

    def line(self) -> str:
        return (
            f"{self.name}: camera_matrix_{self.name} and distortion_coefficients_{self.name} (with the file's R and "
            f"newK) put the {self.name} channel where green's correction puts green: conversion error (against "
            f"green's OpenCV correction after the measured TCA field) RMS {self.rms_px:.4f} px, max "
            f"{self.max_px:.4f} px"
        )


def _fit_channel(green: OpenCVModel, field: TcaField, width: int, height: int) -> OpenCVModel:
    r"""The channel's OpenCV model: green's focal lengths; principal point and coefficients fitted.

    Forward, by least squares from green's own model (the channel differs from it by the TCA: a few
    iterations): every grid point :math:`g` of green's image, ideal :math:`p = U^{cv}_g(g)`, is seen by
    the channel at :math:`T_c^{-1}(g)`; the channel's model, with its principal point moved by
    :math:`\delta`, must distort :math:`p + \delta` there (the same normalised ray).
    """
    from scipy.optimize import least_squares

    g = fit_grid(width, height, CHANNEL_GRID_LONG)
    p = np.asarray(green.undistort_points(g), np.float64)
    ok = np.all(np.isfinite(p), axis=1)
    g, p = g[ok], p[ok]
    target = field.from_reference(g)
    n = len(green.dist)

    def make(theta: np.ndarray) -> OpenCVModel:
        return replace(green, cx=green.cx + theta[0], cy=green.cy + theta[1], dist=tuple(theta[2:]))

    def resid(theta: np.ndarray) -> np.ndarray:
        q = p + theta[:2]
        return np.asarray(make(theta).distort_points(q) - target, np.float64).ravel()

    x0 = np.concatenate([[0.0, 0.0], np.asarray(green.dist, np.float64)])
    scale = np.concatenate([[1.0, 1.0], np.full(n, 1e-3)])
    sol = least_squares(resid, x0, method="lm", x_scale=scale)
    return make(sol.x)


CHANNEL_GRID_LONG = 48
"""Grid points along the longer side over which a channel's OpenCV model is fitted."""


def opencv_channels(
    green: OpenCVModel, tca: Mapping[str, TcaField], width: int, height: int
) -> tuple[OpenCVChannel, ...]:
    r"""Red's and blue's OpenCV models with ``green``'s focal lengths (module docstring).

    The conversion error of each: :math:`|U^{cv}_c(x) - \delta - U^{cv}_g(T_c(x))|` over the
    image (corrected-image pixels; :math:`\delta` the channel's principal point from green's).
    """
    out = []
    for ch in CHANNEL_NAMES:
        m = _fit_channel(green, tca[ch], width, height)
        target = ChannelModel(green, tca[ch])
        shift = np.array([m.cx - green.cx, m.cy - green.cy])
        g = fit_grid(width, height, 64)
        e = np.hypot(*(np.asarray(m.undistort_points(g)) - shift - target.undistort_points(g)).T)
        e = np.where(np.isfinite(e), e, np.inf)
        out.append(OpenCVChannel(ch, m, float(np.sqrt(np.mean(e**2))), float(e.max())))
    return tuple(out)
