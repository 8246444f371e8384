r"""The radial map of an OpenCV pin-hole export beyond the image: no pole, no fold.

OpenCV's pin-hole model maps an ideal ray at normalised radius :math:`r`
(:math:`u = r^2`) to the distorted radius

.. math::
    r_d(r) = r\,\frac{N(u)}{D(u)}, \quad N = 1 + k_1 u + k_2 u^2 + k_3 u^3,
    \quad D = 1 + k_4 u + k_5 u^2 + k_6 u^3

(plus the small tangential and thin-prism terms). A fit over the image only
constrains :math:`r_d` up to the corner radius :math:`r_c` (the ideal image of
the farthest corner): left free, the rational fits put roots of :math:`D` (a
pole: ``cv2.projectPoints`` returns 10^5 px) or of :math:`r_d'` (a fold:
``cv2.initUndistortRectifyMap`` onto a larger canvas scatters pixels) just
outside it. An export is *pole-free* when, on :math:`0 \le r \le
`:data:`EXTRAPOLATION_RADIUS` :math:`\cdot r_c`,

.. math::
    D(u) > 0 \quad\text{and}\quad
    \frac{dr_d}{dr} = \frac{N D + 2u\,(N' D - N D')}{D^2} > 0,

which also makes :math:`N > 0` (:math:`r_d` increases from 0). Both are
polynomial conditions in :math:`u`, checked exactly from the polynomials'
real roots (:func:`radial_fault`); the fit (:func:`pipeline.exports.fit.fit_opencv`)
keeps them with the soft margins :data:`DENOMINATOR_MIN` and :data:`SLOPE_MIN`
(:func:`radial_penalty`, hinge residuals added to its least squares).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import numpy.typing as npt
from numpy.polynomial import polynomial as P

Array = npt.NDArray[np.float64]

EXTRAPOLATION_RADIUS = 1.5
"""The radial map is kept pole-free and monotonic out to this many times the corner radius."""

DENOMINATOR_MIN = 0.1
"""Margin the fit keeps on the denominator :math:`D(u)` (1 at the centre) out to the extrapolation radius."""

SLOPE_MIN = 0.02
"""Margin the fit keeps on :math:`dr_d/dr` (1 at the centre) out to the extrapolation radius."""

PENALTY_WEIGHT_PX = 1.0e3
"""Weight of a unit shortfall of the margins, in pixels of fitting residual."""

PENALTY_SAMPLES = 96
"""Radii (evenly spaced in :math:`r`) on which the fit evaluates the margins."""


def radial_polynomials(dist: Sequence[float]) -> tuple[Array, Array]:
    """Coefficients (increasing powers of :math:`u = r^2`) of :math:`N(u)` and :math:`D(u)`."""
    d = np.zeros(8)
    d[: min(len(dist), 8)] = np.asarray(dist, dtype=np.float64)[:8]
    k1, k2, _p1, _p2, k3, k4, k5, k6 = d
    return np.array([1.0, k1, k2, k3]), np.array([1.0, k4, k5, k6])


def slope_numerator(num: Array, den: Array) -> Array:
    """Coefficients in :math:`u` of :math:`N D + 2u (N' D - N D')`, the numerator of :math:`dr_d/dr`.

    Written with :func:`numpy.convolve` (what :mod:`numpy.polynomial` multiplies with, the same
    figures) rather than through :mod:`numpy.polynomial`'s series checks: the pole-free fits evaluate
    it at every residual evaluation.
    """
    num = np.asarray(num, dtype=np.float64)
    den = np.asarray(den, dtype=np.float64)
    cross = np.convolve(num[1:] * np.arange(1, len(num)), den) - np.convolve(num, den[1:] * np.arange(1, len(den)))
    out = np.convolve(num, den)
    out[1 : 1 + len(cross)] += 2.0 * cross
    return out


def _horner(coeffs: Array, x: Array) -> Array:
    """The polynomial with ``coeffs`` (increasing powers) at ``x``, by Horner's rule (as :func:`numpy.polynomial.polynomial.polyval`)."""
    out = np.full_like(x, coeffs[-1])
    for c in coeffs[-2::-1]:
        out = c + out * x
    return out


def radial_penalty(dist: Sequence[float], r_max: float, n: int = PENALTY_SAMPLES) -> Array:
    """Squared shortfalls of :math:`D` below :data:`DENOMINATOR_MIN` and of :math:`dr_d/dr` below :data:`SLOPE_MIN`.

    On ``n`` radii up to ``r_max`` (normalised), each ``shortfall**2 / margin``: zero where the
    margins hold, and differentiable (a plain hinge stalls Levenberg-Marquardt at the margin).
    The slope is taken as its numerator over :math:`\\max(D, \\text{DENOMINATOR\\_MIN})^2`,
    finite near a pole.
    """
    num, den = radial_polynomials(dist)
    u = np.linspace(0.0, float(r_max), int(n)) ** 2
    dv = _horner(den, u)
    slope = _horner(slope_numerator(num, den), u) / np.maximum(dv, DENOMINATOR_MIN) ** 2
    short_d = np.maximum(0.0, DENOMINATOR_MIN - dv)
    short_s = np.maximum(0.0, SLOPE_MIN - slope)
    return np.concatenate([short_d**2 / DENOMINATOR_MIN, short_s**2 / SLOPE_MIN])


