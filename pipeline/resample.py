r"""Along-edge resampling and smoothing of sub-pixel edge curves.

Per-edge processing of the calibration harp method (Tang et al. 2012 [1]_,
Sect. 3): the ordered edge points of one string edge are resampled at a
uniform arclength step, smoothed along the edge at the scale
:math:`\sigma = 0.8\sqrt{t^2 - 1}` samples (the anti-aliasing filter for a
subsampling by ``t``), and one point in ``t`` is kept. The smoothing averages
the independent noise of about :math:`2.5\sigma` edge points, which brings the
per-point noise of a sub-pixel detector (~0.01 px) down to the ~0.001 px
needed to measure distortion at 0.01 px precision.

Two smoothers (``method``):

``"local-quadratic"`` (default)
    Gaussian-weighted local polynomial regression of degree 2 along the
    arclength [2]_ [3]_, evaluated on a grid of spacing at most ``t`` samples
    that spans the *whole* piece, both end points included
    (:func:`subsample_grid`). At every grid point :math:`s_0` the coordinates
    :math:`x(s)` and :math:`y(s)` are each fitted by
    :math:`a_0 + a_1 (s - s_0) + a_2 (s - s_0)^2`, minimising

    .. math:: \sum_i w_i \bigl(x_i - a_0 - a_1 (s_i - s_0) - a_2 (s_i - s_0)^2\bigr)^2,
              \qquad w_i = \exp\bigl(-(s_i - s_0)^2 / 2\sigma^2\bigr),

    over the samples within ``TRUNCATE`` :math:`\sigma` that lie on the piece;
    the smoothed point is :math:`\hat x(s_0) = a_0`. A local polynomial of
    degree 2 reproduces any polynomial of degree <= 2 *exactly*, whatever
    the weights, so a straight edge stays straight and a curved edge keeps its
    curvature at the ends of the piece, where only one side of the window
    lies on the edge, just as in its middle. In the middle the remaining bias
    is :math:`O(\sigma^4 x^{(4)})` (the plain Gaussian's
    :math:`\sigma^2 x''/2` is removed), at the ends :math:`O(\sigma^3 x''')`.
``"gaussian"``
    The paper's plain Gaussian blur, kept only where the whole (truncated)
    window lies on the piece ("valid" mode), one point in ``t`` centred in
    that range: ``TRUNCATE`` :math:`\sigma` (72 px for t = 30) is lost at each
    end of each piece. Padding the ends instead would bias them: an even
    reflection bends a straight edge into a "V", an odd (point) reflection
    removes the term :math:`\sigma^2 x''/2` at the ends only.

Noise at the ends
-----------------
For independent sample noise of standard deviation :math:`\sigma_\epsilon`
the local fit at :math:`s_0` has the variance

.. math:: \operatorname{Var}\hat x(s_0) = \sigma_\epsilon^2\;
          e_1^\top (X^\top W X)^{-1} X^\top W^2 X (X^\top W X)^{-1} e_1,

with :math:`X` the design matrix of rows :math:`(1, s_i - s_0, (s_i - s_0)^2)`,
:math:`W = \operatorname{diag}(w_i)` and :math:`e_1 = (1, 0, 0)^\top` ([2]_,
Sect. 3.2). In the middle of an edge (symmetric window) this is
:math:`27/16` times the variance :math:`\sigma_\epsilon^2 / (2\sqrt\pi\,\sigma)`
of the plain Gaussian (standard deviation x 1.33 with the truncation at
:math:`3\sigma`). At the ends fewer samples lie on one side and the fit
extrapolates: for t = 30 the standard deviation is 3.50 times the plain
Gaussian's at the first and last point, 1.83 times 10 samples inside, 1.40
times at 24 samples and back to 1.33 from about :math:`2\sigma` (48 samples)
on. (Computed from the formula above; :func:`noise_gain` gives it for any
position.) On the synthetic harps of the test suite (noise 1.5 grey levels)
this is 0.003-0.004 px RMS in the middle and ~0.009 px at the end points.

References
----------
.. [1] Z. Tang, R. Grompone von Gioi, P. Monasse, J.-M. Morel,
   "High-precision camera distortion measurements with a calibration harp",
   JOSA A 29(10), 2012, pp. 2134-2143.
.. [2] J. Fan, I. Gijbels, *Local Polynomial Modelling and Its Applications*,
   Chapman & Hall, 1996 (Sect. 3.2, equivalent kernels and boundary behaviour).
.. [3] D. Ruppert, M. P. Wand, "Multivariate locally weighted least squares
   regression", Annals of Statistics 22(3), 1994, pp. 1346-1370.
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "MAX_EXTEND_PX",
    "METHODS",
    "TRUNCATE",
    "SmoothingMethod",
    "DEFAULT_T",
    "equivalent_kernel",
    "noise_gain",
    "noise_gains",
    "point_sigma",
    "resample_polyline",
    "sample_noise",
    "smooth_subsample",
    "smoothing_sigma",
    "subsample_grid",
]

DEFAULT_T = 30
"""The default along-edge subsampling factor ``t`` (Tang et al. 2012): the one place it is named,
the measurement functions, the configuration (``pipeline.t``) and the commands' ``--t`` import it."""
TRUNCATE = 3.0
"""The Gaussian window is truncated at ``TRUNCATE`` standard deviations."""
MAX_EXTEND_PX = 3.0
"""Largest extrapolation of the local fit beyond a piece's end (``extend``)."""

