r"""Set-up assessment of one harp frame: focus, exposure, strings found and image coverage.

What an operator needs to know *before* a session, several times a second
(the live view, ``harp live``): are the strings sharp, is the exposure
right, which strings are found (and which groups of edge points were
rejected, and why), and which parts of the image the strings cover in two
independent directions, accumulated over the orientations seen so far.

One module per job, everything re-exported here: :mod:`pipeline.assess.assessment` (the frame:
:func:`assess_frame`), :mod:`pipeline.assess.sharpness` (per-string figures),
:mod:`pipeline.assess.focus` (:func:`focus_peak`), :mod:`pipeline.assess.exposure` and
:mod:`pipeline.assess.coverage`; the sections below describe them.

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

from pipeline.assess.assessment import (
    BORDER_PX,
    MIN_ANALYSIS_STRING_PX,
    TARGET_ANALYSIS_PIXELS,
    AssessedEdge,
    Assessment,
    RejectedMark,
    analysis_scale,
    assess_frame,
)
from pipeline.assess.coverage import (
    CELLS_ACROSS,
    DIRECTION_BIN_DEG,
    MIN_CELL_EDGE_FRACTION,
    MIN_SEPARATION_DEG,
    Coverage,
    coverage_grid,
    edge_coverage,
    empty_coverage,
)
from pipeline.assess.exposure import DARK_LEVEL, HISTOGRAM_BINS, ExposureFigures, exposure_figures, full_scale_of
from pipeline.assess.focus import FocusPeak, focus_peak
from pipeline.assess.sharpness import (
    CROSS_SECTIONS,
    EDGE_WIDTH_PER_SIGMA,
    PIXEL_VARIANCE,
    StringSharpness,
    string_sharpness,
)
from pipeline.grouping import REJECT_REASONS

__all__ = [
    "BORDER_PX",
    "CELLS_ACROSS",
    "CROSS_SECTIONS",
    "DARK_LEVEL",
    "DIRECTION_BIN_DEG",
    "EDGE_WIDTH_PER_SIGMA",
    "HISTOGRAM_BINS",
    "MIN_ANALYSIS_STRING_PX",
    "MIN_CELL_EDGE_FRACTION",
    "MIN_SEPARATION_DEG",
    "PIXEL_VARIANCE",
    "REJECT_REASONS",
    "TARGET_ANALYSIS_PIXELS",
    "AssessedEdge",
    "Assessment",
    "Coverage",
    "ExposureFigures",
    "FocusPeak",
    "RejectedMark",
    "StringSharpness",
    "analysis_scale",
    "assess_frame",
    "coverage_grid",
    "edge_coverage",
    "empty_coverage",
    "exposure_figures",
    "focus_peak",
    "full_scale_of",
    "string_sharpness",
]
