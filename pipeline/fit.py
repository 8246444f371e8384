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
(centroid and angle) with respect to :math:`\theta` and the centre columns of
the radial model. It is minimised by
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
  centre; a spec with a centre prior, :mod:`pipeline.fitspec`, uses 1e-2) keeps it
  near the image centre when the data cannot place it.
* ``poly``: the constant and linear terms are fixed to the identity
  (6 degrees of freedom: translation, rotation, scale, shear) and the
  first-order projective part is removed by constraining the quadratic terms
  to ``b_11 = -a_20`` and ``b_02 = -a_11`` (the projection on the two
  projective directions ``a_20 + b_11``, ``a_11 + b_02`` is zero). A weak
  ridge on the coefficients of degree >= 2 fixes what few orientations cannot
  see (e.g. with only horizontal and vertical strings, any ``x_u = g(x)``,
  ``y_u = h(y)`` keeps every string straight).

What to fit is a :class:`pipeline.fitspec.FitSpec` (its ``fit_arguments()`` are the
keyword arguments of :func:`fit_distortion`); each model's free parameters live beside
the model (:class:`~pipeline.models.radial.RadialParametrisation`,
:class:`~pipeline.models.polynomial.PolynomialParametrisation`); the edges, their TLS
lines and the result types are :mod:`pipeline.edgeset`'s.

Robustness: a first fit is followed by a fit where each edge is down-weighted
by the Huber weight ``min(1, 3 m / rms_e)`` of its RMS residual ``rms_e``
(``m`` the median edge RMS), then edges whose RMS residual is an outlier
(``> reject_factor x`` the median edge RMS) are rejected, reported with their
(image, line) index and reason, and the final fit (plain least squares) uses
the remaining edges. (When no edge is down-weighted the weighted fit is the
first one, and when moreover none is rejected the final fit is too: they are
not run again.)

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

from collections.abc import Sequence
from typing import Protocol

import numpy as np
from scipy.optimize import OptimizeResult, least_squares

from pipeline.alvarez import alvarez_initial_k
from pipeline.edgeset import (
    EdgeSet,
    FitFailure,
    FitResult,
    RejectedEdge,
    collect,
    edge_figures,
    summarise,
    tls,
)
from pipeline.fitspec import FREE_CENTER_WEIGHT, FitSpec, spec_problem
from pipeline.models.base import DistortionModel
from pipeline.models.polynomial import PolynomialParametrisation
from pipeline.models.radial import RadialParametrisation

MIN_EDGES = 4
"""A fit needs at least this many usable edges."""


class Parametrisation(Protocol):
    """The free parameters ``theta`` of a model family (beside each model in :mod:`pipeline.models`)."""

    n: int

    def theta0(self, init: DistortionModel | None) -> np.ndarray: ...
    def model(self, th: np.ndarray) -> DistortionModel: ...
    def evaluate(self, xy: np.ndarray, th: np.ndarray, jac: bool = True) -> tuple[np.ndarray, np.ndarray | None]: ...
    def regularisation(self, th: np.ndarray, n_points: int) -> tuple[np.ndarray, np.ndarray]: ...
    def project(
        self, xy: np.ndarray, th: np.ndarray, nrm: np.ndarray, tan: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]: ...


def make_parametrisation(
    width: int,
    height: int,
    spec: FitSpec,
    *,
    w_center: float | None = None,
    w_gauge: float = 1e-3,
    ridge: float | None = None,
) -> RadialParametrisation | PolynomialParametrisation:
    """The free parameters of ``spec`` for a ``width x height`` image (see module doc).

    ``w_center`` defaults to the spec's (:attr:`FitSpec.w_center`); ``ridge`` to 0 for
    radial, 1e-4 for poly.
    """
    if spec.kind == "radial":
        return RadialParametrisation(
            width,
            height,
            int(spec.degree or 0),
            spec.tangential,
            spec.prism,
            spec.w_center if w_center is None else w_center,
            w_gauge,
            0.0 if ridge is None else ridge,
            spec.division,
        )
    return PolynomialParametrisation(width, height, int(spec.degree or 0), 1e-4 if ridge is None else ridge)


