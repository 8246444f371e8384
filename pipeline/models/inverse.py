"""The one safeguarded inverse of the models whose inverse has no closed form.

A model's map ``F`` (:meth:`~pipeline.models.base.DistortionModel.undistort_points` for the
harp models, the projection for OpenCV's, the bilinear maps of a maps file) is inverted at
``F(x) = t`` by :func:`newton_inverse`: Newton steps on ``F`` (Jacobian by central differences
unless given) damped by backtracking (a step is halved until the residual does not grow and the
point stays inside the map's invertible domain), from a start the caller chooses. A radial map
starts from :func:`radial_start`, the exact inverse of its radial part, bracketed on the radius
inside :func:`monotonic_reach` (where the radial map still increases: before its fold or pole),
so that Newton never wanders to a far root of ``F`` beyond a fold (a point with no inverse in the
domain gets none, instead of a far-away one).

The answer, :class:`Inverse`, holds the points (NaN where there is no inverse) and, per point, a
reason code of :data:`INVERSE_REASONS`, so callers can say why.

References
----------
.. [1] J. E. Dennis, R. B. Schnabel, *Numerical Methods for Unconstrained Optimization and
   Nonlinear Equations*, SIAM 1996, ch. 6 (backtracking line search on Newton steps).
.. [2] W. H. Press et al., *Numerical Recipes*, 3rd ed., 2007, sect. 9.4 (``rtsafe``: Newton
   safeguarded by bisection inside a bracket).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

Array = npt.NDArray[np.float64]
Mask = npt.NDArray[np.bool_]
PointMap = Callable[[Array], Array]
RadialMap = Callable[[Array], Array]

INVERTED = 0
"""Reason code: inverted to the tolerance."""
NOT_CONVERGED = 1
"""Reason code: no convergence within the iterations."""
OUTSIDE_DOMAIN = 2
"""Reason code: the inverse would lie outside the domain where the map is invertible."""
FOLDED = 3
"""Reason code: the map folds (Jacobian determinant <= 0) at the solution."""
NOT_FINITE = 4
"""Reason code: the point or the map there is not finite."""

INVERSE_REASONS: dict[int, str] = {
    INVERTED: "inverted",
    NOT_CONVERGED: "Newton iterations did not converge",
    OUTSIDE_DOMAIN: "no inverse inside the domain where the map is invertible (beyond its fold, pole or defined area)",
    FOLDED: "the map folds there (Jacobian determinant <= 0): no unique inverse",
    NOT_FINITE: "the point, or the map at it, is not finite",
}
"""What each reason code of :attr:`Inverse.reason` means."""

MAX_HALVINGS = 40
"""Most halvings of a Newton step in the backtracking line search."""


@dataclass(frozen=True, eq=False)
class Inverse:
    """Inverse points and why some have none.

    Attributes
    ----------
    points : (N, 2) float64
        The inverse, NaN where there is none.
    reason : (N,) int8
        A code of :data:`INVERSE_REASONS` per point (``INVERTED`` where ``points`` is finite).
    """

    points: Array
    reason: npt.NDArray[np.int8]

    @property
    def ok(self) -> Mask:
        """Where the inverse exists."""
        out: Mask = self.reason == INVERTED
        return out

    def summary(self) -> str:
        """One line: how many points have no inverse, and why (empty when all do)."""
        parts = [
            f"{int(np.sum(self.reason == code))} {text}"
            for code, text in INVERSE_REASONS.items()
            if code != INVERTED and np.any(self.reason == code)
        ]
        return "; ".join(parts)


def _jacobian_fd(forward: PointMap, x: Array, h: float) -> tuple[Array, Array, Array, Array]:
    jx = (forward(x + [h, 0.0]) - forward(x - [h, 0.0])) / (2 * h)
    jy = (forward(x + [0.0, h]) - forward(x - [0.0, h])) / (2 * h)
    return jx[:, 0], jy[:, 0], jx[:, 1], jy[:, 1]


def newton_inverse(
    forward: PointMap,
    target: Array,
    start: Array,
    *,
    tol: float,
    h: float,
    max_iter: int = 50,
    inside: Callable[[Array], Mask] | None = None,
    jacobian: Callable[[Array], tuple[Array, Array, Array, Array]] | None = None,
) -> Inverse:
    """Solve ``forward(x) = target`` per point by damped Newton steps from ``start``.

    Parameters
    ----------
    forward : callable ``(N, 2) -> (N, 2)``
        The map to invert (vectorised).
    target, start : (N, 2)
        The values to reach and the first guesses (NaN in either: ``NOT_FINITE``).
    tol : float
        Converged when both components of ``forward(x) - target`` are below ``tol``.
    h : float
        Central-difference step of the Jacobian (unused with ``jacobian``).
    max_iter : int
        Most Newton steps.
    inside : callable ``(N, 2) -> (N,) bool``, optional
        The domain where ``forward`` is invertible; iterates never leave it (a step that would
        is halved) and a start outside it is ``OUTSIDE_DOMAIN``.
    jacobian : callable, optional
        ``x -> (dF_x/dx, dF_x/dy, dF_y/dx, dF_y/dy)``, each ``(N,)``; default central differences.

    Returns
    -------
    Inverse
        ``INVERTED`` where converged with a positive Jacobian determinant inside the domain;
        ``OUTSIDE_DOMAIN`` where the iterations stalled against the domain's border (the
        solution is beyond it); ``FOLDED`` where the determinant is not positive;
        ``NOT_CONVERGED`` otherwise.
    """
    t = np.asarray(target, dtype=np.float64).reshape(-1, 2)
    x = np.array(start, dtype=np.float64).reshape(-1, 2)
    n = len(t)
    reason = np.full(n, NOT_CONVERGED, np.int8)
    active = np.all(np.isfinite(t), axis=1) & np.all(np.isfinite(x), axis=1)
    reason[~active] = NOT_FINITE
    if inside is not None and active.any():
        out = np.zeros(n, bool)
        out[active] = ~inside(x[active])
        reason[out] = OUTSIDE_DOMAIN
        active &= ~out
    jac = jacobian if jacobian is not None else (lambda p: _jacobian_fd(forward, p, h))
    idx = np.flatnonzero(active)
    r = np.full((n, 2), np.nan)
    if len(idx):
        r[idx] = forward(x[idx]) - t[idx]
    blocked = np.zeros(n, bool)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        for it in range(max_iter + 1):
            bad = ~np.all(np.isfinite(r[idx]), axis=1)
            reason[idx[bad]] = NOT_FINITE
            idx = idx[~bad]
            conv = np.all(np.abs(r[idx]) < tol, axis=1)
            reason[idx[conv]] = INVERTED
            idx = idx[~conv]
            if len(idx) == 0 or it == max_iter:
                break
            a, b, c, d = jac(x[idx])
            det = a * d - b * c
            fold = ~(det > 0)
            reason[idx[fold]] = FOLDED
            idx, a, b, c, d, det = idx[~fold], a[~fold], b[~fold], c[~fold], d[~fold], det[~fold]
            ri = r[idx]
            step = np.stack([(d * ri[:, 0] - b * ri[:, 1]) / det, (-c * ri[:, 0] + a * ri[:, 1]) / det], axis=1)
            norm0 = np.hypot(ri[:, 0], ri[:, 1])
            lam = np.ones(len(idx))
            todo = np.ones(len(idx), bool)
            blocked[idx] = False
            for halving in range(MAX_HALVINGS):
                j = np.flatnonzero(todo)
                if len(j) == 0:
                    break
                trial = x[idx[j]] - lam[j, None] * step[j]
                ok = np.ones(len(j), bool) if inside is None else inside(trial)
                if halving == 0:
                    blocked[idx[j[~ok]]] = True
                rt = np.full((len(j), 2), np.inf)
                if ok.any():
                    rt[ok] = forward(trial[ok]) - t[idx[j[ok]]]
                nt = np.hypot(rt[:, 0], rt[:, 1])
                acc = ok & np.isfinite(nt) & ((nt <= norm0[j]) | np.all(np.abs(rt) < tol, axis=1))
                x[idx[j[acc]]] = trial[acc]
                r[idx[j[acc]]] = rt[acc]
                todo[j[acc]] = False
                lam[j[~acc]] *= 0.5
            stuck = todo  # no step kept the residual from growing: a local minimum of |F - t|, or the border
            reason[idx[stuck]] = np.where(blocked[idx[stuck]], OUTSIDE_DOMAIN, NOT_CONVERGED)
            idx = idx[~stuck]
    reason[idx] = np.where(blocked[idx], OUTSIDE_DOMAIN, NOT_CONVERGED)
    good = reason == INVERTED
    if good.any():  # the solution must not sit on a fold
        a, b, c, d = jac(x[good])
        det = a * d - b * c
        g = np.flatnonzero(good)
        reason[g[~(det > 0)]] = FOLDED
    x[reason != INVERTED] = np.nan
    return Inverse(points=x, reason=reason)


def monotonic_reach(g: RadialMap, limit: float, step: float = 1e-3) -> float:
    """The radius up to which the radial map ``g`` (``g(0) = 0``) is finite and increasing.

    ``g`` is sampled every ``step`` on ``[0, limit]``; the first sample where it stops
    increasing (a fold: ``g' <= 0``; a pole: a jump or a non-finite value) is refined by
    bisection on the sign of ``g'``. Returns ``limit`` when ``g`` increases all the way.
    """
    rho = np.arange(0.0, limit + step / 2, step)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        v = g(rho)
    dv = np.diff(v)
    bad = ~(np.isfinite(v[1:]) & (dv > 0))
    if not bad.any():
        return float(limit)
    i = int(np.argmax(bad))  # g increases on [rho[0], rho[i]]; not on [rho[i], rho[i + 1]]
    lo, hi = float(rho[i]), float(rho[i + 1])
    eps = 1e-3 * step  # central differences: exact to O(eps^2 g'''), far above rounding

    def rising(r: float) -> bool:
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            a, b = g(np.array([r - eps, r + eps]))
        return bool(np.isfinite(a) and np.isfinite(b) and b > a)

    for _ in range(60):
        mid = 0.5 * (lo + hi)
        if rising(mid):
            lo = mid
        else:
            hi = mid
    return lo


def radial_start(g: RadialMap, values: Array, reach: float, tol: float) -> tuple[Array, Mask]:
    """Solve ``g(rho) = values`` for ``rho`` in ``[0, reach]`` (``g`` increasing there).

    Newton steps safeguarded by bisection inside the bracket (``rtsafe``), to ``|g - v| < tol``.
    Returns ``(rho, ok)``: ``ok`` is False where ``v`` lies beyond ``g(reach)`` (no inverse
    inside the domain; ``rho`` is ``reach`` there) or is not finite.
    """
    v = np.asarray(values, dtype=np.float64).ravel()
    top = float(g(np.array([reach]))[0])
    ok = np.isfinite(v) & (v >= 0) & (v <= top)
    lo = np.zeros_like(v)
    hi = np.full_like(v, reach)
    rho = np.where(ok, np.clip(v, 0.0, reach), reach)
    dh = 1e-7 * max(reach, 1.0)
    for _ in range(200):
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            gv = g(rho) - v
            done = ~ok | (np.abs(gv) < tol)
            if done.all():
                break
            lo = np.where(gv < 0, rho, lo)
            hi = np.where(gv > 0, rho, hi)
            below = np.maximum(rho - dh, 0.0)
            dg = (g(rho + dh) - g(below)) / (rho + dh - below)
            nxt = rho - gv / dg
        bisect = ~((nxt > lo) & (nxt < hi) & np.isfinite(nxt))
        nxt = np.where(bisect, 0.5 * (lo + hi), nxt)
        stalled = hi - lo < 4 * np.finfo(np.float64).eps * np.maximum(hi, 1.0)
        rho = np.where(done | stalled, rho, nxt)
        if np.all(done | stalled):
            break
    return rho, ok
