r"""Ground truth for measured harp edges: the whole visible edge, exactly (test helper).

For each string edge of a rendered shot (the ideal line
``{p : n . p = offset}`` of :class:`pipeline.render.EdgeTruth`, or for a bent string
of the realistic simulator, :mod:`pipeline.realism`, that line bent by the edge's
shape, ``{p : n . p = offset + shape(t . p)}``) the truth is its exact image through
the lens, over *everything visible in the image*:

1. the distorted curve is ``{x : U(x) in the ideal curve}``, with ``U`` the
   lens map the renderer evaluated per pixel (``lens.undistort_points``, a
   closed-form map of :mod:`tests.pipeline.lenses` or any exact map). It is
   traced by solving ``U(x) = p`` with Newton's method for ideal points ``p``
   every ``DENSE_STEP`` px along the line (:meth:`~pipeline.render.EdgeTruth.ideal_points`) (continuation from the image
   centre outwards), to ``1e-10`` px;
2. it is kept where it lies inside the image minus ``MARGIN_PX`` (the border
   where the detector's smoothing kernel, radius ``ceil(4 sigma)`` = 4 px for
   sigma = 1, reaches outside the image and no gradient can be computed from
   image data alone), every run inside (a string that leaves the image and
   comes back has several) is one *piece* of the same edge, its ends placed on
   the margin exactly;
3. each piece is sampled as the paper does, at uniform arclength in the
   *distorted* image, on the grid the measurement uses: ``K = ceil(L / t) + 1``
   points evenly spaced over its whole arclength ``L`` (one point in ``t``,
   the grid spanning the whole piece), each point put back on the exact curve
   by a Newton step along the normal.

``d`` and ``d_max`` of the truth (Tang et al. 2012, eqs. 5-6) are computed here
from first principles: per edge the total-least-squares line through all its
grid points (eigenvector of the 2x2 scatter matrix), the signed distances to
it, their RMS over all points of all edges and the RMS over edges of their
peak-to-peak. Nothing of this passes through the code under test
(:mod:`pipeline.resample`, :mod:`pipeline.measure`, :mod:`pipeline.straightness`)
and nothing is clipped to what was measured.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from pipeline.render import EdgeTruth, TruthSource

MARGIN_PX = 4.0
"""Border of the image without an image-only gradient (detector kernel radius ceil(4 sigma), sigma = 1)."""
DENSE_STEP = 1.0
"""Spacing (ideal px) of the dense exact points of each curve."""
COARSE_STEP = 40.0
"""Continuation step (ideal px) when following an ideal line through the lens."""
_H = 1e-3  # central-difference step of the Jacobian (the root is exact whatever the Jacobian's error)


@dataclass(frozen=True)
class TrueEdge:
    """One string edge as seen in the image: its visible pieces, dense and on the grid."""

    edge: EdgeTruth
    dense: tuple[np.ndarray, ...]  # exact points every ~DENSE_STEP px, per visible piece
    grid: tuple[np.ndarray, ...]  # the measurement grid (one point in t) per visible piece

    @property
    def length(self) -> float:
        """Total arclength of the visible pieces, px."""
        return float(sum(np.sum(np.hypot(*np.diff(p, axis=0).T)) for p in self.dense))

    @property
    def points(self) -> np.ndarray:
        return np.concatenate(self.grid)


# ------------------------------------------------------------------ exact curves
def _solve(lens, target: np.ndarray, x0: np.ndarray, iters: int = 60) -> np.ndarray:
    """Solve ``U(x) = target`` by damped Newton from ``x0`` (NaN where it does not converge)."""
    x = x0.astype(np.float64).copy()
    todo = np.arange(len(x))
    for _ in range(iters):
        r = lens.undistort_points(x[todo]) - target[todo]
        ok = np.all(np.abs(r) < 1e-10, axis=1)
        todo, r = todo[~ok], r[~ok]
        if not len(todo):
            break
        xt = x[todo]
        jx = (lens.undistort_points(xt + [_H, 0]) - lens.undistort_points(xt - [_H, 0])) / (2 * _H)
        jy = (lens.undistort_points(xt + [0, _H]) - lens.undistort_points(xt - [0, _H])) / (2 * _H)
        a, b, c, d = jx[:, 0], jy[:, 0], jx[:, 1], jy[:, 1]
        det = a * d - b * c
        step = np.column_stack([(d * r[:, 0] - b * r[:, 1]) / det, (-c * r[:, 0] + a * r[:, 1]) / det])
        n = np.hypot(step[:, 0], step[:, 1])
        step *= np.minimum(1.0, 50.0 / np.maximum(n, 1e-300))[:, None]  # damped: at most 50 px
        x[todo] = xt - step
    bad = ~np.all(np.isfinite(x), axis=1)
    bad[todo] = True
    x[bad] = np.nan
    return x


def exact_curves(lens, edges: tuple[EdgeTruth, ...] | list[EdgeTruth], width: int, height: int, reach: float = 0.15):
    """Dense exact distorted points of each edge (every ``DENSE_STEP`` ideal px) near the image.

    Each ideal line is followed from its point closest to the ideal image of the
    image centre outwards in both directions (coarse steps of ``COARSE_STEP``
    ideal px, each Newton solve starting from the previous solution, all edges
    at once) until it leaves the image enlarged by ``reach`` of its size on every
    side; then every ``DENSE_STEP`` px is solved from interpolated starts. The
    points of each edge are ordered along ``(n_y, -n_x)``.
    """
    if not edges:
        return []
    nrm = np.array([e.normal for e in edges], np.float64)
    off = np.array([e.offset for e in edges], np.float64)
    u = np.column_stack([nrm[:, 1], -nrm[:, 0]])
    centre = np.array([(width - 1) / 2.0, (height - 1) / 2.0])
    cu = lens.undistort_points(centre[None])[0]
    tau0 = np.sum((cu[None] - off[:, None] * nrm) * u, axis=1)
    lo = np.array([-reach * width, -reach * height])
    hi = np.array([(1 + reach) * width, (1 + reach) * height])
    ne = len(edges)
    corners = np.array([[0.0, 0.0], [width - 1.0, 0.0], [0.0, height - 1.0], [width - 1.0, height - 1.0]])
    tau_lim = float(np.max(np.hypot(*(lens.undistort_points(corners) - cu).T))) + 4 * COARSE_STEP
    sides = []
    for sgn in (-1.0, 1.0):
        x = centre[None] + (off - nrm @ cu)[:, None] * nrm
        alive = np.ones(ne, bool)
        entered = np.zeros(ne, bool)
        taus: list[list[float]] = [[] for _ in range(ne)]
        pts: list[list[np.ndarray]] = [[] for _ in range(ne)]
        k = 0
        while alive.any():
            tau = tau0 + sgn * COARSE_STEP * k
            idx = np.flatnonzero(alive)
            p = off[idx, None] * nrm[idx] + tau[idx, None] * u[idx]
            for j, i in enumerate(idx):  # a bent edge: its displacement along the normal (EdgeTruth.shape)
                if edges[i].shape is not None:
                    p[j] += edges[i].displacement(tau[i : i + 1])[0] * nrm[i]
            xs = _solve(lens, p, x[idx])
            finite = np.all(np.isfinite(xs), axis=1)
            inbox = finite & np.all((xs >= lo) & (xs <= hi), axis=1)
            # keep going while in the box, or (outside it) until the line has been in the box and
            # left it again, or has run past the ideal image of the whole image
            go = inbox | (finite & ~entered[idx] & (COARSE_STEP * k <= tau_lim))
            for j, i in enumerate(idx):
                if go[j]:
                    taus[i].append(float(tau[i]))
                    pts[i].append(xs[j])
            entered[idx[inbox]] = True
            x[idx[go]] = xs[go]
            alive[idx[~go]] = False
            k += 1
        sides.append((taus, pts))
    out = []
    for i, e in enumerate(edges):
        t_all = np.array(sides[0][0][i][::-1] + sides[1][0][i][1:])
        p_all = np.array(sides[0][1][i][::-1] + sides[1][1][i][1:]).reshape(-1, 2)
        if len(t_all) < 2:
            out.append(np.zeros((0, 2)))
            continue
        # dense points only where the coarse ones come near the image (two coarse steps around)
        near = np.flatnonzero(
            np.all((p_all >= -2 * COARSE_STEP) & (p_all <= [width + 2 * COARSE_STEP, height + 2 * COARSE_STEP]), axis=1)
        )
        if len(near) == 0:
            out.append(np.zeros((0, 2)))
            continue
        t0, t1 = t_all[max(near[0] - 1, 0)], t_all[min(near[-1] + 1, len(t_all) - 1)]
        fine = np.arange(t0, t1 + 1e-9, DENSE_STEP)
        x0 = np.column_stack([np.interp(fine, t_all, p_all[:, 0]), np.interp(fine, t_all, p_all[:, 1])])
        dense = _solve(lens, e.ideal_points(fine), x0)
        out.append(dense[np.all(np.isfinite(dense), axis=1)])
    return out


def _inside(p: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    return np.all((p >= lo) & (p <= hi), axis=1)


def _crossing(a: np.ndarray, b: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Point where the segment from ``a`` (inside) to ``b`` (outside) crosses the margin box."""
    f = 1.0
    for k in range(2):
        for bound in (lo[k], hi[k]):
            den = b[k] - a[k]
            if den != 0:
                g = (bound - a[k]) / den
                if 0 <= g < f:
                    f = g
    return a + f * (b - a)


