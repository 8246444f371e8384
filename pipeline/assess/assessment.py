"""The assessment of one frame (:mod:`pipeline.assess`): strings found on a downscaled copy
(*Speed: find coarse, refine only what is shown*), then exposure, per-string sharpness and
coverage measured on the frame."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from pipeline.assess.coverage import Coverage, edge_coverage
from pipeline.assess.exposure import ExposureFigures, exposure_figures
from pipeline.assess.sharpness import CROSS_SECTIONS, StringSharpness, string_sharpness
from pipeline.edge_thresholds import auto_thresholds
from pipeline.edges import detect_edges
from pipeline.grouping import MIN_PIECE_PX, Grouping, group_string_edges, points_bbox
from pipeline.plain import finite_or_none

Points = NDArray[np.float64]

TARGET_ANALYSIS_PIXELS = 1_000_000
"""Largest number of pixels the strings are searched on (the frame is downscaled to it)."""
MIN_ANALYSIS_STRING_PX = 2.8
"""Narrowest string (px) on the downscaled image; the grouping supports 2 px and up."""
BORDER_PX = 4.0
"""Border of the analysis image where no edge point is kept (as :func:`pipeline.measure.measure_image`)."""


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
    """Everything the live view shows about one frame (:mod:`pipeline.assess`).

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
    """Assess one harp frame for the set-up assistant (:mod:`pipeline.assess`).

    Parameters
    ----------
    image : 2-D ndarray
        Grey frame (uint8, uint16 or float), ``image[y, x]``.
    scale : float or None
        Downscaling factor of the search image (None:
        :func:`analysis_scale` of the frame size alone).
    thresholds : (low, high) or None
        Edge-detector thresholds on the downscaled image (None: estimated,
        :func:`pipeline.edge_thresholds.auto_thresholds`; they depend on the noise
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
