r"""Fit a distortion model that straightens every harp edge of every shot at once.

The objective (Tang et al. 2012, Sect. 3) is the sum over all points of the
squared signed distance of the *corrected* point to the total-least-squares
(TLS) line of its own corrected edge:

.. math::
    C(\theta) = \sum_{e} \sum_{i \in e} \big(n_e(\theta)\cdot(U_\theta(p_i) - m_e(\theta))\big)^2

where :math:`m_e` is the centroid and :math:`n_e` the unit normal of the TLS
line of :math:`\{U_\theta(p_i)\}_{i\in e}`. The lines are not free parameters:
they are recomputed from the corrected points at every evaluation (variable
projection); the Jacobian is analytic, including the derivative of the line
(centroid and angle) with respect to :math:`\theta` (only the two centre
columns of the radial model are central differences). It is minimised by
Levenberg–Marquardt (``scipy.optimize.least_squares``), all edges of all
images at once, in coordinates normalised by half the image diagonal.

Uniqueness (gauge). Straight lines stay straight under any homography, so the
data determine the correction only up to a homography (8 degrees of freedom);
the fit fixes them as follows.

* ``radial``: the model can only express scale, not rotation, shear or
  translation (a shift of the centre is not a translation), so the scale is
  fixed by ``k0 = 1``. With tangential *and* thin-prism terms, the combination
  ``(p1, p2, s1, s3) = (a, b, -b, -a)`` is, to first order, the projective part
  of a homography; it is removed by a penalty on ``p1 - s3`` and ``p2 - s1``.
  The centre is only weakly determined (a shift of the centre is, to first
  order, a tangential term); a penalty ``w_center`` (default 1e-5: a free
  centre; :mod:`pipeline.select` also tries 1e-2, a centre prior) keeps it
  near the image centre when the data cannot place it.
* ``poly``: the constant and linear terms are fixed to the identity
  (6 degrees of freedom: translation, rotation, scale, shear) and the
  first-order projective part is removed by constraining the quadratic terms
  to ``b_11 = -a_20`` and ``b_02 = -a_11`` (the projection on the two
  projective directions ``a_20 + b_11``, ``a_11 + b_02`` is zero). A weak
  ridge on the coefficients of degree >= 2 fixes what few orientations cannot
  see (e.g. with only horizontal and vertical strings, any ``x_u = g(x)``,
  ``y_u = h(y)`` keeps every string straight).

Robustness: a first fit is followed by a fit where each edge is down-weighted
by the Huber weight ``min(1, 3 m / rms_e)`` of its RMS residual ``rms_e``
(``m`` the median edge RMS), then edges whose RMS residual is an outlier
(``> reject_factor x`` the median edge RMS) are rejected, reported with their
(image, line) index and reason, and the final fit (plain least squares) uses
the remaining edges.

References
----------
.. [1] Z. Tang, R. Grompone von Gioi, P. Monasse, J.-M. Morel, "High-precision
   camera distortion measurements with a calibration harp", JOSA A 29(10), 2012.
.. [2] Z. Tang et al., "Lens distortion correction with a calibration harp", ICIP 2011.
.. [3] G. H. Golub, V. Pereyra, "The differentiation of pseudo-inverses and
   nonlinear least squares problems whose variables separate", SIAM J. Numer.
   Anal. 10(2), 1973.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from pipeline.models.base import DistortionModel
from pipeline.models.polynomial import PolynomialModel, monomial_exponents, monomials
from pipeline.models.radial import RadialModel
from pipeline.straightness import straightness

MIN_POINTS_PER_EDGE = 5
MIN_EDGES = 4


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
    kept (non-rejected) edges. ``before`` is the uncorrected input.
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

    ok = True


@dataclass(frozen=True)
class FitFailure:
    """The fit could not produce a trustworthy model; ``reason`` says why."""

    reason: str

    ok = False


# --------------------------------------------------------- edge statistics
@dataclass(frozen=True)
class _Edges:
    xy: np.ndarray  # (N, 2) all points, edges contiguous
    starts: np.ndarray  # (E,)
    counts: np.ndarray  # (E,)
    image: np.ndarray  # (E,) image index
    line: np.ndarray  # (E,) line index within the image

    def subset(self, keep: np.ndarray) -> _Edges:
        keep = np.asarray(keep, bool)
        pieces = [self.xy[s : s + c] for s, c, k in zip(self.starts, self.counts, keep) if k]
        counts = self.counts[keep]
        return _Edges(
            np.concatenate(pieces),
            np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(int),
            counts,
            self.image[keep],
            self.line[keep],
        )


def _tls(u: np.ndarray, starts: np.ndarray, counts: np.ndarray):
    """Per-edge TLS lines of points ``u``; signed residuals and helpers."""
    m = np.add.reduceat(u, starts, axis=0) / counts[:, None]
    dev = u - np.repeat(m, counts, axis=0)
    sxx = np.add.reduceat(dev[:, 0] ** 2, starts)
    syy = np.add.reduceat(dev[:, 1] ** 2, starts)
    sxy = np.add.reduceat(dev[:, 0] * dev[:, 1], starts)
    phi = 0.5 * np.arctan2(2.0 * sxy, sxx - syy)  # direction of the line
    c, s = np.cos(phi), np.sin(phi)
    nrm = np.repeat(np.stack([-s, c], axis=1), counts, axis=0)
    tan = np.repeat(np.stack([c, s], axis=1), counts, axis=0)
    r = np.einsum("ij,ij->i", dev, nrm)
    a = np.einsum("ij,ij->i", dev, tan)
    return r, a, nrm, tan, phi


def edge_residuals(points: np.ndarray) -> np.ndarray:
    """Signed distances of ``points`` (N, 2) to their TLS regression line."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    return _tls(pts, np.array([0]), np.array([len(pts)]))[0]


