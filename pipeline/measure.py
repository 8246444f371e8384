r"""Measure the straightness of every string edge in one harp image.

The whole measurement of Tang et al. (2012) on one grey image:

1. sub-pixel edges, Canny/Devernay (:func:`pipeline.edges.detect_edges`);
2. one point set per string edge, frame / dust / fragments rejected
   (:func:`pipeline.grouping.group_string_edges`);
3. per edge: uniform-arclength resampling, smoothing along the edge at the
   scale :math:`\sigma = 0.8\sqrt{t^2-1}` and one point in :math:`t` kept
   (:func:`pipeline.resample.smooth_subsample`), separately on each
   contiguous piece of the edge (pieces separated by more than
   ``BRIDGE_GAP_PX`` are not bridged, so no straight interpolated segment
   enters the measure). With the default smoother (Gaussian-weighted local
   quadratic regression) every piece is kept *to its ends*: its smoothed
   points span it from its first to its last raw point, and the pieces of
   one edge (a string leaving and re-entering the image, cut by dust) still
   form one edge. The points at the ends of a piece are noisier than in its
   middle (:mod:`pipeline.resample`, "Noise at the ends"). With the paper's
   plain Gaussian (``smoothing="gaussian"``) ``3 sigma`` (72 px for t = 30)
   is lost at each end of each piece. A string one of whose edges keeps
   fewer than ``MIN_SMOOTHED_POINTS`` points is not measured;
4. :math:`d` and :math:`d_{max}` over all edges and per-edge figures
   (:func:`pipeline.straightness.straightness`), plus the high-frequency
   residual (:func:`pipeline.straightness.hf_rms`) of the raw edge points
   resampled at 1 px.

References
----------
.. [1] Z. Tang, R. Grompone von Gioi, P. Monasse, J.-M. Morel,
   "High-precision camera distortion measurements with a calibration harp",
   JOSA A 29(10), 2012.
.. [2] R. Grompone von Gioi, G. Randall, "A Sub-Pixel Edge Detector: an
   Implementation of the Canny/Devernay Algorithm", IPOL 7 (2017).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pipeline.edges import detect_edges
from pipeline.grouping import Grouping, group_string_edges
from pipeline.plain import finite_or_none
from pipeline.resample import (
    DEFAULT_T,
    MAX_EXTEND_PX,
    METHODS,
    SmoothingMethod,
    point_sigma,
    resample_polyline,
    sample_noise,
    smooth_subsample,
)
from pipeline.straightness import hf_rms, straightness

BRIDGE_GAP_PX = 6.0
"""Gaps up to this length inside an edge are bridged by the linear resampling."""
MIN_SMOOTHED_POINTS = 3
"""Fewest smoothed points an edge must keep to be measured."""
BORDER_REACH_PX = 1.5
"""A piece's end this close to the trimmed border line was cut by it."""
END_TANGENT_PTS = 12
"""Raw points giving the tangent at a piece's end."""

Points = NDArray[np.float64]
Ranges = NDArray[np.intp]


def _no_ranges() -> Ranges:
    return np.zeros((0, 2), np.intp)


