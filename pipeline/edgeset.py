r"""The edge set of a fit: every string edge of every shot, its regression lines, its figures.

A fit (:mod:`pipeline.fit`), Alvarez's method (:mod:`pipeline.alvarez`) and the
cross-validation (:mod:`pipeline.select`) all work on the same thing: the point sets
of many edges, each with its total-least-squares (TLS) line. This module holds it:

* :func:`collect` checks and flattens ``lines_per_image`` into one :class:`EdgeSet`
  (all points contiguous, with each edge's start, count, image and line index),
  setting aside edges that cannot be measured (too few points, non-finite
  coordinates, no direction) as :class:`RejectedEdge`\ s with their reason;
* :func:`tls` gives each edge's TLS line (centroid :math:`m_e`, direction
  :math:`\phi_e`) and the signed distance :math:`r_i = n_e \cdot (p_i - m_e)` of
  every point to its own line — the residual of the fit, and the ``S`` of
  Tang et al. 2012;
* :func:`summarise` turns a model and an edge set into a :class:`FitResult`: the
  straightness before and after the correction, per edge, per image and pooled,
  with ``d = sqrt(sum r^2 / N)`` and ``d_max = sqrt(mean over edges of (max r - min r)^2)``;
* :func:`straightness_of` / :func:`corrected_straightness` are the same figures for
  edges given as a list (a holdout measure).

A fit that cannot give a trustworthy model is a :class:`FitFailure`, a value with a
reason; it is *falsy*, so ``if not result:`` is the one test of failure.

References
----------
.. [1] Z. Tang, R. Grompone von Gioi, P. Monasse, J.-M. Morel, "High-precision camera
   distortion measurements with a calibration harp", JOSA A 29(10), 2012.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from pipeline.models.base import DistortionModel
from pipeline.straightness import straightness

MIN_POINTS_PER_EDGE = 5
"""An edge with fewer points is not used (it hardly constrains its line)."""


# ----------------------------------------------------------------- results
@dataclass(frozen=True)
class EdgeFit:
    """Straightness of one edge before and after the correction (pixels)."""

    image: int
    line: int
    n_points: int
    rms_before: float
    p2p_before: float
    rms_after: float
    p2p_after: float
    rejected: bool


@dataclass(frozen=True)
class ImageFit:
    """Straightness of one image's (kept) edges before and after (pixels)."""

    image: int
    n_edges: int
    d_before: float
    d_max_before: float
    d_after: float
    d_max_after: float


@dataclass(frozen=True)
class RejectedEdge:
    """An edge left out of the fit, and why."""

    image: int
    line: int
    reason: str


@dataclass(frozen=True)
class FitResult:
    """A fitted correction with its figures of merit.

    ``d``/``d_max`` follow Tang et al. 2012: ``d`` is the RMS signed distance
    of all points to their edge's regression line; ``d_max`` is
    ``sqrt(mean over edges of (max - min signed distance)^2)``; both over the
    kept (non-rejected) edges. ``before`` is the uncorrected input. ``point_weights`` (N,), when the fit
    weighed its points robustly (``fit_distortion(point_loss=...)``): each kept point's weight in the
    final fit, the kept edges' points in order (the joint fit with the strings,
    :func:`pipeline.harp_shape.fit_harp_shape`, weighs them the same); None otherwise.
    """

    model: DistortionModel
    d_before: float
    d_max_before: float
    d_after: float
    d_max_after: float
    images: tuple[ImageFit, ...]
    edges: tuple[EdgeFit, ...]
    rejected: tuple[RejectedEdge, ...]
    n_iter: int
    cost: float
    message: str
    n_points: int
    n_params: int
    warnings: tuple[str, ...] = ()
    point_weights: np.ndarray | None = field(default=None, compare=False, repr=False)

    def __bool__(self) -> Literal[True]:  # a result is true, a FitFailure false: ``if not fit:``
        return True


@dataclass(frozen=True)
class FitFailure:
    """The fit could not produce a trustworthy model; ``reason`` says why. Falsy."""

    reason: str

    def __bool__(self) -> Literal[False]:
        return False


