"""The fit's solver (:mod:`pipeline.fit`): Levenberg-Marquardt on the normal equations of the
residuals, MINPACK's algorithm (trust region, scaling, stopping rules) [1]_, and MINPACK itself
(``scipy.optimize.least_squares``) when that one cannot go on (non-finite equations). A spent evaluation
budget is not such a case: MINPACK, the same algorithm from the same start, spends it too, ten times slower
on a large problem (the joint fit of a lens with a residual field and every string's bend, 284 parameters and
~10 000 points: 14 s for the budget on the normal equations, then 104 s for MINPACK's, each left unconverged),
so the last iterate is the solution, its status 0 (the fit says it stopped early).

References
----------
.. [1] J. J. Moré, "The Levenberg-Marquardt algorithm: implementation and theory", Numerical
   Analysis, Lecture Notes in Mathematics 630, Springer, 1978, pp. 105-116.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from pipeline.edgeset import EdgeSet
from pipeline.fit_problem import Parametrisation, normal_equations, residuals_and_jacobian

if TYPE_CHECKING:
    from scipy.optimize import OptimizeResult


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
BUDGET_SPENT = "the evaluation budget is spent (max_nfev): the last iterate, not converged"
"""The message of a :class:`Solution` whose solver stopped at its evaluation budget (status 0)."""
LM_FACTOR = 100.0
"""MINPACK's ``factor``: the first trust-region radius, times the scaled parameters' length."""


def _lm_step(a: np.ndarray, b: np.ndarray, diag: np.ndarray, delta: float) -> tuple[np.ndarray, float]:
    """The Levenberg-Marquardt step ``h`` of ``(a + par D^2) h = -b``, ``D = diag(diag)``: the
    Gauss-Newton step (``par = 0``) when ``|D h| <= 1.1 delta``, else ``par > 0`` with ``|D h|``
    within 10 % of ``delta`` (MINPACK's ``lmpar`` criterion), found by safeguarded Newton steps on
    ``1 / |D h(par)|`` over the eigen-decomposition of the scaled ``a`` (Moré 1978). The Gauss-Newton step is
    tried first from a Cholesky factor (:func:`_gauss_newton`; on the joint fits with a residual field it is the
    step of nearly every iteration), the eigen-decomposition made only when that one is not taken."""
    inv = 1.0 / diag
    scaled = a * inv[:, None] * inv[None, :]
    gauss_newton = _gauss_newton(scaled, b * inv, delta)
    if gauss_newton is not None:
        return -gauss_newton * inv, 0.0
    lam, vec = np.linalg.eigh(scaled)
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


GN_RCOND = 1e-11
""":func:`_gauss_newton` takes the Cholesky factor's step only when LAPACK's estimate of the reciprocal condition
number (1-norm) of the scaled normal matrix is above this; else :func:`_lm_step` decides on its eigenvalues."""


def _gauss_newton(scaled: np.ndarray, g: np.ndarray, delta: float) -> np.ndarray | None:
    """The scaled Gauss-Newton step ``s^-1 g`` by a Cholesky factorisation when ``s`` is well conditioned
    (:data:`GN_RCOND`) and the step is within ``1.1 delta``: then it is :func:`_lm_step`'s ``par = 0`` step,
    solved another way (a third of the eigen-decomposition's time). None otherwise."""
    from scipy.linalg import cho_factor, cho_solve, lapack

    try:
        factor = cho_factor(scaled, lower=False, check_finite=False)
    except np.linalg.LinAlgError:
        return None
    rcond, info = lapack.dpocon(factor[0], float(np.abs(scaled).sum(axis=0).max()), "U")
    if info != 0 or not rcond > GN_RCOND:
        return None
    h = cho_solve(factor, g, check_finite=False)
    return h if float(np.linalg.norm(h)) <= 1.1 * delta else None


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
    Jacobian. With the evaluation budget spent, the last accepted iterate with status 0 (as MINPACK's).
    None when it cannot go on (non-finite equations): the caller then runs MINPACK itself.

    References
    ----------
    .. [1] J. J. Moré, "The Levenberg-Marquardt algorithm: implementation and theory", Numerical
       Analysis, LNM 630, Springer, 1978.
    .. [2] J. J. Moré, B. S. Garbow, K. E. Hillstrom, *User guide for MINPACK-1*, ANL-80-74, 1980.
    """
    n_pts = len(edges.xy)
    sw = edges.point_weights(edge_weights)

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
                return Solution(x, 0.5 * f, nfev, 0, BUDGET_SPENT)
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
    """Levenberg–Marquardt on the residuals, optionally weighted per edge (and per point,
    :attr:`EdgeSet.weights`): on the normal equations
    (:func:`_levenberg_marquardt`; with ``max_nfev`` spent, its last iterate, status 0), or MINPACK's on the
    Jacobian when that one cannot go on (non-finite equations)."""
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
    pw = edges.point_weights(edge_weights)
    sw = None if pw is None else np.sqrt(pw)

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