def visible_pieces(curve: np.ndarray, width: int, height: int, margin: float = MARGIN_PX) -> list[np.ndarray]:
    """The runs of ``curve`` inside the image minus ``margin``, ends placed on the margin."""
    lo = np.array([margin, margin])
    hi = np.array([width - 1 - margin, height - 1 - margin])
    ins = _inside(curve, lo, hi)
    d = np.diff(np.concatenate([[0], ins.astype(np.int8), [0]]))
    out = []
    for a, b in zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1)):
        run = curve[a:b]
        if a > 0:
            run = np.vstack([_crossing(curve[a], curve[a - 1], lo, hi), run])
        if b < len(curve):
            run = np.vstack([run, _crossing(curve[b - 1], curve[b], lo, hi)])
        if len(run) >= 2:
            out.append(run)
    return out


def _onto_curve(lens, edge: EdgeTruth, p: np.ndarray) -> np.ndarray:
    """Newton steps along the gradient of ``F(x) = edge.level(U(x))`` (``n . U(x) - offset`` for a
    straight edge, minus the edge's displacement for a bent one) put ``p`` on the exact curve."""
    x = p.copy()
    for _ in range(8):
        f = edge.level(lens.undistort_points(x))
        gx = (edge.level(lens.undistort_points(x + [_H, 0])) - edge.level(lens.undistort_points(x - [_H, 0]))) / (
            2 * _H
        )
        gy = (edge.level(lens.undistort_points(x + [0, _H])) - edge.level(lens.undistort_points(x - [0, _H]))) / (
            2 * _H
        )
        g2 = gx * gx + gy * gy
        x = x - (f / g2)[:, None] * np.column_stack([gx, gy])
        if np.max(np.abs(f)) < 1e-11:
            break
    return x