# ------------------------------------------------------------- the edge set
@dataclass(frozen=True)
class EdgeSet:
    """All points of many edges, edges contiguous.

    ``xy`` (N, 2) the points; per edge (E,): ``starts`` (index of its first point),
    ``counts`` (its number of points), ``image`` (index of its shot) and ``line``
    (its index within the shot, as given). ``weights`` (N,), optional: each point's
    weight in the fit's least squares (inverse variance, :func:`point_weights`); None,
    every point weighs 1 (the paper's fit).
    """

    xy: np.ndarray
    starts: np.ndarray
    counts: np.ndarray
    image: np.ndarray
    line: np.ndarray
    weights: np.ndarray | None = None

    def __bool__(self) -> Literal[True]:  # an edge set is true, a FitFailure false (:func:`collect`)
        return True

    @classmethod
    def of(
        cls,
        pieces: Sequence[np.ndarray],
        image: Sequence[int],
        line: Sequence[int],
        weights: Sequence[np.ndarray] | None = None,
    ) -> EdgeSet:
        """The edge set of the point sets ``pieces`` (each (M, 2)) with their image and line indices
        (and, optionally, each point's weight, one (M,) array per piece)."""
        counts = np.array([len(p) for p in pieces], dtype=int)
        return cls(
            np.concatenate(pieces),
            np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(int),
            counts,
            np.asarray(image, dtype=int),
            np.asarray(line, dtype=int),
            None if weights is None else np.concatenate([np.asarray(w, dtype=np.float64) for w in weights]),
        )

    @property
    def n_edges(self) -> int:
        return len(self.counts)

    def lines(self) -> list[np.ndarray]:
        """The edges as a list of (M, 2) arrays (views of ``xy``)."""
        return [self.xy[s : s + c] for s, c in zip(self.starts, self.counts, strict=True)]

    def subset(self, keep: np.ndarray) -> EdgeSet:
        """The edges where ``keep`` (E,) is true."""
        keep = np.asarray(keep, bool)
        pieces = [self.xy[s : s + c] for s, c, k in zip(self.starts, self.counts, keep, strict=True) if k]
        w = self.weights
        kept_w = (
            None if w is None else [w[s : s + c] for s, c, k in zip(self.starts, self.counts, keep, strict=True) if k]
        )
        return EdgeSet.of(pieces, self.image[keep], self.line[keep], kept_w)

    def point_weights(self, edge_weights: np.ndarray | None = None) -> np.ndarray | None:
        """Each point's weight in the least squares: its own (``weights``) times its edge's
        (``edge_weights`` (E,), e.g. the fit's Huber weights); None when both are absent."""
        if edge_weights is None:
            return self.weights
        per_point = np.repeat(np.asarray(edge_weights, dtype=np.float64), self.counts)
        return per_point if self.weights is None else per_point * self.weights


