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
Levenberg–Marquardt, all edges of all images at once, in coordinates normalised
by half the image diagonal: MINPACK's algorithm (trust region, scaling, stopping
rules) on the normal equations :math:`J^T J`, :math:`J^T r`, which the per-edge
moments give without forming the :math:`N \times n` Jacobian
(:func:`normal_equations`); MINPACK itself (``scipy.optimize.least_squares``)
when that cannot finish.

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
* ``radial`` with a residual field (:mod:`pipeline.models.radial_field`): the radial
  part as above; the field's affine part (translation, rotation, scale, shear: invisible,
  and the null space of its roughness penalty) is held at zero by a penalty on its
  projection, and its first-order projective (quadratic) part, like everything it could
  bend along strings few orientations cannot see, by the roughness penalty.

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
from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol

import numpy as np

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
from pipeline.fitspec import CENTER_PRIOR_WEIGHT, FREE_CENTER_WEIGHT, FitSpec, spec_problem
from pipeline.models.base import DistortionModel
from pipeline.models.polynomial import PolynomialParametrisation
from pipeline.models.radial import RadialParametrisation
from pipeline.models.radial_field import RadialFieldParametrisation

if TYPE_CHECKING:
    from scipy.optimize import OptimizeResult

MIN_EDGES = 4
"""A fit needs at least this many usable edges."""