def _edge_figures(r: np.ndarray, starts, counts):
    ms = np.add.reduceat(r * r, starts) / counts
    p2p = np.maximum.reduceat(r, starts) - np.minimum.reduceat(r, starts)
    return np.sqrt(ms), p2p


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


# ------------------------------------------------------ parametrisations
class _RadialParam:
    """theta = [dcx, dcy, k1..kN, (p1, p2), (s1..s4)]; centre = c0 + s * dc; k0 = 1."""

    def __init__(self, width, height, degree, tangential, prism, w_center, w_gauge, ridge):
        self.s = 0.5 * float(np.hypot(width, height))
        self.c0 = np.array([(width - 1) / 2.0, (height - 1) / 2.0])
        self.degree, self.tangential, self.prism = int(degree), bool(tangential), bool(prism)
        self.n = 2 + self.degree + 2 * self.tangential + 4 * self.prism
        self.w_center, self.w_gauge, self.ridge = w_center, w_gauge, ridge

    def theta0(self, init: DistortionModel | None):
        th = np.zeros(self.n)
        if isinstance(init, RadialModel):
            scale = self.s / init.scale  # rho_init = rho * s / s_init
            th[:2] = (np.asarray(init.center) - self.c0) / self.s
            k0 = init.k[0]
            for m, km in enumerate(init.k[1 : self.degree + 1], start=1):
                th[1 + m] = km / k0 * scale**m  # rescale to this normalisation
        return th

    def model(self, th) -> RadialModel:
        i = 2 + self.degree
        tang = tuple(th[i : i + 2]) if self.tangential else None
        i += 2 * self.tangential
        prism = tuple(th[i : i + 4]) if self.prism else None
        return RadialModel(
            center=tuple(self.c0 + self.s * th[:2]),
            k=(1.0, *th[2 : 2 + self.degree]),
            scale=self.s,
            tangential=tang,
            prism=prism,
        )

    def _linear_part(self, xy, th):
        c = self.c0 + self.s * th[:2]
        xi = (xy[:, 0] - c[0]) / self.s
        eta = (xy[:, 1] - c[1]) / self.s
        rho2 = xi * xi + eta * eta
        rho = np.sqrt(rho2)
        cols_x, cols_y = [], []
        pw = np.ones_like(rho)
        for _ in range(self.degree):
            pw = pw * rho
            cols_x.append(pw * xi)
            cols_y.append(pw * eta)
        z = np.zeros_like(rho)
        if self.tangential:
            cols_x += [2 * xi * eta, rho2 + 2 * xi * xi]
            cols_y += [rho2 + 2 * eta * eta, 2 * xi * eta]
        if self.prism:
            cols_x += [rho2, rho2 * rho2, z, z]
            cols_y += [z, z, rho2, rho2 * rho2]
        bx = np.stack(cols_x, axis=1)
        by = np.stack(cols_y, axis=1)
        lin = th[2:]
        u = np.stack([c[0] + self.s * (xi + bx @ lin), c[1] + self.s * (eta + by @ lin)], axis=1)
        return u, self.s * bx, self.s * by

    def evaluate(self, xy, th, jac=True):
        u, bx, by = self._linear_part(xy, th)
        if not jac:
            return u, None
        d = np.empty((len(xy), 2, self.n))
        d[:, 0, 2:], d[:, 1, 2:] = bx, by
        eps = 1e-6
        for j in range(2):
            tp, tm = th.copy(), th.copy()
            tp[j] += eps
            tm[j] -= eps
            d[:, :, j] = (self._linear_part(xy, tp)[0] - self._linear_part(xy, tm)[0]) / (2 * eps)
        return u, d

    def regularisation(self, th, n_points):
        w = math.sqrt(max(n_points, 1))
        rows, jr = [], []
        for j in range(2):  # centre near the image centre
            e = np.zeros(self.n)
            e[j] = w * self.w_center * self.s
            rows.append(e @ th)
            jr.append(e)
        if self.tangential and self.prism:  # first-order projective gauge
            i = 2 + self.degree
            p1, p2, s1, s3 = i, i + 1, i + 2, i + 4
            for a, b in ((p1, s3), (p2, s1)):
                e = np.zeros(self.n)
                e[a], e[b] = w * self.w_gauge * self.s, -w * self.w_gauge * self.s
                rows.append(e @ th)
                jr.append(e)
        if self.ridge > 0:
            for j in range(2, self.n):
                e = np.zeros(self.n)
                e[j] = w * self.ridge * self.s
                rows.append(e @ th)
                jr.append(e)
        return np.asarray(rows), np.asarray(jr).reshape(-1, self.n)