@dataclass(frozen=True)
class LineMeasurement:
    """One measured string edge.

    Attributes
    ----------
    string_id : int
        String number across the harp (its two edges share it).
    polarity : int
        +1 / -1, see :mod:`pipeline.grouping`.
    points : (M, 2) ndarray
        Smoothed, subsampled edge points, ordered along the edge: the input of
        the straightness measure and of distortion fits.
    raw_points : (N, 2) ndarray
        The raw sub-pixel edge points, ordered along the edge.
    rms, p2p : float
        RMS and peak-to-peak signed distance of ``points`` to their
        regression line, pixels.
    angle_deg : float
        Angle of the regression line, degrees in ``[0, 180)``.
    length_px : float
        Extent of ``points`` along the line, pixels.
    hf_rms : float
        High-frequency residual of the raw points, pixels
        (:func:`pipeline.straightness.hf_rms`).
    width_px : float
        Measured string width, pixels.
    raw_pieces, point_pieces : (P, 2) int ndarrays
        ``[start, stop)`` index ranges of the contiguous pieces of the edge in
        ``raw_points`` and in ``points`` (one row per piece, same order);
        empty when not recorded.
    """

    string_id: int
    polarity: int
    points: Points
    raw_points: Points
    rms: float
    p2p: float
    angle_deg: float
    length_px: float
    hf_rms: float
    width_px: float
    raw_pieces: Ranges = field(default_factory=_no_ranges)
    point_pieces: Ranges = field(default_factory=_no_ranges)

    @property
    def raw(self) -> int:
        """Number of raw sub-pixel edge points."""
        return len(self.raw_points)

    @property
    def start(self) -> tuple[float, float]:
        """First smoothed point ``(x, y)``: one end of the measured edge."""
        return (float(self.points[0, 0]), float(self.points[0, 1]))

    @property
    def end(self) -> tuple[float, float]:
        """Last smoothed point ``(x, y)``: the other end of the measured edge."""
        return (float(self.points[-1, 0]), float(self.points[-1, 1]))

    def to_dict(self) -> dict[str, Any]:
        return {
            "points": int(len(self.points)),
            "rms": self.rms,
            "p2p": self.p2p,
            "angle_deg": self.angle_deg,
            "length_px": self.length_px,
            "hf_rms": self.hf_rms,
            "string": self.string_id,
            "polarity": self.polarity,
            "raw_points": self.raw,
            "width_px": finite_or_none(self.width_px),
            "start": list(self.start),
            "end": list(self.end),
            "pieces": max(1, int(len(self.point_pieces))),
        }


@dataclass(frozen=True)
class Rejection:
    """A group of edge points not measured, with the reason."""

    reason: str
    n_points: int
    bbox: tuple[float, float, float, float]
    detail: str = ""


@dataclass(frozen=True)
class ImageMeasurement:
    """Straightness measurement of one image.

    ``d`` and ``d_max`` are NaN when no string was found (``n_lines == 0``).
    ``rejected`` lists every group of edge points that was not measured;
    ``rejected_points`` holds their points (same order), for overlays.
    ``smoothing`` is the along-edge smoother (:data:`pipeline.resample.METHODS`).
    """

    width: int
    height: int
    t: int
    lines: tuple[LineMeasurement, ...]
    d: float
    d_max: float
    rejected: tuple[Rejection, ...]
    rejected_points: tuple[Points, ...]
    string_width_px: float
    dark_strings: bool
    smoothing: str = METHODS[0]

    @property
    def n_lines(self) -> int:
        return len(self.lines)

    @property
    def n_strings(self) -> int:
        return len({ln.string_id for ln in self.lines})

    def to_dict(self) -> dict[str, Any]:
        """Plain data (the per-image object of ``harp measure --json``, without ``path``)."""
        reasons: dict[str, int] = {}
        for r in self.rejected:
            reasons[r.reason] = reasons.get(r.reason, 0) + 1
        return {
            "width": self.width,
            "height": self.height,
            "d": finite_or_none(self.d),
            "d_max": finite_or_none(self.d_max),
            "n_lines": self.n_lines,
            "n_strings": self.n_strings,
            "t": self.t,
            "smoothing": self.smoothing,
            "string_width_px": finite_or_none(self.string_width_px),
            "lines": [ln.to_dict() for ln in self.lines],
            "rejected": reasons,
        }


def contiguous_pieces(xy: Points, pieces: Sequence[tuple[int, int]]) -> list[tuple[int, int]]:
    """Index ranges of ``xy`` after merging consecutive ``pieces`` across gaps <= ``BRIDGE_GAP_PX``."""
    out: list[list[int]] = []
    for a, b in pieces:
        if out and float(np.hypot(*(xy[a] - xy[out[-1][1] - 1]))) <= BRIDGE_GAP_PX:
            out[-1][1] = b
        else:
            out.append([a, b])
    return [(a, b) for a, b in out]