RADIAL_INDEX_NUM = (0, 1, 4)
"""Positions of :math:`k_1, k_2, k_3` (the numerator's coefficients of :math:`u, u^2, u^3`) in OpenCV's order."""

RADIAL_INDEX_DEN = (5, 6, 7)
"""Positions of :math:`k_4, k_5, k_6` (the denominator's) in OpenCV's order."""


def radial_penalty_jacobian(dist: Sequence[float], r_max: float, n: int = PENALTY_SAMPLES) -> tuple[Array, Array]:
    r"""Derivatives of :func:`radial_penalty`: ``(J_dist (2n, len(dist)), J_r (2n,))``, the second with
    respect to ``r_max``.

    With :math:`S` the slope numerator (:func:`slope_numerator`) and :math:`u^i` a coefficient's power,
    :math:`\partial S/\partial a_i = (1 + 2i) u^i D - 2 u^{i+1} D'` for the numerator's and
    :math:`\partial S/\partial b_i = (1 - 2i) u^i N + 2 u^{i+1} N'` for the denominator's; the samples
    :math:`u_j = (r_{max} j / (n - 1))^2` move with :math:`r_{max}` as :math:`2 u_j / r_{max}`.
    """
    nd = len(dist)
    num, den = radial_polynomials(dist)
    u = np.linspace(0.0, float(r_max), int(n)) ** 2
    dv = _horner(den, u)
    nv = _horner(num, u)
    d_den = _horner(den[1:] * np.arange(1, 4), u)
    d_num = _horner(num[1:] * np.arange(1, 4), u)
    sn = slope_numerator(num, den)
    sv = _horner(sn, u)
    dm = np.maximum(dv, DENOMINATOR_MIN)
    free = dv > DENOMINATOR_MIN  # where the slope's denominator follows D
    short_d = np.maximum(0.0, DENOMINATOR_MIN - dv)
    short_s = np.maximum(0.0, SLOPE_MIN - sv / dm**2)
    # d(penalty)/d(D) and d(penalty)/d(slope)
    gd = -2.0 * short_d / DENOMINATOR_MIN
    gs = -2.0 * short_s / SLOPE_MIN

    def slope_by(d_s: Array, d_d: Array) -> Array:
        out: Array = d_s / dm**2 - np.where(free, 2.0 * sv * d_d / dm**3, 0.0)
        return out

    jd = np.zeros((2 * len(u), nd))
    for i, (ia, ib) in enumerate(zip(RADIAL_INDEX_NUM, RADIAL_INDEX_DEN, strict=True), start=1):
        ui = u**i
        if ia < nd:
            jd[len(u) :, ia] = gs * slope_by((1 + 2 * i) * ui * dv - 2 * ui * u * d_den, np.zeros_like(u))
        if ib < nd:
            jd[: len(u), ib] = gd * ui
            jd[len(u) :, ib] = gs * slope_by((1 - 2 * i) * ui * nv + 2 * ui * u * d_num, ui)
    du = 2.0 * u / float(r_max) if r_max > 0 else np.zeros_like(u)
    d_sn = _horner(sn[1:] * np.arange(1, len(sn)), u)
    jr = np.concatenate([gd * d_den * du, gs * slope_by(d_sn, d_den) * du])
    return jd, jr


def _first_root(coeffs: Array, u_max: float) -> float | None:
    """Smallest real root of a polynomial (increasing powers) in ``[0, u_max]``, or None."""
    c = np.trim_zeros(np.asarray(coeffs, dtype=np.float64), "b")
    if len(c) <= 1:
        return None if len(c) == 0 or c[0] != 0 else 0.0
    roots = P.polyroots(c)
    real = roots.real[(np.abs(roots.imag) <= 1e-9 * np.maximum(1.0, np.abs(roots.real)))]
    inside = real[(real >= 0.0) & (real <= u_max)]
    return float(inside.min()) if len(inside) else None


def radial_fault(dist: Sequence[float], r_max: float) -> str | None:
    """Where the radial map fails on :math:`[0, r_{max}]` (a pole or a fold, exact), or None."""
    num, den = radial_polynomials(dist)
    u_max = float(r_max) ** 2
    faults = []
    ud = _first_root(den, u_max)
    if ud is not None:
        faults.append((ud, f"its denominator 1 + k4 r^2 + k5 r^4 + k6 r^6 vanishes (a pole) at r = {np.sqrt(ud):.4g}"))
    us = _first_root(slope_numerator(num, den), u_max)
    if us is not None:
        faults.append((us, f"its radial map folds back (d r_d / d r = 0) at r = {np.sqrt(us):.4g}"))
    if not faults:
        return None
    return f"{min(faults)[1]} ({EXTRAPOLATION_RADIUS:g}x the corner radius: r = {float(r_max):.4g})"


def corner_radius(ideal: Array, cx: float, cy: float, fx: float, fy: float) -> float:
    """Largest normalised radius of ideal pixels ``ideal`` (the corner radius for an image's grid)."""
    p = np.asarray(ideal, dtype=np.float64).reshape(-1, 2)
    return float(np.max(np.hypot((p[:, 0] - cx) / fx, (p[:, 1] - cy) / fy)))
