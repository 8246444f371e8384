r"""Group sub-pixel edge chains into one point set per physical string edge.

Input: the chains of :func:`pipeline.edges.detect_edges` (ordered sub-pixel
points with their gradients; along a chain the bright side is on the walker's
right). Output: per string edge its ordered points, its polarity and the
string it belongs to, plus every rejected group with the reason.

A harp string, dark on a bright back-lit sheet (or the reverse), gives two
long, smooth edges of opposite gradient, a string width :math:`w` apart.
Everything else the edge detector returns (the harp frame, dust, the zig-zag
spring of the frame, noise) fails at least one of the tests below.

Algorithm
---------
:func:`group_string_edges` runs these steps in order; each is one function
over typed pieces (:class:`_Piece`) and edge candidates (:class:`_Candidate`).

1. **Border** (:func:`_trim`). Points closer than ``border_px`` to the image
   border are removed (there the detector's smoothing reads mirrored data);
   chains are cut there.
2. **Curvature** (:func:`_split_chain`). Along each chain the gradient angle
   is unwrapped and smoothed (Gaussian, ``ANGLE_SMOOTH_PTS`` points). A chain
   is cut where it turns faster than ``MAX_TURN_DEG_PER_PX`` over
   ``2 TURN_BASE_PTS`` points (a corner, a dust spot). Then the *local
   curvature* of the points themselves, the Menger curvature of the points
   ``CURVATURE_BASE_PX`` px before and after each point, is limited to
   ``1 / MIN_RADIUS_PX``: stretches that bend more are *curved* (dust
   spots, rings, the spring of the frame) and cut out. The image of a
   straight string bends far less, even through a wide-angle lens whose
   distortion reaches 30 % of the half-diagonal (radius of curvature above
   2500 px on 1600x1200; the bend of a string may add up to tens of degrees
   along the image, which is why no limit applies to the total turn).
   Pieces shorter than ``MIN_PIECE_PX`` are *short fragments*.
3. **Pairing and string width** (:func:`_pair`). From points of every
   remaining piece, march across the edge and record the first point of
   another piece whose gradient is opposite (cosine < -0.7) and of similar
   magnitude (ratio within ``MAX_CONTRAST_RATIO``: both edges of a string
   separate it from the same background, whereas the border of the frame and
   a string lying against it do not): its distance across is the local
   string width, its piece the partner. A coarse pass
   (``PAIR_COARSE_SAMPLES`` points per piece, both directions, up to
   ``MAX_STRING_WIDTH_PX * PAIR_SEARCH_FACTOR`` px) decides whether strings
   are dark or bright and gives the string width :math:`w_0`, the
   length-weighted median of the pieces' median widths: the direction that
   finds more partners, or, when both find partners for most pieces
   (strings so wide that the gaps between them are in reach too, e.g. 12 px
   strings 30 px apart), the one across the *narrower* band, since harp
   strings are narrower than the gaps between them. Every point of every piece
   then looks outwards (away from its string) up to
   ``max(CROWD_FACTOR * w_0, CROWD_MIN_PX)`` px: a stretch (majority over
   ``CROWD_WINDOW_PTS`` points) where another edge of at least
   ``CROWD_MIN_CONTRAST`` times its contrast lies that close is *crowded*
   (a string running along the frame or a shadow: the blur of the
   neighbouring edge would bias it) and is cut out. A fine pass
   (``PAIR_FINE_SAMPLES`` points per piece, up to
   ``WIDTH_RATIO * w_0 + 2`` px) gives each piece its paired fraction,
   width and partner votes.
4. **Pieces** (:func:`_select`). A piece is *unpaired* (the edge of the
   thick harp frame, of a shadow, of anything that is not a thin string)
   when fewer than ``MIN_PAIRED_FRACTION`` of its samples found a partner,
   and of *wrong width* when its median width is outside
   ``[w_0 / WIDTH_RATIO, w_0 * WIDTH_RATIO]``. An unpaired piece that
   touches the image border is kept aside: near the border a string's other
   edge may already have left the image.
5. **Joining inside the image** (:func:`_join_local`). Pieces of the same edge
   (cut by dust on the string, low contrast, a curvature split) are joined end
   to start, keeping the chain orientation (so the same gradient sign): the
   start of the next piece must lie ahead of the end of the previous one,
   within ``MAX_GAP_FRACTION`` of the image diagonal, the two end tangents
   within ``MAX_JOIN_ANGLE_DEG``, and each piece's end line must pass within
   ``JOIN_LATERAL_PX + JOIN_LATERAL_SLOPE * gap`` of the other's end (a cone
   that allows the curvature of a distorted string, but is far narrower than
   the string spacing). Candidates are accepted greedily by increasing cost;
   each piece has at most one successor and predecessor.
6. **Joining across the outside of the image** (:func:`_join_outside`). Under
   strong distortion a string near the image border bows out of the image and
   comes back: its pieces end and start at the border, far apart and with
   different tangents. A one-parameter division model with a free centre,
   :math:`x_u = c + (x - c) / (1 + \lambda \rho^2 + \lambda_2 \rho^4)`
   (:func:`_radial_guess`, fitted to the long joined edges by Levenberg-Marquardt
   so that they are straight), maps every piece close to a straight line; an
   edge ending at the border is joined to one starting at the border (or to
   an unpaired border piece kept aside in step 4) when, corrected by that
   model, the two lie on one line within ``OUTSIDE_JOIN_TOL * p`` (RMS), with
   :math:`p` the string pitch of the corrected harp, directions within
   ``MAX_JOIN_ANGLE_DEG``, the second after the first. The model is
   only a grouping aid (it is not the calibration) and is used only where its
   own residual on the long edges is below ``OUTSIDE_MODEL_TOL * p``.
7. **Edges** (:func:`_candidates`). An edge whose median gradient is below
   ``MIN_RELATIVE_CONTRAST`` times the strings' (length-weighted median) is
   of *low contrast* (a string seen over the dark frame). An edge made only
   of unpaired border pieces is *unpaired*.
8. **Strings** (:func:`_strings`). Edge ``A``'s partner is the edge that holds
   most of the partner hits of ``A``'s points; two edges form a string when
   they are each other's partner and have opposite polarity. A string is
   kept when its longer edge is at least ``MIN_EDGE_FRACTION`` of the smaller
   image side long (its other edge may be shorter: at the border it leaves
   the image first); the others are *short edges*. An edge without a partner
   is *unpaired*. Strings are numbered across the harp, in order of position
   along the harp normal ``n_h``.

All thresholds are either geometric invariants of a harp image (turning
rate, curvature, angle, fractions of the image size) or relative to the
measured string width and pitch; none depends on the contrast or on
particular test images. Supported: string widths of 2 to
``MAX_STRING_WIDTH_PX`` px, dark or bright strings, any orientation, any
number of strings whose gaps are wider than the strings.

Orientation and polarity: the harp direction ``u_h = (cos a_h, sin a_h)``,
``a_h`` in ``[0, 180)``, is the length-weighted mean direction of all
accepted edges (mean of doubled angles). Every edge's points are ordered
along ``u_h``; with the harp normal ``n_h = (-sin a_h, cos a_h)``,
``polarity = +1`` when the edge's gradient (dark -> bright) points along
``+n_h`` and ``-1`` otherwise. The two edges of a string have opposite
polarities (for dark strings: -1 is the edge at smaller ``n_h . p``).

References
----------
.. [1] Z. Tang, R. Grompone von Gioi, P. Monasse, J.-M. Morel,
   "High-precision camera distortion measurements with a calibration harp",
   JOSA A 29(10), 2012.
.. [2] R. Grompone von Gioi, G. Randall, "A Sub-Pixel Edge Detector: an
   Implementation of the Canny/Devernay Algorithm", IPOL 7 (2017).
.. [3] A. W. Fitzgibbon, "Simultaneous linear estimation of multiple view
   geometry and lens distortion", CVPR 2001 (the division model).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

Points = NDArray[np.float64]
Ints = NDArray[np.int64]
Mask = NDArray[np.bool_]

ANGLE_SMOOTH_PTS = 3.0
"""Sigma (points, ~px) of the smoothing of the gradient angle along a chain."""
MAX_TURN_DEG_PER_PX = 2.0
"""A chain is cut where its smoothed gradient turns faster than this."""
TURN_BASE_PTS = 6
"""Half-base (points) over which the turning rate is measured."""
CURVATURE_BASE_PX = 20
"""Half-base (points, ~px) of the local (Menger) curvature of the points."""
MIN_RADIUS_PX = 150.0
"""Stretches whose local radius of curvature is below this are curved, not a string."""
MIN_PIECE_PX = 8.0
"""Pieces with fewer points (~px of arclength) are short fragments."""
MAX_STRING_WIDTH_PX = 15.0
"""Widest supported string, pixels."""
PAIR_SEARCH_FACTOR = 2.5
"""Partners are searched up to PAIR_SEARCH_FACTOR * MAX_STRING_WIDTH_PX across."""
PAIR_STEP_PX = 0.5
"""Marching step across the edge, pixels."""
MAX_CONTRAST_RATIO = 2.0
"""Largest ratio of the gradient magnitudes of the two edges of a string."""
BOTH_WAYS_FRACTION = 0.6
"""When the weaker marching direction finds at least this fraction of the partners
the stronger one finds, dark/bright is decided by the narrower band."""
CROWD_FACTOR = 1.0
CROWD_MIN_PX = 6.0
"""Outside each string edge, up to max(CROWD_FACTOR * w0, CROWD_MIN_PX) px, there
must be no other edge (the blur of a neighbouring edge would bias it): 6 px is
4.5 sigma of the edge blur of a sharp lens seen through the detector's
smoothing (sigma ~1.3 px); wider strings come with larger images and blur."""
CROWD_MIN_CONTRAST = 0.25
"""Only edges at least this fraction of the edge's own gradient count as crowding."""
CROWD_WINDOW_PTS = 9
"""Crowding is decided by majority over this many consecutive points."""
CROWD_STRIDE = 3
"""Crowding is tested on every CROWD_STRIDE-th point (speed)."""
MIN_PAIRED_FRACTION = 0.5
"""Minimum fraction of a piece's samples that found a partner."""
WIDTH_RATIO = 2.5
"""Accepted piece widths: [w0 / WIDTH_RATIO, w0 * WIDTH_RATIO]."""
MAX_GAP_FRACTION = 0.25
"""Largest gap joined inside one edge, as a fraction of the image diagonal."""
MAX_JOIN_ANGLE_DEG = 12.0
"""Largest angle between the end tangents of two joined pieces (inside the image),
or between their corrected lines (across the outside)."""
JOIN_LATERAL_PX = 1.5
JOIN_LATERAL_SLOPE = 0.05
"""Lateral tolerance of a join: JOIN_LATERAL_PX + JOIN_LATERAL_SLOPE * gap."""
END_FIT_PX = 60
"""Number of end points (~px) used for the end tangent of a piece."""
AT_BORDER_PX = 3.0
"""An end within this distance of the trimmed border is at the border."""
LONG_FRACTION = 0.3
"""Edges at least this fraction of the smaller image side long fit the grouping's radial model."""
MIN_LONG_EDGES = 4
"""Fewest long edges for the radial model (and the joins across the outside)."""
OUTSIDE_JOIN_TOL = 0.1
"""Largest RMS distance of two corrected pieces to their common line, in string pitches."""
OUTSIDE_MODEL_TOL = 0.03
"""Largest RMS residual of the long edges under the grouping's radial model, in string pitches."""
MODEL_POINTS = 24
"""Points per edge used by the grouping's radial model."""
MIN_EDGE_FRACTION = 0.1
"""Shortest accepted string (its longer edge), as a fraction of the smaller image side."""
MIN_RELATIVE_CONTRAST = 0.2
"""Edges whose median gradient is below this fraction of the strings' median are rejected."""
REJECT_REASONS = {
    "short fragment": f"fewer than MIN_PIECE_PX = {MIN_PIECE_PX:g} points (noise, dust, specks)",
    "curved": "bends more than a string can (dust spot, frame corner, spring)",
    "unpaired edge": "no opposite edge a string width away (harp frame, shadow, lone edge)",
    "crowded": "another edge right outside the string (a string along the frame or a shadow)",
    "wrong width": "paired at a width far from the strings' (frame, thick object)",
    "short edge": "string shorter than MIN_EDGE_FRACTION of the smaller image side",
    "low contrast": "edge contrast below MIN_RELATIVE_CONTRAST of the strings' (string over the dark frame)",
}
"""Reasons for rejecting edge points, with their meaning."""
PAIR_COARSE_SAMPLES = 12
"""Points per piece sampled to decide dark/bright strings and measure w0."""
PAIR_FINE_SAMPLES = 64
"""Points per piece sampled for the paired fraction, width and partner votes."""