SmoothingMethod = Literal["local-quadratic", "gaussian"]
"""Along-edge smoother: see the module docstring."""
METHODS: tuple[SmoothingMethod, ...] = ("local-quadratic", "gaussian")
"""Accepted values of ``method``; the first is the default."""

Points = NDArray[np.float64]


def _check_xy(xy: ArrayLike) -> Points:
    a = np.asarray(xy, dtype=np.float64)
    if a.ndim != 2 or a.shape[1] != 2:
        raise ValueError(f"expected an (N, 2) point array, got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError("point array contains NaN or infinite values")
    return a


def _check_t(t: int) -> int:
    t_int = int(t)
    if t_int != t or t_int < 1:
        raise ValueError(f"t must be an integer >= 1, got {t}")
    return t_int


def _arclength(a: Points) -> NDArray[np.float64]:
    seg = np.hypot(np.diff(a[:, 0]), np.diff(a[:, 1]))
    return np.concatenate([[0.0], np.cumsum(seg)])


def resample_polyline(xy: ArrayLike, step: float = 1.0) -> Points:
    """Resample a polyline at a uniform arclength step (linear interpolation).

    Parameters
    ----------
    xy : array_like
        ``(N, 2)`` ordered points ``(x, y)``.
    step : float
        Arclength between consecutive output points (pixels), > 0.

    Returns
    -------
    np.ndarray
        ``(M, 2)`` float64 points at arclengths ``0, step, 2 step, ...`` up to
        the total length ``L`` (``M = floor(L / step) + 1``); the first point
        is ``xy[0]``. Empty ``(0, 2)`` for an empty input; one point for a
        zero-length polyline.

    References
    ----------
    .. [1] Z. Tang et al., JOSA A 29(10), 2012, Sect. 3.
    """
    a = _check_xy(xy)
    if not (np.isfinite(step) and step > 0):
        raise ValueError(f"step must be > 0, got {step}")
    if a.shape[0] == 0:
        return np.zeros((0, 2))
    s = _arclength(a)
    n = int(np.floor(s[-1] / step + 1e-9)) + 1
    u = np.arange(n) * step
    # drop repeated points (zero-length segments) so that s is strictly increasing
    keep = np.concatenate([[True], np.diff(s) > 0])
    s, a = s[keep], a[keep]
    if s.size == 1:
        first: Points = a[:1].copy()
        return first
    out: Points = np.column_stack([np.interp(u, s, a[:, 0]), np.interp(u, s, a[:, 1])])
    return out


def smoothing_sigma(t: int) -> float:
    """Standard deviation ``0.8 * sqrt(t**2 - 1)`` (samples) of the along-edge smoothing."""
    return 0.8 * float(np.sqrt(t * t - 1.0))


def subsample_grid(length: float, t: int) -> NDArray[np.float64]:
    """Positions (in samples) of the smoothed points of a piece ``length`` samples long.

    ``K = ceil(length / t) + 1`` positions evenly spaced from 0 to ``length``
    inclusive: the grid spans the whole piece, its spacing ``length / (K - 1)``
    is at most ``t`` (and tends to ``t`` on long pieces). A piece of length 0
    gives the single position 0.
    """
    t_int = _check_t(t)
    if not (np.isfinite(length) and length >= 0):
        raise ValueError(f"length must be >= 0, got {length}")
    if length == 0:
        return np.zeros(1)
    k = int(np.ceil(length / t_int - 1e-9)) + 1
    return np.linspace(0.0, float(length), max(k, 2))


def _window(
    n: int, s0: NDArray[np.float64], sig: float
) -> tuple[NDArray[np.intp], NDArray[np.float64], NDArray[np.float64]]:
    """Sample indices, scaled offsets ``(s_i - s0) / sig`` and weights of each window."""
    half = int(np.ceil(TRUNCATE * sig))
    centre = np.rint(s0).astype(np.intp)
    idx = centre[:, None] + np.arange(-half, half + 1)[None, :]
    d = idx - s0[:, None]
    w = np.exp(-0.5 * (d / sig) ** 2)
    w[(idx < 0) | (idx >= n) | (np.abs(d) > TRUNCATE * sig)] = 0.0
    return np.clip(idx, 0, max(n - 1, 0)), d / sig, w


def _normal_matrices(
    u: NDArray[np.float64], w: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    r"""``w u``, ``w u^2`` and each window's local-quadratic normal matrix :math:`X^\top W X`, ``(windows, 3, 3)``
    with entries :math:`\sum_i w_i u_i^{j+k}` (``u``, ``w``: :func:`_window`'s offsets and weights)."""
    wu = w * u
    wu2 = wu * u
    m = np.stack([w.sum(1), wu.sum(1), wu2.sum(1), (wu2 * u).sum(1), (wu2 * u * u).sum(1)], axis=1)
    a = np.empty((len(u), 3, 3))
    for i in range(3):
        for j in range(3):
            a[:, i, j] = m[:, i + j]
    return wu, wu2, a


def _local_quadratic(r: Points, s0: NDArray[np.float64], sig: float) -> Points:
    """Local quadratic regression of the samples ``r`` (uniform, unit spacing) at ``s0``."""
    idx, u, w = _window(r.shape[0], s0, sig)
    wu, wu2, a = _normal_matrices(u, w)
    out = np.empty((len(s0), 2))
    for c in range(2):
        v = r[idx, c]
        # offsets from the window's first sample keep the right-hand side well conditioned
        ref = v[:, :1]
        dv = v - ref
        rhs = np.stack([(w * dv).sum(1), (wu * dv).sum(1), (wu2 * dv).sum(1)], axis=1)
        out[:, c] = np.linalg.solve(a, rhs[:, :, None])[:, 0, 0] + ref[:, 0]
    return out


def _hat_rows(n: int, s0: NDArray[np.float64], sig: float) -> tuple[NDArray[np.intp], NDArray[np.float64]]:
    r"""Sample indices and weights ``l_i`` of the local-quadratic estimate at ``s0``:
    :math:`\hat x(s_0) = \sum_i l_i x_i` (the rows of the smoother's hat matrix,
    :math:`l = e_1^\top (X^\top W X)^{-1} X^\top W`)."""
    idx, u, w = _window(n, s0, sig)
    wu, wu2, a = _normal_matrices(u, w)
    e1 = np.zeros((len(s0), 3, 1))
    e1[:, 0, 0] = 1.0
    c = np.linalg.solve(a, e1)[:, :, 0]
    return idx, w * (c[:, :1] + c[:, 1:2] * u + c[:, 2:3] * u * u)


def _valid_gaussian(r: Points, t: int, sig: float) -> Points:
    half = int(np.ceil(TRUNCATE * sig)) if sig > 0 else 0
    n_valid = r.shape[0] - 2 * half
    if n_valid < 1:
        return np.zeros((0, 2))
    if half > 0:
        k = np.arange(-half, half + 1, dtype=np.float64)
        w = np.exp(-0.5 * (k / sig) ** 2)
        w /= w.sum()
        sm = np.column_stack([np.convolve(r[:, 0], w, mode="valid"), np.convolve(r[:, 1], w, mode="valid")])
    else:
        sm = r
    n_keep = (n_valid - 1) // t + 1
    start = ((n_valid - 1) - (n_keep - 1) * t) // 2
    out: Points = sm[start::t][:n_keep].copy()
    return out


def smooth_subsample(
    xy: ArrayLike,
    t: int = DEFAULT_T,
    step: float = 1.0,
    method: SmoothingMethod = "local-quadratic",
    extend: tuple[float, float] = (0.0, 0.0),
) -> Points:
    """Resample, smooth along the edge, and keep one point in ``t``.

    Parameters
    ----------
    xy : array_like
        ``(N, 2)`` ordered edge points ``(x, y)`` of one contiguous piece of
        an edge (e.g. one :class:`pipeline.edges.EdgeChain` ``xy``).
    t : int
        Subsampling factor (>= 1). The smoothing scale is
        ``sigma = 0.8 * sqrt(t**2 - 1)`` samples (0 for ``t = 1``: plain
        resampling, no smoothing).
    step : float
        Arclength step of the uniform resampling, pixels.
    method : {"local-quadratic", "gaussian"}
        The smoother (module docstring): a Gaussian-weighted local quadratic
        regression on a grid spanning the whole piece (default), or the
        paper's plain Gaussian, valid part only.
    extend : (float, float)
        ``"local-quadratic"`` only: the grid starts ``extend[0]`` px before the
        first point and ends ``extend[1]`` px after the last one (each in
        ``[0, MAX_EXTEND_PX]``), the local fit extrapolating there. For a piece
        cut by the image border, whose raw points stop up to a pixel short of
        the border line because they lie on the pixel grid.

    Returns
    -------
    np.ndarray
        ``(K, 2)`` float64 smoothed points in the order of ``xy``.
        ``"local-quadratic"``: at the arclengths ``step * subsample_grid(L /
        step, t)``, ``L`` the arclength of ``xy``: the first and last points are
        the smoothed ends of the piece; empty for an empty input, one point
        for a piece of zero length. ``"gaussian"``: spaced ``t * step``, only
        where the whole window (``TRUNCATE * sigma`` each side) lies on the
        piece, centred in that range; empty for a piece shorter than
        ``2 * ceil(TRUNCATE * sigma) + 1`` samples.

    Notes
    -----
    The local fit at the end points is noisier than in the middle (3.5 times
    the plain Gaussian's standard deviation for t = 30, module docstring,
    :func:`noise_gain`).

    References
    ----------
    .. [1] Z. Tang, R. Grompone von Gioi, P. Monasse, J.-M. Morel,
       "High-precision camera distortion measurements with a calibration
       harp", JOSA A 29(10), 2012, Sect. 3.
    .. [2] J. Fan, I. Gijbels, *Local Polynomial Modelling and Its
       Applications*, Chapman & Hall, 1996.
    """
    t_int = _check_t(t)
    if method not in METHODS:
        raise ValueError(f"unknown smoothing method {method!r} (use one of {', '.join(METHODS)})")
    a = _check_xy(xy)
    r = resample_polyline(a, step)
    sig = smoothing_sigma(t_int)
    if method == "gaussian":
        return _valid_gaussian(r, t_int, sig)
    if r.shape[0] == 0:
        return np.zeros((0, 2))
    if t_int == 1:
        return r
    e0, e1 = (float(e) / step for e in extend)
    if not (0.0 <= e0 <= MAX_EXTEND_PX / step and 0.0 <= e1 <= MAX_EXTEND_PX / step):
        raise ValueError(f"extend must be within [0, {MAX_EXTEND_PX}] px, got {extend}")
    length = float(_arclength(a)[-1]) / step
    if r.shape[0] < 3:  # too few samples for a quadratic: the piece's mean point
        mean: Points = np.mean(r, axis=0, keepdims=True)
        return mean
    return _local_quadratic(r, subsample_grid(length + e0 + e1, t_int) - e0, sig)


def noise_gain(position: float, length: float, t: int = DEFAULT_T) -> float:
    """Noise standard deviation of the local-quadratic point at ``position`` (samples)
    on a piece ``length`` samples long, relative to the plain Gaussian in the middle
    of a long edge (module docstring, "Noise at the ends"; independent sample noise).
    """
    return float(noise_gains(np.array([float(position)]), length, t)[0])


def noise_gains(positions: ArrayLike, length: float, t: int = DEFAULT_T) -> NDArray[np.float64]:
    r""":func:`noise_gain` at each of ``positions`` (samples) on one piece ``length`` samples long, at once:
    :math:`\sqrt{(A^{-1} B A^{-1})_{00} / \sum g^2 (\sum g)^{-2}}` with :math:`A = X^\top W X`,
    :math:`B = X^\top W^2 X` of each point's window."""
    t_int = _check_t(t)
    s0 = np.asarray(positions, dtype=np.float64).reshape(-1)
    sig = smoothing_sigma(t_int)
    if sig == 0:
        return np.ones(len(s0))
    n = int(np.floor(length + 1e-9)) + 1
    _, u, w = _window(n, s0, sig)
    ai = np.linalg.inv(_normal_matrices(u, w)[2])
    var = np.einsum("pi,pij,pj->p", ai[:, 0, :], _normal_matrices(u, w**2)[2], ai[:, 0, :])
    k = np.arange(-int(np.ceil(TRUNCATE * sig)), int(np.ceil(TRUNCATE * sig)) + 1)
    g = np.exp(-0.5 * (k / sig) ** 2)
    var_g = float(np.sum(g**2) / np.sum(g) ** 2)
    out: NDArray[np.float64] = np.sqrt(var / var_g)
    return out


def equivalent_kernel(offset: ArrayLike, t: int = DEFAULT_T) -> NDArray[np.float64]:
    r"""The local-quadratic smoother's weight :math:`l(s)` per sample at offset ``s`` (samples) from an
    interior point: :math:`\hat x(s_0) = \sum_i l(s_i - s_0)\,x_i` where the whole window lies on the
    piece (its equivalent kernel, [2]_ Sect. 3.2.2; about :math:`\phi(u)(3 - u^2)/(2\sigma)`,
    :math:`u = s/\sigma`, for the untruncated Gaussian). A feature much narrower than
    :math:`\sigma` of area :math:`A` (px x px) leaves the smoothed edge displaced by
    :math:`A\,l(s)` at distance ``s`` from it. Linear between the integer offsets, 0 beyond
    ``TRUNCATE`` sigma; for ``t = 1`` (no smoothing) 1 at offset 0 and 0 elsewhere."""
    t_int = _check_t(t)
    s = np.abs(np.asarray(offset, dtype=np.float64))
    sig = smoothing_sigma(t_int)
    if sig == 0:
        out0: NDArray[np.float64] = np.where(s < 0.5, 1.0, 0.0)
        return out0
    half = int(np.ceil(TRUNCATE * sig))
    idx, w = _hat_rows(2 * half + 1, np.array([float(half)]), sig)
    k = idx[0] - half
    out: NDArray[np.float64] = np.interp(s, k[k >= 0].astype(np.float64), w[0][k >= 0], right=0.0)
    return out


def sample_noise(
    xy: ArrayLike, t: int = DEFAULT_T, step: float = 1.0, local: bool = False
) -> float | NDArray[np.float64]:
    r"""Noise of the uniform samples of an edge piece, from the raw points' scatter about the smooth.

    The piece is resampled at ``step`` (:func:`resample_polyline`) and smoothed at every sample by the
    local quadratic regression of :func:`smooth_subsample` (scale ``smoothing_sigma(t)``); the signed
    normal distances ``e`` of the *raw* points to that smooth are the noise it averages (the raw
    points, not the interpolated samples, whose scatter depends on where the interpolation falls).
    The figure is the standard deviation :math:`\sigma_s` of independent samples that would give
    the smoothed points the same variance: :math:`\sigma_s^2 = \sigma_e^2\, g / \rho` with
    :math:`\rho` the raw points per sample and :math:`g = 1 + 2\sum_k \rho_k` the correlation gain
    of neighbouring raw points (the edge detector's Gaussian correlates them: on rendered harps 0.8
    at one point, 0.5 at two), its autocorrelations summed up to the first non-positive one (Geyer's
    initial positive sequence [2]_). With it :func:`point_sigma` gives each smoothed point's
    standard deviation.

    Parameters
    ----------
    xy : array_like
        ``(N, 2)`` ordered raw edge points of one contiguous piece.
    t, step
        As :func:`smooth_subsample`.
    local : bool
        False: one figure for the piece, :math:`\sigma_e` robust (``1.4826 median |e - median e|``).
        True: an array, one value per uniform sample, :math:`\sigma_e` the Gaussian-windowed RMS of
        ``e`` (the smoother's window, ``e`` clipped at 10 times the robust figure): the noise's growth
        along the edge (blur and vignetting towards the corners, a string's ends).

    Returns
    -------
    float or np.ndarray
        Pixels; NaN (or an empty array) for a piece with fewer than 6 samples or points, or ``t = 1``.

    References
    ----------
    .. [1] J. Fan, I. Gijbels, *Local Polynomial Modelling and Its Applications*, Chapman & Hall,
       1996 (Sect. 4.2, residual-based variance estimation).
    .. [2] C. J. Geyer, "Practical Markov chain Monte Carlo", Statistical Science 7(4), 1992,
       pp. 473-483 (the initial positive sequence estimator).
    """
    t_int = _check_t(t)
    a = _check_xy(xy)
    r = resample_polyline(a, step)
    sig = smoothing_sigma(t_int)
    n = r.shape[0]
    if n < 6 or len(a) < 6 or sig == 0:
        return np.zeros(0) if local else float("nan")
    grid = np.arange(n, dtype=np.float64)
    sm = _local_quadratic(r, grid, sig)
    tan = np.gradient(sm, axis=0)
    tan /= np.maximum(np.hypot(tan[:, 0], tan[:, 1]), 1e-12)[:, None]
    pos = _arclength(a) / step  # each raw point's place on the sample grid
    at = [np.interp(pos, grid, c) for c in (sm[:, 0], sm[:, 1], tan[:, 0], tan[:, 1])]
    e = (a[:, 1] - at[1]) * at[2] - (a[:, 0] - at[0]) * at[3]
    robust = 1.4826 * float(np.median(np.abs(e - np.median(e))))
    ec = np.clip(e, -10.0 * robust, 10.0 * robust) if robust > 0 else e  # outliers, not a noisier stretch
    # the windowed RMS of e at every sample: e^2 and counts binned on the grid, then the smoother's window
    k = np.clip(np.rint(pos).astype(np.intp), 0, n - 1)
    e2 = np.bincount(k, ec * ec, minlength=n)
    cnt = np.bincount(k, minlength=n).astype(np.float64)
    idx, _, w = _window(n, grid, sig)
    local_rms = np.sqrt((w * e2[idx]).sum(1) / np.maximum((w * cnt[idx]).sum(1), 1e-12))
    # the correlation of the noise standardised by its local level (a noisier stretch does not set it alone)
    gain = _correlation_gain(ec / np.maximum(local_rms[k], 1e-12))
    per_sample = float(np.sqrt(gain * n / len(a)))  # sqrt(g / rho), rho = raw points per sample
    if not local:
        return robust * per_sample
    out: NDArray[np.float64] = local_rms * per_sample
    return out


MAX_CORRELATION_LAG = 20
"""Longest lag (samples) of the samples' correlation summed by :func:`sample_noise`."""


def _correlation_gain(e: NDArray[np.float64]) -> float:
    """``1 + 2 sum_k rho_k`` over the lags before the first non-positive autocorrelation ``rho_k`` of ``e``
    (Geyer's initial positive sequence): the variance of a long average of correlated samples over the
    variance of as many independent ones."""
    e = e - np.mean(e)
    v = float(e @ e)
    if not v > 0:
        return 1.0
    total = 1.0
    for k in range(1, min(MAX_CORRELATION_LAG, len(e) - 1) + 1):
        rho = float(e[k:] @ e[:-k]) / v
        if rho <= 0:
            break
        total += 2.0 * rho
    return total


def point_sigma(
    xy: ArrayLike,
    noise: float | ArrayLike,
    t: int = DEFAULT_T,
    step: float = 1.0,
    method: SmoothingMethod = "local-quadratic",
    extend: tuple[float, float] = (0.0, 0.0),
) -> NDArray[np.float64]:
    r"""Standard deviation of each point :func:`smooth_subsample` gives, for independent sample noise.

    Each smoothed point is a linear combination :math:`\hat x(s_0) = \sum_i l_i x_i` of the uniform
    samples (module docstring, "Noise at the ends"), so with independent sample noise of standard
    deviation :math:`\sigma_i` its standard deviation is :math:`\sqrt{\sum_i l_i^2 \sigma_i^2}`: the
    smoother's variance factor :math:`\sum_i l_i^2` (the squared norm of its hat-matrix row, largest
    at the ends of the piece where the window is one-sided) times the noise.

    Parameters
    ----------
    xy, t, step, method, extend
        As :func:`smooth_subsample` (the same points are described, in the same order).
    noise : float or array_like
        The samples' noise standard deviation (px): one figure, or one per uniform sample
        (:func:`sample_noise`, ``local=True``).

    Returns
    -------
    np.ndarray
        ``(K,)`` pixels, one per point of ``smooth_subsample(xy, t, step, method, extend)``.

    References
    ----------
    .. [1] J. Fan, I. Gijbels, *Local Polynomial Modelling and Its Applications*, Chapman & Hall,
       1996 (Sect. 3.2, the conditional variance of the local polynomial estimator).
    """
    t_int = _check_t(t)
    if method not in METHODS:
        raise ValueError(f"unknown smoothing method {method!r} (use one of {', '.join(METHODS)})")
    a = _check_xy(xy)
    r = resample_polyline(a, step)
    n = r.shape[0]
    var = np.broadcast_to(np.asarray(noise, dtype=np.float64) ** 2, (n,)) if n else np.zeros(0)
    sig = smoothing_sigma(t_int)
    if method == "gaussian":
        half = int(np.ceil(TRUNCATE * sig)) if sig > 0 else 0
        n_valid = n - 2 * half
        if n_valid < 1:
            return np.zeros(0)
        k = np.arange(-half, half + 1, dtype=np.float64)
        g = np.exp(-0.5 * (k / sig) ** 2) if sig > 0 else np.ones(1)
        g /= g.sum()
        v = np.convolve(var, (g * g)[::-1], mode="valid")
        n_keep = (n_valid - 1) // t_int + 1
        start = ((n_valid - 1) - (n_keep - 1) * t_int) // 2
        return np.sqrt(v[start::t_int][:n_keep])
    if n == 0:
        return np.zeros(0)
    if t_int == 1:
        return np.sqrt(np.array(var))
    e0, e1 = (float(e) / step for e in extend)
    if not (0.0 <= e0 <= MAX_EXTEND_PX / step and 0.0 <= e1 <= MAX_EXTEND_PX / step):
        raise ValueError(f"extend must be within [0, {MAX_EXTEND_PX}] px, got {extend}")
    if n < 3:  # smooth_subsample gives the mean point
        mean_sd: NDArray[np.float64] = np.sqrt(np.array([var.sum() / n**2]))
        return mean_sd
    length = float(_arclength(a)[-1]) / step
    idx, lw = _hat_rows(n, subsample_grid(length + e0 + e1, t_int) - e0, sig)
    out: NDArray[np.float64] = np.sqrt((lw * lw * var[idx]).sum(1))
    return out