def grid_points(lens, edge: EdgeTruth, piece: np.ndarray, t: int) -> np.ndarray:
    """``ceil(L / t) + 1`` points at uniform arclength over the whole piece, on the exact curve."""
    s = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(piece, axis=0).T))])
    length = float(s[-1])
    k = max(2, int(np.ceil(length / t - 1e-9)) + 1) if length > 0 else 1
    sk = np.linspace(0.0, length, k)
    p = np.column_stack([np.interp(sk, s, piece[:, 0]), np.interp(sk, s, piece[:, 1])])
    q = _onto_curve(lens, edge, p)
    # the two ends stay on the margin (the Newton step moves them by < 1e-5 px along the border)
    return q


def whole_edges(r: TruthSource, t: int = 30, margin: float = MARGIN_PX, min_length_px: float = 1.0) -> list[TrueEdge]:
    """Every string edge of ``r`` visible in the image, whole (module docstring)."""
    out = []
    for e, curve in zip(r.edges, exact_curves(r.lens, r.edges, r.width, r.height)):
        if len(curve) < 2:
            continue
        pieces = visible_pieces(curve, r.width, r.height, margin)
        pieces = [p for p in pieces if np.sum(np.hypot(*np.diff(p, axis=0).T)) > 0.0]
        if not pieces:
            continue
        te = TrueEdge(e, tuple(pieces), tuple(grid_points(r.lens, e, p, t) for p in pieces))
        if te.length >= min_length_px:
            out.append(te)
    return out


# ------------------------------------------------------------------ straightness from first principles
@dataclass(frozen=True)
class TrueStraightness:
    d: float
    d_max: float
    rms: tuple[float, ...]
    p2p: tuple[float, ...]


def signed_distances(points: np.ndarray) -> np.ndarray:
    """Signed distances of ``points`` to their total-least-squares line."""
    c = points.mean(axis=0)
    q = points - c
    _, v = np.linalg.eigh(q.T @ q)
    return q @ v[:, 0]  # the normal: eigenvector of the smallest eigenvalue


def straightness_of(point_sets: list[np.ndarray]) -> TrueStraightness:
    """``d`` (RMS over all points) and ``d_max`` (RMS over edges of the peak-to-peak)."""
    s = [signed_distances(p) for p in point_sets]
    n = sum(len(x) for x in s)
    p2p = tuple(float(x.max() - x.min()) for x in s)
    return TrueStraightness(
        d=float(np.sqrt(sum(float(np.sum(x * x)) for x in s) / n)),
        d_max=float(np.sqrt(np.mean(np.square(p2p)))),
        rms=tuple(float(np.sqrt(np.mean(x * x))) for x in s),
        p2p=p2p,
    )


