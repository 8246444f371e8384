r"""Measure the straightness of every string edge in one harp image.

The whole measurement of Tang et al. (2012) on one grey image:

1. sub-pixel edges, Canny/Devernay (:func:`pipeline.edges.detect_edges`);
2. one point set per string edge, frame / dust / fragments rejected
   (:func:`pipeline.grouping.group_string_edges`);
3. per edge: uniform-arclength resampling, Gaussian blur along the edge with
   :math:`\sigma = 0.8\sqrt{t^2-1}`, one point in :math:`t` kept
   (:func:`pipeline.resample.smooth_subsample`), separately on each
   contiguous piece of the edge (pieces separated by more than
   ``BRIDGE_GAP_PX`` are not bridged, so no straight interpolated segment
   enters the measure). The smoothing keeps only points whose whole window
   lies on the piece, so ``3 sigma`` (72 px for t = 30) is lost at each end
   of each piece; a string one of whose edges keeps fewer than
   ``MIN_SMOOTHED_POINTS`` points is not measured;
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

from dataclasses import dataclass

import numpy as np

from pipeline.edges import detect_edges
from pipeline.grouping import Grouping, group_string_edges
from pipeline.resample import resample_polyline, smooth_subsample
from pipeline.straightness import hf_rms, straightness

BRIDGE_GAP_PX = 6.0
"""Gaps up to this length inside an edge are bridged by the linear resampling."""
MIN_SMOOTHED_POINTS = 3
"""Fewest smoothed points an edge must keep to be measured."""


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
        Smoothed, subsampled edge points: the input of the straightness
        measure and of distortion fits.
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
    """

    string_id: int
    polarity: int
    points: np.ndarray
    raw_points: np.ndarray
    rms: float
    p2p: float
    angle_deg: float
    length_px: float
    hf_rms: float
    width_px: float

    @property
    def raw(self) -> int:
        """Number of raw sub-pixel edge points."""
        return len(self.raw_points)

    def to_dict(self) -> dict:
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
            "width_px": _num(self.width_px),
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
    """

    width: int
    height: int
    t: int
    lines: tuple[LineMeasurement, ...]
    d: float
    d_max: float
    rejected: tuple[Rejection, ...]
    rejected_points: tuple[np.ndarray, ...]
    string_width_px: float
    dark_strings: bool

    @property
    def n_lines(self) -> int:
        return len(self.lines)

    @property
    def n_strings(self) -> int:
        return len({ln.string_id for ln in self.lines})

    def to_dict(self) -> dict:
        """Plain data (the per-image object of ``harp measure --json``, without ``path``)."""
        reasons: dict[str, int] = {}
        for r in self.rejected:
            reasons[r.reason] = reasons.get(r.reason, 0) + 1
        return {
            "width": self.width,
            "height": self.height,
            "d": _num(self.d),
            "d_max": _num(self.d_max),
            "n_lines": self.n_lines,
            "n_strings": self.n_strings,
            "t": self.t,
            "string_width_px": _num(self.string_width_px),
            "lines": [ln.to_dict() for ln in self.lines],
            "rejected": reasons,
        }


def _num(v: float):
    return None if not np.isfinite(v) else float(v)


def _contiguous(xy: np.ndarray, pieces) -> list[np.ndarray]:
    """Merge the edge's pieces across gaps <= BRIDGE_GAP_PX; return arrays."""
    out: list[list[int]] = []
    for a, b in pieces:
        if out and np.hypot(*(xy[a] - xy[out[-1][1] - 1])) <= BRIDGE_GAP_PX:
            out[-1][1] = b
        else:
            out.append([a, b])
    return [xy[a:b] for a, b in out]


def measure_grouping(grouping: Grouping, width: int, height: int, t: int = 30) -> ImageMeasurement:
    """Smooth, subsample and measure the edges of an existing grouping.

    A string is measured only if both its edges keep at least
    ``MIN_SMOOTHED_POINTS`` points after the smoothing (which drops
    ``3 sigma`` pixels at each end of each piece); otherwise both edges are
    rejected as ``"short edge"``.
    """
    rejected = [(r.reason, r.detail, r.xy) for r in grouping.rejected]
    smoothed = []
    for e in grouping.edges:
        parts = [smooth_subsample(p, t=t) for p in _contiguous(e.xy, e.pieces)]
        smoothed.append(np.concatenate(parts) if parts else np.zeros((0, 2)))
    short_strings = {e.string_id for e, pts in zip(grouping.edges, smoothed) if len(pts) < MIN_SMOOTHED_POINTS}
    fit_sets, meta = [], []
    for e, pts in zip(grouping.edges, smoothed):
        if e.string_id in short_strings:
            rejected.append(
                ("short edge", f"a string edge keeps < {MIN_SMOOTHED_POINTS} points after smoothing with t={t}", e.xy)
            )
            continue
        fit_sets.append(pts)
        meta.append(e)
    rej = tuple(Rejection(r, len(x), _bbox(x), d) for r, d, x in rejected)
    rej_pts = tuple(x for _, _, x in rejected)
    if not fit_sets:
        return ImageMeasurement(
            width,
            height,
            t,
            (),
            float("nan"),
            float("nan"),
            rej,
            rej_pts,
            grouping.string_width_px,
            grouping.dark_strings,
        )
    st = straightness(fit_sets)
    # renumber strings 0..n-1 in their order across the harp
    ids = {sid: k for k, sid in enumerate(sorted({e.string_id for e in meta}))}
    lines = []
    for i, (e, pts) in enumerate(zip(meta, fit_sets)):
        hf = hf_rms(resample_polyline(e.xy, 1.0))
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
                hf_rms=hf,
                width_px=e.width_px,
            )
        )
    return ImageMeasurement(
        width, height, t, tuple(lines), st.d, st.d_max, rej, rej_pts, grouping.string_width_px, grouping.dark_strings
    )


def _bbox(xy: np.ndarray) -> tuple[float, float, float, float]:
    return (float(xy[:, 0].min()), float(xy[:, 1].min()), float(xy[:, 0].max()), float(xy[:, 1].max()))


def measure_image(
    image: np.ndarray, t: int = 30, sigma: float = 1.0, low: float | None = None, high: float | None = None
) -> ImageMeasurement:
    """Find every string edge of a harp image and measure its straightness.

    Parameters
    ----------
    image : 2-D ndarray
        Grey image, any integer or float dtype, ``image[y, x]``.
    t : int
        Subsampling factor of the along-edge smoothing (blur sigma
        ``0.8 sqrt(t^2 - 1)`` px), default 30 as in Tang et al.
    sigma : float
        Gaussian smoothing of the edge detector, pixels.
    low, high : float or None
        Edge-detector hysteresis thresholds (None: automatic, from the noise).

    Returns
    -------
    ImageMeasurement
        With ``n_lines == 0`` (and NaN ``d``) when no string was found.

    Raises
    ------
    ValueError
        If the image is not 2-D or too small for the edge detector.

    Notes
    -----
    Edge points closer than ``max(4, ceil(3 sigma) + 1)`` px to the image
    border are dropped (there the smoothing reads mirrored pixels).

    References
    ----------
    .. [1] Tang et al., JOSA A 29(10), 2012.
    """
    img = np.asarray(image)
    if img.ndim != 2:
        raise ValueError(f"expected a 2-D grey image, got shape {img.shape}")
    h, w = img.shape
    chains = detect_edges(img, sigma=sigma, low=low, high=high)
    border = max(4.0, np.ceil(3.0 * sigma) + 1.0)
    grouping = group_string_edges(chains, (h, w), border_px=border)
    return measure_grouping(grouping, w, h, t=t)
