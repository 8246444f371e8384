r"""Per-point robust weights for the straightness fit (:mod:`pipeline.fit`): iteratively reweighted
least squares on each point's residual about its edge's smooth trend.

A string's kink (a crimp: a cusp :math:`\lambda` long, :mod:`pipeline.harp_scene`) is a few tens of
points far from their edge's smooth course; the lens cannot express it, but pulls towards it. The
edge-level outlier rejection of :func:`pipeline.fit.fit_distortion` removes a kinked edge only while
its RMS stands out from the median edge's; with real noise and bows it does not. Here each point gets
its own weight instead:

1. its residual :math:`r_i` to its edge's (weighted) TLS line, less the edge's smooth trend along the
   line (a weighted Legendre fit of degree :data:`DETREND_DEGREE` in the position along the line: what
   the lens's misfit and a string's bow leave, both smooth over an edge) is :math:`d_i`, the part
   no lens and no bow explains;
2. its scale :math:`s_i`: with each point's own standard deviation :math:`\sigma_i` given
   (:func:`pipeline.measure.point_sigmas`), :math:`s_i = k\,\sigma_i` with :math:`k` the robust
   (1.4826 x median absolute) size of :math:`d_i/\sigma_i` over all points (the sigmas' common
   calibration); without it, the robust size of :math:`d` over the point's own edge; never below
   :data:`SCALE_FLOOR_PX`;
3. its weight, Tukey's biweight :math:`(1 - (d_i / c s_i)^2)^2` (0 beyond :math:`c s_i`), or Huber's
   :math:`\min(1, c s_i/|d_i|)`, with the textbook constants (95 % efficiency for Gaussian noise,
   :data:`TUKEY_C`, :data:`HUBER_C`): an ordinary point keeps (nearly) full weight, a kink's points
   none (Tukey) or little (Huber).

The constants are the textbook ones, not tuned on any lens.

References
----------
.. [1] P. J. Huber, E. M. Ronchetti, *Robust Statistics*, 2nd ed., Wiley, 2009, Ch. 7 (M-estimators
   of regression, IRLS).
.. [2] A. E. Beaton, J. W. Tukey, "The fitting of power series, meaning polynomials, illustrated on
   band-spectroscopic data", Technometrics 16(2), 1974 (the biweight).
.. [3] P. W. Holland, R. E. Welsch, "Robust regression using iteratively reweighted least-squares",
   Commun. Statist. Theory Methods 6(9), 1977.
"""

from __future__ import annotations

from typing import Literal

import numpy as np

PointLoss = Literal["tukey", "huber"]
POINT_LOSSES: tuple[PointLoss, ...] = ("tukey", "huber")

TUKEY_C = 4.685
"""Tukey's biweight constant (95 % asymptotic efficiency under Gaussian noise)."""
HUBER_C = 1.345
"""Huber's constant (95 % asymptotic efficiency under Gaussian noise)."""
DETREND_DEGREE = 4
"""Degree of the smooth trend taken out of each edge's residuals before they are judged."""
SCALE_FLOOR_PX = 1e-3
"""Smallest scale a point's residual is judged against (px): below the noise of any measured edge."""
MAD_TO_SIGMA = 1.4826
"""Median absolute deviation to standard deviation for Gaussian noise."""


def detrended(r: np.ndarray, a: np.ndarray, starts: np.ndarray, counts: np.ndarray, w: np.ndarray) -> np.ndarray:
    """``r`` (N,) less, per edge, its ``w``-weighted Legendre fit of degree :data:`DETREND_DEGREE` in ``a``
    (the positions along the line, scaled to [-1, 1] per edge); an edge with too few points for that
    degree (fewer than three per coefficient) keeps its mean removed only."""
    out = np.empty_like(r)
    for s, c in zip(starts, counts, strict=True):
        rr, aa, ww = r[s : s + c], a[s : s + c], w[s : s + c]
        deg = DETREND_DEGREE if c >= 3 * (DETREND_DEGREE + 1) else 0
        lo, hi = float(aa.min()), float(aa.max())
        x = 2.0 * (aa - lo) / max(hi - lo, 1e-12) - 1.0
        v = np.polynomial.legendre.legvander(x, deg)
        sw = np.sqrt(np.maximum(ww, 0.0))
        coef = np.linalg.lstsq(v * sw[:, None], rr * sw, rcond=None)[0]
        out[s : s + c] = rr - v @ coef
    return out


def point_scales(d: np.ndarray, starts: np.ndarray, counts: np.ndarray, sigma: np.ndarray | None = None) -> np.ndarray:
    """Each point's scale (px, module docstring step 2) for the detrended residuals ``d`` (N,):
    ``k sigma`` with each point's ``sigma`` given, else its edge's robust size of ``d``."""
    if sigma is not None:
        k = MAD_TO_SIGMA * float(np.median(np.abs(d) / sigma))
        s = k * sigma
    else:
        per_edge = np.array([MAD_TO_SIGMA * float(np.median(np.abs(d[a : a + c]))) for a, c in zip(starts, counts)])
        s = np.repeat(per_edge, counts)
    out: np.ndarray = np.maximum(s, SCALE_FLOOR_PX)
    return out


def loss_weights(d: np.ndarray, scale: np.ndarray, loss: PointLoss) -> np.ndarray:
    """IRLS weights of residuals ``d`` at scales ``scale`` (module docstring step 3)."""
    if loss == "tukey":
        z = d / (TUKEY_C * scale)
        out: np.ndarray = np.where(np.abs(z) < 1.0, (1.0 - z * z) ** 2, 0.0)
        return out
    if loss == "huber":
        out = np.minimum(1.0, HUBER_C * scale / np.maximum(np.abs(d), 1e-300))
        return out
    raise ValueError(f"point loss must be one of {POINT_LOSSES}, got {loss!r}")


def robust_point_weights(
    r: np.ndarray,
    a: np.ndarray,
    starts: np.ndarray,
    counts: np.ndarray,
    loss: PointLoss,
    sigma: np.ndarray | None = None,
    previous: np.ndarray | None = None,
) -> np.ndarray:
    """Each point's robust weight (0..1, module docstring) from its residual ``r`` to its edge's line and
    its position ``a`` along it (:func:`pipeline.edgeset.tls`), edges contiguous (``starts``, ``counts``).

    ``sigma`` (N,), optional: each point's standard deviation (relative values suffice); ``previous``
    (N,): the last iteration's robust weights, weighting the trend (default 1)."""
    w = np.ones_like(r) if previous is None else previous
    d = detrended(r, a, starts, counts, w)
    return loss_weights(d, point_scales(d, starts, counts, sigma), loss)
