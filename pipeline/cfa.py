r"""Colour filter arrays: string edges measured per CFA channel on the raw mosaic.

A camera with a Bayer colour filter array records one colour per pixel, in a 2 x 2
pattern repeated over the sensor. ``pattern`` names it row by row from the top-left
pixel, e.g. ``"RGGB"``: ``image[0, 0]`` red, ``image[0, 1]`` and ``image[1, 0]``
green, ``image[1, 1]`` blue. Each of the four sites of the pattern is a *plane*,
an image of half the width and height sampled at its own positions: the pixel
``plane[i, j]`` of the plane at offset :math:`(o_x, o_y)` is the mosaic pixel at

.. math::
    x = 2 j + o_x, \qquad y = 2 i + o_y .

The edges of every string are measured on each plane separately
(:func:`pipeline.measure.measure_image`: sub-pixel Canny/Devernay, grouping,
along-edge smoothing), and the points brought back to mosaic coordinates by that
affine map, which is exact: no pixel is interpolated, no colour demosaiced. A
demosaicing algorithm fills the missing colours of each pixel from its neighbours
(of all colours, for the edge-directed ones), which moves an edge of one channel
towards where the other channels see it: exactly the lateral chromatic aberration
this measurement is for.

The two green planes (``"G1"`` the first green of the pattern in reading order,
``"G2"`` the second) are measured separately: they sample the same green image at
two offsets, so each is an independent measurement of the same edges.

Scale: a plane has half the mosaic's resolution; the measurement runs with the
along-edge subsampling ``t // 2`` in plane pixels, so that the smoothing scale and
the spacing of the kept points are the same length on the sensor as ``t`` on a grey
image of the mosaic's size. The optical blur, in plane pixels, is halved: an edge
needs a blur of about 1 mosaic pixel or more (an anti-aliasing filter, or a lens
not perfectly sharp: most lenses on most sensors) for the detector's sub-pixel
interpolation not to lock onto the plane's coarser grid.

References
----------
.. [1] B. E. Bayer, "Color imaging array", US patent 3,971,065, 1976.
.. [2] J. Mallon, P. F. Whelan, "Calibration and removal of lateral chromatic
   aberration in images", Pattern Recognition Letters 28(1), 2007 (edges measured
   per colour channel, no demosaicing).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pipeline.measure import ImageMeasurement, LineMeasurement, Rejection, measure_image
from pipeline.resample import DEFAULT_T, SmoothingMethod

CFA_PATTERNS = ("RGGB", "BGGR", "GRBG", "GBRG")
"""The Bayer patterns, named row by row from the top-left pixel."""
PLANE_NAMES = ("R", "G1", "G2", "B")
"""The four planes of a Bayer mosaic."""
OFFSETS = ((0, 0), (1, 0), (0, 1), (1, 1))
"""``(o_x, o_y)`` of the four sites of a pattern, in its reading order."""


@dataclass(frozen=True)
class CfaPlane:
    """One site of the pattern: its name, colour, offset in the mosaic and pixels."""

    name: str
    colour: str
    offset: tuple[int, int]
    image: NDArray[Any]


def check_pattern(pattern: str) -> str:
    """``pattern`` upper-cased, or ValueError naming the patterns known."""
    p = str(pattern).upper()
    if p not in CFA_PATTERNS:
        raise ValueError(f"unknown CFA pattern {pattern!r}; known: {', '.join(CFA_PATTERNS)}")
    return p


def plane_offsets(pattern: str) -> dict[str, tuple[int, int]]:
    """``{"R": (ox, oy), "G1": ..., "G2": ..., "B": ...}`` of a Bayer pattern."""
    p = check_pattern(pattern)
    out: dict[str, tuple[int, int]] = {}
    greens = 0
    for colour, off in zip(p, OFFSETS):
        if colour == "G":
            greens += 1
            out[f"G{greens}"] = off
        else:
            out[colour] = off
    return {n: out[n] for n in PLANE_NAMES}


def cfa_planes(mosaic: NDArray[Any], pattern: str) -> tuple[CfaPlane, ...]:
    """The four planes of a Bayer ``mosaic`` (``image[y, x]``), in :data:`PLANE_NAMES` order.

    An odd width or height drops the last column or row (a plane must have one pixel
    per pattern). ValueError for an image that is not 2-D or smaller than 4 x 4.
    """
    m = np.asarray(mosaic)
    if m.ndim != 2:
        raise ValueError(f"a CFA mosaic is a 2-D image, got shape {m.shape}")
    h, w = (m.shape[0] // 2) * 2, (m.shape[1] // 2) * 2
    if h < 4 or w < 4:
        raise ValueError(f"a CFA mosaic needs at least 4x4 pixels, got {m.shape[1]}x{m.shape[0]}")
    return tuple(
        CfaPlane(name, name[0], off, np.ascontiguousarray(m[off[1] : h : 2, off[0] : w : 2]))
        for name, off in plane_offsets(pattern).items()
    )


def plane_to_mosaic(xy: NDArray[np.float64], offset: tuple[int, int]) -> NDArray[np.float64]:
    """Plane coordinates ``(N, 2)`` to mosaic coordinates: ``2 * xy + offset`` (exact)."""
    return 2.0 * np.asarray(xy, np.float64) + np.asarray(offset, np.float64)


def _line_to_mosaic(ln: LineMeasurement, offset: tuple[int, int]) -> LineMeasurement:
    return replace(
        ln,
        points=plane_to_mosaic(ln.points, offset),
        raw_points=plane_to_mosaic(ln.raw_points, offset),
        rms=2.0 * ln.rms,
        p2p=2.0 * ln.p2p,
        length_px=2.0 * ln.length_px,
        hf_rms=2.0 * ln.hf_rms,
        width_px=2.0 * ln.width_px,
    )


def _rejection_to_mosaic(r: Rejection, offset: tuple[int, int]) -> Rejection:
    x0, y0, x1, y1 = r.bbox
    ox, oy = offset
    return replace(r, bbox=(2 * x0 + ox, 2 * y0 + oy, 2 * x1 + ox, 2 * y1 + oy))


def to_mosaic(m: ImageMeasurement, offset: tuple[int, int], width: int, height: int) -> ImageMeasurement:
    """A plane's measurement in mosaic coordinates (every length doubled; ``t`` in mosaic pixels)."""
    return replace(
        m,
        width=int(width),
        height=int(height),
        t=2 * m.t,
        lines=tuple(_line_to_mosaic(ln, offset) for ln in m.lines),
        d=2.0 * m.d,
        d_max=2.0 * m.d_max,
        rejected=tuple(_rejection_to_mosaic(r, offset) for r in m.rejected),
        rejected_points=tuple(plane_to_mosaic(p, offset) for p in m.rejected_points),
        string_width_px=2.0 * m.string_width_px,
    )