def _border_extension(xy: Points, at_end: bool, frame: tuple[float, float, float, float]) -> float:
    """How far (px) the piece's end, cut by the trimmed border ``frame``, lies short of it along its tangent.

    ``frame`` is ``(x_min, y_min, x_max, y_max)`` of the kept region. Raw points lie on the pixel
    grid, so a piece cut by the border stops up to a pixel short of the border line; 0 when the end
    is not at the border (within ``BORDER_REACH_PX``) or runs along it.
    """
    q = xy[-END_TANGENT_PTS:] if at_end else xy[:END_TANGENT_PTS][::-1]  # towards the end
    if len(q) < 2:
        return 0.0
    c = q.mean(axis=0)
    _, v = np.linalg.eigh((q - c).T @ (q - c))
    t = v[:, 1] if v[:, 1] @ (q[-1] - q[0]) >= 0 else -v[:, 1]
    p = q[-1]
    x0, y0, x1, y1 = frame
    best = 0.0
    for dist, comp in ((p[0] - x0, -t[0]), (x1 - p[0], t[0]), (p[1] - y0, -t[1]), (y1 - p[1], t[1])):
        if 0.0 <= dist <= BORDER_REACH_PX and comp > 0.3:
            best = max(best, min(dist / comp, MAX_EXTEND_PX))
    return best


def _smooth_edge(
    xy: Points,
    pieces: Sequence[tuple[int, int]],
    t: int,
    method: SmoothingMethod,
    frame: tuple[float, float, float, float] | None,
) -> tuple[Points, Ranges, Ranges]:
    """Smoothed points of one edge, its contiguous raw ranges and the matching point ranges.

    With ``frame`` (the kept region of the image) the local-quadratic grid of a piece cut by
    the border is extended to the border line (:func:`_border_extension`).
    """
    raw_rng = contiguous_pieces(xy, pieces if pieces else [(0, len(xy))])
    parts = []
    for a, b in raw_rng:
        ext = (0.0, 0.0)
        if frame is not None and method == "local-quadratic":
            ext = (_border_extension(xy[a:b], False, frame), _border_extension(xy[a:b], True, frame))
        parts.append(smooth_subsample(xy[a:b], t=t, method=method, extend=ext))
    kept = [(r, p) for r, p in zip(raw_rng, parts) if len(p)]
    if not kept:
        return np.zeros((0, 2)), _no_ranges(), _no_ranges()
    sizes = np.cumsum([0] + [len(p) for _, p in kept])
    pts = np.concatenate([p for _, p in kept])
    return (
        pts,
        np.array([r for r, _ in kept], np.intp).reshape(-1, 2),
        np.column_stack([sizes[:-1], sizes[1:]]).astype(np.intp),
    )


