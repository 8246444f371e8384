r"""Lateral chromatic aberration fitted from the string edges of every colour channel.

Every string edge of a harp shot is seen in each colour channel (on a Bayer sensor
each channel at its own sample positions, :mod:`pipeline.cfa`). Through a lens with
lateral chromatic aberration the red and blue images of an edge lie beside the green
one; how far, across the edge, is one observation of the channel's field
:math:`T_c` (:class:`~pipeline.models.tca_model.TcaField`) in the direction of the
edge's normal. With edges at several orientations (the turntable's shots) the
normal components determine the whole 2-D field.

Observations
------------
For each smoothed point :math:`p` of a channel edge, the matching reference edge
(green: the edge of the same string, both green planes) is approximated near
:math:`p` by a quadratic through its five nearest smoothed points, in their own
frame (chord direction :math:`s`, normal :math:`d`): :math:`d = g(s)`. The
condition that :math:`T(p) = p + \Delta(p)` lies on it, linearised in
:math:`\Delta` (exact to first order in :math:`\Delta`, which is below a few pixels
against a curvature radius of thousands):

.. math::
    \Delta_d - g'(s_p)\,\Delta_s = g(s_p) - d_p

is one linear equation in the field's coefficients (:func:`edge_offsets`); all of
them, from all shots, are solved by least squares (:func:`fit_tca`), twice with the
observations re-taken at :math:`T(p)`, edges whose residual is an outlier rejected.
The quadratic's model error, for a curve of radius :math:`\kappa^{-1}` and points
``t`` apart, is of order :math:`\kappa' t^3`, below 1e-5 px for the distortions of
real lenses.

The fit is linear, so it needs no start and cannot end in a local minimum; it fails
(a :class:`~pipeline.edgeset.FitFailure` with the reason) when the edges have one
orientation only (the field along the strings is not seen), when too few edges
match, or when the points do not cover the image.

References
----------
.. [1] J. Mallon, P. F. Whelan, "Calibration and removal of lateral chromatic
   aberration in images", Pattern Recognition Letters 28(1), 2007.
.. [2] Z. Tang, R. Grompone von Gioi, P. Monasse, J.-M. Morel,
   "High-precision camera distortion measurements with a calibration harp",
   JOSA A 29(10), 2012.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pipeline.cfa import MosaicMeasurement
from pipeline.edgeset import FitFailure
from pipeline.models.tca_model import (
    LENSFUN_TCA_TERMS,
    TCA_DEGREE_BOUNDS,
    LensfunTca,
    TcaField,
    n_tca_params,
    tca_basis,
)

Floats = NDArray[np.float64]

DEFAULT_TCA_DEGREE = 3
"""Total degree of the fitted :class:`TcaField` (odd radial terms up to :math:`\\rho^3`)."""
WINDOW = 5
"""Reference points of the local quadratic (:func:`edge_offsets`)."""
MIN_EDGES = 6
"""Fewest matched edges a TCA fit needs."""
MIN_ORIENTATION_RATIO = 0.05
"""Smallest eigenvalue of the normals' mean scatter, :math:`\\overline{nn^T}`, a fit needs (0.5 for isotropy)."""
REJECT_FACTOR = 5.0
"""An edge whose RMS residual exceeds this many times the median edge's is rejected."""
GRID_STEP_PX = 8.0
"""Step of the grid over which fields are compared and lensfun's models fitted."""