FAR_CENTRE = 0.05
"""A free distortion centre farther than this from the image centre (in half image diagonals) is
checked against the fit started from the centre-prior solution (:func:`fit_distortion`)."""


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
) -> RadialParametrisation | RadialFieldParametrisation | PolynomialParametrisation:
    """The free parameters of ``spec`` for a ``width x height`` image (see module doc).

    ``w_center`` defaults to the spec's (:attr:`FitSpec.w_center`); ``ridge`` to 0 for
    radial, 1e-4 for poly. A spec with a field: the radial parameters followed by the field's
    (:class:`~pipeline.models.radial_field.RadialFieldParametrisation`).
    """
    if spec.kind == "radial":
        radial = RadialParametrisation(
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
        if spec.field is None:
            return radial
        return RadialFieldParametrisation(
            radial, width, height, (spec.field[1], spec.field[0]), float(spec.field_penalty or 0)
        )
    return PolynomialParametrisation(width, height, int(spec.degree or 0), 1e-4 if ridge is None else ridge)


# ------------------------------------------------------------- objective
def _projected(
    param: Parametrisation, edges: EdgeSet, th: np.ndarray, jac: bool
) -> tuple[np.ndarray, np.ndarray, np.ndarray | None, np.ndarray | None]:
    """``(r, a, P, T)``: the residuals, the positions along the lines and (``jac``) the Jacobian of
    the corrected points projected on each point's line normal (``P``) and direction (``T``), one row
    per parameter (``(n, N)``)."""
    u, _ = param.evaluate(edges.xy, th, jac=False)
    r, a, nrm, tan, _ = tls(u, edges.starts, edges.counts)
    if not jac:
        return r, a, None, None
    p_mat, t_mat = param.project(edges.xy, th, nrm, tan)
    return r, a, p_mat, t_mat


def _line_turn(
    p_mat: np.ndarray, t_mat: np.ndarray, r: np.ndarray, a: np.ndarray, st: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per edge (columns, ``(n, E)``): the sums of ``P`` and of ``a P``, and ``d phi / d theta``, the
    rotation of its TLS line (Golub-Pereyra):
    ``d phi = sum_i (a_i (P_i - mean P) + r_i (T_i - mean T)) / sum_i (a_i^2 - r_i^2)``; the means
    drop out because ``sum a = sum r = 0`` on each edge (distances from its centroid)."""
    sum_p = np.add.reduceat(p_mat, st, axis=1)
    sum_ap = np.add.reduceat(p_mat * a, st, axis=1)
    sum_rt = np.add.reduceat(t_mat * r, st, axis=1)
    den = np.add.reduceat(a * a - r * r, st)
    return sum_p, sum_ap, (sum_ap + sum_rt) / np.where(np.abs(den) > 1e-300, den, 1e-300)


def residuals_and_jacobian(
    param: Parametrisation, edges: EdgeSet, th: np.ndarray, jac: bool = True
) -> tuple[np.ndarray, np.ndarray | None]:
    """Signed distances of the corrected points to their own edge's TLS line, and (``jac``)
    their analytic Jacobian ``(N, n)`` in ``theta``, the line's motion included (variable
    projection): ``J_i = P_i - mean_e P - a_i d phi_e`` (``P_i = n_e . du_i``, :func:`_line_turn`)."""
    r, a, p_mat, t_mat = _projected(param, edges, th, jac)
    if p_mat is None or t_mat is None:
        return r, None
    st, ct = edges.starts, edges.counts
    sum_p, _, dphi = _line_turn(p_mat, t_mat, r, a, st)
    j = p_mat - np.repeat(sum_p / ct, ct, axis=1)
    j -= np.repeat(dphi, ct, axis=1) * a
    return r, j.T


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
    sum_p, sum_ap, dphi = _line_turn(p_mat, t_mat, r, a, st)
    mean_p = sum_p / ct
    sum_a = np.add.reduceat(a, st)
    sum_r = np.add.reduceat(r, st)
    sum_aa = np.add.reduceat(a * a, st)
    sum_ar = np.add.reduceat(a * r, st)
    s_ap = sum_ap - mean_p * sum_a  # sum a Pc
    w = np.ones(edges.n_edges) if edge_weights is None else np.asarray(edge_weights, dtype=np.float64)
    w_pt = None if edge_weights is None else np.repeat(w, ct)
    bounds = [0] if groups is None else [int(g) for g in groups]
    bounds.append(edges.n_edges)
    n = p_mat.shape[0]
    ata = np.empty((len(bounds) - 1, n, n))
    atb = np.empty((len(bounds) - 1, n))
    ss = np.empty(len(bounds) - 1)
    for g, (e0, e1) in enumerate(zip(bounds[:-1], bounds[1:], strict=True)):
        p0 = int(st[e0]) if e0 < edges.n_edges else len(r)
        p1 = int(st[e1]) if e1 < edges.n_edges else len(r)
        pg, rg = p_mat[:, p0:p1], r[p0:p1]
        if w_pt is not None:
            rw = rg * w_pt[p0:p1]
            pw = pg * w_pt[p0:p1]
        else:
            rw, pw = rg, pg
        we = w[e0:e1]
        mp, dp, sp = mean_p[:, e0:e1], dphi[:, e0:e1], s_ap[:, e0:e1]
        cross = (sp * we) @ dp.T
        ata[g] = pw @ pg.T - (mp * (ct[e0:e1] * we)) @ mp.T - cross - cross.T + (dp * (sum_aa[e0:e1] * we)) @ dp.T
        atb[g] = pw @ rg - mp @ (sum_r[e0:e1] * we) - dp @ (sum_ar[e0:e1] * we)
        ss[g] = rw @ rg
    return ata, atb, ss


@dataclass(frozen=True)
class Solution:
    """What a least-squares run found (the fields of scipy's ``OptimizeResult`` that are used)."""

    x: np.ndarray
    cost: float  # half the sum of squares, as scipy reports it
    nfev: int
    status: int  # > 0 converged, 0 evaluation budget spent
    message: str


LM_TOL = 1e-12
"""MINPACK's ``ftol``, ``xtol`` and ``gtol`` as the fit sets them: relative reductions of the sum of squares,
trust-region radius relative to the scaled parameters, cosine of the gradient with the residuals."""
LM_FACTOR = 100.0
"""MINPACK's ``factor``: the first trust-region radius, times the scaled parameters' length."""


def _lm_step(a: np.ndarray, b: np.ndarray, diag: np.ndarray, delta: float) -> tuple[np.ndarray, float]:
    """The Levenberg-Marquardt step ``h`` of ``(a + par D^2) h = -b``, ``D = diag(diag)``: the
    Gauss-Newton step (``par = 0``) when ``|D h| <= 1.1 delta``, else ``par > 0`` with ``|D h|``
    within 10 % of ``delta`` (MINPACK's ``lmpar`` criterion), found by safeguarded Newton steps on
    ``1 / |D h(par)|`` over the eigen-decomposition of the scaled ``a`` (Moré 1978)."""
    inv = 1.0 / diag
    lam, vec = np.linalg.eigh(a * inv[:, None] * inv[None, :])
    c = vec.T @ (b * inv)
    c2 = c * c
    lam = np.maximum(lam, 0.0)
    floor = 1e-14 * max(float(lam[-1]), 1e-300)

    def norm_at(par: float) -> tuple[float, float]:
        den = lam + par
        return float(np.sqrt(np.sum(c2 / (den * den)))), -2.0 * float(np.sum(c2 / (den * den * den)))

    if lam[0] > floor and norm_at(0.0)[0] <= 1.1 * delta:
        return -(vec @ (c / lam)) * inv, 0.0
    lo, hi = 0.0, float(np.sqrt(np.sum(c2))) / delta  # |D h(hi)| <= delta
    par = max(1e-3 * hi, floor)
    for _ in range(50):
        q, dq2 = norm_at(par)
        if abs(q - delta) <= 0.1 * delta:
            break
        if q > delta:
            lo = par
        else:
            hi = par
        # Newton on 1/q - 1/delta (nearly linear in par): d(1/q)/dpar = -dq2 / (2 q^3)
        new = par - (1.0 / q - 1.0 / delta) / (-dq2 / (2.0 * q**3)) if dq2 != 0 else 0.5 * (lo + hi)
        par = new if lo < new < hi else 0.5 * (lo + hi)
    return -(vec @ (c / (lam + par))) * inv, par


def _levenberg_marquardt(
    param: Parametrisation,
    edges: EdgeSet,
    th0: np.ndarray,
    edge_weights: np.ndarray | None,
    max_nfev: int,
) -> Solution | None:
    """MINPACK's Levenberg-Marquardt (``lmder``: a trust region on the step scaled by the running
    maximum of the Jacobian's column norms, its radius update and its stopping rules) on the normal
    equations (:func:`normal_equations`, ``n x n``) instead of a QR factorisation of the ``N x n``
    Jacobian. None when it cannot go on (non-finite equations, the evaluation budget spent): the
    caller then runs MINPACK itself.

    References
    ----------
    .. [1] J. J. Moré, "The Levenberg-Marquardt algorithm: implementation and theory", Numerical
       Analysis, LNM 630, Springer, 1978.
    .. [2] J. J. Moré, B. S. Garbow, K. E. Hillstrom, *User guide for MINPACK-1*, ANL-80-74, 1980.
    """
    n_pts = len(edges.xy)
    sw = None if edge_weights is None else np.repeat(edge_weights, edges.counts)

    def cost(t: np.ndarray) -> float:
        r, _ = residuals_and_jacobian(param, edges, t, jac=False)
        g, _ = param.regularisation(t, n_pts)
        c = float((r if sw is None else r * sw) @ r + g @ g)
        return c if np.isfinite(c) else float("inf")

    def equations(t: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
        ata, atb, _ = normal_equations(param, edges, t, edge_weights=edge_weights)
        g, jg = param.regularisation(t, n_pts)
        a = ata[0] + jg.T @ jg
        b = atb[0] + jg.T @ g
        return (a, b) if np.all(np.isfinite(a)) and np.all(np.isfinite(b)) else None

    eps = float(np.finfo(np.float64).eps)
    x = np.asarray(th0, dtype=np.float64).copy()
    f = cost(x)
    nfev = 1
    if not np.isfinite(f):
        return None
    diag = np.zeros(len(x))
    delta = xnorm = 0.0
    first = True
    while True:
        eq = equations(x)
        if eq is None:
            return None
        a, b = eq
        col = np.sqrt(np.maximum(np.diag(a), 0.0))
        if first:
            diag = np.where(col > 0, col, 1.0)
            xnorm = float(np.linalg.norm(diag * x))
            delta = LM_FACTOR * xnorm if xnorm > 0 else LM_FACTOR
        if f == 0.0:
            return Solution(x, 0.0, nfev, 1, "zero residual")
        nz = col > 0
        if not nz.any() or float(np.max(np.abs(b[nz]) / (col[nz] * np.sqrt(f)))) <= LM_TOL:
            return Solution(x, 0.5 * f, nfev, 4, "the gradient is orthogonal to the residuals (gtol)")
        diag = np.maximum(diag, col)
        while True:
            try:
                h, par = _lm_step(a, b, diag, delta)
            except np.linalg.LinAlgError:
                return None
            pnorm = float(np.linalg.norm(diag * h))
            if first:
                delta = min(delta, pnorm)
            f_new = cost(x + h)
            nfev += 1
            actred = 1.0 - f_new / f if 0.1 * np.sqrt(f_new) < np.sqrt(f) else -1.0
            jh2 = float(h @ a @ h) / f
            dp2 = par * pnorm * pnorm / f
            prered = jh2 + 2.0 * dp2
            dirder = -(jh2 + dp2)
            ratio = actred / prered if prered != 0 else 0.0
            if ratio <= 0.25:
                temp = 0.5 if actred >= 0 else 0.5 * dirder / (dirder + 0.5 * actred)
                if 0.1 * np.sqrt(f_new) >= np.sqrt(f) or temp < 0.1:
                    temp = 0.1
                delta = temp * min(delta, pnorm / 0.1)
            elif par == 0.0 or ratio >= 0.75:
                delta = pnorm / 0.5
            accepted = ratio >= 1e-4
            if accepted:
                x = x + h
                f = f_new
                xnorm = float(np.linalg.norm(diag * x))
                first = False
            if abs(actred) <= LM_TOL and prered <= LM_TOL and 0.5 * ratio <= 1.0:
                return Solution(x, 0.5 * f, nfev, 2, "both actual and predicted relative reductions below ftol")
            if delta <= LM_TOL * xnorm:
                return Solution(x, 0.5 * f, nfev, 3, "the trust region is below xtol of the parameters")
            if nfev >= max_nfev:
                return None
            if abs(actred) <= eps and prered <= eps and 0.5 * ratio <= 1.0:
                return Solution(x, 0.5 * f, nfev, 2, "no further reduction is possible (machine precision)")
            if delta <= eps * xnorm:
                return Solution(x, 0.5 * f, nfev, 3, "no further improvement is possible (machine precision)")
            if accepted:
                break


def solve(
    param: Parametrisation,
    edges: EdgeSet,
    th0: np.ndarray,
    edge_weights: np.ndarray | None = None,
    max_nfev: int = 200,
) -> Solution:
    """Levenberg–Marquardt on the residuals, optionally weighted per edge: on the normal equations
    (:func:`_levenberg_marquardt`), or MINPACK's on the Jacobian when that one cannot finish."""
    sol = _levenberg_marquardt(param, edges, th0, edge_weights, max_nfev)
    if sol is not None:
        return sol
    ref = _solve_minpack(param, edges, th0, edge_weights, max_nfev)
    return Solution(np.asarray(ref.x), float(ref.cost), int(ref.nfev), int(ref.status), str(ref.message))


def _solve_minpack(
    param: Parametrisation,
    edges: EdgeSet,
    th0: np.ndarray,
    edge_weights: np.ndarray | None = None,
    max_nfev: int = 200,
) -> OptimizeResult:
    """Levenberg–Marquardt (MINPACK) on the residuals, optionally weighted per edge."""
    from scipy.optimize import least_squares  # only when the normal-equations solver cannot finish

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


def fold_problem(model: DistortionModel, width: int, height: int) -> str | None:
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
    field: tuple[int, int] | None = None,
    field_penalty: float | None = None,
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
    field, field_penalty
        Radial only: a residual field of ``(nx, ny)`` B-spline control points and its roughness
        weight (:class:`~pipeline.models.radial_field.RadialFieldParametrisation`; default
        :data:`pipeline.fitspec.DEFAULT_FIELD_PENALTY`), started at 0 (or at ``init``'s).
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
    problem = spec_problem(model, degree, tangential, prism, division, field, field_penalty)
    if problem:
        return FitFailure(problem)
    spec = FitSpec(model, degree, tangential, prism, division=division, field=field, field_penalty=field_penalty)
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

    radial_like = isinstance(param, (RadialParametrisation, RadialFieldParametrisation))
    if init is None and radial_like:
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
            sol = solve(param, edges, th, max_nfev=max_nfev)
            n_iter += sol.nfev
            if (
                init is None
                and isinstance(param, (RadialParametrisation, RadialFieldParametrisation))
                and param.w_center < CENTER_PRIOR_WEIGHT
                and float(np.hypot(*sol.x[:2])) > FAR_CENTRE
            ):
                # continuation: a free centre that ended far from the image centre may sit in a local
                # minimum (a lens decentred by 60 px on 1000x750 with tangential and prism terms ended
                # 300 px away); the same fit started from its centre-prior solution, the lower cost kept
                held = make_parametrisation(width, height, spec, w_center=CENTER_PRIOR_WEIGHT, ridge=ridge)
                pre = solve(held, edges, th, max_nfev=max_nfev)
                alt = solve(param, edges, pre.x, max_nfev=max_nfev)
                n_iter += pre.nfev + alt.nfev
                if alt.cost < sol.cost:
                    sol = alt
            th = sol.x
            if robust and n_e > MIN_EDGES:
                r, _ = residuals_and_jacobian(param, edges, th, jac=False)
                rms, _ = edge_figures(r, edges.starts, edges.counts)
                scale = 3.0 * max(float(np.median(rms)), 1e-6)
                weights = np.minimum(1.0, scale / np.maximum(rms, 1e-12))  # Huber weights per edge
                weighted = bool(np.any(weights < 1.0))
                if weighted:  # (all weights 1: the weighted problem is the one just solved)
                    sol = solve(param, edges, th, edge_weights=weights, max_nfev=max_nfev)
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
                    sol = solve(param, edges, th, max_nfev=max_nfev)
                    n_iter += sol.nfev
                    th = sol.x
    except (ValueError, np.linalg.LinAlgError) as exc:
        return FitFailure(f"optimisation failed: {exc}")
    if not np.all(np.isfinite(th)):
        return FitFailure("optimisation diverged (non-finite parameters)")
    fitted = param.model(th)
    fold = fold_problem(fitted, width, height)
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