class ChainLike(Protocol):
    """What grouping reads of an edge chain (:class:`pipeline.edges.EdgeChain`)."""

    @property
    def xy(self) -> NDArray[np.float64]: ...

    @property
    def grad(self) -> NDArray[np.float64]: ...


def points_bbox(xy: Points) -> tuple[float, float, float, float]:
    """``(x_min, y_min, x_max, y_max)`` of an ``(N, 2)`` array of points (x = column, y = row)."""
    return (float(xy[:, 0].min()), float(xy[:, 1].min()), float(xy[:, 0].max()), float(xy[:, 1].max()))


@dataclass(frozen=True)
class StringEdge:
    """One string edge: its points ordered along the edge.

    Attributes
    ----------
    xy : (N, 2) ndarray
        Sub-pixel edge points ordered along the harp direction ``u_h``
        (module docstring).
    pieces : tuple of (start, stop)
        Index ranges of ``xy`` that are contiguous chains (no gap larger than
        a few pixels inside); joins happened between consecutive ranges.
    polarity : int
        +1 if the gradient points along the harp normal ``n_h``, else -1.
    string_id : int
        Index of the string (0, 1, ... across the harp).
    width_px : float
        Median distance to the other edge of the string, pixels.
    """

    xy: Points
    pieces: tuple[tuple[int, int], ...]
    polarity: int
    string_id: int
    width_px: float