@dataclass(frozen=True)
class MosaicMeasurement:
    """The measurement of every plane of one mosaic, in mosaic coordinates.

    ``planes`` maps :data:`PLANE_NAMES` to :class:`~pipeline.measure.ImageMeasurement`
    (``width`` x ``height`` = the mosaic's size).
    """

    pattern: str
    width: int
    height: int
    planes: dict[str, ImageMeasurement]

    def channel(self, colour: str) -> tuple[ImageMeasurement, ...]:
        """The measurements of one colour: ``"R"``, ``"B"``, or ``"G"`` (both green planes)."""
        return tuple(m for n, m in self.planes.items() if n[0] == colour)

    def lines(self, colour: str) -> list[NDArray[np.float64]]:
        """The smoothed points of every edge of one colour (both green planes for ``"G"``)."""
        return [ln.points for m in self.channel(colour) for ln in m.lines]


def measure_mosaic(
    mosaic: NDArray[Any],
    pattern: str,
    t: int = DEFAULT_T,
    sigma: float = 1.0,
    smoothing: SmoothingMethod = "local-quadratic",
) -> MosaicMeasurement:
    """Measure every string edge on each plane of a Bayer mosaic, without demosaicing.

    Parameters
    ----------
    mosaic : 2-D ndarray
        The raw mosaic, ``image[y, x]``, any integer or float dtype (black level
        subtracted or not: the edge detector sees gradients).
    pattern : str
        One of :data:`CFA_PATTERNS`.
    t : int
        Along-edge subsampling in mosaic pixels (the planes use ``max(2, t // 2)``
        of their own pixels: the same length on the sensor).
    sigma : float
        Gaussian smoothing of the edge detector, in plane pixels.
    smoothing : {"local-quadratic", "gaussian"}
        The along-edge smoother (:func:`pipeline.measure.measure_image`).

    Returns
    -------
    MosaicMeasurement
        Per plane, edge points in mosaic coordinates (module docstring).

    References
    ----------
    .. [1] Mallon and Whelan, Pattern Recognition Letters 28(1), 2007.
    """
    planes = cfa_planes(mosaic, pattern)
    h, w = np.asarray(mosaic).shape
    t_plane = max(2, int(t) // 2)
    out = {
        p.name: to_mosaic(measure_image(p.image, t=t_plane, sigma=sigma, smoothing=smoothing), p.offset, w, h)
        for p in planes
    }
    return MosaicMeasurement(check_pattern(pattern), int(w), int(h), out)


def measure_channels(
    image: NDArray[Any],
    t: int = DEFAULT_T,
    sigma: float = 1.0,
    smoothing: SmoothingMethod = "local-quadratic",
    order: str = "RGB",
) -> MosaicMeasurement:
    """Measure every string edge in each channel of a colour image (already demosaiced).

    ``image[y, x, channel]`` with channels in ``order`` (``"RGB"``, or ``"BGR"`` as
    OpenCV reads files; a fourth, alpha channel is ignored). Each channel is measured
    on every pixel (:func:`pipeline.measure.measure_image`); the result's ``planes`` are
    ``"R"``, ``"G"``, ``"B"`` and its ``pattern`` is ``order``. A demosaiced image has
    had its colours interpolated across the pattern: the edges of one channel are
    pulled towards the others', so a TCA measured on it is smaller than the lens's (a
    camera RAW file, :func:`measure_mosaic`, does not have this bias).
    """
    img = np.asarray(image)
    if img.ndim != 3 or img.shape[2] < 3:
        raise ValueError(f"a colour image has 3 channels, got shape {img.shape}")
    if sorted(order.upper()) != ["B", "G", "R"]:
        raise ValueError(f"channel order must be RGB or BGR, got {order!r}")
    h, w = img.shape[:2]
    planes = {
        c: measure_image(np.ascontiguousarray(img[:, :, order.upper().index(c)]), t=t, sigma=sigma, smoothing=smoothing)
        for c in "RGB"
    }
    return MosaicMeasurement(order.upper(), int(w), int(h), planes)


def mosaic_luma(mosaic: NDArray[Any]) -> NDArray[np.float64]:
    r"""A grey image of a Bayer mosaic at full resolution: the mosaic filtered by
    :math:`\tfrac{1}{16}[1\ 2\ 1]^T[1\ 2\ 1]`.

    Centred on any site of any Bayer pattern, the kernel weighs red, green and blue as
    :math:`\tfrac14, \tfrac12, \tfrac14` (the four sites of each 2 x 2 cell add to the same
    weights), so the pattern's checkerboard cancels and nothing is shifted: a grey picture
    for the figures that do not need colour (the live view's assessment of a Bayer camera's
    frames). Borders are mirrored.
    """
    m = np.asarray(mosaic, np.float64)
    if m.ndim != 2:
        raise ValueError(f"a CFA mosaic is a 2-D image, got shape {m.shape}")
    p = np.pad(m, 1, mode="reflect")
    rows = p[:-2] + 2.0 * p[1:-1] + p[2:]
    return np.asarray((rows[:, :-2] + 2.0 * rows[:, 1:-1] + rows[:, 2:]) / 16.0, np.float64)
