r"""Straightness of edges: the calibration-harp distortion measure.

Each edge (the image of one straight string edge) is a set of points
:math:`p_i = (x_i, y_i)`. Its total-least-squares (orthogonal) regression line
passes through the centroid :math:`c` with unit normal :math:`n`, the
eigenvector of the smallest eigenvalue of the scatter matrix; the *signed
distance* of a point to that line is

.. math:: S_i = (p_i - c) \cdot n .

Over a set of :math:`L` edges with :math:`N_l` points each (Tang et al. 2012,
eqs. 5 and 6):

.. math::
    d = \sqrt{\frac{\sum_{l=1}^{L}\sum_{i=1}^{N_l} S_{l,i}^2}{\sum_{l} N_l}},
    \qquad
    d_{\max} = \sqrt{\frac{1}{L}\sum_{l=1}^{L}
              \bigl(\max_i S_{l,i} - \min_i S_{l,i}\bigr)^2 } .

Per edge: RMS :math:`\sqrt{\overline{S^2}}`, peak-to-peak
:math:`\max S - \min S`, angle of the line (degrees in ``[0, 180)``, see the
convention in :mod:`pipeline`), length (extent of the points along the line)
and, with :func:`hf_rms`, the high-frequency residual that tells a bad string
(kink, dust, vibration) from lens distortion, which is smooth.

References
----------
.. [1] Z. Tang, R. Grompone von Gioi, P. Monasse, J.-M. Morel,
   "High-precision camera distortion measurements with a calibration harp",
   JOSA A 29(10), 2012, section 3 (eqs. 5, 6).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

HF_SIGMA_PX = 40.0
"""Gaussian sigma (pixels of arclength) of the low-pass used by :func:`hf_rms`."""


@dataclass(frozen=True)
class LineFit:
    """Total-least-squares line of one edge and the signed distances to it.

    Attributes
    ----------
    centroid : (2,) ndarray
        Point of the line (centroid of the points).
    direction : (2,) ndarray
        Unit direction ``(cos a, sin a)`` with ``a = angle_deg`` in ``[0, 180)``.
    normal : (2,) ndarray
        Unit normal ``(-sin a, cos a)``; positive ``S`` lies on this side.
    S : (N,) ndarray
        Signed distances of the points to the line, in pixels.
    """

    centroid: np.ndarray
    direction: np.ndarray
    normal: np.ndarray
    S: np.ndarray

    @property
    def angle_deg(self) -> float:
        return float(np.degrees(np.arctan2(self.direction[1], self.direction[0])))

    @property
    def rms(self) -> float:
        return float(np.sqrt(np.mean(self.S**2)))

    @property
    def p2p(self) -> float:
        return float(self.S.max() - self.S.min())


def fit_line(points: np.ndarray) -> LineFit:
    """Total-least-squares regression line of ``points`` ``(N, 2)``, ``N >= 2``.

    The normal is the eigenvector of the smallest eigenvalue of the 2x2
    scatter matrix of the centred points; the direction is oriented so that
    its angle lies in ``[0, 180)``.
    """
    p = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    if len(p) < 2:
        raise ValueError(f"a line needs at least 2 points, got {len(p)}")
    c = p.mean(axis=0)
    q = p - c
    cov = q.T @ q
    w, v = np.linalg.eigh(cov)  # ascending eigenvalues
    direction = v[:, 1].copy()
    # angle in [0, 180): y >= 0, and (1, 0) rather than (-1, 0)
    if direction[1] < 0 or (direction[1] == 0 and direction[0] < 0):
        direction = -direction
    if np.degrees(np.arctan2(direction[1], direction[0])) >= 180.0:
        # (-1, +1e-16): the angle rounds to 180; it is the horizontal direction 0
        direction = np.array([1.0, 0.0])
    normal = np.array([-direction[1], direction[0]])
    return LineFit(centroid=c, direction=direction, normal=normal, S=q @ normal)


def hf_rms(points: np.ndarray, sigma_px: float = HF_SIGMA_PX) -> float:
    r"""RMS of the high-frequency part of an edge's residual.

    The signed distances :math:`S(s)` of the ordered ``points`` to their
    regression line, as a signal of the arclength :math:`s`, minus its
    Gaussian smoothing :math:`\hat S` with :math:`\sigma` = ``sigma_px``
    pixels of arclength: :math:`\sqrt{\overline{(S - \hat S)^2}}`. Lens
    distortion bends an edge smoothly over hundreds of pixels and leaves this
    near zero; a kinked or dusty string or a grouping error does not.

    The smoothing is a Gaussian-weighted *local linear* regression: at each
    :math:`s_0`, :math:`\hat S(s_0) = a` where :math:`a + b (s - s_0)`
    minimises :math:`\sum G_\sigma(s - s_0) (S(s) - a - b (s - s_0))^2`. In
    the interior of a uniformly sampled edge this equals the plain Gaussian
    smoothing up to a term in :math:`S''\sigma^2/2`; at the ends of the edge,
    where the Gaussian is truncated, it does not pull the smooth bend of a
    distorted edge towards the interior (which a truncated Gaussian would,
    by about ``slope * 0.8 sigma``).

    The points must be ordered along the edge and roughly uniformly spaced
    (e.g. from a uniform-arclength resampling). Returns 0.0 for fewer than 3
    points.
    """
    p = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    if len(p) < 3:
        return 0.0
    S = fit_line(p).S
    seg = np.hypot(*np.diff(p, axis=0).T)
    step = float(np.mean(seg))
    if not step > 0:
        return 0.0
    sig = sigma_px / step  # in samples
    k = np.arange(S.size, dtype=np.float64) - 0.5 * (S.size - 1)
    k = k / max(1.0, sig)  # scaled to O(1): keeps the moments well conditioned
    half = int(np.ceil(4.0 * sig))
    ker = np.exp(-0.5 * (np.arange(-half, half + 1) / sig) ** 2)
    ker /= ker.sum()
    # five Gaussian moments at once; zero outside the edge (normalised below)
    sig_stack = np.stack([np.ones_like(k), k, k * k, S, k * S])
    if half > 64 and S.size > 64:
        sm = _fft_convolve_same(sig_stack, ker)
    else:
        # centred "same" slice of the full convolution: np.convolve(mode="same")
        # returns max(len(v), len(ker)) samples when the kernel is the longer one
        sm = np.stack([np.convolve(v, ker, mode="full")[half : half + S.size] for v in sig_stack])
    a0, a1, a2, b0, b1 = sm
    m1 = a1 - k * a0
    m2 = a2 - 2 * k * a1 + k * k * a0
    y1 = b1 - k * b0
    det = a0 * m2 - m1 * m1
    ok = det > 1e-12 * np.maximum(a0 * m2, 1e-300)
    smooth = np.where(ok, (m2 * b0 - m1 * y1) / np.where(ok, det, 1.0), b0 / a0)
    hf = S - smooth
    return float(np.sqrt(np.mean(hf**2)))


def _fft_convolve_same(rows: np.ndarray, ker: np.ndarray) -> np.ndarray:
    """Each row of ``rows`` convolved with the odd-length ``ker``, centred ("same" size), by FFT
    (numpy's: the measurement imports nothing heavier)."""
    n, k = rows.shape[1], ker.size
    size = 1 << int(np.ceil(np.log2(n + k - 1)))
    full = np.fft.irfft(np.fft.rfft(rows, size, axis=1) * np.fft.rfft(ker, size)[None, :], size, axis=1)
    half = (k - 1) // 2
    out: np.ndarray = full[:, half : half + n]
    return out


@dataclass(frozen=True)
class Straightness:
    """Straightness measure of a set of edges (Tang et al. 2012, eqs. 5, 6).

    Attributes
    ----------
    d : float
        RMS signed distance over all points of all edges, pixels.
    d_max : float
        RMS over edges of the per-edge peak-to-peak distance, pixels.
    n_points : int
        Total number of points.
    rms, p2p, angle_deg, length_px : tuple of float
        Per edge: RMS distance, peak-to-peak, angle of the line in degrees
        ``[0, 180)``, extent of the points along the line.
    n : tuple of int
        Per edge number of points.
    fits : tuple of LineFit
        Per edge regression line and signed distances ``S``.
    """

    d: float
    d_max: float
    n_points: int
    rms: tuple[float, ...]
    p2p: tuple[float, ...]
    angle_deg: tuple[float, ...]
    length_px: tuple[float, ...]
    n: tuple[int, ...]
    fits: tuple[LineFit, ...]

    @property
    def n_lines(self) -> int:
        return len(self.fits)


def straightness(point_sets: Sequence[np.ndarray]) -> Straightness:
    """Measure how straight a set of edges is.

    Parameters
    ----------
    point_sets : sequence of (N_l, 2) arrays
        One array of points per edge (``N_l >= 2``), e.g. the smoothed and
        subsampled edge points of :func:`pipeline.resample.smooth_subsample`.

    Returns
    -------
    Straightness
        ``d`` and ``d_max`` over all edges plus per-edge figures.

    Raises
    ------
    ValueError
        If ``point_sets`` is empty or an edge has fewer than 2 points.

    References
    ----------
    .. [1] Tang et al., JOSA A 29(10), 2012, eqs. 5 and 6.
    """
    if len(point_sets) == 0:
        raise ValueError("straightness needs at least one edge")
    fits = tuple(fit_line(p) for p in point_sets)
    sum_s2 = float(sum(np.sum(f.S**2) for f in fits))
    n = tuple(int(f.S.size) for f in fits)
    p2p = tuple(f.p2p for f in fits)
    lengths = []
    for f, p in zip(fits, point_sets):
        u = (np.asarray(p, dtype=np.float64).reshape(-1, 2) - f.centroid) @ f.direction
        lengths.append(float(u.max() - u.min()))
    return Straightness(
        d=float(np.sqrt(sum_s2 / sum(n))),
        d_max=float(np.sqrt(np.mean(np.square(p2p)))),
        n_points=int(sum(n)),
        rms=tuple(f.rms for f in fits),
        p2p=p2p,
        angle_deg=tuple(f.angle_deg for f in fits),
        length_px=tuple(lengths),
        n=n,
        fits=fits,
    )