@dataclass(frozen=True)
class RejectedGroup:
    """Edge points that were not taken as a string edge, and why.

    ``reason`` is one of ``REJECT_REASONS``; ``detail`` may add figures.
    """

    reason: str
    xy: Points
    detail: str = ""
    grad: Points | None = field(default=None, repr=False)

    @property
    def n_points(self) -> int:
        return int(len(self.xy))

    @property
    def bbox(self) -> tuple[float, float, float, float]:
        """``(x_min, y_min, x_max, y_max)``."""
        return points_bbox(self.xy)


@dataclass(frozen=True)
class Grouping:
    """Result of :func:`group_string_edges`.

    ``edges`` are sorted by ``(string_id, polarity)``; ``string_width_px`` is
    the measured width ``w0`` (NaN when nothing paired); ``dark_strings``
    tells whether strings are darker than the background.
    """

    edges: tuple[StringEdge, ...]
    rejected: tuple[RejectedGroup, ...]
    string_width_px: float
    dark_strings: bool

    @property
    def n_strings(self) -> int:
        return len({e.string_id for e in self.edges})


# --------------------------------------------------------------------------- #
# typed intermediate results
# --------------------------------------------------------------------------- #
@dataclass
class _Piece:
    """A contiguous stretch of one chain (ordered as the chain walks)."""

    xy: Points
    grad: Points
    paired: float = 0.0  # fraction of the fine samples that found a partner
    width: float = float("nan")  # median width to the partner, px
    at_start: bool = False  # its first / last point lies at the image border
    at_end: bool = False

    def __len__(self) -> int:
        return int(len(self.xy))


@dataclass
class _Candidate:
    """A joined edge candidate: pieces of one edge, in order."""

    pieces: list[int]
    xy: Points
    grad: Points
    ranges: list[tuple[int, int]]
    centroid: Points
    direction: Points
    length: float
    contrast: float
    polarity: int = 0
    all_unpaired: bool = False


@dataclass
class _Context:
    """The image the grouping works on and where everything rejected goes."""

    height: int
    width: int
    border_px: float
    rejected: list[RejectedGroup] = field(default_factory=list)

    @property
    def diag(self) -> float:
        return float(np.hypot(self.width, self.height))

    def reject(self, reason: str, xy: Points, detail: str = "", grad: Points | None = None) -> None:
        self.rejected.append(RejectedGroup(reason, xy, detail, grad))

    def at_border(self, p: Points) -> bool:
        d = min(p[0], p[1], self.width - 1 - p[0], self.height - 1 - p[1])
        return bool(d <= self.border_px + AT_BORDER_PX)


@dataclass
class _PairingResult:
    dark: bool
    w0: float
    pieces: list[_Piece]
    sample_piece: Ints  # piece of each fine sample
    sample_partner: Ints  # partner piece of each fine sample (-1: none)


# --------------------------------------------------------------------------- #
# small numerics (numpy only: the measurement imports nothing heavier)
# --------------------------------------------------------------------------- #
def _runs(mask: Mask) -> list[tuple[int, int]]:
    """Index ranges [a, b) where ``mask`` is True."""
    if mask.size == 0:
        return []
    d = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    return list(zip(np.nonzero(d == 1)[0].tolist(), np.nonzero(d == -1)[0].tolist()))


def _gaussian_nearest(a: Points, sigma: float) -> Points:
    """Gaussian smoothing of a 1-D signal, edge values repeated (radius ``int(4 sigma + 0.5)``)."""
    r = int(4.0 * sigma + 0.5)
    k = np.exp(-0.5 * (np.arange(-r, r + 1) / sigma) ** 2)
    k /= k.sum()
    out: Points = np.convolve(np.pad(a, r, mode="edge"), k, mode="valid")
    return out


def _mean_nearest(a: Points, size: int) -> Points:
    """Moving mean over ``size`` (odd) samples, edge values repeated."""
    r = size // 2
    out: Points = np.convolve(np.pad(a, r, mode="edge"), np.full(size, 1.0 / size), mode="valid")
    return out


def _arclength(xy: Points) -> Points:
    return np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(xy, axis=0).T))])


def _tls(q: Points) -> tuple[Points, Points, float]:
    """Centroid, unit direction and RMS residual of the total-least-squares line of ``q``."""
    c = q.mean(axis=0)
    d = q - c
    w, v = np.linalg.eigh(d.T @ d)
    return c, v[:, 1], float(np.sqrt(max(w[0], 0.0) / len(q)))


# --------------------------------------------------------------------------- #
# steps 1-2: border and curvature
# --------------------------------------------------------------------------- #
def _trim(chains: Sequence[ChainLike], ctx: _Context) -> list[tuple[Points, Points]]:
    """Step 1: the stretches of every chain at least ``border_px`` inside the image."""
    b, w, h = ctx.border_px, ctx.width, ctx.height
    out: list[tuple[Points, Points]] = []
    for ch in chains:
        xy = np.asarray(ch.xy, np.float64)
        gr = np.asarray(ch.grad, np.float64)
        inner = (xy[:, 0] >= b) & (xy[:, 0] <= w - 1 - b) & (xy[:, 1] >= b) & (xy[:, 1] <= h - 1 - b)
        out.extend((xy[a:e], gr[a:e]) for a, e in _runs(inner))
    return out


def _local_radius(xy: Points) -> Points:
    """Menger radius of curvature through the points ``CURVATURE_BASE_PX`` before and after each point."""
    n = len(xy)
    k = min(CURVATURE_BASE_PX, (n - 1) // 2)
    rad = np.full(n, np.inf)
    if k < 2:
        return rad
    a, p, b = xy[: n - 2 * k], xy[k : n - k], xy[2 * k :]
    u, v = p - a, b - p
    cross = np.abs(u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0])
    la, lb, lc = np.hypot(*u.T), np.hypot(*v.T), np.hypot(*(b - a).T)
    with np.errstate(divide="ignore"):
        r = la * lb * lc / (2.0 * cross)
    rad[k : n - k] = r
    rad[:k] = r[0]  # the ends take the radius of their nearest full base
    rad[n - k :] = r[-1]
    return rad