def measure_grouping(
    grouping: Grouping,
    width: int,
    height: int,
    t: int = DEFAULT_T,
    smoothing: SmoothingMethod = "local-quadratic",
    border: float | None = None,
) -> ImageMeasurement:
    """Smooth, subsample and measure the edges of an existing grouping.

    A string is measured only if both its edges keep at least
    ``MIN_SMOOTHED_POINTS`` points after the smoothing; otherwise both edges
    are rejected as ``"short edge"``. ``smoothing`` is the along-edge smoother
    (:func:`pipeline.resample.smooth_subsample`). ``border``: the border (px)
    the grouping trimmed; pieces it cut are smoothed up to its line (their raw
    points, on the pixel grid, stop up to a pixel short of it). None: not
    known, the pieces end at their last raw point.
    """
    if smoothing not in METHODS:
        raise ValueError(f"unknown smoothing method {smoothing!r} (use one of {', '.join(METHODS)})")
    rejected: list[tuple[str, str, Points]] = [(r.reason, r.detail, r.xy) for r in grouping.rejected]
    frame = None if border is None else (border, border, width - 1.0 - border, height - 1.0 - border)
    smoothed = [_smooth_edge(e.xy, e.pieces, t, smoothing, frame) for e in grouping.edges]
    short_strings = {e.string_id for e, s in zip(grouping.edges, smoothed) if len(s[0]) < MIN_SMOOTHED_POINTS}
    meta = []
    for e, s in zip(grouping.edges, smoothed):
        if e.string_id in short_strings:
            rejected.append(
                ("short edge", f"a string edge keeps < {MIN_SMOOTHED_POINTS} points after smoothing with t={t}", e.xy)
            )
            continue
        meta.append((e, s))
    rej = tuple(Rejection(r, len(x), _bbox(x), d) for r, d, x in rejected)
    rej_pts = tuple(x for _, _, x in rejected)
    if not meta:
        nan = float("nan")
        return ImageMeasurement(
            width, height, t, (), nan, nan, rej, rej_pts, grouping.string_width_px, grouping.dark_strings, smoothing
        )
    st = straightness([s[0] for _, s in meta])
    # renumber strings 0..n-1 in their order across the harp
    ids = {sid: k for k, sid in enumerate(sorted({e.string_id for e, _ in meta}))}
    lines = []
    for i, (e, (pts, raw_rng, pt_rng)) in enumerate(meta):
        lines.append(
            LineMeasurement(
                string_id=ids[e.string_id],
                polarity=e.polarity,
                points=pts,
                raw_points=e.xy,
                rms=st.rms[i],
                p2p=st.p2p[i],
                angle_deg=st.angle_deg[i],
                length_px=st.length_px[i],
                hf_rms=hf_rms(resample_polyline(e.xy, 1.0)),
                width_px=e.width_px,
                raw_pieces=raw_rng,
                point_pieces=pt_rng,
            )
        )
    return ImageMeasurement(
        width,
        height,
        t,
        tuple(lines),
        st.d,
        st.d_max,
        rej,
        rej_pts,
        grouping.string_width_px,
        grouping.dark_strings,
        smoothing,
    )


def _bbox(xy: Points) -> tuple[float, float, float, float]:
    return (float(xy[:, 0].min()), float(xy[:, 1].min()), float(xy[:, 0].max()), float(xy[:, 1].max()))


def measure_image(
    image: NDArray[Any],
    t: int = DEFAULT_T,
    sigma: float = 1.0,
    low: float | None = None,
    high: float | None = None,
    smoothing: SmoothingMethod = "local-quadratic",
) -> ImageMeasurement:
    """Find every string edge of a harp image and measure its straightness.

    Parameters
    ----------
    image : 2-D ndarray
        Grey image, any integer or float dtype, ``image[y, x]``.
    t : int
        Subsampling factor of the along-edge smoothing (scale
        ``0.8 sqrt(t^2 - 1)`` px), default 30 as in Tang et al.
    sigma : float
        Gaussian smoothing of the edge detector, pixels.
    low, high : float or None
        Edge-detector hysteresis thresholds (None: automatic, from the noise).
    smoothing : {"local-quadratic", "gaussian"}
        Along-edge smoother (:mod:`pipeline.resample`): local quadratic
        regression keeping every piece to its ends (default) or the paper's
        plain Gaussian, valid part only.

    Returns
    -------
    ImageMeasurement
        With ``n_lines == 0`` (and NaN ``d``) when no string was found.

    Raises
    ------
    ValueError
        If the image is not 2-D or too small for the edge detector, or
        ``smoothing`` is unknown.

    Notes
    -----
    Edge points closer than ``max(4, ceil(3 sigma) + 1)`` px to the image
    border are dropped (there the smoothing reads mirrored pixels).

    References
    ----------
    .. [1] Tang et al., JOSA A 29(10), 2012.
    """
    if smoothing not in METHODS:
        raise ValueError(f"unknown smoothing method {smoothing!r} (use one of {', '.join(METHODS)})")
    img = np.asarray(image)
    if img.ndim != 2:
        raise ValueError(f"expected a 2-D grey image, got shape {img.shape}")
    h, w = img.shape
    chains = detect_edges(img, sigma=sigma, low=low, high=high)
    border = border_px(sigma)
    grouping = group_string_edges(chains, (h, w), border_px=border)
    return measure_grouping(grouping, w, h, t=t, smoothing=smoothing, border=border)