# ------------------------------------------------------------------ matching
@dataclass(frozen=True)
class Match:
    """A measured line and its true edge."""

    line: int  # index in m.lines
    truth: int  # index in the list of true edges
    distance: float  # median distance of (up to 200 of) the raw points to the true curve, px
    coverage: float  # fraction of the true edge's arclength between the ends of the measured pieces


def _arclength_positions(truth: TrueEdge, pts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(piece index, arclength along it) of the true point nearest to each of ``pts``."""
    dense = np.concatenate(truth.dense)
    piece = np.repeat(np.arange(len(truth.dense)), [len(p) for p in truth.dense])
    s = np.concatenate([np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(p, axis=0).T))]) for p in truth.dense])
    _, i = cKDTree(dense).query(pts)
    return piece[i], s[i]


def coverage(truth: TrueEdge, line) -> float:
    """Fraction of the true arclength lying between the first and last smoothed point of a measured piece."""
    ranges = line.point_pieces if len(line.point_pieces) else np.array([[0, len(line.points)]])
    covered = 0.0
    spans: dict[int, list[tuple[float, float]]] = {}
    for a, b in ranges:
        pc, s = _arclength_positions(truth, line.points[[a, b - 1]])
        if pc[0] == pc[1]:
            spans.setdefault(int(pc[0]), []).append((min(s), max(s)))
    for k, iv in spans.items():
        iv.sort()
        lo, hi = iv[0]
        for a, b in iv[1:]:
            if a > hi:
                covered += hi - lo
                lo, hi = a, b
            else:
                hi = max(hi, b)
        covered += hi - lo
        del k
    return covered / truth.length


def curve_distance(truth: TrueEdge, pts: np.ndarray) -> np.ndarray:
    """Distance of each of ``pts`` to the true curve (to its nearest segment of the dense polyline)."""
    best = np.full(len(pts), np.inf)
    for piece in truth.dense:
        _, i = cKDTree(piece).query(pts)
        for j0 in (np.maximum(i - 1, 0), i):
            j1 = np.minimum(j0 + 1, len(piece) - 1)
            a, b = piece[j0], piece[j1]
            ab = b - a
            den = np.maximum(np.sum(ab * ab, axis=1), 1e-300)
            f = np.clip(np.sum((pts - a) * ab, axis=1) / den, 0.0, 1.0)
            best = np.minimum(best, np.hypot(*(a + f[:, None] * ab - pts).T))
    return best


def match_lines(truths: list[TrueEdge], m, max_dist: float = 1.5) -> list[Match]:
    """Match every measured line to the true edge its raw points lie on (asserts that one exists)."""
    dense = np.concatenate([np.concatenate(te.dense) for te in truths])
    label = np.repeat(np.arange(len(truths)), [sum(len(p) for p in te.dense) for te in truths])
    tree = cKDTree(dense)
    out = []
    for i, ln in enumerate(m.lines):
        q = ln.raw_points[:: max(1, len(ln.raw_points) // 200)]
        _, idx = tree.query(q)
        k = int(np.bincount(label[idx]).argmax())
        med = float(np.median(curve_distance(truths[k], q)))
        assert med < max_dist, f"measured line {i} lies on no true edge ({med:.2f} px off)"
        out.append(Match(i, k, med, coverage(truths[k], ln)))
    return out


@dataclass(frozen=True)
class Comparison:
    """A measurement against the whole-edge truth."""

    truths: list[TrueEdge]
    matches: list[Match]
    true: TrueStraightness  # over the true edges matched, each whole
    missing: list[TrueEdge]  # true edges >= min_found_px not found
    duplicated: list[int]  # true edges found more than once


def compare(r: TruthSource, m, min_found_fraction: float = 0.1, max_dist: float = 1.5) -> Comparison:
    """Match ``m`` to the whole-edge truth of ``r``; truth figures over the matched edges."""
    truths = whole_edges(r, t=m.t)
    matches = match_lines(truths, m, max_dist)
    found: dict[int, int] = {}
    for mt in matches:
        found[mt.truth] = found.get(mt.truth, 0) + 1
    min_len = min_found_fraction * min(r.width, r.height)
    missing = [te for k, te in enumerate(truths) if te.length >= min_len and k not in found]
    dup = [k for k, c in found.items() if c > 1]
    true = straightness_of([truths[mt.truth].points for mt in matches])
    return Comparison(truths, matches, true, missing, dup)