def _split_chain(xy: Points, grad: Points, ctx: _Context) -> list[_Piece]:
    """Step 2: cut one (border-trimmed) chain at sharp turns and curved stretches."""
    n = len(xy)
    if n < MIN_PIECE_PX:
        ctx.reject("short fragment", xy, grad=grad)
        return []
    ang = np.unwrap(np.arctan2(grad[:, 1], grad[:, 0]))
    angs = _gaussian_nearest(ang, ANGLE_SMOOTH_PTS)
    k = min(TURN_BASE_PTS, max(1, (n - 1) // 2))
    rate = np.zeros(n)
    # turning over a base of 2k points, normalised by the arclength
    s = _arclength(xy)
    ds = s[2 * k :] - s[: -2 * k]
    rate[k : n - k] = np.degrees(np.abs(angs[2 * k :] - angs[: -2 * k])) / np.maximum(ds, 1e-9)
    out = []
    for a, b in _runs(rate <= MAX_TURN_DEG_PER_PX):
        if b - a < MIN_PIECE_PX:
            ctx.reject("short fragment", xy[a:b], grad=grad[a:b])
            continue
        smooth = _local_radius(xy[a:b]) >= MIN_RADIUS_PX
        for c, d in _runs(~smooth):
            if d - c >= MIN_PIECE_PX:
                ctx.reject("curved", xy[a + c : a + d], grad=grad[a + c : a + d])
        for c, d in _runs(smooth):
            if d - c < MIN_PIECE_PX:
                ctx.reject("short fragment", xy[a + c : a + d], grad=grad[a + c : a + d])
            else:
                out.append(_Piece(xy[a + c : a + d], grad[a + c : a + d]))
    # turning points themselves (not part of any run) are dropped silently unless long
    for a, b in _runs(rate > MAX_TURN_DEG_PER_PX):
        if b - a >= MIN_PIECE_PX:
            ctx.reject("curved", xy[a:b], grad=grad[a:b])
    return out


# --------------------------------------------------------------------------- #
# step 3: pairing across the string
# --------------------------------------------------------------------------- #
class _Pairing:
    """Label map of all piece points and marching across edges."""

    def __init__(self, pieces: Sequence[_Piece], shape: tuple[int, int], extra: tuple[Points, Points] | None = None):
        """``extra``: ``(xy, grad)`` of other edge points (rejected pieces):
        they occupy the map for :meth:`crowded` but are never partners."""
        h, w = shape
        self.shape = shape
        self.set_pieces(pieces)
        xs = [p.xy for p in pieces]
        gs = [p.grad for p in pieces]
        pid = [np.repeat(np.arange(len(pieces), dtype=np.int32), self.lens)]
        if extra is not None and len(extra[0]):
            xs.append(extra[0])
            gs.append(extra[1])
            pid.append(np.full(len(extra[0]), -1, np.int32))
        self.xy: Points = np.concatenate(xs)
        g = np.concatenate(gs)
        self.gmag: Points = np.hypot(g[:, 0], g[:, 1])
        self.ghat: Points = g / np.maximum(self.gmag, 1e-12)[:, None]
        self.pid: NDArray[np.int32] = np.concatenate(pid)
        lab = np.full((h, w), -1, np.int32)
        flat = lab.ravel()  # flat indices: the same cells, cheaper than (row, column) pairs
        ij = np.rint(self.xy).astype(np.int32)
        inside = (ij[:, 0] >= 0) & (ij[:, 0] < w) & (ij[:, 1] >= 0) & (ij[:, 1] < h)
        src = np.nonzero(inside)[0].astype(np.int32)
        ij = ij[inside]
        # piece points win over extra points: write the extras first
        order = np.argsort(self.pid[src] >= 0, kind="stable")
        src, ij = src[order], ij[order]
        x, y = ij[:, 0].astype(np.intp), ij[:, 1].astype(np.intp)
        flat[y * w + x] = src
        # also fill the free 4-neighbours (pieces first), so that a ray cannot
        # slip between two diagonal pixels of an 8-connected edge
        for sel in (np.flatnonzero(self.pid[src] >= 0), np.flatnonzero(self.pid[src] < 0)):
            sx, sy, ss = x[sel], y[sel], src[sel]
            for dx, dy, ok in ((1, 0, sx < w - 1), (-1, 0, sx > 0), (0, 1, sy < h - 1), (0, -1, sy > 0)):
                f2 = (sy[ok] + dy) * w + (sx[ok] + dx)
                s2 = ss[ok]
                free = flat[f2] < 0
                flat[f2[free]] = s2[free]
        self.lab = lab

    def set_pieces(self, pieces: Sequence[_Piece], starts: Sequence[int] | None = None) -> None:
        """Piece lengths and where each starts in the point arrays (contiguous by default)."""
        self.lens: Ints = np.array([len(p) for p in pieces], np.int64)
        if starts is None:
            self.starts: Ints = np.concatenate([[0], np.cumsum(self.lens)[:-1]]).astype(np.int64)
        else:
            self.starts = np.asarray(starts, np.int64)
        self.n = int(self.lens.sum())

    def sample(self, per_piece: int) -> Ints:
        """Indices of up to ``per_piece`` evenly spread points of every piece."""
        k = np.minimum(self.lens, per_piece)
        rep = np.repeat(np.arange(len(self.lens)), k)
        pos = np.arange(int(k.sum())) - np.repeat(np.cumsum(k) - k, k)
        off = ((pos + 0.5) * self.lens[rep] / k[rep]).astype(np.int64)
        out: Ints = self.starts[rep] + off
        return out

    def march(self, sample: Ints, sign: float, max_dist: float) -> tuple[Ints, Points]:
        """From each sampled point, walk ``sign * gradient`` up to ``max_dist``.

        Returns ``(partner piece or -1, width)`` of the first point of another
        piece with an opposite gradient (cosine < -0.7) and a similar gradient
        magnitude (ratio within ``MAX_CONTRAST_RATIO``): both edges of a
        string separate it from the same background.
        """
        h, w = self.shape
        steps = (np.arange(1, int(np.ceil(max_dist / PAIR_STEP_PX)) + 1) * PAIR_STEP_PX).astype(np.float32)
        p0 = self.xy[sample].astype(np.float32)
        g0 = self.ghat[sample].astype(np.float32)
        xi = np.rint(p0[:, 0:1] + sign * g0[:, 0:1] * steps[None, :]).astype(np.int32)
        yi = np.rint(p0[:, 1:2] + sign * g0[:, 1:2] * steps[None, :]).astype(np.int32)
        ok = (xi >= 0) & (xi < w) & (yi >= 0) & (yi < h)
        hit = np.full(xi.shape, -1, np.int32)
        hit[ok] = self.lab.ravel()[yi[ok].astype(np.intp) * w + xi[ok]]
        valid = hit >= 0
        hs = np.where(valid, hit, 0)
        valid &= (self.pid[hs] != self.pid[sample][:, None]) & (self.pid[hs] >= 0)
        cosg = self.ghat[hs, 0] * g0[:, None, 0] + self.ghat[hs, 1] * g0[:, None, 1]
        valid &= cosg < -0.7
        first = np.argmax(valid, axis=1)
        rows = np.arange(len(sample))
        found = valid[rows, first]
        j = hs[rows, first]
        ratio = self.gmag[j] / np.maximum(self.gmag[sample], 1e-12)
        found &= (ratio <= MAX_CONTRAST_RATIO) & (ratio >= 1.0 / MAX_CONTRAST_RATIO)
        d = self.xy[j] - self.xy[sample]
        width = np.abs(d[:, 0] * self.ghat[sample, 0] + d[:, 1] * self.ghat[sample, 1])
        return np.where(found, self.pid[j], -1).astype(np.int64), np.where(found, width, np.nan)

    def crowded(self, sign: float, reach: float) -> Mask:
        """For every piece point: is there another edge within ``reach`` px
        on its outer side (away from its string), of at least
        ``CROWD_MIN_CONTRAST`` times its gradient magnitude?"""
        h, w = self.shape
        # every CROWD_STRIDE-th point (the decision is a majority over
        # CROWD_WINDOW_PTS points anyway), spread back to its neighbours
        idx = np.arange(0, self.n, CROWD_STRIDE)
        steps = np.arange(1, int(np.ceil(reach)) + 1, dtype=np.float32)
        p0 = self.xy[idx].astype(np.float32)
        g0 = (-sign * self.ghat[idx]).astype(np.float32)
        own = self.pid[idx]
        gmin = CROWD_MIN_CONTRAST * self.gmag[idx]
        out = np.zeros(len(idx), bool)
        lab = self.lab.ravel()
        for k in steps:  # a few steps; vectorised over all points
            xi = np.rint(p0[:, 0] + g0[:, 0] * k).astype(np.int32)
            yi = np.rint(p0[:, 1] + g0[:, 1] * k).astype(np.int32)
            ok = np.nonzero((xi >= 0) & (xi < w) & (yi >= 0) & (yi < h) & ~out)[0]
            hit = lab[yi[ok].astype(np.intp) * w + xi[ok]]
            j = np.maximum(hit, 0)
            out[ok] |= (hit >= 0) & (self.pid[j] != own[ok]) & (self.gmag[j] >= gmin[ok])
        res: Mask = np.repeat(out, CROWD_STRIDE)[: self.n]
        return res


def _per_piece(spid: Ints, spart: Ints, swidth: Points, npcs: int) -> tuple[Points, Points]:
    """Per piece: fraction of samples paired and median width."""
    n_samp = np.bincount(spid, minlength=npcs)
    found = spart >= 0
    frac = np.bincount(spid[found], minlength=npcs) / np.maximum(n_samp, 1)
    med_w = np.full(npcs, np.nan)
    order = np.argsort(spid[found], kind="stable")
    fw, fp = swidth[found][order], spid[found][order]
    bounds = np.searchsorted(fp, np.arange(npcs + 1))
    for i in np.nonzero(bounds[1:] > bounds[:-1])[0]:
        med_w[i] = np.median(fw[bounds[i] : bounds[i + 1]])
    return frac.astype(np.float64), med_w


def _weighted_median(values: Points, weights: Points) -> float:
    o = np.argsort(values)
    cum = np.cumsum(weights[o])
    return float(values[o][np.searchsorted(cum, 0.5 * cum[-1])])


def _uncrowd(pieces: list[_Piece], pr: _Pairing, crowd: Mask, ctx: _Context) -> list[_Piece]:
    """Cut the crowded stretches out of the pieces; the label map stays, piece ids change."""
    new_pieces: list[_Piece] = []
    new_starts: list[int] = []
    new_pid = np.full(len(pr.pid), -1, np.int32)
    for i, p in enumerate(pieces):
        s0 = int(pr.starts[i])
        c = crowd[s0 : s0 + pr.lens[i]]
        if c.any():
            c = _mean_nearest(c.astype(np.float64), CROWD_WINDOW_PTS) > 0.5
            for a, b in _runs(c):
                ctx.reject("crowded", p.xy[a:b], "another edge just outside the string")
            runs = _runs(~c)
        else:
            runs = [(0, len(p))]
        for a, b in runs:
            if b - a >= MIN_PIECE_PX:
                new_pid[s0 + a : s0 + b] = len(new_pieces)
                new_starts.append(s0 + a)
                new_pieces.append(_Piece(p.xy[a:b], p.grad[a:b]))
            else:
                ctx.reject("short fragment", p.xy[a:b])
    pr.pid = new_pid
    pr.set_pieces(new_pieces, new_starts)
    return new_pieces


def _pair(pieces: list[_Piece], ctx: _Context) -> _PairingResult:
    """Step 3: dark or bright strings, the string width, crowding, per-piece pairing."""
    extra = None
    with_grad = [(x.xy, x.grad) for x in ctx.rejected if x.grad is not None]
    if with_grad:
        extra = (np.concatenate([x for x, _ in with_grad]), np.concatenate([g for _, g in with_grad]))
    pr = _Pairing(pieces, (ctx.height, ctx.width), extra)
    lens = pr.lens.astype(np.float64)
    coarse = pr.sample(PAIR_COARSE_SAMPLES)
    cpid = pr.pid[coarse].astype(np.int64)
    search = MAX_STRING_WIDTH_PX * PAIR_SEARCH_FACTOR
    npcs = len(pieces)
    ways = {}
    for name, sign in (("dark", -1.0), ("bright", 1.0)):  # dark strings: towards the dark side
        part, wid = pr.march(coarse, sign, search)
        frac, med_w = _per_piece(cpid, part, wid, npcs)
        paired = frac >= MIN_PAIRED_FRACTION
        w = _weighted_median(med_w[paired], lens[paired]) if paired.any() else float("nan")
        ways[name] = (int((part >= 0).sum()), paired, w)
    nd, nb = ways["dark"][0], ways["bright"][0]
    if min(nd, nb) >= BOTH_WAYS_FRACTION * max(nd, nb) and np.isfinite(ways["dark"][2] + ways["bright"][2]):
        dark = ways["dark"][2] <= ways["bright"][2]  # both ways pair: the string is the narrower band
    else:
        dark = nd >= nb
    _, paired, w0 = ways["dark" if dark else "bright"]
    if not paired.any():
        for p in pieces:
            ctx.reject("unpaired edge", p.xy)
        return _PairingResult(dark, float("nan"), [], np.zeros(0, np.int64), np.zeros(0, np.int64))
    sign = -1.0 if dark else 1.0
    # edges crowded on their outer side (a string running along the frame or a
    # shadow) are biased by the neighbouring edge: cut those stretches out
    crowd = pr.crowded(sign, max(CROWD_FACTOR * w0, CROWD_MIN_PX))
    if crowd.any():
        pieces = _uncrowd(pieces, pr, crowd, ctx)
        if not pieces:
            return _PairingResult(dark, w0, [], np.zeros(0, np.int64), np.zeros(0, np.int64))
    # the fine pass: more points, search only up to the widest accepted width
    fine = pr.sample(PAIR_FINE_SAMPLES)
    spid = pr.pid[fine].astype(np.int64)
    spart, swidth = pr.march(fine, sign, w0 * WIDTH_RATIO + 2.0)
    frac, med_w = _per_piece(spid, spart, swidth, len(pieces))
    for p, f, mw in zip(pieces, frac, med_w):
        p.paired, p.width = float(f), float(mw)
        p.at_start, p.at_end = ctx.at_border(p.xy[0]), ctx.at_border(p.xy[-1])
    return _PairingResult(dark, w0, pieces, spid, spart)


# --------------------------------------------------------------------------- #
# step 4: pieces kept, pieces kept aside
# --------------------------------------------------------------------------- #
def _select(pair: _PairingResult, ctx: _Context) -> tuple[list[int], list[int]]:
    """Step 4: indices of the string pieces, and of the unpaired pieces kept aside at the border."""
    keep, aside = [], []
    w0 = pair.w0
    for i, p in enumerate(pair.pieces):
        if p.paired < MIN_PAIRED_FRACTION:
            if p.at_start or p.at_end:
                aside.append(i)
            else:
                ctx.reject("unpaired edge", p.xy)
        elif not (w0 / WIDTH_RATIO <= p.width <= w0 * WIDTH_RATIO):
            ctx.reject("wrong width", p.xy, f"{p.width:.1f} px wide, strings are {w0:.1f} px")
        else:
            keep.append(i)
    return keep, aside


# --------------------------------------------------------------------------- #
# step 5: joining pieces along an edge, inside the image
# --------------------------------------------------------------------------- #
def _end_tangent(xy: Points, at_end: bool) -> tuple[Points, Points]:
    m = min(len(xy), END_FIT_PX)
    q = xy[-m:] if at_end else xy[:m]
    c, t, _ = _tls(q)
    if t @ (q[-1] - q[0]) < 0:
        t = -t
    return c, t


def _greedy(n: int, cand: list[tuple[float, int, int]]) -> list[list[int]]:
    """Accept links ``a -> b`` by increasing cost (one successor and predecessor each, no cycle)."""
    cand.sort()
    nxt = np.full(n, -1)
    prv = np.full(n, -1)
    root = np.arange(n)

    def find(i: int) -> int:
        while root[i] != i:
            root[i] = root[root[i]]
            i = int(root[i])
        return i

    for _, a, b in cand:
        if nxt[a] >= 0 or prv[b] >= 0:
            continue
        ra, rb = find(a), find(b)
        if ra == rb:
            continue  # would close a cycle
        nxt[a], prv[b] = b, a
        root[rb] = ra
    groups = []
    for i in range(n):
        if prv[i] < 0:
            g = [i]
            while nxt[g[-1]] >= 0:
                g.append(int(nxt[g[-1]]))
            groups.append(g)
    return groups


def _join_local(pieces: Sequence[_Piece], diag: float) -> list[list[int]]:
    """Step 5: greedy end-to-start joining inside the image; lists of indices into ``pieces``."""
    n = len(pieces)
    ends = [_end_tangent(p.xy, True) for p in pieces]
    starts = [_end_tangent(p.xy, False) for p in pieces]
    e_pt = np.array([p.xy[-1] for p in pieces]).reshape(-1, 2)
    s_pt = np.array([p.xy[0] for p in pieces]).reshape(-1, 2)
    gmax = MAX_GAP_FRACTION * diag
    cos_max = np.cos(np.radians(MAX_JOIN_ANGLE_DEG))
    cb = np.array([c for c, _ in starts]).reshape(-1, 2)
    tb = np.array([t for _, t in starts]).reshape(-1, 2)
    cand: list[tuple[float, int, int]] = []
    for a in range(n):
        ca, ta = ends[a]
        gvec = s_pt - e_pt[a]
        gap = np.hypot(gvec[:, 0], gvec[:, 1])
        along = gvec @ ta
        tol = JOIN_LATERAL_PX + JOIN_LATERAL_SLOPE * gap
        # lateral offsets: B's start from A's end line (fitted on A's last
        # END_FIT_PX points), A's end from B's start line
        lat_a = np.abs(ta[0] * (s_pt[:, 1] - ca[1]) - ta[1] * (s_pt[:, 0] - ca[0]))
        lat_b = np.abs(tb[:, 0] * (e_pt[a, 1] - cb[:, 1]) - tb[:, 1] * (e_pt[a, 0] - cb[:, 0]))
        lat = np.maximum(lat_a, lat_b)
        ok = (gap <= gmax) & (tb @ ta >= cos_max) & (along >= -2.0) & (lat <= tol)
        ok[a] = False
        for b in np.nonzero(ok)[0]:
            cand.append((float(lat[b] / tol[b] + gap[b] / gmax), a, int(b)))
    return _greedy(n, cand)


# --------------------------------------------------------------------------- #
# step 6: joining across the outside of the image
# --------------------------------------------------------------------------- #
@dataclass(frozen=True)
class _RadialGuess:
    """The grouping's division model ``x_u = c + (x - c) / (1 + l1 rho^2 + l2 rho^4)``, ``rho = |x - c| / r0``."""

    cx: float
    cy: float
    l1: float
    l2: float
    r0: float

    def undistort(self, xy: Points) -> Points:
        v = xy - [self.cx, self.cy]
        r2 = (v[:, 0] ** 2 + v[:, 1] ** 2) / self.r0**2
        den = 1.0 + self.l1 * r2 + self.l2 * r2 * r2
        out: Points = np.array([self.cx, self.cy]) + v / np.where(den > 0.05, den, np.nan)[:, None]
        return out


def _line_residuals(q: Points, lab: Ints, nsets: int) -> Points:
    """Signed distances of the points of each set (``lab``) to that set's TLS line."""
    cnt = np.bincount(lab, minlength=nsets).astype(np.float64)
    mx = np.bincount(lab, q[:, 0], nsets) / cnt
    my = np.bincount(lab, q[:, 1], nsets) / cnt
    dx, dy = q[:, 0] - mx[lab], q[:, 1] - my[lab]
    sxx = np.bincount(lab, dx * dx, nsets)
    syy = np.bincount(lab, dy * dy, nsets)
    sxy = np.bincount(lab, dx * dy, nsets)
    theta = 0.5 * np.arctan2(2 * sxy, sxx - syy)  # direction of the largest spread
    nx, ny = -np.sin(theta), np.cos(theta)
    out: Points = dx * nx[lab] + dy * ny[lab]
    return out


def _radial_guess(sets: Sequence[Points], ctx: _Context) -> tuple[_RadialGuess, Points] | None:
    """Division model (centre, two coefficients) that straightens ``sets``; with each set's RMS residual.

    Levenberg-Marquardt on the signed distances of ``MODEL_POINTS`` points per
    set to their lines, from the identity at the image centre (Jacobian by
    forward differences).
    """
    pts, labs = [], []
    for i, s in enumerate(sets):
        idx = np.linspace(0, len(s) - 1, min(len(s), MODEL_POINTS)).astype(np.int64)
        pts.append(s[idx])
        labs.append(np.full(len(idx), i, np.int64))
    q = np.concatenate(pts)
    lab = np.concatenate(labs)
    ns = len(sets)
    r0 = 0.5 * ctx.diag
    x = np.array([(ctx.width - 1) / 2.0, (ctx.height - 1) / 2.0, 0.0, 0.0])
    scale = np.array([r0, r0, 1.0, 1.0])  # parameters in units of O(1)

    def res(x: Points) -> Points:
        m = _RadialGuess(float(x[0]), float(x[1]), float(x[2]), float(x[3]), r0)
        return _line_residuals(m.undistort(q), lab, ns)

    r = res(x)
    if not np.all(np.isfinite(r)):
        return None
    f = float(r @ r)
    mu = 1e-3
    converged = False
    for _ in range(40):
        jac = np.empty((len(r), 4))
        for j in range(4):
            h = 1e-6 * scale[j]
            dx = x.copy()
            dx[j] += h
            jac[:, j] = (res(dx) - r) / h * scale[j]
        a = jac.T @ jac
        g = jac.T @ r
        improved = False
        while mu < 1e10:
            step = np.linalg.solve(a + mu * np.diag(np.diag(a) + 1e-12), -g) * scale
            rn = res(x + step)
            fn = float(rn @ rn) if np.all(np.isfinite(rn)) else np.inf
            if fn < f:
                converged = f - fn < 1e-10 * f
                x, r, f, mu, improved = x + step, rn, fn, mu * 0.3, True
                break
            mu *= 10.0
        if not improved or converged:
            break
        converged = False
    model = _RadialGuess(float(x[0]), float(x[1]), float(x[2]), float(x[3]), r0)
    per = np.sqrt(np.bincount(lab, r * r, ns) / np.bincount(lab, minlength=ns))
    return model, per


def _pitch(lines: Sequence[tuple[Points, Points]]) -> float:
    """String pitch of corrected edges ``(centroid, direction)``: median spacing of same-direction edges."""
    d2 = np.array([2 * np.arctan2(t[1], t[0]) for _, t in lines])
    a = 0.5 * np.arctan2(np.mean(np.sin(d2)), np.mean(np.cos(d2)))
    u = np.array([np.cos(a), np.sin(a)])
    nrm = np.array([-u[1], u[0]])
    gaps = []
    for sgn in (1.0, -1.0):
        off = np.sort([c @ nrm for c, t in lines if sgn * (t @ u) > 0])
        gaps.extend(np.diff(off).tolist())
    return float(np.median(gaps)) if gaps else float("nan")


def _join_outside(
    groups: list[list[int]], aside: list[int], pieces: Sequence[_Piece], ctx: _Context
) -> list[list[int]]:
    """Step 6: join edges (and unpaired border pieces) across the outside of the image.

    ``groups`` hold indices into ``pieces`` (string pieces joined in step 5);
    ``aside`` the unpaired border pieces. Returns the new groups (each a list of
    piece indices); groups made only of pieces of ``aside`` are returned as well.
    """
    nodes = [list(g) for g in groups] + [[i] for i in aside]
    xy = [np.concatenate([pieces[i].xy for i in g]) for g in nodes]
    length = np.array([float(_arclength(x)[-1]) for x in xy])
    long = [k for k in range(len(groups)) if length[k] >= LONG_FRACTION * min(ctx.width, ctx.height)]
    if len(long) < MIN_LONG_EDGES:
        return nodes
    guess = _radial_guess([xy[k] for k in long], ctx)
    if guess is None:
        return nodes
    model, per = guess
    corr = [model.undistort(x[np.linspace(0, len(x) - 1, min(len(x), 4 * MODEL_POINTS)).astype(np.int64)]) for x in xy]
    if not all(np.all(np.isfinite(c)) for c in [corr[k] for k in long]):
        return nodes
    lines = [_tls(corr[k])[:2] for k in long]
    pitch = _pitch(lines)
    if not (np.isfinite(pitch) and pitch > 0 and float(np.median(per)) <= OUTSIDE_MODEL_TOL * pitch):
        return nodes
    at_end = np.array([pieces[g[-1]].at_end for g in nodes])
    at_start = np.array([pieces[g[0]].at_start for g in nodes])
    finite = np.array([bool(np.all(np.isfinite(c))) for c in corr])
    # per node: corrected line (centroid, direction along the walk) and extent along it
    cen = np.zeros((len(nodes), 2))
    dirs = np.zeros((len(nodes), 2))
    for k in np.flatnonzero(finite):
        c, t, _ = _tls(corr[k])
        cen[k], dirs[k] = c, (t if t @ (corr[k][-1] - corr[k][0]) >= 0 else -t)
    cos_max = np.cos(np.radians(MAX_JOIN_ANGLE_DEG))
    tol = OUTSIDE_JOIN_TOL * pitch
    n_str = len(groups)
    cand: list[tuple[float, int, int]] = []
    for a in np.flatnonzero(at_end & finite):
        ok = at_start & finite & (dirs @ dirs[a] >= cos_max)
        ok[a] = False
        if a >= n_str:
            ok[n_str:] = False  # two unpaired pieces alone never make an edge
        # prefilter: the other centroid near this line (loose: the line may tilt by the angle limit)
        rel = cen - cen[a]
        lateral = np.abs(rel[:, 0] * dirs[a, 1] - rel[:, 1] * dirs[a, 0])
        ok &= lateral <= 3.0 * tol + np.abs(rel @ dirs[a]) * np.sin(np.radians(MAX_JOIN_ANGLE_DEG))
        ok &= rel @ dirs[a] > 0
        for b in np.flatnonzero(ok):
            both = np.concatenate([corr[a], corr[b]])
            _, t, rms = _tls(both)
            t = t if t @ dirs[a] >= 0 else -t
            if float(np.max(corr[a] @ t)) > float(np.min(corr[b] @ t)) + 2.0:
                continue  # b does not come after a
            if rms <= tol:
                cand.append((rms / pitch, int(a), int(b)))
    if not cand:
        return nodes
    joined = _greedy(len(nodes), cand)
    return [[i for k in g for i in nodes[k]] for g in joined]


# --------------------------------------------------------------------------- #
# step 7-8: edges and strings
# --------------------------------------------------------------------------- #
def _candidates(groups: list[list[int]], pieces: Sequence[_Piece], aside: set[int], ctx: _Context) -> list[_Candidate]:
    """Step 7: one candidate per joined group; unpaired-only and low-contrast candidates are rejected."""
    cand = []
    for g in groups:
        xy = np.concatenate([pieces[i].xy for i in g])
        gr = np.concatenate([pieces[i].grad for i in g])
        if all(i in aside for i in g):
            ctx.reject("unpaired edge", xy)
            continue
        c, u, _ = _tls(xy)
        ext = (xy - c) @ u
        bnd = np.concatenate([[0], np.cumsum([len(pieces[i]) for i in g])])
        cand.append(
            _Candidate(
                pieces=list(g),
                xy=xy,
                grad=gr,
                ranges=[(int(bnd[k]), int(bnd[k + 1])) for k in range(len(g))],
                centroid=c,
                direction=u,
                length=float(ext.max() - ext.min()),
                contrast=float(np.median(np.hypot(gr[:, 0], gr[:, 1]))),
            )
        )
    if not cand:
        return cand
    # contrast: a string seen against the dark frame, or in deep shadow, is
    # not measured (its edges are displaced by the surrounding shading)
    gm = np.array([e.contrast for e in cand])
    ref = _weighted_median(gm, np.array([e.length for e in cand]))
    out = []
    for e in cand:
        if e.contrast < MIN_RELATIVE_CONTRAST * ref:
            ctx.reject("low contrast", e.xy, f"gradient {e.contrast:.3g}, strings {ref:.3g}")
        else:
            out.append(e)
    return out


def _orient(cand: list[_Candidate]) -> Points:
    """Harp normal ``n_h``; every candidate ordered along ``u_h`` and given its polarity."""
    ang2 = np.array([2 * np.arctan2(e.direction[1], e.direction[0]) for e in cand])
    wt = np.array([e.length for e in cand])
    a_h = 0.5 * np.arctan2(np.sum(wt * np.sin(ang2)), np.sum(wt * np.cos(ang2))) % np.pi
    u_h = np.array([np.cos(a_h), np.sin(a_h)])
    n_h = np.array([-u_h[1], u_h[0]])
    for e in cand:
        if (e.xy[-1] - e.xy[0]) @ u_h < 0:
            n = len(e.xy)
            e.xy, e.grad = e.xy[::-1].copy(), e.grad[::-1].copy()
            e.ranges = [(n - b, n - a) for a, b in reversed(e.ranges)]
            e.pieces = e.pieces[::-1]
        e.polarity = 1 if float(np.median(e.grad @ n_h)) > 0 else -1
    return n_h


def _strings(cand: list[_Candidate], pair: _PairingResult, ctx: _Context) -> list[tuple[int, int]]:
    """Step 8: mutual partners of opposite polarity, long enough; rejects the rest."""
    piece_edge = np.full(len(pair.pieces), -1)
    for k, e in enumerate(cand):
        piece_edge[e.pieces] = k
    ne = len(cand)
    votes = np.zeros((ne, ne))
    found = pair.sample_partner >= 0
    pe = piece_edge[pair.sample_piece[found]]
    qe = piece_edge[pair.sample_partner[found]]
    ok = (pe >= 0) & (qe >= 0)
    np.add.at(votes, (pe[ok], qe[ok]), 1.0)
    best = np.where(votes.max(axis=1) > 0, votes.argmax(axis=1), -1) if ne else np.zeros(0, np.int64)
    min_len = MIN_EDGE_FRACTION * min(ctx.width, ctx.height)
    strings = []
    used: set[int] = set()
    for a in range(ne):
        b = int(best[a])
        if b > a and best[b] == a and cand[a].polarity != cand[b].polarity:
            used.update((a, b))
            if max(cand[a].length, cand[b].length) >= min_len:
                strings.append((a, b))
            else:
                for k in (a, b):
                    ctx.reject("short edge", cand[k].xy, f"string shorter than {min_len:.0f} px")
    for a in range(ne):
        if a not in used:
            if cand[a].length < min_len:
                ctx.reject("short edge", cand[a].xy, f"shorter than {min_len:.0f} px")
            else:
                ctx.reject("unpaired edge", cand[a].xy)
    return strings


# --------------------------------------------------------------------------- #
# public entry point
# --------------------------------------------------------------------------- #
def group_string_edges(chains: Sequence[ChainLike], shape: tuple[int, int], border_px: float = 4.0) -> Grouping:
    """Group edge chains into string edges (the steps of the module docstring).

    Parameters
    ----------
    chains : sequence of EdgeChain
        Output of :func:`pipeline.edges.detect_edges` (``xy``, ``grad``;
        bright side on the right of the chain direction).
    shape : (height, width)
        Image shape.
    border_px : float
        Points closer than this to the image border are removed.

    Returns
    -------
    Grouping
    """
    ctx = _Context(int(shape[0]), int(shape[1]), float(border_px))
    pieces = [p for xy, gr in _trim(chains, ctx) for p in _split_chain(xy, gr, ctx)]
    if not pieces:
        return Grouping((), tuple(ctx.rejected), float("nan"), True)
    pair = _pair(pieces, ctx)
    if not pair.pieces:
        return Grouping((), tuple(ctx.rejected), pair.w0, pair.dark)
    keep, aside = _select(pair, ctx)
    if not keep:
        for i in aside:
            ctx.reject("unpaired edge", pair.pieces[i].xy)
        return Grouping((), tuple(ctx.rejected), pair.w0, pair.dark)
    local = _join_local([pair.pieces[i] for i in keep], ctx.diag)
    groups = _join_outside([[keep[i] for i in g] for g in local], aside, pair.pieces, ctx)
    cand = _candidates(groups, pair.pieces, set(aside), ctx)
    if not cand:
        return Grouping((), tuple(ctx.rejected), pair.w0, pair.dark)
    n_h = _orient(cand)
    strings = _strings(cand, pair, ctx)
    if not strings:
        return Grouping((), tuple(ctx.rejected), pair.w0, pair.dark)
    # number the strings across the harp, along n_h
    pos = [0.5 * (cand[a].centroid + cand[b].centroid) @ n_h for a, b in strings]
    edges = []
    for sid, k in enumerate(np.argsort(pos)):
        a, b = strings[k]
        ws = np.array([pair.pieces[i].width for i in cand[a].pieces + cand[b].pieces])
        width = float(np.nanmedian(ws)) if np.isfinite(ws).any() else float("nan")
        for e in sorted((cand[a], cand[b]), key=lambda c: c.polarity):
            edges.append(StringEdge(e.xy, tuple(e.ranges), e.polarity, sid, width))
    return Grouping(tuple(edges), tuple(ctx.rejected), pair.w0, pair.dark)