def border_px(sigma: float = 1.0) -> float:
    """Width of the image border where no edge point is kept: ``max(4, ceil(3 sigma) + 1)`` px."""
    return max(4.0, float(np.ceil(3.0 * sigma)) + 1.0)


def point_sigmas(m: ImageMeasurement, border: float | None = None, local: bool = False) -> list[Points]:
    r"""Each measured point's standard deviation, one ``(M,)`` array per line of ``m`` (its ``points``).

    Per edge, the raw points' scatter about the along-edge smooth gives the noise of the uniform
    samples (:func:`pipeline.resample.sample_noise`: one robust figure pooled over the edge's pieces,
    or with ``local`` its growth along the edge); each smoothed point's standard deviation is that
    noise through the smoother's row, :math:`\sqrt{\sum_i l_i^2 \sigma_i^2}`
    (:func:`pipeline.resample.point_sigma`): about 2.6 times the middle's at the ends of a piece for
    t = 30, where the local fit's window is one-sided. The input of the fit's per-point weights
    (``fit_distortion(..., point_sigma=...)``).

    ``border``: the border (px) the measurement trimmed (``border_px(sigma)`` of
    :func:`measure_image`, default ``border_px()``), to extend the pieces it cut as the measurement
    did; the noise is that of the interpolated samples, a little below the raw points' (only the
    ratios between points and edges weigh in the fit).

    References
    ----------
    .. [1] J. Fan, I. Gijbels, *Local Polynomial Modelling and Its Applications*, Chapman & Hall, 1996.
    """
    b = border_px() if border is None else border
    frame = (b, b, m.width - 1.0 - b, m.height - 1.0 - b)
    method: SmoothingMethod = "gaussian" if m.smoothing == "gaussian" else "local-quadratic"
    out: list[Points] = []
    for ln in m.lines:
        rng = ln.raw_pieces if len(ln.raw_pieces) else np.array([[0, len(ln.raw_points)]])
        pieces = [ln.raw_points[a:c] for a, c in rng]
        noise = [sample_noise(p, m.t, local=local) for p in pieces]
        if local:
            e = np.concatenate([np.asarray(v) for v in noise]) if noise else np.zeros(0)
            edge = float(np.sqrt(np.mean(e**2))) if len(e) else float("nan")
        else:
            lens = np.array([len(p) for p in pieces], dtype=np.float64)
            v = np.array(noise, dtype=np.float64)
            ok = np.isfinite(v)
            edge = float(np.sqrt(np.sum(lens[ok] * v[ok] ** 2) / np.sum(lens[ok]))) if ok.any() else float("nan")
        if not (np.isfinite(edge) and edge > 0):
            edge = 1.0  # no noise figure: the smoother's variance factor alone
        parts = []
        for p, nz in zip(pieces, noise, strict=True):
            ext = (0.0, 0.0)
            if method == "local-quadratic":
                ext = (_border_extension(p, False, frame), _border_extension(p, True, frame))
            use = nz if local and len(np.atleast_1d(nz)) and np.all(np.asarray(nz) > 0) else edge
            parts.append(point_sigma(p, use, m.t, method=method, extend=ext))
        sig = np.concatenate(parts) if parts else np.zeros(0)
        if len(sig) != len(ln.points):
            raise ValueError(f"line {ln.string_id}: {len(sig)} sigmas for {len(ln.points)} points (border?)")
        out.append(np.maximum(sig, 1e-6 * edge))
    return out