class _PolyParam:
    """Free coefficients of a :class:`PolynomialModel` with the gauge fixed (see module doc)."""

    def __init__(self, width, height, degree, ridge):
        self.ident = PolynomialModel.identity(width, height, degree)
        self.s = self.ident.scale
        self.degree = int(degree)
        m = PolynomialModel.n_coefficients(degree)
        self.m = m
        # full = t0 + T @ theta, full = [a (m), b (m)]
        self.t0 = self.ident.params()
        cols = []
        for k in range(3, m):  # a_ij, degree >= 2
            e = np.zeros(2 * m)
            e[k] = 1.0
            if k == 3:
                e[m + 4] = -1.0  # b11 = -a20
            if k == 4:
                e[m + 5] = -1.0  # b02 = -a11
            cols.append(e)
        for k in range(3, m):
            if k in (4, 5):
                continue
            e = np.zeros(2 * m)
            e[m + k] = 1.0
            cols.append(e)
        self.T = np.stack(cols, axis=1)
        self.n = self.T.shape[1]
        self.ridge = ridge

    def theta0(self, init):
        if isinstance(init, PolynomialModel) and init.degree <= self.degree:
            full = np.zeros(2 * self.m)
            ex = monomial_exponents(self.degree)
            idx = {e: i for i, e in enumerate(ex)}
            for i, e in enumerate(monomial_exponents(init.degree)):
                full[idx[e]] = init.a[i]
                full[self.m + idx[e]] = init.b[i]
            return np.linalg.lstsq(self.T, full - self.t0, rcond=None)[0]
        return np.zeros(self.n)

    def model(self, th) -> PolynomialModel:
        full = self.t0 + self.T @ th
        return PolynomialModel(
            center=self.ident.center, degree=self.degree, a=tuple(full[: self.m]), b=tuple(full[self.m :]), scale=self.s
        )

    def evaluate(self, xy, th, jac=True):
        c = self.ident.center
        mon = monomials((xy[:, 0] - c[0]) / self.s, (xy[:, 1] - c[1]) / self.s, self.degree)
        full = self.t0 + self.T @ th
        u = np.stack([c[0] + self.s * (mon @ full[: self.m]), c[1] + self.s * (mon @ full[self.m :])], axis=1)
        if not jac:
            return u, None
        d = np.empty((len(xy), 2, self.n))
        d[:, 0, :] = self.s * (mon @ self.T[: self.m])
        d[:, 1, :] = self.s * (mon @ self.T[self.m :])
        return u, d

    def regularisation(self, th, n_points):
        if self.ridge <= 0:
            return np.zeros(0), np.zeros((0, self.n))
        e = math.sqrt(max(n_points, 1)) * self.ridge * self.s * np.eye(self.n)
        return e @ th, e