@dataclass(frozen=True)
class EdgeOffsets:
    """Linear observations of a channel's field (module docstring).

    Row ``i``: ``coef[i] . Delta(points[i]) = offset[i]``, ``coef`` a unit vector
    (the reference edge's normal there); ``edge[i]`` numbers the channel edge
    (over all shots), ``shot[i]`` its shot.
    """

    points: Floats
    coef: Floats
    offset: Floats
    edge: NDArray[np.intp]
    shot: NDArray[np.intp]

    @property
    def n_edges(self) -> int:
        return int(len(np.unique(self.edge)))

    @staticmethod
    def concat(parts: Sequence[EdgeOffsets]) -> EdgeOffsets:
        if not parts:
            z = np.zeros((0, 2))
            return EdgeOffsets(z, z, np.zeros(0), np.zeros(0, np.intp), np.zeros(0, np.intp))
        return EdgeOffsets(
            np.concatenate([p.points for p in parts]),
            np.concatenate([p.coef for p in parts]),
            np.concatenate([p.offset for p in parts]),
            np.concatenate([p.edge for p in parts]),
            np.concatenate([p.shot for p in parts]),
        )


def _local_quadratics(ref: Floats, lo: NDArray[np.intp], p: Floats) -> tuple[Floats, Floats, NDArray[np.bool_]]:
    """Observations at points ``p`` (M, 2) from the :data:`WINDOW` reference points ``ref[lo : lo + WINDOW]``.

    Returns the unit coefficient vectors (M, 2), the offsets (M,) and which points have
    one (a point beyond the window's ends, past the end of its reference edge, is not
    extrapolated).
    """
    w = WINDOW
    win = ref[lo[:, None] + np.arange(w)[None, :]]  # (M, w, 2)
    m = win.mean(axis=1)
    tvec = win[:, -1] - win[:, 0]
    tn = np.hypot(tvec[:, 0], tvec[:, 1])
    ok = tn > 0
    tvec = tvec / np.where(ok, tn, 1.0)[:, None]
    nvec = np.column_stack([-tvec[:, 1], tvec[:, 0]])
    rel = win - m[:, None, :]
    s = np.einsum("mwk,mk->mw", rel, tvec)
    d = np.einsum("mwk,mk->mw", rel, nvec)
    sp = np.einsum("mk,mk->m", p - m, tvec)
    dp = np.einsum("mk,mk->m", p - m, nvec)
    spacing = (s[:, -1] - s[:, 0]) / (w - 1)
    ok &= (sp >= s[:, 0] - 0.5 * spacing) & (sp <= s[:, -1] + 0.5 * spacing)
    v = np.stack([np.ones_like(s), s, s * s], axis=2)  # (M, w, 3)
    ata = np.einsum("mwi,mwj->mij", v, v) + 1e-12 * np.eye(3)
    atb = np.einsum("mwi,mw->mi", v, d)
    cf = np.linalg.solve(ata, atb[..., None])[..., 0]  # c0 + c1 s + c2 s^2
    g = cf[:, 0] + sp * (cf[:, 1] + sp * cf[:, 2])
    slope = cf[:, 1] + 2 * sp * cf[:, 2]
    vec = nvec - slope[:, None] * tvec
    norm = np.hypot(vec[:, 0], vec[:, 1])
    return vec / norm[:, None], (g - dp) / norm, ok