def collect(
    lines_per_image: Sequence[Sequence[np.ndarray]],
    width: int,
    height: int,
    margin: float = 2.0,
    point_sigma: Sequence[Sequence[np.ndarray]] | None = None,
) -> tuple[EdgeSet | FitFailure, list[RejectedEdge]]:
    """Check and flatten the edges of every shot into one :class:`EdgeSet`.

    Edges with non-finite coordinates, fewer than :data:`MIN_POINTS_PER_EDGE` points
    or no direction (points not elongated along a line) are set aside as
    :class:`RejectedEdge`. Points that are not an (M, 2) array of numbers, or lie
    outside the ``width x height`` image (by more than ``margin`` px), make the whole
    input a :class:`FitFailure` (wrong data, not a bad edge). ``point_sigma``, optional,
    shaped like ``lines_per_image`` (one (M,) array per edge): each point's standard
    deviation, turned into the kept points' weights (:func:`point_weights`); a shape that
    does not match, or a value that is not finite and > 0, is a :class:`FitFailure`.

    Returns
    -------
    (EdgeSet or FitFailure, list of RejectedEdge)
    """
    arrays: list[np.ndarray] = []
    where: list[tuple[int, int]] = []
    for i, lines in enumerate(lines_per_image):
        for j, raw in enumerate(lines):
            try:
                p = np.asarray(raw, dtype=np.float64)
            except (ValueError, TypeError):
                return FitFailure(f"image {i} line {j}: points must be an (M, 2) array of numbers"), []
            if p.ndim != 2 or p.shape[1] != 2:
                return FitFailure(f"image {i} line {j}: points must be an (M, 2) array, got shape {p.shape}"), []
            arrays.append(p)
            where.append((i, j))
    sigmas: list[np.ndarray] | None = None
    if point_sigma is not None:
        sigmas = []
        if len(point_sigma) != len(lines_per_image):
            return FitFailure(
                f"point_sigma has {len(point_sigma)} images, the lines {len(lines_per_image)}: one per image"
            ), []
        for i, (lines, sig_i) in enumerate(zip(lines_per_image, point_sigma, strict=True)):
            if len(sig_i) != len(lines):
                return FitFailure(f"image {i}: point_sigma has {len(sig_i)} edges, the lines {len(lines)}"), []
            for j, (raw, sg) in enumerate(zip(lines, sig_i, strict=True)):
                q = np.asarray(sg, dtype=np.float64).reshape(-1)
                if len(q) != len(raw) or not np.all(np.isfinite(q) & (q > 0)):
                    return FitFailure(
                        f"image {i} line {j}: point_sigma must be one finite value > 0 per point ({len(raw)})"
                    ), []
                sigmas.append(q)
    rejected: list[RejectedEdge] = []
    if not arrays:
        return FitFailure("no usable edges (every edge has too few points, non-finite coordinates or no direction)"), []
    # per-edge checks, vectorised over all edges (the points of every edge in one array)
    counts = np.array([len(p) for p in arrays], dtype=int)
    allp = np.concatenate(arrays)
    nonempty = counts > 0
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(int)
    st = starts[nonempty]
    finite = np.ones(len(arrays), bool)
    finite[nonempty] = np.logical_and.reduceat(np.all(np.isfinite(allp), axis=1), st)
    ok = finite & (counts >= MIN_POINTS_PER_EDGE)
    # bounds: on the finite edges only (a non-finite edge is rejected, not a failure)
    okf = ok & nonempty
    if okf.any():
        sel = np.repeat(okf, counts)
        cf = counts[okf]
        sf = np.concatenate([[0], np.cumsum(cf)[:-1]]).astype(int)
        q = allp[sel]
        lo = np.minimum.reduceat(q, sf, axis=0)
        hi = np.maximum.reduceat(q, sf, axis=0)
        out = (
            (lo[:, 0] < -0.5 - margin)
            | (lo[:, 1] < -0.5 - margin)
            | (hi[:, 0] > width - 0.5 + margin)
            | (hi[:, 1] > height - 0.5 + margin)
        )
        if out.any():
            k = int(np.flatnonzero(out)[0])
            i, j = where[int(np.flatnonzero(okf)[k])]
            return FitFailure(
                f"image {i} line {j} has points outside the {width}x{height} image "
                f"(x {lo[k, 0]:.1f}..{hi[k, 0]:.1f}, y {lo[k, 1]:.1f}..{hi[k, 1]:.1f}): wrong image size?"
            ), []
        # scatter: an edge is elongated along its line (eigenvalues of the 2x2 scatter matrix)
        m = np.add.reduceat(q, sf, axis=0) / cf[:, None]
        d = q - np.repeat(m, cf, axis=0)
        sxx = np.add.reduceat(d[:, 0] ** 2, sf)
        syy = np.add.reduceat(d[:, 1] ** 2, sf)
        sxy = np.add.reduceat(d[:, 0] * d[:, 1], sf)
        half_tr, rad = 0.5 * (sxx + syy), np.hypot(0.5 * (sxx - syy), sxy)
        ev0, ev1 = half_tr - rad, half_tr + rad
        line_like = np.zeros(len(arrays), bool)
        line_like[okf] = (ev1 > 0) & (ev0 <= 0.25 * ev1)
    else:
        line_like = np.zeros(len(arrays), bool)
    pieces: list[np.ndarray] = []
    kept_sigma: list[np.ndarray] = []
    img: list[int] = []
    lin: list[int] = []
    for k, (i, j) in enumerate(where):
        if not finite[k]:
            rejected.append(RejectedEdge(i, j, "non-finite coordinates"))
        elif counts[k] < MIN_POINTS_PER_EDGE:
            rejected.append(RejectedEdge(i, j, f"too few points ({counts[k]} < {MIN_POINTS_PER_EDGE})"))
        elif not line_like[k]:
            rejected.append(RejectedEdge(i, j, "degenerate: its points have no direction (not a line)"))
        else:
            pieces.append(arrays[k])
            if sigmas is not None:
                kept_sigma.append(sigmas[k])
            img.append(i)
            lin.append(j)
    if not pieces:
        return (
            FitFailure("no usable edges (every edge has too few points, non-finite coordinates or no direction)"),
            rejected,
        )
    weights = None
    if sigmas is not None:
        w_all = point_weights(np.concatenate(kept_sigma))
        weights = np.split(w_all, np.cumsum([len(p) for p in pieces])[:-1])
    return EdgeSet.of(pieces, img, lin, weights), rejected