# ------------------------------------------------------------- objective
def _residuals_and_jacobian(param, edges: _Edges, th, jac=True):
    u, du = param.evaluate(edges.xy, th, jac)
    st, ct = edges.starts, edges.counts
    r, a, nrm, tan, _ = _tls(u, st, ct)
    if not jac:
        return r, None
    mean_du = np.add.reduceat(du, st, axis=0) / ct[:, None, None]
    ddu = du - np.repeat(mean_du, ct, axis=0)
    n_d = nrm[:, 0, None] * ddu[:, 0, :] + nrm[:, 1, None] * ddu[:, 1, :]
    t_d = tan[:, 0, None] * ddu[:, 0, :] + tan[:, 1, None] * ddu[:, 1, :]
    num = np.add.reduceat(a[:, None] * n_d + r[:, None] * t_d, st, axis=0)
    den = np.add.reduceat(a * a - r * r, st)
    dphi = num / np.where(np.abs(den) > 1e-300, den, 1e-300)[:, None]
    return r, n_d - np.repeat(dphi, ct, axis=0) * a[:, None]


def _solve(param, edges: _Edges, th0, edge_weights=None, max_nfev=200):
    """Levenberg–Marquardt (MINPACK) on the residuals, optionally weighted per edge."""
    n_pts = len(edges.xy)
    sw = None if edge_weights is None else np.repeat(np.sqrt(edge_weights), edges.counts)

    def fun(th):
        r, _ = _residuals_and_jacobian(param, edges, th, jac=False)
        g, _ = param.regularisation(th, n_pts)
        return np.concatenate([r if sw is None else r * sw, g])

    def jac(th):
        _, j = _residuals_and_jacobian(param, edges, th, jac=True)
        _, jg = param.regularisation(th, n_pts)
        return np.vstack([j if sw is None else j * sw[:, None], jg])

    return least_squares(
        fun, th0, jac=jac, method="lm", x_scale="jac", max_nfev=max_nfev, xtol=1e-12, ftol=1e-12, gtol=1e-12
    )


# ------------------------------------------------------------ input checks
def _orientation_problem(edges: _Edges, min_spread_deg: float) -> str | None:
    """None if the edges have at least two orientations, else the reason."""
    r = []
    for s, c in zip(edges.starts, edges.counts):
        p = edges.xy[s : s + c]
        dev = p - p.mean(axis=0)
        sxx, syy, sxy = (dev[:, 0] ** 2).sum(), (dev[:, 1] ** 2).sum(), (dev[:, 0] * dev[:, 1]).sum()
        r.append(np.arctan2(2 * sxy, sxx - syy))  # doubled angle
    z = np.exp(1j * np.asarray(r))
    mean = np.angle(z.mean()) if abs(z.mean()) > 1e-9 else 0.0
    off = np.degrees(np.abs(np.angle(z * np.exp(-1j * mean)))) / 2.0
    n_off = int(np.sum(off > min_spread_deg / 2.0))
    if n_off < 2:
        return (
            f"all {len(z)} edges lie within {2 * float(off.max()):.1f} deg of one orientation "
            f"({np.degrees(mean) / 2 % 180:.1f} deg): one orientation cannot constrain the "
            f"distortion along the strings; give shots of the harp at >= 2 orientations "
            f"at least {min_spread_deg:g} deg apart"
        )
    return None