class _References:
    """The reference edges of one shot (those with at least :data:`WINDOW` points), searchable."""

    def __init__(self, reference_lines: Sequence[Floats]) -> None:
        from scipy.spatial import cKDTree

        refs = [np.asarray(r, np.float64).reshape(-1, 2) for r in reference_lines]
        self.refs = [r for r in refs if len(r) >= WINDOW]
        self.trees = [cKDTree(r) for r in self.refs]
        if self.refs:
            allref = np.concatenate(self.refs)
            self.label = np.repeat(np.arange(len(self.refs)), [len(r) for r in self.refs])
            self.tree = cKDTree(allref)

    def window_starts(self, j: int, p: Floats) -> NDArray[np.intp]:
        """Start of the window of reference edge ``j`` centred on the point nearest each of ``p``."""
        k = np.asarray(self.trees[j].query(p)[1], np.intp)
        return np.clip(k - WINDOW // 2, 0, len(self.refs[j]) - WINDOW).astype(np.intp)

    def observe(self, j: int, p: Floats) -> tuple[Floats, Floats, NDArray[np.bool_]]:
        return _local_quadratics(self.refs[j], self.window_starts(j, p), p)

    def match(self, p: Floats, max_distance_px: float) -> int | None:
        """The reference edge an edge of points ``p`` matches (:func:`edge_offsets`), or None."""
        if not self.refs:
            return None
        near = self.tree.query(p, k=min(4, len(self.label)))[1].reshape(len(p), -1)
        found = []
        for j in np.unique(self.label[near]):
            _, off, ok = self.observe(int(j), p)
            if ok.sum() >= max(3, len(p) // 2):
                found.append((float(np.median(np.abs(off[ok]))), int(j)))
        found.sort()
        if not found or found[0][0] >= max_distance_px:
            return None
        if len(found) > 1 and found[0][0] >= 0.5 * found[1][0]:
            return None  # as near another reference edge: not matched
        return found[0][1]


def edge_offsets(
    channel_lines: Sequence[Floats],
    reference_lines: Sequence[Floats],
    max_distance_px: float = 4.0,
    shot: int = 0,
    first_edge: int = 0,
    field: TcaField | None = None,
    matches: Sequence[int | None] | None = None,
) -> EdgeOffsets:
    """The observations of one shot: every channel edge against its reference edge.

    Parameters
    ----------
    channel_lines, reference_lines : sequences of (M, 2) arrays
        Smoothed edge points (ordered along each edge) of the channel and of the
        reference, in the same pixel coordinates.
    max_distance_px : float
        A channel edge matches the reference edge whose median distance to its points
        (across the edge) is the smallest, when that is below this and below half the
        distance to the next nearest reference edge (the other edge of the same string,
        for instance).
    shot, first_edge : int
        Numbers recorded in the result (``shot``, ``edge`` from ``first_edge`` on: the
        channel edge's index in ``channel_lines`` plus ``first_edge``).
    field : TcaField, optional
        Observations taken at ``field.to_reference(p)`` instead of ``p`` (the later
        passes of :func:`fit_tca`); the offsets are then what is left of the field.
    matches : sequence of int or None, optional
        The reference edge of each channel edge (:func:`match_edges`), else matched here.
    """
    refs = _References(reference_lines)
    if matches is None:
        matches = match_edges(channel_lines, reference_lines, max_distance_px)
    pts: list[Floats] = []
    coefs: list[Floats] = []
    offs: list[Floats] = []
    edges: list[NDArray[np.intp]] = []
    for i, (line, j) in enumerate(zip(channel_lines, matches)):
        if j is None:
            continue
        p0 = np.asarray(line, np.float64).reshape(-1, 2)
        p = field.to_reference(p0) if field is not None else p0
        coef, off, ok = refs.observe(j, p)
        pts.append(p0[ok])
        coefs.append(coef[ok])
        offs.append(off[ok])
        edges.append(np.full(int(ok.sum()), first_edge + i, np.intp))
    if not pts:
        return EdgeOffsets.concat([])
    n = sum(len(x) for x in offs)
    return EdgeOffsets(
        np.concatenate(pts),
        np.concatenate(coefs),
        np.concatenate(offs),
        np.concatenate(edges),
        np.full(n, shot, np.intp),
    )


def match_edges(
    channel_lines: Sequence[Floats], reference_lines: Sequence[Floats], max_distance_px: float = 4.0
) -> list[int | None]:
    """The index (among the reference edges with at least :data:`WINDOW` points) each channel edge matches."""
    refs = _References(reference_lines)
    out: list[int | None] = []
    for line in channel_lines:
        p = np.asarray(line, np.float64).reshape(-1, 2)
        out.append(refs.match(p, max_distance_px) if len(p) >= 3 else None)
    return out


def shot_offsets(
    channel_shots: Sequence[Sequence[Floats]],
    reference_shots: Sequence[Sequence[Floats]],
    field: TcaField | None = None,
    max_distance_px: float = 4.0,
    matches: Sequence[Sequence[int | None]] | None = None,
) -> EdgeOffsets:
    """:func:`edge_offsets` of every shot, edges numbered over all of them (``matches`` per shot)."""
    if len(channel_shots) != len(reference_shots):
        raise ValueError(f"{len(channel_shots)} channel shots but {len(reference_shots)} reference shots")
    parts: list[EdgeOffsets] = []
    first = 0
    for i, (ch, ref) in enumerate(zip(channel_shots, reference_shots)):
        mt = None if matches is None else matches[i]
        parts.append(edge_offsets(ch, ref, max_distance_px, shot=i, first_edge=first, field=field, matches=mt))
        first += len(ch)
    return EdgeOffsets.concat(parts)


def channel_pairs(
    shots: Sequence[MosaicMeasurement], colour: str, reference: str = "G"
) -> tuple[list[list[Floats]], list[list[Floats]]]:
    """``(channel_shots, reference_shots)`` for :func:`fit_tca` from measured mosaics.

    The reference's planes (both green planes) are each a reference of their own: a
    channel's edges are paired with each of them in turn (the two green planes see the
    same edge a few thousandths of a pixel apart: matched together, no edge would be
    nearer one than the other).
    """
    ch: list[list[Floats]] = []
    ref: list[list[Floats]] = []
    for m in shots:
        lines = m.lines(colour)
        for r in m.channel(reference):
            ch.append(lines)
            ref.append([ln.points for ln in r.lines])
    return ch, ref


OUTWARD_MIN_COS = 0.5
"""A point counts for :meth:`ChannelOffsets.outward` when its edge normal is within 60 degrees of
the radial direction (an edge along the radius sees nothing of a radial TCA)."""
ZONES = ((0.0, 1.0 / 3.0), (1.0 / 3.0, 2.0 / 3.0), (2.0 / 3.0, 1.0))
"""The rings of :meth:`ChannelOffsets.summary`, in fractions of the half-diagonal."""


@dataclass(frozen=True)
class ChannelOffsets:
    r"""How far one channel's edges lie from green's in one shot, point by point (pixels).

    ``offset[i]`` is :math:`n_i \cdot \Delta(p_i)`: the channel -> green shift at the channel's
    edge point ``points[i]`` along green's normal ``normal[i]`` there (the observations of
    :func:`edge_offsets`, not a fit). For a radial TCA the figure that reads at a glance is
    :meth:`outward`: how far the channel's edge lies farther from the image centre than green's.
    """

    channel: str
    width: int
    height: int
    points: Floats
    normal: Floats
    offset: Floats

    def radius(self) -> Floats:
        """Distance of each point from the image centre over the half-diagonal."""
        c = np.array([(self.width - 1) / 2.0, (self.height - 1) / 2.0])
        return np.asarray(np.hypot(*(self.points - c).T) / (0.5 * float(np.hypot(self.width, self.height))))

    def outward(self) -> Floats:
        r"""The channel's edge outward of green's (px; > 0: farther from the centre): :math:`-\Delta \cdot n\,
        \mathrm{sign}(n \cdot \hat r)`, NaN where the normal is more than 60 degrees off the radius."""
        c = np.array([(self.width - 1) / 2.0, (self.height - 1) / 2.0])
        d = self.points - c
        rr = np.hypot(d[:, 0], d[:, 1])
        cos = np.einsum("ij,ij->i", self.normal, d) / np.where(rr > 0, rr, np.inf)
        out = -self.offset * np.sign(cos)
        return np.where(np.abs(cos) >= OUTWARD_MIN_COS, out, np.nan)

    def summary(self) -> dict[str, Any]:
        """Plain figures: points, RMS offset, and per ring (:data:`ZONES`) the median outward offset."""
        rho, out = self.radius(), self.outward()
        zones = []
        for lo, hi in ZONES:
            sel = (rho >= lo) & ((rho < hi) | (hi >= 1.0)) & np.isfinite(out)
            zones.append(
                {
                    "from": lo,
                    "to": hi,
                    "points": int(sel.sum()),
                    "median_outward_px": float(np.median(out[sel])) if sel.any() else None,
                }
            )
        rms = float(np.sqrt(np.mean(self.offset**2))) if len(self.offset) else None
        return {"channel": self.channel, "points": int(len(self.offset)), "rms_px": rms, "zones": zones}


def channel_offsets(m: MosaicMeasurement, reference: str = "G") -> dict[str, ChannelOffsets]:
    """Red's and blue's edge offsets from green's in one measured shot (:class:`ChannelOffsets`).

    Each reference plane (both green planes of a mosaic) is a reference of its own
    (:func:`channel_pairs`), so every channel point appears once per green plane.
    """
    out = {}
    for ch in ("R", "B"):
        obs = shot_offsets(*channel_pairs([m], ch, reference))
        out[ch] = ChannelOffsets(ch, m.width, m.height, obs.points, obs.coef, obs.offset)
    return out


@dataclass(frozen=True)
class TcaFit:
    """A channel's fitted field and its figures (pixels).

    ``offset_rms`` is the RMS distance of the channel's edges to the reference's
    before correction (the size of the TCA seen), ``residual_rms`` after it (what
    the field does not explain: the measurement's noise and model error);
    ``field_max`` the largest shift over the image; ``n_points`` / ``n_edges`` /
    ``rejected_edges`` what was used.
    """

    channel: str
    field: TcaField
    offset_rms: float
    residual_rms: float
    field_rms: float
    field_max: float
    n_points: int
    n_edges: int
    rejected_edges: int

    def to_dict(self) -> dict[str, Any]:
        return {
            "channel": self.channel,
            "field": self.field.to_dict(),
            "offset_rms_px": self.offset_rms,
            "residual_rms_px": self.residual_rms,
            "field_rms_px": self.field_rms,
            "field_max_px": self.field_max,
            "n_points": self.n_points,
            "n_edges": self.n_edges,
            "rejected_edges": self.rejected_edges,
        }


def image_grid(width: int, height: int, step: float = GRID_STEP_PX) -> Floats:
    """Points every ``step`` px over the whole image, borders and corners included."""
    xs = np.unique(np.append(np.arange(0.0, width - 1.0, step), width - 1.0))
    ys = np.unique(np.append(np.arange(0.0, height - 1.0, step), height - 1.0))
    gx, gy = np.meshgrid(xs, ys)
    return np.column_stack([gx.ravel(), gy.ravel()])


def _orientation_problem(coef: Floats) -> str | None:
    s = coef.T @ coef / max(len(coef), 1)
    lo = float(np.linalg.eigvalsh(s)[0])
    if lo < MIN_ORIENTATION_RATIO:
        return (
            f"the edges have one orientation (normals' smallest spread {lo:.3f} < {MIN_ORIENTATION_RATIO}): "
            "the field along the strings is not seen; add shots with the harp turned"
        )
    return None


def _solve(obs: EdgeOffsets, width: int, height: int, degree: int, keep: NDArray[np.bool_]) -> Floats:
    a2 = tca_basis(obs.points[keep], width, height, degree)
    n = int(keep.sum())
    a = obs.coef[keep, :1] * a2[:n] + obs.coef[keep, 1:] * a2[n:]
    scale = np.sqrt(np.sum(a * a, axis=0))
    scale[scale == 0] = 1.0
    a /= scale
    theta = np.linalg.solve(a.T @ a, a.T @ obs.offset[keep])
    return np.asarray(theta / scale, np.float64)


def _residuals(obs: EdgeOffsets, fld: TcaField) -> Floats:
    return np.asarray(obs.offset - np.sum(obs.coef * fld.shift(obs.points), axis=1), np.float64)


def fit_tca(
    channel_shots: Sequence[Sequence[Floats]],
    reference_shots: Sequence[Sequence[Floats]],
    width: int,
    height: int,
    channel: str = "R",
    degree: int = DEFAULT_TCA_DEGREE,
    max_distance_px: float = 4.0,
) -> TcaFit | FitFailure:
    """Fit a channel's :class:`TcaField` from its edges and the reference's, shot by shot.

    Parameters
    ----------
    channel_shots, reference_shots : per shot, sequences of (M, 2) arrays
        Smoothed edge points of the channel and of the reference (green) in the
        same shots, mosaic pixel coordinates (:meth:`pipeline.cfa.MosaicMeasurement.lines`).
    width, height : int
        Image size.
    channel : str
        Its name, recorded in the result.
    degree : int
        Total degree of the field (:data:`~pipeline.models.tca_model.TCA_DEGREE_BOUNDS`).
    max_distance_px : float
        Largest distance between a channel edge and its reference edge.

    Returns
    -------
    TcaFit or FitFailure
        Never raises for a data problem.

    References
    ----------
    .. [1] Mallon and Whelan, Pattern Recognition Letters 28(1), 2007.
    """
    lo, hi = TCA_DEGREE_BOUNDS
    if not lo <= int(degree) <= hi:
        return FitFailure(f"TCA degree must be {lo}..{hi}, got {degree}")
    if len(channel_shots) != len(reference_shots):
        return FitFailure(f"{len(channel_shots)} channel shots but {len(reference_shots)} reference shots")
    matches = [match_edges(ch, ref, max_distance_px) for ch, ref in zip(channel_shots, reference_shots)]
    obs = shot_offsets(channel_shots, reference_shots, max_distance_px=max_distance_px, matches=matches)
    if obs.n_edges < MIN_EDGES:
        return FitFailure(
            f"channel {channel}: {obs.n_edges} edges match a reference edge (need {MIN_EDGES}): "
            "are the channel and the reference the same shots?"
        )
    problem = _orientation_problem(obs.coef)
    if problem:
        return FitFailure(f"channel {channel}: {problem}")
    if len(obs.offset) < 3 * n_tca_params(degree):
        return FitFailure(f"channel {channel}: {len(obs.offset)} points for {n_tca_params(degree)} coefficients")
    offset_rms = float(np.sqrt(np.mean(obs.offset**2)))
    keep = np.ones(len(obs.offset), bool)
    fld = TcaField.zero(width, height, degree)
    rejected = 0
    for _ in range(3):
        theta = _solve(obs, width, height, degree, keep)
        fld = TcaField(width, height, degree, tuple(theta))
        # observations again at T(p): the quadratic's foot where the corrected point is
        again = shot_offsets(channel_shots, reference_shots, field=fld, matches=matches)
        if len(again.offset) >= 3 * n_tca_params(degree):
            # the remaining offsets are what the field leaves; add the field back to get the full ones
            full = again.offset + np.sum(again.coef * fld.shift(again.points), axis=1)
            obs = EdgeOffsets(again.points, again.coef, full, again.edge, again.shot)
        r = _residuals(obs, fld)
        per_edge = np.sqrt(np.bincount(obs.edge, r * r) / np.maximum(np.bincount(obs.edge), 1))
        med = float(np.median(per_edge[np.bincount(obs.edge) > 0]))
        bad = per_edge > REJECT_FACTOR * max(med, 1e-6)
        keep = ~bad[obs.edge]
        rejected = int(bad.sum())
    theta = _solve(obs, width, height, degree, keep)
    fld = TcaField(width, height, degree, tuple(theta))
    r = _residuals(obs, fld)[keep]
    grid = image_grid(width, height)
    mag = np.hypot(*fld.shift(grid).T)
    return TcaFit(
        channel=channel,
        field=fld,
        offset_rms=offset_rms,
        residual_rms=float(np.sqrt(np.mean(r * r))),
        field_rms=float(np.sqrt(np.mean(mag * mag))),
        field_max=float(mag.max()),
        n_points=int(keep.sum()),
        n_edges=int(len(np.unique(obs.edge[keep]))),
        rejected_edges=rejected,
    )


@dataclass(frozen=True)
class FieldDifference:
    """How far two channel -> reference maps differ over the image (pixels)."""

    rms: float
    max: float


def field_difference(
    a: Any,
    b: Any,
    width: int,
    height: int,
    step: float = GRID_STEP_PX,
) -> FieldDifference:
    """RMS and max of ``|a(x) - b(x)|`` over :func:`image_grid`: ``a``, ``b`` map (N, 2) arrays to (N, 2)."""
    g = image_grid(width, height, step)
    d = np.hypot(*(np.asarray(a(g)) - np.asarray(b(g))).T)
    return FieldDifference(float(np.sqrt(np.mean(d * d))), float(d.max()))


@dataclass(frozen=True)
class LensfunTcaFit:
    """Lensfun's TCA fitted to the channels' fields, with its conversion error per channel (pixels)."""

    model: LensfunTca
    error: Mapping[str, FieldDifference]

    def lines(self) -> list[str]:
        return [
            f"TCA {self.model.kind} channel {c}: conversion error RMS {e.rms:.4f} px, max {e.max:.4f} px"
            for c, e in self.error.items()
        ]


def lensfun_tca(
    fields: Mapping[str, TcaField],
    kind: str = "poly3",
    step: float = GRID_STEP_PX,
    center: tuple[float, float] = (0.0, 0.0),
) -> LensfunTcaFit:
    """Lensfun's ``kind`` TCA closest to the fields of ``"R"`` and ``"B"`` over the whole image.

    ``center``: the lens's ``<center>`` the file is written with (lensfun applies the TCA about
    it, as it does the distortion); the image centre by default.

    Fitted in lensfun's direction (reference -> channel, :class:`LensfunTca`) by linear
    least squares on :func:`image_grid`: for each grid point of the channel
    :math:`x_c`, its reference position :math:`y = T_c(x_c)` must map back to
    :math:`x_c`. The conversion error is the distance between lensfun's channel
    position and :math:`x_c`.
    """
    if kind not in LENSFUN_TCA_TERMS:
        raise ValueError(f"unsupported lensfun TCA model {kind!r}; supported: {sorted(LENSFUN_TCA_TERMS)}")
    missing = {"R", "B"} - set(fields)
    if missing:
        raise ValueError(f"lensfun TCA needs the red and blue fields; missing {sorted(missing)}")
    w, h = fields["R"].width, fields["R"].height
    ones = (1.0,) * len(LENSFUN_TCA_TERMS[kind])
    probe = LensfunTca(kind, ones, ones, w, h, center=center)
    o, s = np.asarray(probe.origin), probe.unit
    terms: dict[str, tuple[float, ...]] = {}
    for ch in ("R", "B"):
        xc = image_grid(w, h, step)
        y = fields[ch].to_reference(xc)
        q = (y - o) / s
        ru = np.hypot(q[:, 0], q[:, 1])
        target = ((xc - o) / s).T.ravel()  # x rows then y rows
        cols = [np.ones_like(ru)] if kind == "linear" else [np.ones_like(ru), ru, ru * ru]
        a = np.vstack([np.column_stack([q[:, 0] * c for c in cols]), np.column_stack([q[:, 1] * c for c in cols])])
        theta, *_ = np.linalg.lstsq(a, target, rcond=None)
        terms[ch] = tuple(float(v) for v in theta)
    model = LensfunTca(kind, terms["R"], terms["B"], w, h, center=center)
    err = {}
    for ch in ("R", "B"):
        fld = fields[ch]
        err[ch] = field_difference(lambda g: model.from_reference(ch, fld.to_reference(g)), lambda g: g, w, h, step)
    return LensfunTcaFit(model, err)
