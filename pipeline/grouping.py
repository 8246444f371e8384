r"""Group sub-pixel edge chains into one point set per physical string edge.

Input: the chains of :func:`pipeline.edges.detect_edges` (ordered sub-pixel
points with their gradients; along a chain the bright side is on the walker's
right). Output: per string edge its ordered points, its polarity and the
string it belongs to, plus every rejected group with the reason.

A harp string, dark on a bright back-lit sheet (or the reverse), gives two
long, almost straight edges of opposite gradient, a string width :math:`w`
apart. Everything else the edge detector returns (the harp frame, dust, the
zig-zag spring of the frame, noise) fails at least one of the tests below.

Algorithm
---------
1. **Border.** Points closer than ``border_px`` to the image border are
   removed (there the smoothing reads mirrored data); chains are cut there.
2. **Curvature split.** Along each chain the gradient angle is unwrapped and
   smoothed (Gaussian, ``ANGLE_SMOOTH_PTS`` points). A chain is cut where it
   turns faster than ``MAX_TURN_DEG_PER_PX`` (radius of curvature below
   ~29 px: a corner or a dust spot, never the image of a straight string
   even under tens of pixels of distortion, whose radius of curvature is
   thousands of pixels). A piece whose smoothed gradient angle spans more
   than ``MAX_PIECE_TURN_DEG`` is *curved* (a dust spot, a spring).
   Pieces shorter than ``MIN_PIECE_PX`` are *short fragments*.
3. **Pairing and string width.** From points of every remaining piece,
   march across the edge (towards the dark side for dark strings) and
   record the first point of another piece whose gradient is opposite
   (cosine < -0.7) and of similar magnitude (ratio within
   ``MAX_CONTRAST_RATIO``: both edges of a string separate it from the same
   background, whereas the border of the frame and a string lying against
   it do not): its distance across is the local string width, its piece
   the partner. A coarse pass (``PAIR_COARSE_SAMPLES`` points per piece,
   both directions, up to ``MAX_STRING_WIDTH_PX * PAIR_SEARCH_FACTOR`` px)
   decides whether strings are dark or bright (the direction that finds
   more partners) and gives the string width :math:`w_0`, the
   length-weighted median of the pieces' median widths. A fine pass
   (``PAIR_FINE_SAMPLES`` points per piece, up to
   ``WIDTH_RATIO * w_0 + 2`` px) gives each piece its paired fraction,
   width and partner votes. A piece is *unpaired* (the edge of the thick
   harp frame, of a shadow, of anything that is not a thin string) when
   fewer than ``MIN_PAIRED_FRACTION`` of its samples found a partner, and
   of *wrong width* when its median width is outside
   ``[w_0 / WIDTH_RATIO, w_0 * WIDTH_RATIO]``.
   Then every point of every piece looks outwards (away from its string)
   up to ``max(CROWD_FACTOR * w_0, CROWD_MIN_PX)`` px: a stretch (majority
   over ``CROWD_WINDOW_PTS`` points) where another edge of at least
   ``CROWD_MIN_CONTRAST`` times its contrast lies that close is *crowded*
   (a string running along the frame or a shadow: the blur of the
   neighbouring edge would bias it) and is cut out.
4. **Joining.** Pieces of the same edge (cut by dust on the string, low
   contrast, a curvature split) are joined end to start, keeping the chain
   orientation (so the same gradient sign): the start of the next piece
   must lie ahead of the end of the previous one, within
   ``MAX_GAP_FRACTION`` of the image diagonal, the two end tangents within
   ``MAX_JOIN_ANGLE_DEG``, and each piece's end line must pass within
   ``JOIN_LATERAL_PX + JOIN_LATERAL_SLOPE * gap`` of the other's end (a
   cone that allows the curvature of a distorted string, but is far
   narrower than the string spacing). Candidates are accepted greedily by
   increasing cost; each piece has at most one successor and predecessor.
5. **Edges and strings.** A joined edge shorter than ``MIN_EDGE_FRACTION``
   of the smaller image side is *short*; one whose median gradient is below
   ``MIN_RELATIVE_CONTRAST`` times the strings' (length-weighted median) is
   of *low contrast* (a string seen over the dark frame). The remaining
   edges are paired into strings: edge ``A``'s partner is the edge that
   holds most of the partner hits of ``A``'s points; two edges form a
   string when they are each other's partner and have opposite polarity.
   An edge without a partner is *unpaired*. Strings are numbered across the
   harp, in order of position along the harp normal ``n_h``.

All thresholds are either geometric invariants of a harp image (turning
rate, angle, fractions of the image size) or relative to the measured
string width; none depends on the contrast or on particular test images.
Supported: string widths of 2 to ``MAX_STRING_WIDTH_PX`` px, any
orientation, any number of strings whose spacing exceeds a few string widths.

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
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy.ndimage import gaussian_filter1d, uniform_filter1d

ANGLE_SMOOTH_PTS = 3.0
"""Sigma (points, ~px) of the smoothing of the gradient angle along a chain."""
MAX_TURN_DEG_PER_PX = 2.0
"""A chain is cut where its smoothed gradient turns faster than this."""
TURN_BASE_PTS = 6
"""Half-base (points) over which the turning rate is measured."""
MAX_PIECE_TURN_DEG = 30.0
"""A piece whose gradient angle spans more than this is curved, not a string."""
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
"""Largest angle between the end tangents of two joined pieces."""
JOIN_LATERAL_PX = 1.5
JOIN_LATERAL_SLOPE = 0.05
"""Lateral tolerance of a join: JOIN_LATERAL_PX + JOIN_LATERAL_SLOPE * gap."""
END_FIT_PX = 60
"""Number of end points (~px) used for the end tangent of a piece."""
MIN_EDGE_FRACTION = 0.1
"""Shortest accepted edge, as a fraction of the smaller image side."""
MIN_RELATIVE_CONTRAST = 0.2
"""Edges whose median gradient is below this fraction of the strings' median are rejected."""
REJECT_REASONS = {
    "short fragment": f"fewer than MIN_PIECE_PX = {MIN_PIECE_PX:g} points (noise, dust, specks)",
    "curved": "turns more than a straight string can (dust spot, frame corner, spring)",
    "unpaired edge": "no opposite edge a string width away (harp frame, shadow, lone edge)",
    "crowded": "another edge right outside the string (a string along the frame or a shadow)",
    "wrong width": "paired at a width far from the strings' (frame, thick object)",
    "short edge": "joined edge shorter than MIN_EDGE_FRACTION of the smaller image side",
    "low contrast": "edge contrast below MIN_RELATIVE_CONTRAST of the strings' (string over the dark frame)",
}
"""Reasons for rejecting edge points, with their meaning."""
PAIR_COARSE_SAMPLES = 12
"""Points per piece sampled to decide dark/bright strings and measure w0."""
PAIR_FINE_SAMPLES = 64
"""Points per piece sampled for the paired fraction, width and partner votes."""


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

    xy: np.ndarray
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
    xy: np.ndarray
    detail: str = ""
    grad: np.ndarray | None = field(default=None, repr=False)

    @property
    def n_points(self) -> int:
        return int(len(self.xy))

    @property
    def bbox(self) -> tuple[float, float, float, float]:
        """``(x_min, y_min, x_max, y_max)``."""
        return (
            float(self.xy[:, 0].min()),
            float(self.xy[:, 1].min()),
            float(self.xy[:, 0].max()),
            float(self.xy[:, 1].max()),
        )


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
# step 1-2: border trim and curvature split
# --------------------------------------------------------------------------- #
def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """Index ranges [a, b) where ``mask`` is True."""
    if mask.size == 0:
        return []
    d = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    return list(zip(np.nonzero(d == 1)[0].tolist(), np.nonzero(d == -1)[0].tolist()))