def _collect(lines_per_image, width, height, margin=2.0):
    """Flatten the input, dropping edges too short to measure. -> (_Edges | str, rejected)."""
    pieces, img, lin, rejected = [], [], [], []
    for i, lines in enumerate(lines_per_image):
        for j, p in enumerate(lines):
            try:
                p = np.asarray(p, dtype=np.float64)
            except (ValueError, TypeError):
                return f"image {i} line {j}: points must be an (M, 2) array of numbers", []
            if p.ndim != 2 or p.shape[1] != 2:
                return f"image {i} line {j}: points must be an (M, 2) array, got shape {p.shape}", []
            if not np.all(np.isfinite(p)):
                rejected.append(RejectedEdge(i, j, "non-finite coordinates"))
                continue
            if len(p) < MIN_POINTS_PER_EDGE:
                rejected.append(RejectedEdge(i, j, f"too few points ({len(p)} < {MIN_POINTS_PER_EDGE})"))
                continue
            lo, hi = p.min(axis=0), p.max(axis=0)
            if (
                lo[0] < -0.5 - margin
                or lo[1] < -0.5 - margin
                or hi[0] > width - 0.5 + margin
                or hi[1] > height - 0.5 + margin
            ):
                return (
                    f"image {i} line {j} has points outside the {width}x{height} image "
                    f"(x {lo[0]:.1f}..{hi[0]:.1f}, y {lo[1]:.1f}..{hi[1]:.1f}): wrong image size?"
                ), []
            ev = np.linalg.eigvalsh(np.cov(p.T))  # scatter: an edge is elongated along its line
            if not ev[1] > 0 or ev[0] > 0.25 * ev[1]:
                rejected.append(RejectedEdge(i, j, "degenerate: its points have no direction (not a line)"))
                continue
            pieces.append(p)
            img.append(i)
            lin.append(j)
    if not pieces:
        return "no usable edges (every edge has too few points, non-finite coordinates or no direction)", rejected
    counts = np.array([len(p) for p in pieces])
    return _Edges(
        np.concatenate(pieces),
        np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(int),
        counts,
        np.array(img),
        np.array(lin),
    ), rejected


def _fold_problem(model: DistortionModel, width, height) -> str | None:
    """None if the correction is locally invertible (orientation-preserving) over the image."""
    xs = np.linspace(-0.5, width - 0.5, 25)
    ys = np.linspace(-0.5, height - 0.5, 19)
    xx, yy = np.meshgrid(xs, ys)
    p = np.stack([xx.ravel(), yy.ravel()], axis=1)
    h = 0.5
    jx = (model.undistort_points(p + [h, 0]) - model.undistort_points(p - [h, 0])) / (2 * h)
    jy = (model.undistort_points(p + [0, h]) - model.undistort_points(p - [0, h])) / (2 * h)
    det = jx[:, 0] * jy[:, 1] - jx[:, 1] * jy[:, 0]
    if not np.all(np.isfinite(det)) or det.min() <= 0.05:
        k = int(np.nanargmin(det)) if np.any(np.isfinite(det)) else 0
        return (
            f"the fitted correction folds over inside the image near ({p[k, 0]:.0f}, {p[k, 1]:.0f}) "
            f"(Jacobian determinant {det[k]:.3g}); too few orientations or too high a degree"
        )
    return None


# ------------------------------------------------------------------- API
def make_parametrisation(
    width, height, model="radial", degree=None, tangential=False, prism=False, w_center=1e-5, w_gauge=1e-3, ridge=None
):
    """The free parameters of a model kind (see module doc); used by :func:`fit_distortion`."""
    if model == "radial":
        return _RadialParam(
            width,
            height,
            4 if degree is None else degree,
            tangential,
            prism,
            w_center,
            w_gauge,
            0.0 if ridge is None else ridge,
        )
    if model == "poly":
        return _PolyParam(width, height, 5 if degree is None else degree, 1e-4 if ridge is None else ridge)
    raise ValueError(f"unknown model kind {model!r}; known: 'radial', 'poly'")