# ------------------------------------------------------------- objective
def _projected(
    param: Parametrisation, edges: EdgeSet, th: np.ndarray, jac: bool
) -> tuple[np.ndarray, np.ndarray, np.ndarray | None, np.ndarray | None]:
    """``(r, a, P, T)``: the residuals, the positions along the lines and (``jac``) the Jacobian of
    the corrected points projected on each point's line normal (``P``) and direction (``T``)."""
    u, _ = param.evaluate(edges.xy, th, jac=False)
    r, a, nrm, tan, _ = tls(u, edges.starts, edges.counts)
    if not jac:
        return r, a, None, None
    p_mat, t_mat = param.project(edges.xy, th, nrm, tan)
    return r, a, p_mat, t_mat


def _line_turn(
    p_mat: np.ndarray, t_mat: np.ndarray, r: np.ndarray, a: np.ndarray, st: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Per edge: ``(sum of P, d phi / d theta)``, the rotation of its TLS line (Golub-Pereyra).

    ``d phi = sum_i (a_i (P_i - mean P) + r_i (T_i - mean T)) / sum_i (a_i^2 - r_i^2)``; the
    means drop out because ``sum a = sum r = 0`` on each edge (distances from its centroid)."""
    sum_p = np.add.reduceat(p_mat, st, axis=0)
    num = np.add.reduceat(a[:, None] * p_mat + r[:, None] * t_mat, st, axis=0)
    den = np.add.reduceat(a * a - r * r, st)
    return sum_p, num / np.where(np.abs(den) > 1e-300, den, 1e-300)[:, None]


def residuals_and_jacobian(
    param: Parametrisation, edges: EdgeSet, th: np.ndarray, jac: bool = True
) -> tuple[np.ndarray, np.ndarray | None]:
    """Signed distances of the corrected points to their own edge's TLS line, and (``jac``)
    their analytic Jacobian in ``theta``, the line's motion included (variable projection):
    ``J_i = P_i - mean_e P - a_i d phi_e`` (``P_i = n_e . du_i``, :func:`_line_turn`)."""
    r, a, p_mat, t_mat = _projected(param, edges, th, jac)
    if p_mat is None or t_mat is None:
        return r, None
    st, ct = edges.starts, edges.counts
    sum_p, dphi = _line_turn(p_mat, t_mat, r, a, st)
    j = p_mat - np.repeat(sum_p / ct[:, None], ct, axis=0)
    j -= np.repeat(dphi, ct, axis=0) * a[:, None]
    return r, j


def normal_equations(
    param: Parametrisation,
    edges: EdgeSet,
    th: np.ndarray,
    groups: Sequence[int] | None = None,
    edge_weights: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``J^T W J``, ``J^T W r`` and ``r^T W r`` of :func:`residuals_and_jacobian` at ``th`` without
    forming ``J`` (``W``: the per-edge ``edge_weights``, default 1), per group of edges: ``groups``
    are the edge indices where each group starts (the edges of a group contiguous; default one
    group), the results stacked ``(G, n, n)``, ``(G, n)``, ``(G,)``.

    With ``Pc`` the per-edge centred ``P``, ``J = Pc - a dphi``, so per edge
    ``J^T J = P^T P - n mean P mean P^T - S dphi^T - dphi S^T + (sum a^2) dphi dphi^T`` with
    ``S = sum a Pc`` and ``J^T r = P^T r - mean P sum r - dphi sum a r`` (the last two terms zero to
    rounding). A Gauss-Newton or Levenberg-Marquardt step needs only these (``n x n``), not the
    ``N x n`` Jacobian."""
    r, a, p_mat, t_mat = _projected(param, edges, th, True)
    assert p_mat is not None and t_mat is not None
    st, ct = edges.starts, edges.counts
    sum_p = np.add.reduceat(p_mat, st, axis=0)
    sum_ap = np.add.reduceat(a[:, None] * p_mat, st, axis=0)
    sum_rt = np.add.reduceat(r[:, None] * t_mat, st, axis=0)
    den = np.add.reduceat(a * a - r * r, st)
    dphi = (sum_ap + sum_rt) / np.where(np.abs(den) > 1e-300, den, 1e-300)[:, None]  # as _line_turn
    mean_p = sum_p / ct[:, None]
    sum_a = np.add.reduceat(a, st)
    sum_r = np.add.reduceat(r, st)
    sum_aa = np.add.reduceat(a * a, st)
    sum_ar = np.add.reduceat(a * r, st)
    s_ap = sum_ap - mean_p * sum_a[:, None]  # sum a Pc
    w = np.ones(edges.n_edges) if edge_weights is None else np.asarray(edge_weights, dtype=np.float64)
    w_pt = None if edge_weights is None else np.repeat(w, ct)
    bounds = [0] if groups is None else [int(g) for g in groups]
    bounds.append(edges.n_edges)
    n = p_mat.shape[1]
    ata = np.empty((len(bounds) - 1, n, n))
    atb = np.empty((len(bounds) - 1, n))
    ss = np.empty(len(bounds) - 1)
    for g, (e0, e1) in enumerate(zip(bounds[:-1], bounds[1:], strict=True)):
        p0 = int(st[e0]) if e0 < edges.n_edges else len(r)
        p1 = int(st[e1]) if e1 < edges.n_edges else len(r)
        pg, rg = p_mat[p0:p1], r[p0:p1]
        if w_pt is not None:
            rw = rg * w_pt[p0:p1]
            pw = pg * w_pt[p0:p1, None]
        else:
            rw, pw = rg, pg
        we = w[e0:e1]
        mp, dp, sp = mean_p[e0:e1], dphi[e0:e1], s_ap[e0:e1]
        cross = (sp * we[:, None]).T @ dp
        ata[g] = pw.T @ pg - (mp.T * (ct[e0:e1] * we)) @ mp - cross - cross.T + (dp.T * (sum_aa[e0:e1] * we)) @ dp
        atb[g] = pw.T @ rg - mp.T @ (sum_r[e0:e1] * we) - dp.T @ (sum_ar[e0:e1] * we)
        ss[g] = rw @ rg
    return ata, atb, ss


def _solve(
    param: Parametrisation,
    edges: EdgeSet,
    th0: np.ndarray,
    edge_weights: np.ndarray | None = None,
    max_nfev: int = 200,
) -> OptimizeResult:
    """Levenberg–Marquardt (MINPACK) on the residuals, optionally weighted per edge."""
    n_pts = len(edges.xy)
    sw = None if edge_weights is None else np.repeat(np.sqrt(edge_weights), edges.counts)

    last: dict[str, tuple[bytes, np.ndarray]] = {}  # the optimiser asks twice for some points: once is enough

    def fun(th: np.ndarray) -> np.ndarray:
        key = th.tobytes()
        if "fun" in last and last["fun"][0] == key:
            return last["fun"][1].copy()
        r, _ = residuals_and_jacobian(param, edges, th, jac=False)
        g, _ = param.regularisation(th, n_pts)
        out = np.concatenate([r if sw is None else r * sw, g])
        last["fun"] = (key, out)
        return out.copy()

    def jac(th: np.ndarray) -> np.ndarray:
        key = th.tobytes()
        if "jac" in last and last["jac"][0] == key:
            return last["jac"][1].copy()
        _, j = residuals_and_jacobian(param, edges, th, jac=True)
        assert j is not None
        _, jg = param.regularisation(th, n_pts)
        out = np.vstack([j if sw is None else j * sw[:, None], jg])
        last["jac"] = (key, out)
        return out.copy()

    return least_squares(
        fun, th0, jac=jac, method="lm", x_scale="jac", max_nfev=max_nfev, xtol=1e-12, ftol=1e-12, gtol=1e-12
    )


# ------------------------------------------------------------ input checks
def _orientation_problem(edges: EdgeSet, min_spread_deg: float) -> str | None:
    """None if the edges have at least two orientations, else the reason."""
    st, ct = edges.starts, edges.counts
    m = np.add.reduceat(edges.xy, st, axis=0) / ct[:, None]
    dev = edges.xy - np.repeat(m, ct, axis=0)
    sxx = np.add.reduceat(dev[:, 0] ** 2, st)
    syy = np.add.reduceat(dev[:, 1] ** 2, st)
    sxy = np.add.reduceat(dev[:, 0] * dev[:, 1], st)
    r = np.arctan2(2 * sxy, sxx - syy)  # doubled angle
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


def _fold_problem(model: DistortionModel, width: int, height: int) -> str | None:
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
def fit_distortion(
    lines_per_image: Sequence[Sequence[np.ndarray]],
    width: int,
    height: int,
    model: str = "radial",
    degree: int | None = None,
    tangential: bool = False,
    prism: bool = False,
    *,
    division: int = 0,
    image_sizes: Sequence[tuple[int, int]] | None = None,
    init: DistortionModel | None = None,
    robust: bool = True,
    reject_factor: float = 5.0,
    max_reject_fraction: float = 0.25,
    min_orientation_spread_deg: float = 20.0,
    ridge: float | None = None,
    w_center: float = FREE_CENTER_WEIGHT,
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
    model, degree, tangential, prism
        What to fit, as :meth:`pipeline.fitspec.FitSpec.fit_arguments` gives it:
        ``model`` 'radial' (:class:`~pipeline.models.radial.RadialModel`, free centre,
        ``k0 = 1``, ``k1..k_degree``, degree 1..10, default 4) or 'poly'
        (:class:`~pipeline.models.polynomial.PolynomialModel`, total degree 3..11,
        default 5); radial only: decentering (p1, p2) / thin-prism (s1..s4) terms.
        The bounds are :data:`pipeline.fitspec.DEGREE_BOUNDS`.
    division : int
        Radial only: division (rational) denominator coefficients ``d1 .. dM`` (0..3,
        :class:`~pipeline.models.radial.RadialModel`), started at 0.
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
    problem = spec_problem(model, degree, tangential, prism, division)
    if problem:
        return FitFailure(problem)
    spec = FitSpec(model, degree, tangential, prism, division=division)
    if image_sizes is not None:
        sizes = {(int(w), int(h)) for w, h in image_sizes}
        if sizes != {(int(width), int(height))}:
            return FitFailure(
                f"images of different sizes {sorted(sizes)}: one model fits one image size ({width}x{height})"
            )
    if len(lines_per_image) == 0:
        return FitFailure("no images given")
    edges, rejected = collect(lines_per_image, width, height)
    if not edges:
        return edges
    param = make_parametrisation(width, height, spec, w_center=w_center, ridge=ridge)
    n_e = edges.n_edges
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

    if init is None and isinstance(param, RadialParametrisation):
        try:
            k2 = alvarez_initial_k(edges.lines(), width, height)
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
    rejected = list(rejected)
    try:
        with np.errstate(all="ignore"):
            sol = _solve(param, edges, th, max_nfev=max_nfev)
            n_iter += sol.nfev
            th = sol.x
            if robust and n_e > MIN_EDGES:
                r, _ = residuals_and_jacobian(param, edges, th, jac=False)
                rms, _ = edge_figures(r, edges.starts, edges.counts)
                scale = 3.0 * max(float(np.median(rms)), 1e-6)
                weights = np.minimum(1.0, scale / np.maximum(rms, 1e-12))  # Huber weights per edge
                weighted = bool(np.any(weights < 1.0))
                if weighted:  # (all weights 1: the weighted problem is the one just solved)
                    sol = _solve(param, edges, th, edge_weights=weights, max_nfev=max_nfev)
                    n_iter += sol.nfev
                    th = sol.x
                    r, _ = residuals_and_jacobian(param, edges, th, jac=False)
                    rms, _ = edge_figures(r, edges.starts, edges.counts)
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
                    if edges.n_edges < MIN_EDGES:
                        return FitFailure(f"too few edges left after rejecting outliers: {edges.n_edges}")
                    problem = _orientation_problem(edges, min_orientation_spread_deg)
                    if problem:
                        return FitFailure("after rejecting outlier edges, " + problem)
                if weighted or len(bad):  # (else the final plain fit is the first one)
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