def point_weights(sigma: np.ndarray) -> np.ndarray:
    """Least-squares weights ``1 / sigma^2`` of points of standard deviations ``sigma``, scaled to a
    mean of 1: only their ratios matter to the data, and at mean 1 the fit's penalties (centre prior,
    gauge, ridge, field roughness: each "a residual of so many px on every point") keep the
    strength they have in the unweighted fit."""
    w = 1.0 / np.asarray(sigma, dtype=np.float64) ** 2
    out: np.ndarray = w / np.mean(w)
    return out


# ------------------------------------------------------------ TLS lines
def tls(
    u: np.ndarray, starts: np.ndarray, counts: np.ndarray, weights: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Per-edge TLS lines of the points ``u`` (N, 2), edges contiguous (``starts``, ``counts``).

    ``weights`` (N,), optional: the weighted TLS line (weighted centroid and scatter matrix), the
    line minimising ``sum w r^2``; None, the plain one (the paper's, and every figure's: d, d_max).

    Returns
    -------
    r : (N,) signed distance of each point to its edge's line (along the normal)
    a : (N,) position of each point along its line, from the centroid
    normal, tangent : (N, 2) unit normal and direction of the point's line
    phi : (E,) direction angle of each line (radians)
    """
    ux, uy = u[:, 0], u[:, 1]
    if weights is None:
        dx = ux - np.repeat(np.add.reduceat(ux, starts) / counts, counts)
        dy = uy - np.repeat(np.add.reduceat(uy, starts) / counts, counts)
        sxx = np.add.reduceat(dx * dx, starts)
        syy = np.add.reduceat(dy * dy, starts)
        sxy = np.add.reduceat(dx * dy, starts)
    else:
        sw = np.add.reduceat(weights, starts)
        dx = ux - np.repeat(np.add.reduceat(weights * ux, starts) / sw, counts)
        dy = uy - np.repeat(np.add.reduceat(weights * uy, starts) / sw, counts)
        sxx = np.add.reduceat(weights * dx * dx, starts)
        syy = np.add.reduceat(weights * dy * dy, starts)
        sxy = np.add.reduceat(weights * dx * dy, starts)
    phi = 0.5 * np.arctan2(2.0 * sxy, sxx - syy)  # direction of the line
    c = np.repeat(np.cos(phi), counts)
    s = np.repeat(np.sin(phi), counts)
    r = dy * c - dx * s
    a = dx * c + dy * s
    return r, a, np.stack([-s, c], axis=1), np.stack([c, s], axis=1), phi


def edge_figures(r: np.ndarray, starts: np.ndarray, counts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per edge: RMS of the residuals ``r`` and their peak-to-peak (max - min), pixels."""
    ms = np.add.reduceat(r * r, starts) / counts
    p2p = np.maximum.reduceat(r, starts) - np.minimum.reduceat(r, starts)
    return np.sqrt(ms), p2p


def held_out_edges(lines: Sequence[np.ndarray]) -> list[np.ndarray]:
    """The edges of ``lines`` a held-out figure measures, as (M, 2) float arrays in order: those with 3
    points or more, all finite, as the fit keeps them."""
    pts = [np.asarray(p, dtype=np.float64).reshape(-1, 2) for p in lines if len(p) >= 3]
    return [p for p in pts if np.isfinite(p).all()]


def held_out_residuals(model: DistortionModel, lines: Sequence[np.ndarray]) -> np.ndarray:
    """Residuals ``r`` of the edges ``lines`` after correction by ``model``, all edges
    concatenated; the edges of :func:`held_out_edges` only, as the fit skips the others
    (NaN from the correction itself stays)."""
    pts = held_out_edges(lines)
    if not pts:
        return np.zeros(0)
    counts = np.array([len(p) for p in pts])
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(int)
    return tls(model.undistort_points(np.concatenate(pts)), starts, counts)[0]


def straightness_of(points_list: Sequence[np.ndarray]) -> tuple[float, float]:
    """``(d, d_max)`` (:func:`pipeline.straightness.straightness`) of the edges of
    ``points_list`` (each (M, 2)) that have 3 points or more; NaN when none has."""
    pts = [np.asarray(p, dtype=np.float64).reshape(-1, 2) for p in points_list]
    pts = [p for p in pts if len(p) >= 3]
    if not pts:
        return float("nan"), float("nan")
    st = straightness(pts)
    return st.d, st.d_max


def corrected_straightness(model: DistortionModel, points_list: Sequence[np.ndarray]) -> tuple[float, float]:
    """``(d, d_max)`` of the edges after correction by ``model`` (holdout figure); edges with
    non-finite points are skipped, as the fit skips them (NaN from the correction itself stays)."""
    pts = [np.asarray(p, dtype=np.float64).reshape(-1, 2) for p in points_list]
    return straightness_of([model.undistort_points(p) for p in pts if len(p) >= 3 and np.all(np.isfinite(p))])


# -------------------------------------------------------------- summary
def summarise(
    model: DistortionModel,
    all_edges: EdgeSet,
    kept: EdgeSet,
    rejected: Sequence[RejectedEdge],
    *,
    n_iter: int = 0,
    cost: float = float("nan"),
    message: str = "",
    n_params: int = 0,
    warnings: Sequence[str] = (),
) -> FitResult:
    """Before/after figures of ``model`` on the edges (``kept`` for the totals)."""
    st, ct = all_edges.starts, all_edges.counts
    rb = tls(all_edges.xy, st, ct)[0]
    ra = tls(model.undistort_points(all_edges.xy), st, ct)[0]
    rms_b, p2p_b = edge_figures(rb, st, ct)
    rms_a, p2p_a = edge_figures(ra, st, ct)
    rej = {(e.image, e.line) for e in rejected}
    is_rej = np.array([(int(i), int(j)) in rej for i, j in zip(all_edges.image, all_edges.line, strict=True)])
    edges = tuple(
        EdgeFit(int(i), int(j), int(c), float(a), float(b), float(cc), float(dd), bool(x))
        for i, j, c, a, b, cc, dd, x in zip(
            all_edges.image, all_edges.line, ct, rms_b, p2p_b, rms_a, p2p_a, is_rej, strict=True
        )
    )

    def pooled(mask: np.ndarray) -> tuple[float, float, float, float]:
        n = ct[mask]
        if n.sum() == 0:
            return (float("nan"),) * 4
        return (
            float(np.sqrt(np.sum(rms_b[mask] ** 2 * n) / n.sum())),
            float(np.sqrt(np.mean(p2p_b[mask] ** 2))),
            float(np.sqrt(np.sum(rms_a[mask] ** 2 * n) / n.sum())),
            float(np.sqrt(np.mean(p2p_a[mask] ** 2))),
        )

    images = []
    for i in sorted({int(v) for v in all_edges.image}):
        mask = (all_edges.image == i) & ~is_rej
        images.append(ImageFit(i, int(mask.sum()), *pooled(mask)))
    total = pooled(~is_rej)
    return FitResult(
        model=model,
        d_before=total[0],
        d_max_before=total[1],
        d_after=total[2],
        d_max_after=total[3],
        images=tuple(images),
        edges=edges,
        rejected=tuple(sorted(rejected, key=lambda e: (e.image, e.line))),
        n_iter=int(n_iter),
        cost=cost,
        message=message,
        n_points=int(kept.counts.sum()),
        n_params=int(n_params),
        warnings=tuple(warnings),
    )
