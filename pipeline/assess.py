r"""Set-up assessment of one harp frame: focus, exposure, strings found and image coverage.

What an operator needs to know *before* a session, several times a second
(the live view, ``harp live``): are the strings sharp, is the exposure
right, which strings are found (and which groups of edge points were
rejected, and why), and which parts of the image the strings cover in two
independent directions, accumulated over the orientations seen so far.

Speed: find coarse, refine only what is shown
---------------------------------------------
The strings are found on a downscaled copy of the frame (area average,
factor :func:`analysis_scale`: at most :data:`TARGET_ANALYSIS_PIXELS`
pixels, never so small that a string is narrower than
:data:`MIN_ANALYSIS_STRING_PX`), with the sub-pixel edge detector
(:func:`pipeline.edges.detect_edges`, parabolic sub-pixel peaks: the live
view needs no 0.01 px positions) and the string grouping
(:func:`pipeline.grouping.group_string_edges`; edge chains shorter than its shortest piece,
``MIN_PIECE_PX``, are dropped first: they could only be rejected as fragments). Only the figures shown per
string are then refined on the full-resolution pixels, on
:data:`CROSS_SECTIONS` cross-sections per string.

Sharpness of a string: slanted-edge profile fit
-----------------------------------------------
A back-lit opaque string of width :math:`w` seen through a point spread
function of standard deviation :math:`\sigma` (optics and pixel integration
together) images, across the string, as

.. math::
    v(s) = B + A\,g(s), \qquad
    g(s) = \Phi\!\left(\frac{s + w/2}{\sigma}\right) - \Phi\!\left(\frac{s - w/2}{\sigma}\right)

with :math:`s` the signed distance to the string's centre line, :math:`B`
the background and :math:`A` the string's amplitude (negative for dark
strings), :math:`\Phi` the normal CDF. On each cross-section the full
resolution pixels of one row (or column, whichever is closer to the string
normal) are taken at their exact distance :math:`s` to the locally straight
centre line, as in the slanted-edge method of ISO 12233: the pixel centres
fall at many sub-pixel phases, so no interpolation blurs the profile. Per
cross-section :math:`i` the centre is refined (centroid of the string's
darkness) and :math:`B_i, A_i` are linear (shading and vignetting change
them along the string); the shared :math:`(w, \sigma)` of each string are
fitted by Gauss-Newton with those linear parameters projected out (variable
projection, Golub & Pereyra). The string's *edge width* is the 10-90 % rise
distance of one edge, :math:`2\,\Phi^{-1}(0.9)\,\sigma = 2.5631\,\sigma`, and
its *contrast* :math:`|A| / \max(B, B + A)`. A string narrower than about twice
the blur :math:`\sigma` shows only its shadow's area :math:`|A|\,w` (a narrow deep
profile and a wide shallow one blur alike), so depth and width trade off in the
fit; a depth beyond the background (:math:`A < -B`: light below zero, contrast
above 1) is then read as what it must be, an opaque string (contrast 1) of the
same shadow area :math:`w' = w\,|A|/B`. A pixel-integrating sensor adds
:math:`1/12` px\ :sup:`2` to :math:`\sigma^2` (the variance of a unit box
projected on any direction), so a perfectly focused edge is 0.74 px wide.

The *focus score* of the frame is the reciprocal of the median edge width
over the strings (1/px; larger is sharper). Defocus widens the PSF with the
distance to the plane of sharp focus, which over a focus ring's travel is
linear in the setting: :math:`\sigma^2(f) = \sigma_0^2 + k^2 (f - f^*)^2`,
so the squared edge width is a parabola in :math:`f` and :func:`focus_peak`
finds :math:`f^*` as the vertex of a parabola fitted to the squared widths
around their minimum (through-focus curve fitting).

Exposure
--------
:func:`exposure_figures`: a histogram, the fraction of saturated pixels (at
the top code value), of dark ones (at most :data:`DARK_LEVEL` of full
scale), and the dynamic range ``(p99.5 - p0.5) / full scale``: the figures
the session's acceptance checks compare with their limits, computed the same
way (the percentiles of an integer image are read exactly from its
histogram, with numpy's linear interpolation).

Coverage
--------
:func:`edge_coverage` records, per cell of a grid over the image
(:data:`CELLS_ACROSS` cells along the longer side) and per direction bin of
:data:`DIRECTION_BIN_DEG`, the length of string edge seen. A cell is
*covered* when it holds edges in two directions at least
:data:`MIN_SEPARATION_DEG` apart: each edge measures the distortion across
itself only, and two directions :math:`\alpha` apart recover the second
component with a sensitivity :math:`\sin\alpha` (at least 1/2). Coverages of
successive orientations are combined with :meth:`Coverage.merge`; the fit
needs the corners, which only the combination of orientations covers.

References
----------
.. [1] Z. Tang, R. Grompone von Gioi, P. Monasse, J.-M. Morel,
   "High-precision camera distortion measurements with a calibration harp",
   JOSA A 29(10), 2012 (blur, motion and out-of-focus strings must be avoided).
.. [2] ISO 12233:2017, Photography -- Electronic still picture imaging --
   Resolution and spatial frequency responses (slanted-edge method).
.. [3] G. Golub, V. Pereyra, "Separable nonlinear least squares: the variable
   projection method and its applications", Inverse Problems 19(2), 2003.
.. [4] M. Subbarao, J.-K. Tian, "Selecting the optimal focus measure for
   autofocusing and depth-from-focus", IEEE TPAMI 20(8), 1998.
.. [5] R. Grompone von Gioi, G. Randall, "A Sub-Pixel Edge Detector: an
   Implementation of the Canny/Devernay Algorithm", IPOL 7 (2017).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray
from scipy.special import ndtr

from pipeline.edges import auto_thresholds, detect_edges
from pipeline.grouping import MIN_PIECE_PX, REJECT_REASONS, Grouping, group_string_edges, points_bbox
from pipeline.plain import finite_or_none

Points = NDArray[np.float64]
Floats = NDArray[np.float64]

TARGET_ANALYSIS_PIXELS = 1_000_000
"""Largest number of pixels the strings are searched on (the frame is downscaled to it)."""
MIN_ANALYSIS_STRING_PX = 2.8
"""Narrowest string (px) on the downscaled image; the grouping supports 2 px and up."""
CROSS_SECTIONS = 24
"""Cross-sections per string on which sharpness, contrast and width are measured."""
EDGE_WIDTH_PER_SIGMA = 2.0 * 1.2815515655446004
"""10-90 % rise distance of a Gaussian-blurred step, in units of its sigma (2 Phi^-1(0.9))."""
PIXEL_VARIANCE = 1.0 / 12.0
"""Variance (px^2) a unit pixel adds along any direction."""
DARK_LEVEL = 0.02
"""A pixel at or below this fraction of full scale is dark (no usable signal)."""
HISTOGRAM_BINS = 64
"""Bins of :attr:`ExposureFigures.histogram` over ``[0, full scale]``."""
CELLS_ACROSS = 8
"""Coverage cells along the longer image side (square cells)."""
DIRECTION_BIN_DEG = 15.0
"""Width of a coverage direction bin, degrees (12 bins over 180 degrees)."""
MIN_SEPARATION_DEG = 30.0
"""Two directions at least this far apart cover a cell."""
MIN_CELL_EDGE_FRACTION = 0.25
"""Edge length (fraction of the cell side) that makes a direction present in a cell."""
BORDER_PX = 4.0
"""Border of the analysis image where no edge point is kept (as :func:`pipeline.measure.measure_image`)."""
_MAX_GN_ITER = 12
_WIDTH_TO_SIGMA = (0.5, 1.0, 2.0, 3.0, 4.0, 6.0, 9.0, 14.0)


# ----------------------------------------------------------------------------- exposure
@dataclass(frozen=True)
class ExposureFigures:
    """What the exposure of a frame looks like.

    Attributes
    ----------
    full_scale : float
        The top code value (255 for 8-bit, 65535 for 16-bit frames).
    histogram : (HISTOGRAM_BINS,) int ndarray
        Pixel counts in equal bins over ``[0, full_scale]`` (the last bin
        holds the top value).
    saturated_fraction : float
        Fraction of pixels at (or above) ``full_scale``.
    dark_fraction : float
        Fraction of pixels at or below ``DARK_LEVEL * full_scale``.
    low, high : float
        The 0.5 and 99.5 percentiles (numpy's linear interpolation).
    dynamic_range : float
        ``(high - low) / full_scale``.
    mean : float
        Mean grey level.
    """

    full_scale: float
    histogram: NDArray[np.int64]
    saturated_fraction: float
    dark_fraction: float
    low: float
    high: float
    dynamic_range: float
    mean: float

    def to_dict(self) -> dict[str, Any]:
        return {
            "full_scale": self.full_scale,
            "histogram": [int(c) for c in self.histogram],
            "saturated_fraction": self.saturated_fraction,
            "dark_fraction": self.dark_fraction,
            "low": self.low,
            "high": self.high,
            "dynamic_range": self.dynamic_range,
            "mean": self.mean,
        }


def full_scale_of(image: NDArray[Any]) -> float:
    """Top code value of an integer image's dtype; 255 for float images (8-bit scale)."""
    dt = np.asarray(image).dtype
    return float(np.iinfo(dt).max) if np.issubdtype(dt, np.integer) else 255.0


def _percentile_from_counts(counts: NDArray[np.int64], q: float) -> float:
    """numpy's linear percentile of the values ``0..len(counts)-1`` repeated ``counts`` times."""
    n = int(counts.sum())
    cum = np.cumsum(counts)
    pos = q / 100.0 * (n - 1)
    lo = math.floor(pos)
    frac = pos - lo
    v_lo = int(np.searchsorted(cum, lo, side="right"))
    v_hi = int(np.searchsorted(cum, min(lo + 1, n - 1), side="right"))
    return float(v_lo + frac * (v_hi - v_lo))


def exposure_figures(image: NDArray[Any], full_scale: float | None = None) -> ExposureFigures:
    """Histogram, saturated and dark fractions and dynamic range of a grey image.

    Parameters
    ----------
    image : 2-D ndarray
        uint8, uint16 or float grey image.
    full_scale : float or None
        Top code value (None: from the dtype, :func:`full_scale_of`).

    Returns
    -------
    ExposureFigures
        For integer images every figure is exact (read from the per-code
        histogram); float images (averaged frames) use ``np.percentile``.

    References
    ----------
    .. [1] numpy.percentile, method "linear" (Hyndman & Fan definition 7).
    """
    img = np.asarray(image)
    if img.ndim != 2 or img.size == 0:
        raise ValueError(f"expected a non-empty 2-D grey image, got shape {img.shape}")
    full = full_scale_of(img) if full_scale is None else float(full_scale)
    if not full > 0:
        raise ValueError(f"full_scale must be > 0, got {full!r}")
    n = img.size
    dark_top = DARK_LEVEL * full
    if img.dtype in (np.uint8, np.uint16):
        codes = 256 if img.dtype == np.uint8 else 65536
        counts = cv2.calcHist([img], [0], None, [codes], [0, codes]).ravel().astype(np.int64)
        values = np.arange(codes, dtype=np.float64)
        saturated = float(counts[values >= full].sum()) / n
        dark = float(counts[values <= dark_top].sum()) / n
        low, high = _percentile_from_counts(counts, 0.5), _percentile_from_counts(counts, 99.5)
        mean = float(counts @ values) / n
        edges = np.minimum((values / full * HISTOGRAM_BINS).astype(np.int64), HISTOGRAM_BINS - 1)
        hist = np.bincount(edges, weights=counts, minlength=HISTOGRAM_BINS)[:HISTOGRAM_BINS].astype(np.int64)
    else:
        f = img.astype(np.float64, copy=False)
        saturated = float(np.count_nonzero(f >= full - 1e-9)) / n
        dark = float(np.count_nonzero(f <= dark_top)) / n
        low, high = (float(v) for v in np.percentile(f, [0.5, 99.5]))
        mean = float(f.mean())
        idx = np.clip((f / full * HISTOGRAM_BINS).astype(np.int64), 0, HISTOGRAM_BINS - 1)
        hist = np.bincount(idx.ravel(), minlength=HISTOGRAM_BINS).astype(np.int64)
    return ExposureFigures(full, hist, saturated, dark, low, high, (high - low) / full, mean)


# ----------------------------------------------------------------------------- coverage
@dataclass(frozen=True)
class Coverage:
    """Edge length seen per image cell and direction (module docstring, *Coverage*).

    Attributes
    ----------
    width, height : int
        Image size, pixels.
    cell_px : float
        Side of a (square) cell; the last row and column may be cut by the image.
    length_px : (ny, nx, nbins) float ndarray
        Edge length seen in each cell per direction bin (bin ``k`` holds
        angles in ``[k, k + 1) * DIRECTION_BIN_DEG``, angles in ``[0, 180)``).
    """

    width: int
    height: int
    cell_px: float
    length_px: Floats

    @property
    def shape(self) -> tuple[int, int]:
        """``(ny, nx)`` cells."""
        return (int(self.length_px.shape[0]), int(self.length_px.shape[1]))

    @property
    def directions(self) -> NDArray[np.bool_]:
        """``(ny, nx, nbins)``: which directions are present in each cell."""
        return self.length_px >= MIN_CELL_EDGE_FRACTION * self.cell_px

    @property
    def present(self) -> NDArray[np.bool_]:
        """``(ny, nx)``: cells holding string edges in at least one direction."""
        return np.asarray(self.directions.any(axis=2))

    @property
    def covered(self) -> NDArray[np.bool_]:
        """``(ny, nx)``: cells holding edges in two directions >= ``MIN_SEPARATION_DEG`` apart."""
        d = self.directions
        nb = d.shape[2]
        sep = int(math.ceil(MIN_SEPARATION_DEG / DIRECTION_BIN_DEG - 1e-9))
        out = np.zeros(d.shape[:2], bool)
        for k in range(sep, nb - sep + 1):  # circular bin distance >= sep
            out |= (d & np.roll(d, k, axis=2)).any(axis=2)
        return out

    @property
    def covered_fraction(self) -> float:
        """Fraction of the cells that are covered."""
        return float(self.covered.mean())

    @property
    def corners_covered(self) -> tuple[bool, bool, bool, bool]:
        """Corner cells covered: top-left, top-right, bottom-left, bottom-right."""
        c = self.covered
        return (bool(c[0, 0]), bool(c[0, -1]), bool(c[-1, 0]), bool(c[-1, -1]))

    def merge(self, other: Coverage) -> Coverage:
        """The coverage of both (cell-wise maximum: a frame seen twice adds nothing)."""
        if (self.width, self.height, self.length_px.shape) != (other.width, other.height, other.length_px.shape):
            raise ValueError("coverages of different image sizes or grids cannot be merged")
        return Coverage(self.width, self.height, self.cell_px, np.maximum(self.length_px, other.length_px))

    def to_dict(self) -> dict[str, Any]:
        return {
            "cells": list(self.shape),
            "cell_px": self.cell_px,
            "present": self.present.astype(int).tolist(),
            "covered": self.covered.astype(int).tolist(),
            "covered_fraction": self.covered_fraction,
            "corners_covered": list(self.corners_covered),
        }


def coverage_grid(width: int, height: int) -> tuple[int, int, float]:
    """``(nx, ny, cell_px)``: square cells, :data:`CELLS_ACROSS` along the longer side."""
    cell = max(width, height) / CELLS_ACROSS
    return max(1, math.ceil(width / cell - 1e-9)), max(1, math.ceil(height / cell - 1e-9)), float(cell)


def empty_coverage(width: int, height: int) -> Coverage:
    """A coverage with no edge seen (the start of an accumulation)."""
    nx, ny, cell = coverage_grid(width, height)
    nb = int(round(180.0 / DIRECTION_BIN_DEG))
    return Coverage(int(width), int(height), cell, np.zeros((ny, nx, nb)))


def edge_coverage(polylines: Sequence[Points], width: int, height: int) -> Coverage:
    """Coverage of an image by edges given as ordered polylines ``(N, 2)`` of ``(x, y)`` points.

    Each segment between consecutive points adds its length to the cell
    holding its midpoint, in the bin of its direction (modulo 180 degrees).
    Segments longer than a quarter cell are ignored (gaps in an edge).
    """
    cov = empty_coverage(width, height)
    ny, nx, nb = cov.length_px.shape
    acc = np.zeros(ny * nx * nb)
    for xy in polylines:
        p = np.asarray(xy, np.float64)
        if len(p) < 2:
            continue
        d = np.diff(p, axis=0)
        seg = np.hypot(d[:, 0], d[:, 1])
        mid = 0.5 * (p[1:] + p[:-1])
        ok = (seg > 0) & (seg <= 0.25 * cov.cell_px)
        ok &= (mid[:, 0] >= -0.5) & (mid[:, 0] < width - 0.5) & (mid[:, 1] >= -0.5) & (mid[:, 1] < height - 0.5)
        if not ok.any():
            continue
        ang = np.degrees(np.arctan2(d[ok, 1], d[ok, 0])) % 180.0
        b = np.minimum((ang / DIRECTION_BIN_DEG).astype(np.int64), nb - 1)
        cx = np.clip(((mid[ok, 0] + 0.5) / cov.cell_px).astype(np.int64), 0, nx - 1)
        cy = np.clip(((mid[ok, 1] + 0.5) / cov.cell_px).astype(np.int64), 0, ny - 1)
        acc += np.bincount((cy * nx + cx) * nb + b, weights=seg[ok], minlength=acc.size)
    return Coverage(cov.width, cov.height, cov.cell_px, acc.reshape(ny, nx, nb))


# ----------------------------------------------------------------------------- sharpness
@dataclass(frozen=True)
class StringSharpness:
    """Figures of one string, measured on the full-resolution frame (module docstring).

    Attributes
    ----------
    string_id : int
        The grouping's string number (0, 1, ... across the harp).
    sigma_px : float
        Standard deviation of the fitted PSF across the string (optics and
        pixel integration), px; NaN when the fit failed.
    edge_width_px : float
        10-90 % width of one edge, ``EDGE_WIDTH_PER_SIGMA * sigma_px``.
    contrast : float
        ``|A| / max(B, B + A)``: the fraction of the brighter level the string
        takes away (dark strings) or adds (bright ones); at most 1 (an opaque
        string). For a string narrower than about 2 sigma only ``contrast *
        width_px`` (its shadow) is well determined (module docstring).
    width_px : float
        Fitted string width, px.
    angle_deg : float
        Direction of the string in ``[0, 180)`` (pipeline convention).
    centre : (float, float)
        A point of the string's centre line near its middle, ``(x, y)``.
    cross_sections : int
        Cross-sections that entered the fit.
    residual : float
        RMS residual of the fit relative to ``|A|``.
    offset_px : float
        Median distance between the centre line given (from the edges) and the one refined on
        the pixels: how far the string is from where it was looked for.
    """

    string_id: int
    sigma_px: float
    edge_width_px: float
    contrast: float
    width_px: float
    angle_deg: float
    centre: tuple[float, float]
    cross_sections: int
    residual: float
    offset_px: float = float("nan")

    def to_dict(self) -> dict[str, Any]:
        return {
            "string": self.string_id,
            "sigma_px": finite_or_none(self.sigma_px),
            "edge_width_px": finite_or_none(self.edge_width_px),
            "contrast": finite_or_none(self.contrast),
            "width_px": finite_or_none(self.width_px),
            "angle_deg": finite_or_none(self.angle_deg),
            "centre": [self.centre[0], self.centre[1]],
            "cross_sections": self.cross_sections,
            "residual": finite_or_none(self.residual),
            "offset_px": finite_or_none(self.offset_px),
        }


def _interp_along(xy: Points, u_of: Floats, u: Floats) -> Points:
    return np.stack([np.interp(u, u_of, xy[:, 0]), np.interp(u, u_of, xy[:, 1])], axis=1)


def _cross_sections(a: Points, b: Points, k: int, direction: Points) -> tuple[Points, Points, float] | None:
    """Centres, unit normals (``(k, 2)`` each) and width of a string from its two edges."""
    ua, ub = a @ direction, b @ direction
    oa, ob = np.argsort(ua), np.argsort(ub)
    ua, ub, a, b = ua[oa], ub[ob], a[oa], b[ob]
    lo, hi = max(ua[0], ub[0]), min(ua[-1], ub[-1])
    if not hi - lo > 4.0:
        return None
    u = lo + (hi - lo) * (np.arange(k) + 0.5) / k
    pa, pb = _interp_along(a, ua, u), _interp_along(b, ub, u)
    centre = 0.5 * (pa + pb)
    h = min(8.0, 0.25 * (hi - lo) / k + 2.0)
    ta = _interp_along(a, ua, np.minimum(u + h, hi)) - _interp_along(a, ua, np.maximum(u - h, lo))
    tb = _interp_along(b, ub, np.minimum(u + h, hi)) - _interp_along(b, ub, np.maximum(u - h, lo))
    t = ta + tb
    t /= np.maximum(np.hypot(t[:, 0], t[:, 1]), 1e-12)[:, None]
    normal = np.stack([-t[:, 1], t[:, 0]], axis=1)
    width = float(np.median(np.abs(np.sum((pb - pa) * normal, axis=1))))
    return centre, normal, width


def _profile(s: Floats, w: Floats, sig: Floats) -> Floats:
    """``g(s)`` of the module docstring (a blurred box of width ``w``)."""
    return np.asarray(ndtr((s + 0.5 * w) / sig) - ndtr((s - 0.5 * w) / sig), np.float64)


class _Rows:
    """Samples grouped by cross-section, with the sums of the linear model that do not change.

    The linear part of the model is ``v ~ B + C s + A g`` per cross-section (row): the slope
    ``C`` absorbs the shading across one cross-section (vignetting). Only the sums involving
    ``g`` change while ``(w, sigma)`` are fitted.
    """

    def __init__(self, s: Floats, v: Floats, row: NDArray[np.intp], nrows: int) -> None:
        self.s, self.v, self.row, self.nrows = s, v, row, nrows
        self.n = np.bincount(row, minlength=nrows).astype(np.float64)
        self.ss, self.sss = self._sum(row, s), self._sum(row, s * s)
        self.sv, self.ssv = self._sum(row, v), self._sum(row, s * v)

    def _sum(self, row: NDArray[np.intp], x: Floats) -> Floats:
        return np.bincount(row, weights=x, minlength=self.nrows).astype(np.float64)

    def project(self, g: Floats, sel: NDArray[np.intp] | None = None) -> tuple[Floats, Floats, Floats, Floats]:
        """``B``, ``C``, ``A`` per row and the residual of the samples ``sel`` (all: None).

        ``g`` is the profile at the samples ``sel``; rows not in ``sel`` get meaningless values.
        """
        s, v, row = (self.s, self.v, self.row) if sel is None else (self.s[sel], self.v[sel], self.row[sel])
        sg, sgg, ssg, sgv = self._sum(row, g), self._sum(row, g * g), self._sum(row, s * g), self._sum(row, g * v)
        ata = np.empty((self.nrows, 3, 3))
        ata[:, 0, 0], ata[:, 1, 1], ata[:, 2, 2] = self.n, self.sss, sgg
        ata[:, 0, 1] = ata[:, 1, 0] = self.ss
        ata[:, 0, 2] = ata[:, 2, 0] = sg
        ata[:, 1, 2] = ata[:, 2, 1] = ssg
        atb = np.stack([self.sv, self.ssv, sgv], axis=1)
        scale = np.maximum(ata[:, 0, 0] + ata[:, 1, 1] + ata[:, 2, 2], 1e-300)
        coef = np.asarray(
            np.linalg.solve(ata / scale[:, None, None] + 1e-12 * np.eye(3), (atb / scale[:, None])[..., None])[..., 0],
            np.float64,
        )
        bg, slope, amp = coef[:, 0], coef[:, 1], coef[:, 2]
        return bg, slope, amp, v - bg[row] - slope[row] * s - amp[row] * g


def _fit_strings(
    rows: _Rows,
    string_of_row: NDArray[np.intp],
    w0: Floats,
    sig0: Floats,
) -> tuple[Floats, Floats, Floats]:
    """Variable-projection Levenberg-Marquardt for ``(w, sigma)`` of every string at once.

    Each string stops iterating once converged (the others go on without it).
    Returns ``w``, ``sigma`` and the cost (sum of squared residuals) per string.
    """
    ns = len(w0)
    st = string_of_row[rows.row]
    p = np.stack([np.log(np.maximum(w0, 0.5)), np.log(np.maximum(sig0, 0.3))], axis=1)
    lam = np.full(ns, 1e-3)
    s = rows.s

    def resid(q: Floats, sel: NDArray[np.intp]) -> Floats:
        k = st[sel]
        return rows.project(_profile(s[sel], np.exp(q[k, 0]), np.exp(q[k, 1])), sel)[3]

    def per_string(sel: NDArray[np.intp], x: Floats) -> Floats:
        return np.bincount(st[sel], weights=x, minlength=ns).astype(np.float64)

    everything = np.arange(len(s))
    r = resid(p, everything)
    c = per_string(everything, r * r)
    active = np.ones(ns, bool)
    eps = 1e-5
    for _ in range(_MAX_GN_ITER):
        sel = np.nonzero(active[st])[0]
        if not len(sel):
            break
        rs = r[sel]
        j0 = (resid(p + [eps, 0.0], sel) - rs) / eps
        j1 = (resid(p + [0.0, eps], sel) - rs) / eps
        a00, a01, a11 = per_string(sel, j0 * j0), per_string(sel, j0 * j1), per_string(sel, j1 * j1)
        g0, g1 = per_string(sel, j0 * rs), per_string(sel, j1 * rs)
        a00d, a11d = a00 * (1.0 + lam) + 1e-12, a11 * (1.0 + lam) + 1e-12
        det = a00d * a11d - a01 * a01
        det = np.where(np.abs(det) > 1e-300, det, 1e-300)
        step = np.stack([-(a11d * g0 - a01 * g1) / det, -(a00d * g1 - a01 * g0) / det], axis=1)
        step = np.where(active[:, None], np.clip(step, -0.7, 0.7), 0.0)
        q = p + step
        q[:, 1] = np.maximum(q[:, 1], math.log(0.2))
        rq = resid(q, sel)
        cq = np.where(active, per_string(sel, rq * rq), np.inf)
        better = cq < c
        small = better & ((np.abs(step).max(axis=1) < 1e-3) | (c - cq < 1e-5 * c))
        p = np.where(better[:, None], q, p)
        r[sel] = np.where(better[st[sel]], rq, rs)
        c = np.where(better, cq, c)
        lam = np.where(better, lam * 0.2, lam * 10.0)
        active &= ~(small | (lam > 1e4))
    return np.exp(p[:, 0]), np.exp(p[:, 1]), c


def _gather(
    img: NDArray[Any], centre: Points, normal: Points, reach: float
) -> tuple[Floats, Floats, NDArray[np.bool_]]:
    """Pixels of one row or column through each centre, with their distance along the normal.

    Returns ``(K, J)`` arrays: signed distance ``s`` to the centre line,
    value, and a mask of the pixels inside the image and within ``reach``.
    """
    h, w = img.shape
    along_x = np.abs(normal[:, 0]) >= np.abs(normal[:, 1])  # walk a row (else a column)
    comp = np.where(along_x, np.abs(normal[:, 0]), np.abs(normal[:, 1]))
    half = int(math.ceil(reach / math.sqrt(0.5))) + 1
    j = np.arange(-half, half + 1, dtype=np.float64)[None, :]
    xs = np.where(along_x[:, None], np.round(centre[:, 0:1]) + j, np.round(centre[:, 0:1]))
    ys = np.where(along_x[:, None], np.round(centre[:, 1:2]), np.round(centre[:, 1:2]) + j)
    xs = np.broadcast_to(xs, (len(centre), j.size))
    ys = np.broadcast_to(ys, (len(centre), j.size))
    inside = (xs >= 0) & (xs <= w - 1) & (ys >= 0) & (ys <= h - 1)
    xi = np.clip(xs, 0, w - 1).astype(np.intp)
    yi = np.clip(ys, 0, h - 1).astype(np.intp)
    vals = img[yi, xi].astype(np.float64)
    s = (xs - centre[:, 0:1]) * normal[:, 0:1] + (ys - centre[:, 1:2]) * normal[:, 1:2]
    mask = inside & (np.abs(s) <= reach) & (comp[:, None] > 0)
    return s, vals, mask


def string_sharpness(
    image: NDArray[Any],
    strings: Sequence[tuple[int, Points, Points]],
    *,
    cross_sections: int = CROSS_SECTIONS,
    reach_px: float | None = None,
) -> tuple[StringSharpness, ...]:
    """Sharpness, contrast, width and angle of each string (module docstring, *Sharpness*).

    Parameters
    ----------
    image : 2-D ndarray
        The full-resolution grey frame, ``image[y, x]``.
    strings : sequence of (string_id, edge_a, edge_b)
        The two edges of each string, ``(N, 2)`` points ``(x, y)`` in the
        frame's pixels (any order along the edge, any accuracy to about a
        pixel: the centre of each cross-section is refined on the pixels).
    cross_sections : int
        Cross-sections per string.
    reach_px : float or None
        Half-length of a cross-section beyond the string's half width
        (None: 16 px, at most 45 % of the string pitch minus the half width).

    Returns
    -------
    tuple of StringSharpness
        One per string, in the given order; a string too short or a fit that
        fails gives NaN figures (``cross_sections == 0``).

    References
    ----------
    .. [1] ISO 12233:2017 (slanted-edge sampling).
    .. [2] G. Golub, V. Pereyra, Inverse Problems 19(2), 2003.
    """
    img = np.asarray(image)
    if img.ndim != 2:
        raise ValueError(f"expected a 2-D grey image, got shape {img.shape}")
    k = max(2, int(cross_sections))
    nan = float("nan")
    prepared: list[tuple[int, Points, Points, float, float, tuple[float, float]] | None] = []
    centres_all = []
    for sid, a, b in strings:
        pa, pb = np.asarray(a, np.float64), np.asarray(b, np.float64)
        if len(pa) < 2 or len(pb) < 2:
            prepared.append(None)
            continue
        c0 = np.concatenate([pa, pb]).mean(axis=0)
        direction = _direction(pa, pb)
        cs = _cross_sections(pa, pb, k, direction)
        if cs is None:
            prepared.append(None)
            continue
        centre, normal, width = cs
        angle = math.degrees(math.atan2(direction[1], direction[0])) % 180.0
        mid = centre[len(centre) // 2]
        prepared.append((sid, centre, normal, width, angle, (float(mid[0]), float(mid[1]))))
        centres_all.append((c0, direction, width))
    if reach_px is None:
        pitch = _pitch(centres_all)
        half_w = max((p[3] for p in prepared if p is not None), default=0.0) / 2.0
        extra = 16.0 if not math.isfinite(pitch) else max(4.0, min(16.0, 0.45 * pitch - half_w))
    else:
        extra = float(reach_px)
    live = [i for i, p in enumerate(prepared) if p is not None]
    fitted = _fit_batch(img, [p for p in prepared if p is not None], extra) if live else []
    out = [StringSharpness(int(sid), nan, nan, nan, nan, nan, (nan, nan), 0, nan) for sid, _, _ in strings]
    for i, fig in zip(live, fitted):
        p = prepared[i]
        assert p is not None
        sid, _, _, _, angle, mid = p
        out[i] = StringSharpness(int(sid), fig[0], fig[1], fig[2], fig[3], angle, mid, fig[4], fig[5], fig[6])
    return tuple(out)


def _direction(a: Points, b: Points) -> Points:
    """Unit direction of a string: the length-weighted doubled-angle mean of its edges' own
    total-least-squares directions (two edges of unequal extent would tilt a joint fit)."""
    acc = np.zeros(2)
    for xy in (a, b):
        c = xy - xy.mean(axis=0)
        val, vec = np.linalg.eigh(c.T @ c)
        t = vec[:, 1]
        ang = 2.0 * math.atan2(t[1], t[0])
        acc += math.sqrt(max(float(val[1]), 0.0)) * np.array([math.cos(ang), math.sin(ang)])
    half = 0.5 * math.atan2(acc[1], acc[0])
    return np.array([math.cos(half), math.sin(half)])


def _pitch(lines: Sequence[tuple[Points, Points, float]]) -> float:
    """Median distance between neighbouring string centre lines (NaN with fewer than two)."""
    if len(lines) < 2:
        return float("nan")
    d = np.mean(
        [ln[1] for ln in lines if ln[1] @ lines[0][1] >= 0] + [-ln[1] for ln in lines if ln[1] @ lines[0][1] < 0],
        axis=0,
    )
    n = np.array([-d[1], d[0]]) / max(float(np.hypot(*d)), 1e-12)
    off = np.sort([float(ln[0] @ n) for ln in lines])
    gaps = np.diff(off)
    gaps = gaps[gaps > 1.0]
    return float(np.median(gaps)) if len(gaps) else float("nan")


def _line_fit(s: Floats, v: Floats, m: NDArray[np.bool_]) -> tuple[Floats, Floats]:
    """Per row least-squares line ``v ~ b0 + b1 s`` over the masked samples (``(R, J)`` arrays)."""
    mf = m.astype(np.float64)
    n, ss, sv = mf.sum(-1), (s * mf).sum(-1), (v * mf).sum(-1)
    sss, ssv = (s * s * mf).sum(-1), (s * v * mf).sum(-1)
    det = n * sss - ss * ss
    ok = det > 1e-9
    b1 = np.where(ok, (n * ssv - ss * sv) / np.where(ok, det, 1.0), 0.0)
    b0 = np.where(n > 0, (sv - b1 * ss) / np.maximum(n, 1.0), 0.0)
    return b0, b1


def _centre(s: Floats, d: Floats, m: NDArray[np.bool_]) -> tuple[Floats, Floats]:
    """Per row centroid and variance of the darkness ``d`` over the mask (noise averages out: not clipped)."""
    wt = d * m
    tot = wt.sum(-1)
    good = tot > 1e-9
    mean = np.where(good, (wt * s).sum(-1) / np.where(good, tot, 1.0), 0.0)
    var = np.where(good, (wt * s * s).sum(-1) / np.where(good, tot, 1.0) - mean**2, np.nan)
    return mean, var


def _fit_batch(
    img: NDArray[Any],
    live: Sequence[tuple[int, Points, Points, float, float, tuple[float, float]]],
    extra: float,
) -> list[tuple[float, float, float, float, int, float, float]]:
    """Fit every string at once; per string (sigma, edge width, contrast, width, sections, residual, offset)."""
    ns = len(live)
    widths = np.array([p[3] for p in live])
    reach = float(np.max(widths)) / 2.0 + extra
    gathered = [_gather(img, p[1], p[2], reach) for p in live]
    s = np.concatenate([g[0] for g in gathered])  # (R, J): every cross-section of every string
    v = np.concatenate([g[1] for g in gathered])
    m0 = np.concatenate([g[2] for g in gathered])
    nrows = len(s)
    sor = np.repeat(np.arange(ns), [len(g[0]) for g in gathered]).astype(np.intp)  # string of each row
    half = widths[sor][:, None] / 2.0
    inner_lim, outer_lim = half + 0.6 * extra, half + extra
    # a cross-section is used only with background on both sides (not cut by the image border)
    both = (np.any(m0 & (s <= -inner_lim), axis=-1) & np.any(m0 & (s >= inner_lim), axis=-1))[:, None]
    m0 = m0 & both & (np.abs(s) <= outer_lim)
    # first guess: a background line through the outer pixels, the amplitude at the extreme,
    # then centre and sigma from the moments of the darkness (variance w^2 / 12 + sigma^2)
    b0, b1 = _line_fit(s, v, m0 & (np.abs(s) >= inner_lim))
    dev = np.where(m0, v - b0[:, None] - b1[:, None] * s, 0.0)
    inner = m0 & (np.abs(s) < inner_lim)
    lo, hi = np.where(inner, dev, np.inf).min(-1), np.where(inner, dev, -np.inf).max(-1)
    amp = np.where(np.abs(lo) > np.abs(hi), lo, hi)
    amp = np.where(np.isfinite(amp) & (np.abs(amp) > 1e-12), amp, 1.0)
    moved = np.zeros(nrows)  # how far each cross-section's centre was moved
    sd = np.full(ns, extra / 3.0)  # the profile's standard deviation, sqrt(w^2 / 12 + sigma^2)
    for _ in range(3):
        win = np.minimum(3.0 * sd + 1.0, widths / 2.0 + 0.6 * extra)[sor][:, None]
        shift, var = _centre(s, dev / amp[:, None], m0 & (np.abs(s) <= win))
        s = s - shift[:, None]
        moved += shift
        with np.errstate(all="ignore"):
            var_s = np.array(
                [np.nanmedian(var[sor == i]) if np.isfinite(var[sor == i]).any() else np.nan for i in range(ns)]
            )
        sd = np.where(np.isfinite(var_s), np.sqrt(np.clip(var_s, 0.09, None)), 1.0)
    # split that variance between the string width and the blur: the best of a few ratios w / sigma
    rr, jj = np.nonzero(m0 & (np.abs(s) <= np.minimum(4.0 * sd + 3.0, widths / 2.0 + extra)[sor][:, None]))
    rows = _Rows(s[rr, jj], v[rr, jj], rr.astype(np.intp), nrows)
    st = sor[rr]
    best = np.full(ns, np.inf)
    w_fit, sig_fit = np.maximum(widths, 1.0), np.maximum(sd / 2.0, 0.3)
    for rho in _WIDTH_TO_SIGMA:
        sig = sd / math.sqrt(rho * rho / 12.0 + 1.0)
        res = rows.project(_profile(rows.s, rho * sig[st], sig[st]))[3]
        c = np.bincount(st, weights=res * res, minlength=ns)
        take = c < best
        best = np.where(take, c, best)
        w_fit, sig_fit = np.where(take, rho * sig, w_fit), np.where(take, sig, sig_fit)
    cost = np.zeros(ns)
    rr = np.zeros(0, np.intp)
    bg = amp_f = np.zeros(nrows)
    for rnd in range(2):
        # fit on the string and enough background on both sides: w/2 + 5 sigma + 3 (within the reach)
        fit_win = np.minimum(w_fit / 2.0 + 5.0 * sig_fit + 3.0, widths / 2.0 + extra)
        rr, jj = np.nonzero(m0 & (np.abs(s) <= fit_win[sor][:, None]))
        rr = rr.astype(np.intp)
        rows = _Rows(s[rr, jj], v[rr, jj], rr, nrows)
        w_fit, sig_fit, cost = _fit_strings(rows, sor, w_fit, sig_fit)
        bg, slope, amp_f, _ = rows.project(_profile(rows.s, w_fit[sor[rr]], sig_fit[sor[rr]]))
        if rnd == 0:  # re-centre each cross-section on the fitted model's darkness
            a_safe = np.where(np.abs(amp_f) > 1e-12, amp_f, 1.0)[:, None]
            win = (w_fit / 2.0 + 3.0 * sig_fit + 1.0)[sor][:, None]
            shift, _ = _centre(s, (v - bg[:, None] - slope[:, None] * s) / a_safe, m0 & (np.abs(s) <= win))
            s = s - shift[:, None]
            moved += shift
    counts = np.bincount(rr, minlength=nrows)
    n_str = np.bincount(sor, weights=counts, minlength=ns)
    out = []
    for i in range(ns):
        ok = (sor == i) & (counts >= 5) & (np.abs(amp_f) > 0)
        a, b = amp_f[ok], bg[ok]
        if ok.sum() < 2 or not (0.2 < sig_fit[i] < 0.5 * extra + 10.0):
            out.append((float("nan"),) * 4 + (0, float("nan"), float("nan")))
            continue
        contrast = float(np.median(np.abs(a) / np.maximum(np.maximum(b, b + a), 1e-12)))
        width = float(w_fit[i])
        if contrast > 1.0:  # light below zero: an opaque string narrower than the blur (module docstring)
            width, contrast = width * contrast, 1.0
        rel = math.sqrt(cost[i] / max(n_str[i], 1.0)) / max(float(np.median(np.abs(a))), 1e-12)
        sg = float(sig_fit[i])
        offset = float(np.median(np.abs(moved[ok])))
        out.append((sg, EDGE_WIDTH_PER_SIGMA * sg, contrast, width, int(ok.sum()), rel, offset))
    return out


# ----------------------------------------------------------------------------- focus peak
@dataclass(frozen=True)
class FocusPeak:
    """Where the focus score peaks over a series of (focus setting, score) samples.

    ``focus``: the vertex of the parabola fitted to the squared edge widths
    ``1 / score^2`` around their minimum when the samples bracket it
    (``bracketed``), else the best sample's setting; ``score``: the score
    there (the parabola's, or the best sample's); ``samples``: how many
    samples entered.
    """

    focus: float
    score: float
    bracketed: bool
    samples: int

    def to_dict(self) -> dict[str, Any]:
        return {"focus": self.focus, "score": self.score, "bracketed": self.bracketed, "samples": self.samples}


def focus_peak(positions: Sequence[float], scores: Sequence[float]) -> FocusPeak | None:
    """The focus setting of best focus from a through-focus series (module docstring).

    Parameters
    ----------
    positions, scores : sequences of float
        Focus settings and the focus scores measured there (1 / edge width);
        non-finite scores are ignored; repeated settings are averaged.

    Returns
    -------
    FocusPeak or None
        None without a finite sample.

    References
    ----------
    .. [1] M. Subbarao, J.-K. Tian, IEEE TPAMI 20(8), 1998.
    """
    f = np.asarray(positions, np.float64)
    sc = np.asarray(scores, np.float64)
    ok = np.isfinite(f) & np.isfinite(sc) & (sc > 0)
    if not ok.any():
        return None
    f, sc = f[ok], sc[ok]
    uf, inv = np.unique(f, return_inverse=True)
    w2 = np.bincount(inv, weights=1.0 / sc**2) / np.bincount(inv)
    best = int(np.argmin(w2))
    best_score = float(1.0 / math.sqrt(w2[best]))
    if len(uf) < 3 or best in (0, len(uf) - 1):
        return FocusPeak(float(uf[best]), best_score, False, int(ok.sum()))
    # the samples near the minimum: squared width within 4x of it (a width within 2x), at least 3
    near = np.nonzero(w2 <= 4.0 * w2[best])[0]
    lo, hi = best, best
    while lo - 1 >= 0 and lo - 1 in near:
        lo -= 1
    while hi + 1 < len(uf) and hi + 1 in near:
        hi += 1
    lo, hi = min(lo, best - 1), max(hi, best + 1)
    a, b, c = np.polyfit(uf[lo : hi + 1], w2[lo : hi + 1], 2)
    if not a > 0:
        return FocusPeak(float(uf[best]), best_score, False, int(ok.sum()))
    vertex = -b / (2.0 * a)
    if not uf[lo] <= vertex <= uf[hi]:
        return FocusPeak(float(uf[best]), best_score, False, int(ok.sum()))
    at = c - b * b / (4.0 * a)
    score = float(1.0 / math.sqrt(at)) if at > 0 else best_score
    return FocusPeak(float(vertex), score, True, int(ok.sum()))


# ----------------------------------------------------------------------------- the assessment
@dataclass(frozen=True)
class AssessedEdge:
    """A string edge found, in the frame's pixels (``xy`` ordered along the edge)."""

    string_id: int
    polarity: int
    xy: Points


@dataclass(frozen=True)
class RejectedMark:
    """A group of edge points the grouping rejected, with its reason (:data:`pipeline.grouping.REJECT_REASONS`)."""

    reason: str
    xy: Points
    detail: str = ""

    @property
    def bbox(self) -> tuple[float, float, float, float]:
        """``(x_min, y_min, x_max, y_max)`` in the frame's pixels."""
        return points_bbox(self.xy)


@dataclass(frozen=True)
class Assessment:
    """Everything the live view shows about one frame (module docstring).

    Attributes
    ----------
    width, height : int
        Frame size.
    scale : float
        Downscaling factor of the image the strings were found on.
    thresholds : (float, float)
        Edge-detector thresholds used on that image (pass them back to
        :func:`assess_frame` to skip their estimation on the next frame).
    edges : tuple of AssessedEdge
        The string edges found, frame pixels.
    rejected : tuple of RejectedMark
        Rejected groups of edge points, frame pixels.
    strings : tuple of StringSharpness
        Per string figures, in string order.
    focus_score : float
        ``1 / edge_width_px`` (NaN without a measured string).
    edge_width_px : float
        Median 10-90 % edge width over the strings, px.
    exposure : ExposureFigures
    coverage : Coverage
        This frame's coverage.
    angle_deg : float
        The harp direction (length-weighted doubled-angle mean), NaN without strings.
    string_width_px : float
        The grouping's string width, frame pixels.
    dark_strings : bool
    rejected_reasons : dict
        Rejected groups per reason.
    tracked : bool
        True when the strings were not searched again but taken from a previous assessment
        (:func:`assess_frame` ``previous``); every figure of the strings is still measured on
        this frame's pixels.
    """

    width: int
    height: int
    scale: float
    thresholds: tuple[float, float]
    edges: tuple[AssessedEdge, ...]
    rejected: tuple[RejectedMark, ...]
    strings: tuple[StringSharpness, ...]
    focus_score: float
    edge_width_px: float
    exposure: ExposureFigures
    coverage: Coverage
    angle_deg: float
    string_width_px: float
    dark_strings: bool
    rejected_reasons: dict[str, int] = field(default_factory=dict)
    tracked: bool = False

    @property
    def n_strings(self) -> int:
        return len({e.string_id for e in self.edges})

    @property
    def n_edges(self) -> int:
        return len(self.edges)

    @property
    def offset_px(self) -> float:
        """Median over the strings of :attr:`StringSharpness.offset_px` (NaN without strings):
        with ``tracked``, how far the strings moved since they were searched."""
        v = [s.offset_px for s in self.strings if math.isfinite(s.offset_px)]
        return float(np.median(v)) if v else float("nan")

    def to_dict(self) -> dict[str, Any]:
        """Plain figures (no point lists): the object of ``harp live --once --json``."""
        return {
            "width": self.width,
            "height": self.height,
            "analysis_scale": self.scale,
            "strings_found": self.n_strings,
            "tracked": self.tracked,
            "edges_found": self.n_edges,
            "focus_score": finite_or_none(self.focus_score),
            "edge_width_px": finite_or_none(self.edge_width_px),
            "angle_deg": finite_or_none(self.angle_deg),
            "string_width_px": finite_or_none(self.string_width_px),
            "dark_strings": self.dark_strings,
            "strings": [s.to_dict() for s in self.strings],
            "rejected": dict(self.rejected_reasons),
            "exposure": self.exposure.to_dict(),
            "coverage": self.coverage.to_dict(),
        }


def analysis_scale(
    width: int, height: int, string_width_px: float | None = None, target_pixels: int = TARGET_ANALYSIS_PIXELS
) -> float:
    """Downscaling factor (an integer >= 1: an exact box average) of the image the strings are searched on.

    At most ``target_pixels`` pixels, unless that would make a string of
    ``string_width_px`` (as last measured, frame pixels; None: unknown, taken
    as :data:`MIN_ANALYSIS_STRING_PX` times the factor) narrower than
    :data:`MIN_ANALYSIS_STRING_PX`.
    """
    by_size = math.sqrt(width * height / float(target_pixels))
    if string_width_px is not None and math.isfinite(string_width_px):
        by_size = min(by_size, string_width_px / MIN_ANALYSIS_STRING_PX)
    return float(max(1, math.floor(by_size + 1e-9)))


def _downscale(img: NDArray[Any], scale: float) -> NDArray[Any]:
    if scale <= 1.0 + 1e-9:
        return img
    h, w = img.shape
    size = (max(16, int(round(w / scale))), max(16, int(round(h / scale))))
    src = img if img.dtype in (np.uint8, np.uint16) else img.astype(np.float32)
    return np.asarray(cv2.resize(src, size, interpolation=cv2.INTER_AREA))


def _to_frame(xy: Points, sx: float, sy: float) -> Points:
    """Analysis-image points (pixel centres at integers) to frame pixels."""
    out = np.empty_like(xy)
    out[:, 0] = (xy[:, 0] + 0.5) * sx - 0.5
    out[:, 1] = (xy[:, 1] + 0.5) * sy - 0.5
    return out


def _harp_angle(edges: Sequence[AssessedEdge]) -> float:
    if not edges:
        return float("nan")
    c = s = 0.0
    for e in edges:
        d = e.xy[-1] - e.xy[0]
        length = float(np.hypot(*d))
        a = 2.0 * math.atan2(d[1], d[0])
        c, s = c + length * math.cos(a), s + length * math.sin(a)
    return math.degrees(math.atan2(s, c) / 2.0) % 180.0


def assess_frame(
    image: NDArray[Any],
    *,
    scale: float | None = None,
    thresholds: tuple[float, float] | None = None,
    full_scale: float | None = None,
    cross_sections: int = CROSS_SECTIONS,
    sigma: float = 1.0,
    previous: Assessment | None = None,
) -> Assessment:
    """Assess one harp frame for the set-up assistant (module docstring).

    Parameters
    ----------
    image : 2-D ndarray
        Grey frame (uint8, uint16 or float), ``image[y, x]``.
    scale : float or None
        Downscaling factor of the search image (None:
        :func:`analysis_scale` of the frame size alone).
    thresholds : (low, high) or None
        Edge-detector thresholds on the downscaled image (None: estimated,
        :func:`pipeline.edges.auto_thresholds`; they depend on the noise
        only, so a live view passes back the previous frame's).
    full_scale : float or None
        Top code value (None: from the dtype).
    cross_sections : int
        Cross-sections per string for the sharpness figures.
    sigma : float
        Smoothing of the edge detector on the downscaled image.
    previous : Assessment or None
        An assessment of an earlier frame of the same, unmoved scene: its strings, rejected
        groups and coverage are taken instead of searching again (``tracked``), and only the
        per-string figures and the exposure are measured on this frame. Each cross-section is
        re-centred on this frame's pixels, so a string that moved shows as ``offset_px``: a
        caller searches again when it grows (a live view also after every turntable move and
        every second or so).

    Returns
    -------
    Assessment

    Raises
    ------
    ValueError
        If the image is not 2-D or too small.

    References
    ----------
    .. [1] Tang et al., JOSA A 29(10), 2012.
    .. [2] Grompone von Gioi & Randall, IPOL 7 (2017).
    """
    img = np.asarray(image)
    if img.ndim != 2:
        raise ValueError(f"expected a 2-D grey image, got shape {img.shape}")
    h, w = img.shape
    if min(h, w) < 16:
        raise ValueError(f"image {w}x{h} is too small to assess (at least 16x16)")
    exposure = exposure_figures(img, full_scale)
    if previous is not None and (previous.width, previous.height) == (w, h):
        return _tracked(img, previous, exposure, cross_sections)
    sc = analysis_scale(w, h) if scale is None else max(1.0, float(scale))
    small = _downscale(img, sc)
    sh, sw = small.shape
    sx, sy = w / sw, h / sh
    if thresholds is None:
        thresholds = auto_thresholds(small, sigma)
    low, high = float(thresholds[0]), float(thresholds[1])
    # chains shorter than the grouping's shortest piece would only come back as "short fragment"s
    chains = detect_edges(
        small, sigma=sigma, low=low, high=high, min_length=int(MIN_PIECE_PX), interpolation="parabola"
    )
    grouping: Grouping = group_string_edges(chains, (sh, sw), border_px=BORDER_PX)
    edges = tuple(AssessedEdge(e.string_id, e.polarity, _to_frame(e.xy, sx, sy)) for e in grouping.edges)
    rejected = tuple(RejectedMark(r.reason, _to_frame(r.xy, sx, sy), r.detail) for r in grouping.rejected)
    reasons: dict[str, int] = {}
    for r in rejected:
        reasons[r.reason] = reasons.get(r.reason, 0) + 1
    strings = string_sharpness(img, _pairs(edges), cross_sections=cross_sections)
    focus, edge_width = _focus(strings)
    return Assessment(
        width=w,
        height=h,
        scale=sc,
        thresholds=(low, high),
        edges=edges,
        rejected=rejected,
        strings=strings,
        focus_score=focus,
        edge_width_px=edge_width,
        exposure=exposure,
        coverage=edge_coverage([e.xy for e in edges], w, h),
        angle_deg=_harp_angle(edges),
        string_width_px=float(grouping.string_width_px) * 0.5 * (sx + sy),
        dark_strings=bool(grouping.dark_strings),
        rejected_reasons=reasons,
    )


def _pairs(edges: Sequence[AssessedEdge]) -> list[tuple[int, Points, Points]]:
    by_string: dict[int, list[Points]] = {}
    for e in edges:
        by_string.setdefault(e.string_id, []).append(e.xy)
    return [(sid, xs[0], xs[1]) for sid, xs in sorted(by_string.items()) if len(xs) == 2]


def _focus(strings: Sequence[StringSharpness]) -> tuple[float, float]:
    widths = np.array([s.edge_width_px for s in strings if math.isfinite(s.edge_width_px)])
    edge_width = float(np.median(widths)) if len(widths) else float("nan")
    focus = 1.0 / edge_width if math.isfinite(edge_width) and edge_width > 0 else float("nan")
    return focus, edge_width


def _tracked(img: NDArray[Any], prev: Assessment, exposure: ExposureFigures, cross_sections: int) -> Assessment:
    strings = string_sharpness(img, _pairs(prev.edges), cross_sections=cross_sections)
    focus, edge_width = _focus(strings)
    return dataclasses.replace(
        prev, strings=strings, focus_score=focus, edge_width_px=edge_width, exposure=exposure, tracked=True
    )


__all__ = [
    "REJECT_REASONS",
    "AssessedEdge",
    "Assessment",
    "Coverage",
    "ExposureFigures",
    "FocusPeak",
    "RejectedMark",
    "StringSharpness",
    "analysis_scale",
    "assess_frame",
    "edge_coverage",
    "empty_coverage",
    "exposure_figures",
    "focus_peak",
    "string_sharpness",
]