def fit_distortion(
    lines_per_image: Sequence[Sequence[np.ndarray]],
    width: int,
    height: int,
    model: str = "radial",
    degree: int | None = None,
    tangential: bool = False,
    prism: bool = False,
    *,
    image_sizes: Sequence[tuple[int, int]] | None = None,
    init: DistortionModel | None = None,
    robust: bool = True,
    reject_factor: float = 5.0,
    max_reject_fraction: float = 0.25,
    min_orientation_spread_deg: float = 20.0,
    ridge: float | None = None,
    w_center: float = 1e-5,
    max_nfev: int = 200,
) -> FitResult | FitFailure:
    """Fit a distortion correction straightening all edges of all images at once.

    Parameters
    ----------
    lines_per_image : sequence over images of sequences of (M, 2) arrays
        Edge points (pixels, distorted) of each string edge of each shot, as
        given by the measurement (smoothed, every t-th point).
    width, height : int
        Image size (all shots must share it).
    model : {'radial', 'poly'}
        :class:`~pipeline.models.radial.RadialModel` (free centre, ``k0 = 1``,
        ``k1..k_degree``; default degree 4) or
        :class:`~pipeline.models.polynomial.PolynomialModel` (default degree 5).
    degree : int, optional
        Radial: highest power of rho in f; poly: total degree (3..11).
    tangential, prism : bool
        Radial only: add decentering (p1, p2) / thin-prism (s1..s4) terms.
    image_sizes : sequence of (width, height), optional
        Size of each shot; a mismatch gives a :class:`FitFailure`.
    init : DistortionModel, optional
        Start (default: identity for poly; Alvarez's closed-form k2 for radial).
    robust : bool
        Down-weight (Huber, per edge) then reject outlier edges (see module doc).
    reject_factor, max_reject_fraction : float
        An edge is rejected if its RMS residual exceeds ``reject_factor`` x
        the median edge RMS; at most this fraction of the edges is rejected.
    min_orientation_spread_deg : float
        At least 2 edges must differ by more than half this from the mean orientation.
    ridge : float, optional
        Weight of the ridge penalty (poly default 1e-4, radial default 0).
    w_center : float
        Radial: weight of the penalty keeping the centre near the image centre
        (a centre offset of ``delta`` (px) costs like a residual of
        ``w_center * delta`` px on every point); 1e-5 leaves it free.
    max_nfev : int
        Evaluation budget of each Levenberg–Marquardt run.

    Returns
    -------
    FitResult or FitFailure
        Never raises for a data problem: a :class:`FitFailure` says why.
    """
    if model not in ("radial", "poly"):
        return FitFailure(f"unknown model {model!r}; use 'radial' or 'poly'")
    if model == "poly" and degree is not None and not 2 <= degree <= 11:
        return FitFailure(f"polynomial degree must be within 2..11, got {degree}")
    if model == "radial" and degree is not None and not 1 <= degree <= 10:
        return FitFailure(f"radial degree must be within 1..10, got {degree}")
    if model == "poly" and (tangential or prism):
        return FitFailure("tangential/prism terms apply to the radial model only (poly contains them)")
    if image_sizes is not None:
        sizes = {(int(w), int(h)) for w, h in image_sizes}
        if sizes != {(int(width), int(height))}:
            return FitFailure(
                f"images of different sizes {sorted(sizes)}: one model fits one image size ({width}x{height})"
            )
    if len(lines_per_image) == 0:
        return FitFailure("no images given")
    edges, rejected = _collect(lines_per_image, width, height)
    if isinstance(edges, str):
        return FitFailure(edges)
    param = make_parametrisation(width, height, model, degree, tangential, prism, w_center=w_center, ridge=ridge)
    n_e = len(edges.counts)
    n_constraints = int(np.sum(edges.counts - 2))
    if n_e < MIN_EDGES:
        return FitFailure(f"too few edges: {n_e} usable (need >= {MIN_EDGES})")
    if n_constraints < 2 * param.n:
        return FitFailure(
            f"too few points: {n_constraints} constraints from {n_e} edges for "
            f"{param.n} parameters (need >= {2 * param.n}); lower the degree or add shots"
        )
    problem = _orientation_problem(edges, min_orientation_spread_deg)
    if problem:
        return FitFailure(problem)

    if init is None and model == "radial":
        from pipeline.alvarez import alvarez_initial_k

        try:
            k2 = alvarez_initial_k(edges_list(edges), width, height)
        except (ValueError, np.linalg.LinAlgError, FloatingPointError):
            k2 = 0.0
        th = np.zeros(param.n)
        if param.degree >= 2:
            th[3] = k2
    else:
        th = param.theta0(init)

    all_edges = edges
    warnings: list[str] = []
    n_iter = 0
    try:
        with np.errstate(all="ignore"):
            sol = _solve(param, edges, th, max_nfev=max_nfev)
            n_iter += sol.nfev
            th = sol.x
            if robust and n_e > MIN_EDGES:
                r, _ = _residuals_and_jacobian(param, edges, th, jac=False)
                rms, _ = _edge_figures(r, edges.starts, edges.counts)
                scale = 3.0 * max(float(np.median(rms)), 1e-6)
                weights = np.minimum(1.0, scale / np.maximum(rms, 1e-12))  # Huber weights per edge
                sol = _solve(param, edges, th, edge_weights=weights, max_nfev=max_nfev)
                n_iter += sol.nfev
                th = sol.x
                r, _ = _residuals_and_jacobian(param, edges, th, jac=False)
                rms, _ = _edge_figures(r, edges.starts, edges.counts)
                thresh = reject_factor * max(float(np.median(rms)), 1e-6)
                bad = np.flatnonzero(rms > thresh)
                max_bad = int(max_reject_fraction * n_e)
                if len(bad) > max_bad:
                    warnings.append(
                        f"{len(bad)} edges above the outlier threshold {thresh:.3g} px; "
                        f"rejected only the worst {max_bad}"
                    )
                    bad = bad[np.argsort(rms[bad])[::-1][:max_bad]]
                if len(bad):
                    keep = np.ones(n_e, bool)
                    keep[bad] = False
                    for b in bad:
                        rejected.append(
                            RejectedEdge(
                                int(edges.image[b]),
                                int(edges.line[b]),
                                f"outlier: residual RMS {rms[b]:.3g} px > "
                                f"{thresh:.3g} px ({reject_factor:g} x median edge RMS)",
                            )
                        )
                    edges = edges.subset(keep)
                    if len(edges.counts) < MIN_EDGES:
                        return FitFailure(f"too few edges left after rejecting outliers: {len(edges.counts)}")
                    problem = _orientation_problem(edges, min_orientation_spread_deg)
                    if problem:
                        return FitFailure("after rejecting outlier edges, " + problem)
                sol = _solve(param, edges, th, max_nfev=max_nfev)
                n_iter += sol.nfev
                th = sol.x
    except (ValueError, np.linalg.LinAlgError) as exc:
        return FitFailure(f"optimisation failed: {exc}")
    if not np.all(np.isfinite(th)):
        return FitFailure("optimisation diverged (non-finite parameters)")
    fitted = param.model(th)
    fold = _fold_problem(fitted, width, height)
    if fold:
        return FitFailure(fold)
    if sol.status <= 0:
        warnings.append(f"optimiser stopped early: {sol.message}")
    result = summarise(
        fitted,
        all_edges,
        edges,
        rejected,
        n_iter=n_iter,
        cost=float(sol.cost),
        message=str(sol.message),
        n_params=param.n,
        warnings=tuple(warnings),
    )
    if result.d_after > result.d_before * 1.01 + 1e-9:
        return FitFailure(f"the fit made the edges less straight (d {result.d_before:.4g} -> {result.d_after:.4g} px)")
    return result