def _split_chain(xy, grad, rejected):
    """Cut one (border-trimmed) chain at sharp turns; returns accepted pieces."""
    n = len(xy)
    if n < MIN_PIECE_PX:
        rejected.append(RejectedGroup("short fragment", xy, grad=grad))
        return []
    ang = np.unwrap(np.arctan2(grad[:, 1], grad[:, 0]))
    angs = gaussian_filter1d(ang, ANGLE_SMOOTH_PTS, mode="nearest")
    k = min(TURN_BASE_PTS, max(1, (n - 1) // 2))
    rate = np.zeros(n)
    # turning over a base of 2k points, normalised by the arclength
    seg = np.hypot(*np.diff(xy, axis=0).T)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    ds = s[2 * k :] - s[: -2 * k]
    rate[k : n - k] = np.degrees(np.abs(angs[2 * k :] - angs[: -2 * k])) / np.maximum(ds, 1e-9)
    straight = rate <= MAX_TURN_DEG_PER_PX
    out = []
    for a, b in _runs(straight):
        pxy, pgr = xy[a:b], grad[a:b]
        if b - a < MIN_PIECE_PX:
            rejected.append(RejectedGroup("short fragment", pxy, grad=pgr))
            continue
        span = np.degrees(angs[a:b].max() - angs[a:b].min())
        if span > MAX_PIECE_TURN_DEG:
            rejected.append(RejectedGroup("curved", pxy, grad=pgr))
            continue
        out.append((pxy, pgr))
    # turning points themselves (not part of any run) are dropped silently
    bad = ~straight
    for a, b in _runs(bad):
        if b - a >= MIN_PIECE_PX:
            rejected.append(RejectedGroup("curved", xy[a:b], grad=grad[a:b]))
    return out


# --------------------------------------------------------------------------- #
# step 3: pairing across the string
# --------------------------------------------------------------------------- #
class _Pairing:
    """Label map of all piece points and marching across edges."""

    def __init__(self, pieces, shape, extra=None):
        """``extra``: ``(xy, grad)`` of other edge points (rejected pieces):
        they occupy the map for :meth:`crowded` but are never partners."""
        h, w = shape
        self.shape = shape
        self.lens = np.array([len(p[0]) for p in pieces])
        self.starts = np.concatenate([[0], np.cumsum(self.lens)[:-1]])
        self.n = int(self.lens.sum())
        xs = [p[0] for p in pieces]
        gs = [p[1] for p in pieces]
        pid = [np.repeat(np.arange(len(pieces), dtype=np.int32), self.lens)]
        if extra is not None and len(extra[0]):
            xs.append(extra[0])
            gs.append(extra[1])
            pid.append(np.full(len(extra[0]), -1, np.int32))
        self.xy = np.concatenate(xs)
        g = np.concatenate(gs)
        self.gmag = np.hypot(g[:, 0], g[:, 1])
        self.ghat = g / np.maximum(self.gmag, 1e-12)[:, None]
        self.pid = np.concatenate(pid)
        lab = np.full((h, w), -1, np.int32)
        ij = np.rint(self.xy).astype(np.int32)
        inside = (ij[:, 0] >= 0) & (ij[:, 0] < w) & (ij[:, 1] >= 0) & (ij[:, 1] < h)
        src = np.nonzero(inside)[0].astype(np.int32)
        ij = ij[inside]
        # piece points win over extra points: write the extras first
        order = np.argsort(self.pid[src] >= 0, kind="stable")
        src, ij = src[order], ij[order]
        lab[ij[:, 1], ij[:, 0]] = src
        # also fill the free 4-neighbours (pieces first), so that a ray cannot
        # slip between two diagonal pixels of an 8-connected edge
        for sel in (self.pid[src] >= 0, self.pid[src] < 0):
            for dx, dy in ((1, 0), (-1, 0), (0, 1), (0, -1)):
                x2, y2 = ij[sel, 0] + dx, ij[sel, 1] + dy
                ok = (x2 >= 0) & (x2 < w) & (y2 >= 0) & (y2 < h)
                x2, y2, s2 = x2[ok], y2[ok], src[sel][ok]
                free = lab[y2, x2] < 0
                lab[y2[free], x2[free]] = s2[free]
        self.lab = lab

    def sample(self, per_piece: int) -> np.ndarray:
        """Indices of up to ``per_piece`` evenly spread points of every piece."""
        k = np.minimum(self.lens, per_piece)
        rep = np.repeat(np.arange(len(self.lens)), k)
        pos = np.arange(int(k.sum())) - np.repeat(np.cumsum(k) - k, k)
        off = ((pos + 0.5) * self.lens[rep] / k[rep]).astype(np.int64)
        return self.starts[rep] + off

    def march(self, sample: np.ndarray, sign: float, max_dist: float):
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
        hit[ok] = self.lab[yi[ok], xi[ok]]
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
        return np.where(found, self.pid[j], -1), np.where(found, width, np.nan)

    def crowded(self, sign: float, reach: float) -> np.ndarray:
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
        for k in steps:  # a few steps; vectorised over all points
            xi = np.rint(p0[:, 0] + g0[:, 0] * k).astype(np.int32)
            yi = np.rint(p0[:, 1] + g0[:, 1] * k).astype(np.int32)
            ok = np.nonzero((xi >= 0) & (xi < w) & (yi >= 0) & (yi < h) & ~out)[0]
            hit = self.lab[yi[ok], xi[ok]]
            j = np.maximum(hit, 0)
            out[ok] |= (hit >= 0) & (self.pid[j] != own[ok]) & (self.gmag[j] >= gmin[ok])
        return np.repeat(out, CROWD_STRIDE)[: self.n]


def _per_piece(spid, spart, swidth, npcs):
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
    return frac, med_w


# --------------------------------------------------------------------------- #
# step 4: joining pieces along an edge
# --------------------------------------------------------------------------- #
def _end_tangent(xy, at_end):
    m = min(len(xy), END_FIT_PX)
    q = xy[-m:] if at_end else xy[:m]
    c = q.mean(axis=0)
    _, v = np.linalg.eigh((q - c).T @ (q - c))
    t = v[:, 1]
    travel = q[-1] - q[0]
    if t @ travel < 0:
        t = -t
    return c, t


def _join(pieces, diag):
    """Greedy end-to-start joining; returns a list of index lists (ordered)."""
    n = len(pieces)
    ends = [_end_tangent(p[0], True) for p in pieces]
    starts = [_end_tangent(p[0], False) for p in pieces]
    e_pt = np.array([p[0][-1] for p in pieces])
    s_pt = np.array([p[0][0] for p in pieces])
    gmax = MAX_GAP_FRACTION * diag
    cos_max = np.cos(np.radians(MAX_JOIN_ANGLE_DEG))
    cb = np.array([c for c, _ in starts])
    tb = np.array([t for _, t in starts])
    cand = []
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
    cand.sort()
    nxt = np.full(n, -1)
    prv = np.full(n, -1)
    root = np.arange(n)

    def find(i):
        while root[i] != i:
            root[i] = root[root[i]]
            i = root[i]
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


# --------------------------------------------------------------------------- #
# public entry point
# --------------------------------------------------------------------------- #
def group_string_edges(chains: Sequence, shape: tuple[int, int], border_px: float = 4.0) -> Grouping:
    """Group edge chains into string edges (see the module docstring).

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
    h, w = int(shape[0]), int(shape[1])
    diag = float(np.hypot(w, h))
    rejected: list[RejectedGroup] = []
    pieces = []
    for ch in chains:
        xy = np.asarray(ch.xy, np.float64)
        gr = np.asarray(ch.grad, np.float64)
        inner = (
            (xy[:, 0] >= border_px)
            & (xy[:, 0] <= w - 1 - border_px)
            & (xy[:, 1] >= border_px)
            & (xy[:, 1] <= h - 1 - border_px)
        )
        for a, b in _runs(inner):
            pieces.extend(_split_chain(xy[a:b], gr[a:b], rejected))
    if not pieces:
        return Grouping((), tuple(rejected), float("nan"), True)

    # --- pairing: dark or bright strings, their width w0 (coarse pass on a
    # few points per piece, both directions, full search range) ...
    npcs = len(pieces)
    extra = None
    with_grad = [x for x in rejected if x.grad is not None]
    if with_grad:
        extra = (np.concatenate([x.xy for x in with_grad]), np.concatenate([x.grad for x in with_grad]))
    pr = _Pairing(pieces, (h, w), extra)
    lens = pr.lens.astype(float)
    coarse = pr.sample(PAIR_COARSE_SAMPLES)
    cpid = pr.pid[coarse]
    search = MAX_STRING_WIDTH_PX * PAIR_SEARCH_FACTOR
    part_d, wid_d = pr.march(coarse, -1.0, search)  # dark strings: towards the dark side
    part_b, wid_b = pr.march(coarse, +1.0, search)  # bright strings
    dark = int((part_d >= 0).sum()) >= int((part_b >= 0).sum())
    sign = -1.0 if dark else 1.0
    frac, med_w = _per_piece(cpid, part_d if dark else part_b, wid_d if dark else wid_b, npcs)
    paired = frac >= MIN_PAIRED_FRACTION
    if not paired.any():
        for p in pieces:
            rejected.append(RejectedGroup("unpaired edge", p[0]))
        return Grouping((), tuple(rejected), float("nan"), dark)
    ws, ls = med_w[paired], lens[paired]
    o = np.argsort(ws)
    cum = np.cumsum(ls[o])
    w0 = float(ws[o][np.searchsorted(cum, 0.5 * cum[-1])])  # length-weighted median
    # ... edges crowded on their outer side (a string running along the frame
    # or a shadow) are biased by the neighbouring edge: cut those stretches out
    crowd = pr.crowded(sign, max(CROWD_FACTOR * w0, CROWD_MIN_PX))
    if crowd.any():
        # split the pieces; the label map stays, only the piece ids change
        new_pieces, new_starts = [], []
        new_pid = np.full(len(pr.pid), -1, np.int32)
        for i, p in enumerate(pieces):
            s0 = int(pr.starts[i])
            c = crowd[s0 : s0 + pr.lens[i]]
            if c.any():
                c = uniform_filter1d(c.astype(np.float32), CROWD_WINDOW_PTS, mode="nearest") > 0.5
                for a, b in _runs(c):
                    rejected.append(RejectedGroup("crowded", p[0][a:b], "another edge just outside the string"))
                runs = _runs(~c)
            else:
                runs = [(0, len(p[0]))]
            for a, b in runs:
                if b - a >= MIN_PIECE_PX:
                    new_pid[s0 + a : s0 + b] = len(new_pieces)
                    new_starts.append(s0 + a)
                    new_pieces.append((p[0][a:b], p[1][a:b]))
                else:
                    rejected.append(RejectedGroup("short fragment", p[0][a:b]))
        pieces = new_pieces
        if not pieces:
            return Grouping((), tuple(rejected), w0, dark)
        npcs = len(pieces)
        pr.pid = new_pid
        pr.starts = np.array(new_starts)
        pr.lens = np.array([len(p[0]) for p in pieces])
        lens = pr.lens.astype(float)
    # ... then the fine pass: more points, search only up to the widest accepted width
    fine = pr.sample(PAIR_FINE_SAMPLES)
    spid = pr.pid[fine]
    spart, swidth = pr.march(fine, sign, w0 * WIDTH_RATIO + 2.0)
    frac, med_w = _per_piece(spid, spart, swidth, npcs)
    found = spart >= 0

    keep = []
    for i, p in enumerate(pieces):
        if frac[i] < MIN_PAIRED_FRACTION:
            rejected.append(RejectedGroup("unpaired edge", p[0]))
        elif not (w0 / WIDTH_RATIO <= med_w[i] <= w0 * WIDTH_RATIO):
            rejected.append(RejectedGroup("wrong width", p[0], f"{med_w[i]:.1f} px wide, strings are {w0:.1f} px"))
        else:
            keep.append(i)
    kept = [pieces[i] for i in keep]
    if not kept:
        return Grouping((), tuple(rejected), w0, dark)
    groups = _join(kept, diag)

    # --- edges: length, harp direction, orientation, polarity
    min_len = MIN_EDGE_FRACTION * min(w, h)
    cand = []
    for g in groups:
        idx = [keep[i] for i in g]
        xy = np.concatenate([pieces[i][0] for i in idx])
        gr = np.concatenate([pieces[i][1] for i in idx])
        c = xy.mean(axis=0)
        _, v = np.linalg.eigh((xy - c).T @ (xy - c))
        u = v[:, 1]
        ext = (xy - c) @ u
        length = float(ext.max() - ext.min())
        if length < min_len:
            rejected.append(RejectedGroup("short edge", xy, f"shorter than {min_len:.0f} px"))
            continue
        bnd = np.concatenate([[0], np.cumsum([len(pieces[i][0]) for i in idx])])
        pcs = [(int(bnd[k]), int(bnd[k + 1])) for k in range(len(idx))]
        cand.append(dict(xy=xy, gr=gr, pcs=pcs, u=u, c=c, pieces=idx, length=length))
    # contrast: a string seen against the dark frame, or in deep shadow, is
    # not measured (its edges are displaced by the surrounding shading)
    if cand:
        gm = np.array([float(np.median(np.hypot(e["gr"][:, 0], e["gr"][:, 1]))) for e in cand])
        ln = np.array([e["length"] for e in cand])
        o = np.argsort(gm)
        ref = gm[o][np.searchsorted(np.cumsum(ln[o]), 0.5 * ln.sum())]
        low = gm < MIN_RELATIVE_CONTRAST * ref
        for e, lo, g_ in zip(cand, low, gm):
            if lo:
                rejected.append(RejectedGroup("low contrast", e["xy"], f"gradient {g_:.3g}, strings {ref:.3g}"))
        cand = [e for e, lo in zip(cand, low) if not lo]
    if not cand:
        return Grouping((), tuple(rejected), w0, dark)
    # mean direction of the harp (doubled angles, length-weighted), in [0, 180)
    ang2 = np.array([2 * np.arctan2(e["u"][1], e["u"][0]) for e in cand])
    wt = np.array([e["length"] for e in cand])
    a_h = 0.5 * np.arctan2(np.sum(wt * np.sin(ang2)), np.sum(wt * np.cos(ang2))) % np.pi
    u_h = np.array([np.cos(a_h), np.sin(a_h)])
    n_h = np.array([-u_h[1], u_h[0]])
    piece_edge = np.full(npcs, -1)
    for k, e in enumerate(cand):
        if (e["xy"][-1] - e["xy"][0]) @ u_h < 0:
            N = len(e["xy"])
            e["xy"], e["gr"] = e["xy"][::-1].copy(), e["gr"][::-1].copy()
            e["pcs"] = [(N - b, N - a) for a, b in reversed(e["pcs"])]
        e["pol"] = 1 if float(np.median(e["gr"] @ n_h)) > 0 else -1
        for i in e["pieces"]:
            piece_edge[i] = k

    # --- strings: mutual partners of opposite polarity
    ne = len(cand)
    votes = np.zeros((ne, ne))
    fmask = found & (piece_edge[spid] >= 0)
    pe = piece_edge[spid[fmask]]
    qe = piece_edge[spart[fmask]]
    okq = qe >= 0
    np.add.at(votes, (pe[okq], qe[okq]), 1.0)
    best = np.where(votes.max(axis=1) > 0, votes.argmax(axis=1), -1)
    strings = []
    used = set()
    for a in range(ne):
        b = best[a]
        if b > a and best[b] == a and cand[a]["pol"] != cand[b]["pol"]:
            strings.append((a, b))
            used.update((a, b))
    for a in range(ne):
        if a not in used:
            rejected.append(RejectedGroup("unpaired edge", cand[a]["xy"]))
    if not strings:
        return Grouping((), tuple(rejected), w0, dark)

    # --- number the strings across the harp, along n_h
    pos = [0.5 * (cand[a]["c"] + cand[b]["c"]) @ n_h for a, b in strings]
    edges = []
    for sid, k in enumerate(np.argsort(pos)):
        a, b = strings[k]
        ws = med_w[cand[a]["pieces"] + cand[b]["pieces"]]
        width = float(np.nanmedian(ws)) if np.isfinite(ws).any() else float("nan")
        for e in sorted((a, b), key=lambda i: cand[i]["pol"]):
            edges.append(
                StringEdge(
                    xy=cand[e]["xy"],
                    pieces=tuple(cand[e]["pcs"]),
                    polarity=cand[e]["pol"],
                    string_id=sid,
                    width_px=width,
                )
            )
    return Grouping(tuple(edges), tuple(rejected), w0, dark)
