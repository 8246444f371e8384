r"""Alvarez–Gómez–Sendra line-rectification energy, and its algebraic minimiser.

Alvarez, Gómez and Sendra correct radial distortion with
:math:`x_u = c + L(r)(x_d - c)`, :math:`L(r) = 1 + k_1 \rho^2 + k_2 \rho^4`
(:math:`\rho = |x_d - c| / s`), choosing :math:`k` to minimise the energy

.. math::
    E(k) = \frac{1}{L} \sum_{l} \big(S^l_{xx} S^l_{yy} - (S^l_{xy})^2\big)

where :math:`S^l` are the centred second moments (per-point means) of the
corrected points of line :math:`l`: the determinant of a line's scatter
matrix is zero exactly when its points are collinear. Because the corrected
points are linear in :math:`k`, every :math:`S` is quadratic and :math:`E` is
a quartic polynomial in :math:`k`: with one coefficient its minimum is a root
of a cubic (closed form); with two, :math:`E` is minimised from that start.

Their method needed lines picked by hand; fed with the automatic harp edges
of :mod:`pipeline.measure` it becomes automatic (Tang et al. 2012, Sect. 6:
"automatic edges make Alvarez's method automatic"). Here it also provides the
initial ``k2`` of :func:`pipeline.fit.fit_distortion` for the radial model. It works on
the edge set of :mod:`pipeline.edgeset`, as the fit does.

References
----------
.. [1] L. Alvarez, L. Gómez, J. R. Sendra, "An algebraic approach to lens
   distortion by line rectification", J. Math. Imaging Vis. 35(1), 2009.
.. [2] Z. Tang et al., "High-precision camera distortion measurements with a
   calibration harp", JOSA A 29(10), 2012.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.polynomial import polynomial as P
from numpy.typing import ArrayLike, NDArray

from pipeline.edgeset import FitFailure, FitResult, collect, summarise
from pipeline.models.base import DistortionModel
from pipeline.models.radial import RadialModel

Floats = NDArray[np.float64]


def alvarez_energy(lines: Sequence[np.ndarray], model: DistortionModel | None = None) -> float:
    """E = mean over lines of ``S_xx S_yy - S_xy^2`` of the (corrected) points, px^4."""
    vals = []
    for p in lines:
        p = np.asarray(p, dtype=np.float64).reshape(-1, 2)
        if len(p) < 3:
            continue
        u = model.undistort_points(p) if model is not None else p
        d = u - u.mean(axis=0)
        sxx, syy, sxy = np.mean(d[:, 0] ** 2), np.mean(d[:, 1] ** 2), np.mean(d[:, 0] * d[:, 1])
        vals.append(sxx * syy - sxy * sxy)
    if not vals:
        raise ValueError("alvarez_energy needs at least one line of >= 3 points")
    return float(np.mean(vals))


def _line_terms(
    lines: Sequence[np.ndarray], center: Floats, scale: float, powers: Sequence[int]
) -> list[tuple[Floats, Floats]]:
    """Per line: centred x (N,2) and the centred displacement basis (K, N, 2)."""
    out = []
    for p in lines:
        p = np.asarray(p, dtype=np.float64).reshape(-1, 2)
        if len(p) < 3:
            continue
        q = p - center
        rho2 = np.sum(q * q, axis=1) / scale**2
        v = np.stack([(rho2 ** (k // 2))[:, None] * q for k in powers])  # rho^k (x - c)
        out.append((p - p.mean(axis=0), v - v.mean(axis=1, keepdims=True)))
    if not out:
        raise ValueError("need at least one line of >= 3 points")
    return out


def _quartic_one(lines: Sequence[np.ndarray], center: np.ndarray, scale: float, power: int = 2) -> NDArray[np.float64]:
    """Coefficients (ascending) of E(k) for u = x + k rho^power (x - c).

    Per line, with centred points ``x0`` and the centred displacement basis ``v``, every second
    moment of ``u = x0 + k v`` is ``m_ij(k) = (x0_i.x0_j + k (x0_i.v_j + v_i.x0_j) + k^2 v_i.v_j) / n``;
    ``E`` is the mean over the lines of ``m_00 m_11 - m_01^2``. All lines at once (sums per line).
    """
    pts = [q for q in (np.asarray(p, dtype=np.float64).reshape(-1, 2) for p in lines) if len(q) >= 3]
    if not pts:
        raise ValueError("need at least one line of >= 3 points")
    counts = np.array([len(q) for q in pts])
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    xy = np.concatenate(pts)
    q = xy - center
    rho2 = np.sum(q * q, axis=1) / scale**2
    basis = (rho2 ** (power // 2))[:, None] * q

    def centred(a: NDArray[np.float64]) -> NDArray[np.float64]:
        mean = np.add.reduceat(a, starts, axis=0) / counts[:, None]
        out: NDArray[np.float64] = a - np.repeat(mean, counts, axis=0)
        return out

    x0, v = centred(xy), centred(basis)

    def moment(i: int, j: int) -> tuple[NDArray[np.float64], ...]:
        def dot(a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64]:
            out: NDArray[np.float64] = np.add.reduceat(a * b, starts) / counts
            return out

        return dot(x0[:, i], x0[:, j]), dot(x0[:, i], v[:, j]) + dot(v[:, i], x0[:, j]), dot(v[:, i], v[:, j])

    a, b, c = moment(0, 0), moment(1, 1), moment(0, 1)
    # the product of two quadratics in k, per line, minus the square of the third; summed over the lines
    e = np.array(
        [
            a[0] * b[0] - c[0] * c[0],
            a[0] * b[1] + a[1] * b[0] - 2.0 * c[0] * c[1],
            a[0] * b[2] + a[1] * b[1] + a[2] * b[0] - (2.0 * c[0] * c[2] + c[1] * c[1]),
            a[1] * b[2] + a[2] * b[1] - 2.0 * c[1] * c[2],
            a[2] * b[2] - c[2] * c[2],
        ]
    ).sum(axis=1)
    out: NDArray[np.float64] = e / max(len(lines), 1)
    return out


def alvarez_initial_k(lines: Sequence[np.ndarray], width: int, height: int, center: ArrayLike | None = None) -> float:
    """Closed-form minimiser of E over k2 of ``u = c + (1 + k2 rho^2)(x - c)``.

    ``rho`` is normalised by half the image diagonal; ``c`` defaults to the
    image centre. Returns the real critical point (root of the cubic dE/dk)
    that is a local minimum of E closest to 0 (no distortion).
    """
    c = np.array([(width - 1) / 2.0, (height - 1) / 2.0]) if center is None else np.asarray(center, float)
    s = 0.5 * float(np.hypot(width, height))
    e = _quartic_one(lines, c, s)
    roots = P.polyroots(P.polyder(e))
    d2 = P.polyder(e, 2)
    cand = [r.real for r in roots if abs(r.imag) < 1e-9 * max(1.0, abs(r)) and P.polyval(r.real, d2) > 0]
    if not cand:
        raise ValueError("Alvarez energy has no minimum in k")
    return float(min(cand, key=abs))


def fit_alvarez(
    lines_per_image: Sequence[Sequence[np.ndarray]],
    width: int,
    height: int,
    n_k: int = 2,
    center: Sequence[float] | None = None,
) -> FitResult | FitFailure:
    """Alvarez's method on harp edges: minimise E over ``k1`` (rho^2) and ``k2`` (rho^4).

    Returns a :class:`pipeline.edgeset.FitResult` whose model is a
    :class:`RadialModel` with ``k = (1, 0, k1, 0, k2)`` (centre fixed, default
    the image centre), or a :class:`pipeline.edgeset.FitFailure`.
    """
    from scipy.optimize import minimize  # the two-coefficient fit only (the fit's start needs none)

    edges, rejected = collect(lines_per_image, width, height)
    if not edges:
        return edges
    lines = edges.lines()
    c = np.array([(width - 1) / 2.0, (height - 1) / 2.0]) if center is None else np.asarray(center, float)
    s = 0.5 * float(np.hypot(width, height))
    try:
        k1 = alvarez_initial_k(lines, width, height, center=c)
    except ValueError as exc:
        return FitFailure(str(exc))
    if n_k not in (1, 2):
        return FitFailure(f"n_k must be 1 or 2, got {n_k}")
    # corrected, centred points of line l: u = x0 + k1 v1 + k2 v2 = sum_a kappa_a b_a, kappa = (1, k1, k2);
    # S_xx = kappa^T A kappa, S_yy = kappa^T B kappa, S_xy = kappa^T C kappa with 3x3 moment matrices
    mats = []
    for x0, v in _line_terms(lines, c, s, [2, 4]):
        basis = np.stack([x0, v[0], v[1]])  # (3, N, 2)
        n = x0.shape[0]
        mats.append(
            [
                np.einsum("an,bn->ab", basis[:, :, 0], basis[:, :, 0]) / n,
                np.einsum("an,bn->ab", basis[:, :, 1], basis[:, :, 1]) / n,
                0.5
                * (
                    np.einsum("an,bn->ab", basis[:, :, 0], basis[:, :, 1])
                    + np.einsum("an,bn->ab", basis[:, :, 1], basis[:, :, 0])
                )
                / n,
            ]
        )
    A, B, C = (np.asarray(m) for m in zip(*mats))  # each (L, 3, 3)

    def energy_grad(z: Floats) -> tuple[float, Floats]:
        kap = np.array([1.0, z[0], z[1] if n_k == 2 else 0.0])
        sa, sb, sc = (np.einsum("a,lab,b->l", kap, M, kap) for M in (A, B, C))
        ga, gb, gc = (2 * np.einsum("lab,b->la", M, kap) for M in (A, B, C))
        e = np.mean(sa * sb - sc * sc)
        g = np.mean(ga * sb[:, None] + sa[:, None] * gb - 2 * sc[:, None] * gc, axis=0)[1:]
        return e, (g if n_k == 2 else g[:1])

    k = np.array([k1, 0.0])
    if n_k == 2:
        e0 = max(energy_grad(k)[0], 1e-300)
        res = minimize(
            lambda z: tuple(v / e0 for v in energy_grad(z)),
            k,
            jac=True,
            method="BFGS",
            options={"gtol": 1e-14, "maxiter": 500},
        )
        k = res.x
    model = RadialModel(center=tuple(c), k=(1.0, 0.0, float(k[0]), 0.0, float(k[1])), scale=s)
    return summarise(model, edges, edges, rejected, message="Alvarez algebraic energy minimum", n_params=n_k)