def edges_list(edges: _Edges) -> list[np.ndarray]:
    """The edges of an :class:`_Edges` as a list of (M, 2) arrays."""
    return [edges.xy[s : s + c] for s, c in zip(edges.starts, edges.counts)]


def summarise(
    model: DistortionModel,
    all_edges: _Edges,
    kept: _Edges,
    rejected,
    *,
    n_iter=0,
    cost=float("nan"),
    message="",
    n_params=0,
    warnings=(),
) -> FitResult:
    """Before/after figures of ``model`` on the edges (``kept`` for the totals)."""
    st, ct = all_edges.starts, all_edges.counts
    rb = _tls(all_edges.xy, st, ct)[0]
    ra = _tls(model.undistort_points(all_edges.xy), st, ct)[0]
    rms_b, p2p_b = _edge_figures(rb, st, ct)
    rms_a, p2p_a = _edge_figures(ra, st, ct)
    rej = {(e.image, e.line) for e in rejected}
    is_rej = np.array([(int(i), int(j)) in rej for i, j in zip(all_edges.image, all_edges.line)])
    edges = tuple(
        EdgeFit(int(i), int(j), int(c), float(a), float(b), float(cc), float(dd), bool(x))
        for i, j, c, a, b, cc, dd, x in zip(all_edges.image, all_edges.line, ct, rms_b, p2p_b, rms_a, p2p_a, is_rej)
    )

    def pooled(mask):
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
    for i in sorted(set(int(v) for v in all_edges.image)):
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
