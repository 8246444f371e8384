"""Sub-pixel edge detection: Canny/Devernay as improved by Grompone von Gioi & Randall.

The detector follows the IPOL 2017 implementation [1]_ of the Canny [3]_ /
Devernay [2]_ algorithm, fully vectorised with numpy/OpenCV:

1. Gaussian smoothing of the image (sampled, normalised Gaussian kernel of
   standard deviation ``sigma`` pixels, applied separably with OpenCV).
2. Gradient by centred differences of the smoothed image ``L``::

       gx(x, y) = (L(x+1, y) - L(x-1, y)) / 2,   gy(x, y) = (L(x, y+1) - L(x, y-1)) / 2

   (units: grey levels per pixel; the IPOL code omits the 1/2, which only
   rescales the thresholds).
3. Non-maximum suppression of the gradient modulus ``m = |(gx, gy)|`` along
   *one image axis*, chosen by the dominant gradient component: when
   ``|gx| >= |gy|`` a pixel is kept if ``m(x-1) < m(x) >= m(x+1)``, otherwise,
   when ``|gy| >= |gx|``, if ``m(y-1) < m(y) >= m(y+1)`` (at a tie
   ``|gx| = |gy|`` both axes are tried, x first, as in the IPOL code). Interpolating along an
   image axis instead of along the gradient removes the oscillation of the
   original Devernay method at 45 degrees [1]_.
4. Sub-pixel position of the maximum of the modulus along that axis, pixel
   centres at integer coordinates. Three models (``interpolation``):

   * ``"parabola"``: Devernay's parabola through ``(m-, m0, m+)`` [2]_, as
     in the IPOL code: ``offset = 0.5 (m- - m+) / (m- - 2 m0 + m+)``;
   * ``"gaussian"``: the same formula on ``(ln m-, ln m0, ln m+)``, exact
     for a Gaussian modulus profile;
   * ``"continuous"`` (default): no interpolation model at all. The smoothed
     image is the continuous function ``L(x) = sum_j I[j] G(x - j)`` (the
     kernel is a sampled Gaussian), so the very gradient defined in step 2
     can be evaluated at any real position along the axis; its modulus is
     maximised by two Newton steps started from the log-parabola offset
     (:func:`_refine_continuous`; the image is mirrored at its border as by
     the smoothing). Any point whose Newton steps fail or leave
     ``|offset| <= 1`` keeps the log-parabola offset. Needs ``sigma >= 0.5`` (below, the
     ``"gaussian"`` model is used).

   Measured on anti-aliased straight edges (optical blur 0.7 px, ``sigma``
   1; benchmarks/RESULTS-edges.md), the error that depends on the sub-pixel
   position of the edge ("pixel locking") is up to 0.024 px for the parabola
   and < 0.001 px for the two others on an isolated edge. On the edges of a
   3 px wide dark string, whose two gradient peaks overlap, the log-parabola
   error grows to 0.07 px peak-to-peak while the continuous maximum stays at
   0.002 px: that is what the 0.01 px precision of the calibration harp
   needs. (All three place the edges of a thin string ~0.2 px outwards, the
   same on every point: harmless for straightness.)
5. Chaining: every edge point looks for the nearest point that continues
   the curve *forward* and the nearest that continues it *backward*, among
   its 8 neighbours and, where none is found there, in the outer ring of its
   5x5 neighbourhood (the IPOL code scans the whole 5x5 window at once).
   Points ``e`` and ``n`` are compatible when both gradients lie on the same
   side of the segment ``e -> n``; the link is forward when
   ``gy(e) dx - gx(e) dy > 0`` with ``(dx, dy) = n - e``: looking at the
   image on screen (y down) and walking along a chain, the bright side is on
   the walker's right (see :func:`detect_edges`, Notes). Mutual choices are
   linked first, then the others by decreasing ``1/distance``, so that every
   point has at most one successor and one predecessor (the IPOL code
   resolves conflicts sequentially).
6. Hysteresis: a chain (a connected set of linked points, all with modulus
   above ``low``) is kept when at least one of its points has modulus above
   ``high``.

Steps 1-4 run by bands of rows (two threads on large images): each band's smoothed images,
gradient and modulus are computed from the image rows it needs, into buffers that stay in the
processor cache, bit for bit as on the whole image; only the points the NMS keeps leave a band.
The gradient modulus is ``sqrt(gx**2 + gy**2)`` in float32, each operation rounded on its own.

Automatic thresholds
--------------------
When ``low``/``high`` are ``None`` they are ``4 sigma_g`` and ``8 sigma_g``, ``sigma_g`` the
noise of one gradient component measured on the gradient itself, floored at that of the
quantisation: :mod:`pipeline.edge_thresholds` (:func:`~pipeline.edge_thresholds.auto_thresholds`).

References
----------
.. [1] R. Grompone von Gioi, G. Randall, "A Sub-Pixel Edge Detector: an
   Implementation of the Canny/Devernay Algorithm", Image Processing On Line
   7 (2017), pp. 347-372. https://doi.org/10.5201/ipol.2017.216
.. [2] F. Devernay, "A non-maxima suppression method for edge detection with
   sub-pixel accuracy", INRIA Research Report RR-2724, 1995.
.. [3] J. Canny, "A computational approach to edge detection", IEEE TPAMI
   8(6), 1986, pp. 679-698.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, TypeVar

import cv2
import numpy as np
from numpy.lib.stride_tricks import as_strided
from numpy.typing import NDArray

from pipeline.edge_chains import link_points, order_chains
from pipeline.edge_gradient import as_float_image, check_image, gaussian_kernels, gradient_modulus
from pipeline.edge_thresholds import noise_from_samples, noise_stride, thresholds_from_noise

_T = TypeVar("_T")
_R = TypeVar("_R")

__all__ = ["EdgeChain", "detect_edges", "edge_points"]

MIN_SIGMA_CONTINUOUS = 0.5

Floats = NDArray[np.float64]
Ints = NDArray[np.int64]


@dataclass(frozen=True, eq=False)
class EdgeChain:
    """One chained edge curve.

    Attributes
    ----------
    xy : np.ndarray
        ``(N, 2)`` float64 sub-pixel edge points ``(x=col, y=row)``, ordered
        along the chain (consecutive points are about 1 pixel apart).
    grad : np.ndarray
        ``(N, 2)`` float64 gradient ``(gx, gy)`` of the smoothed image at the
        pixel of each point (grey levels per pixel, pointing dark -> bright).

    Notes
    -----
    Equality is identity (arrays are not compared element-wise).
    """

    xy: np.ndarray
    grad: np.ndarray

    def __len__(self) -> int:
        return int(self.xy.shape[0])


# --------------------------------------------------------------------------- #
# the gradient at continuous positions (sub-pixel step)
# --------------------------------------------------------------------------- #
def _refine_radius(sigma: float) -> int:
    """Taps ``-r..r`` of the continuous evaluation, ``r = ceil(4 sigma) + 2``: for
    ``|u| <= 1`` the terms left out are weighted by ``G(t)`` with ``|t| >= 4 sigma``
    (the centred difference reaches one pixel further), i.e. < 4e-4 of the peak, and
    mostly cancel; measured effect < 2e-5 px (``4 sigma + 1`` gives 8e-4 px)."""
    return int(np.ceil(4.0 * sigma)) + 2


def _refine_continuous(
    s_img: np.ndarray,
    pos: NDArray[np.intp],
    base: NDArray[np.intp],
    tap: int,
    cross: int,
    u0: Floats,
    sigma: float,
    n_iter: int = 2,
    *,
    size: int | None = None,
    origin: int = 0,
) -> Floats:
    """Maximise the continuous gradient modulus along one image axis.

    A point sits at coordinate ``pos`` along its NMS axis and at flat index
    ``base + (pos - origin) * tap`` of ``s_img`` (``tap`` = 1 for the x axis, ``w`` for y;
    ``cross`` is the flat stride of the other axis; ``origin``: the image coordinate of the
    first sample of ``s_img`` along the axis, non-zero when ``s_img`` is a band of rows;
    ``size``: the image's extent along the axis, that of ``s_img`` by default). ``s_img`` is
    the image smoothed across that axis only. With ``G`` the Gaussian of std ``sigma`` and
    ``S[m]`` the samples of ``s_img`` along the axis at ``pos + m``, the
    smoothed image along the axis is ``L(u) = sum_m S[m] G(u - m)``; the
    gradient component along the axis is ``(L(u+1) - L(u-1)) / 2`` and the
    one across it is ``sum_m (S_+[m] - S_-[m]) / 2 G(u - m)`` (``S_+-``: the
    neighbouring lines ``+-cross``): exactly the detector's gradient
    (Gaussian smoothing, centred differences) at a continuous position
    ``u``. Beyond the image the samples are mirrored (``BORDER_REFLECT``, as
    the smoothing). Newton iterations on the squared modulus, started at
    ``u0``. Returns ``u`` (NaN where Newton failed: no maximum within 1 px).
    """
    r = _refine_radius(sigma)
    if size is None:
        size = s_img.shape[1] if tap == 1 else s_img.shape[0]
    flat = np.ascontiguousarray(s_img).ravel()
    nt = 2 * r + 1
    # float32 is ample here (relative 1e-7 on sums of ~30 terms -> < 1e-5 px) and 2x faster
    s0 = np.empty((pos.shape[0], nt), flat.dtype)
    sc = np.empty((pos.shape[0], nt), flat.dtype)
    near = (pos < r) | (pos >= size - r)
    far = np.flatnonzero(~near)
    if far.size:  # the taps of a point: nt samples `tap` apart, read through a strided view
        start = base[far] + (pos[far] - r - origin) * tap
        step = flat.itemsize
        win = as_strided(flat, shape=(flat.size - (nt - 1) * tap, nt), strides=(step, step * tap), writeable=False)
        s0[far] = win[start]
        sc[far] = 0.5 * (win[start + cross] - win[start - cross])
    if far.size < pos.shape[0]:  # within r of the image border: mirrored taps
        nr = np.flatnonzero(near)
        j = pos[nr, None] + np.arange(-r, r + 1)[None, :]
        j = np.where(j < 0, -j - 1, j)
        j = np.where(j >= size, 2 * size - j - 1, j)
        j = np.clip(j, 0, size - 1)  # clip: only for images narrower than the kernel
        ix = base[nr, None] + (j - origin) * tap
        s0[nr] = flat[ix]
        sc[nr] = 0.5 * (flat[ix + cross] - flat[ix - cross])
    inv = np.float32(1.0 / (sigma * sigma))
    u = u0.copy()
    ok = np.ones(u.shape, bool)
    # Gaussian and derivatives on the taps -r-1..r+1: G(t + 1) at tap m is G(t) at tap m - 1
    me = np.arange(-r - 1, r + 2, dtype=np.float32)[None, :]
    t, e0, e1, e2 = (np.empty((u.shape[0], nt + 2), np.float32) for _ in range(4))
    dif = np.empty((u.shape[0], nt), np.float32)
    k0, k1 = np.float32(-0.5) * inv, -inv
    for _ in range(n_iter):
        # e0 = exp(-0.5 inv t^2), e1 = -inv t e0, e2 = (inv t^2 - 1) inv e0, written in place
        np.subtract(u.astype(np.float32)[:, None], me, out=t)
        np.multiply(t, k0, out=e0)
        e0 *= t
        np.exp(e0, out=e0)
        np.multiply(t, k1, out=e1)
        e1 *= e0
        np.multiply(t, inv, out=e2)
        e2 *= t
        e2 -= np.float32(1.0)
        e2 *= inv
        e2 *= e0
        # centre taps -r..r are columns 1..2r+1; G(t+1) -> columns 0..2r; G(t-1) -> 2..2r+2
        a0 = np.einsum("ij,ij->i", s0, np.subtract(e0[:, :-2], e0[:, 2:], out=dif)) * 0.5  # along the axis
        a1 = np.einsum("ij,ij->i", s0, np.subtract(e1[:, :-2], e1[:, 2:], out=dif)) * 0.5
        a2 = np.einsum("ij,ij->i", s0, np.subtract(e2[:, :-2], e2[:, 2:], out=dif)) * 0.5
        c0 = np.einsum("ij,ij->i", sc, e0[:, 1:-1])  # across the axis
        c1 = np.einsum("ij,ij->i", sc, e1[:, 1:-1])
        c2 = np.einsum("ij,ij->i", sc, e2[:, 1:-1])
        f1 = (a0 * a1 + c0 * c1).astype(np.float64)
        f2 = (a1 * a1 + a0 * a2 + c1 * c1 + c0 * c2).astype(np.float64)
        good = f2 < 0
        ok &= good
        u = np.where(good, u - f1 / np.where(good, f2, -1.0), u)
    ok &= np.isfinite(u) & (np.abs(u) <= 1.0)
    return np.where(ok, u, np.nan)


# --------------------------------------------------------------------------- #
# NMS + sub-pixel points
# --------------------------------------------------------------------------- #
def _peak_offset(a: np.ndarray, m0: np.ndarray, b: np.ndarray, interpolation: str) -> np.ndarray:
    """Sub-pixel offset of a sampled peak ``(a, m0, b)`` at ``(-1, 0, +1)``.

    ``"parabola"``: Devernay's parabola through the moduli. ``"gaussian"``: the
    same parabola through their logarithms (exact for a Gaussian profile);
    falls back to the parabola where a neighbour modulus is 0.
    """
    off = np.zeros_like(m0)
    if interpolation == "gaussian":
        pos = (a > 0) & (b > 0)
        la = np.log(np.where(pos, a, 1.0))
        lb = np.log(np.where(pos, b, 1.0))
        l0 = np.log(m0)
        den = la - 2.0 * l0 + lb
        ok = pos & (den < 0)
        off[ok] = 0.5 * (la[ok] - lb[ok]) / den[ok]
        rest = ~pos
    else:
        rest = np.ones(m0.shape, bool)
    den = a - 2.0 * m0 + b
    ok = rest & (den < 0)
    off[ok] = 0.5 * (a[ok] - b[ok]) / den[ok]
    return off


_CV_INPUT = (np.uint8, np.uint16, np.int16, np.float32)


THREADS = 2
"""Threads of the dense stage (bands of rows) on large images."""
PARALLEL_MIN_PX = 3_000_000
"""Images smaller than this are processed by one thread (no thread start-up cost)."""
BAND_PX = 400_000
"""Pixels of one band of rows of the dense stage: the five float32 images of a band (smoothed
twice, gradient, modulus) stay in the processor cache, and no image-sized float array is made
(on a 24 MP image each would be 96 MB of fresh memory, paid in page faults)."""
NOISE_BOUND_ROWS = 24
"""Rows of the noise sample used for the provisional lower threshold (see :func:`_nms_points`)."""
NOISE_BOUND_FACTOR = 0.8
"""Provisional lower threshold = this fraction of the noise measured on those rows."""


def _threaded(fn: Callable[[_T], _R], parts: Sequence[_T]) -> list[_R]:
    """``[fn(p) for p in parts]``, by :data:`THREADS` threads when there are several parts (numpy and
    OpenCV release the GIL in these array operations; each part is independent, so the results are
    exactly those of one thread)."""
    if len(parts) < 2:
        return [fn(p) for p in parts]
    from concurrent.futures import ThreadPoolExecutor

    with ThreadPoolExecutor(max_workers=min(THREADS, len(parts))) as ex:
        return list(ex.map(fn, parts))


@dataclass(frozen=True, eq=False)
class _NmsPoints:
    """Points kept by the non-maximum suppression, in raster order.

    ``idx``: flat pixel index; ``m0``: gradient modulus; ``grad``: ``(N, 2)`` gradient;
    ``off``: 3-point sub-pixel offset along the NMS axis; ``along_x``: the NMS axis is x;
    ``u``: the continuous sub-pixel offset (NaN where Newton failed, or all NaN without it).
    """

    idx: NDArray[np.intp]
    m0: Floats
    grad: Floats
    off: Floats
    along_x: NDArray[np.bool_]
    u: Floats

    def select(self, keep: NDArray[np.bool_] | NDArray[np.intp]) -> _NmsPoints:
        """The points ``keep`` (a mask or indices)."""
        return _NmsPoints(
            self.idx[keep], self.m0[keep], self.grad[keep], self.off[keep], self.along_x[keep], self.u[keep]
        )

    @staticmethod
    def concat(parts: Sequence[_NmsPoints]) -> _NmsPoints:
        """The points of ``parts``, one after the other."""
        return _NmsPoints(*(np.concatenate([getattr(p, f) for p in parts]) for f in _NMS_FIELDS))


_NMS_FIELDS = ("idx", "m0", "grad", "off", "along_x", "u")


class _Dense:
    """The dense stage of the detector on bands of rows: smoothing, gradient, noise samples,
    non-maximum suppression and the continuous sub-pixel step.

    Every value is computed exactly as on the whole image: a band of output rows ``[r0, r1)`` is
    computed from the image rows ``[r0 - M, r1 + M)`` (``M = ceil(4 sigma) + 2``: the smoothing,
    the centred difference, the NMS neighbours and the taps of the sub-pixel step), and OpenCV's
    filters give bit-identical results on a band and on the whole image (the image border is
    mirrored by the same rule, the other rows are real ones).
    """

    def __init__(self, img: NDArray[Any], sigma: float, interpolation: str) -> None:
        self.img = img
        self.h, self.w = img.shape
        self.sigma = sigma
        self.interpolation = interpolation
        self.continuous = interpolation == "continuous" and sigma >= MIN_SIGMA_CONTINUOUS
        if sigma > 0:
            self.g, self.d = gaussian_kernels(sigma)
            self.margin = int(np.ceil(4.0 * sigma)) + 2
        else:
            self.margin = 2
        k = noise_stride(img.shape)
        self.noise_rows = np.arange(2, self.h - 2, k)
        self.noise_cols = np.arange(2, self.w - 2, k)
        self.local = threading.local()

    # ---------------------------------------------------------------- gradient
    def _buffers(self, rows: int) -> list[NDArray[np.float32]]:
        bufs: list[NDArray[np.float32]] | None = getattr(self.local, "bufs", None)
        if bufs is None or bufs[0].shape[0] < rows:
            bufs = [np.empty((rows, self.w), np.float32) for _ in range(5)]
            self.local.bufs = bufs
        return [b[:rows] for b in bufs]

    def gradient(self, block: NDArray[Any], rows: tuple[int, int] | None = None) -> tuple[NDArray[np.float32], ...]:
        """``gx, gy, mod, sv, sh`` of a block of rows (``sv``, ``sh``: smoothed in y / x only;
        for ``sigma = 0`` they are not computed). With ``rows = (lo, hi)``, ``gx`` and ``mod`` are
        only computed on the block's rows ``[lo, hi)`` (``gx`` is a filter along x: each row on its
        own), the others hold anything."""
        sv, sh, gx, gy, mod = self._buffers(block.shape[0])
        lo, hi = (0, block.shape[0]) if rows is None else rows
        if self.sigma > 0:
            b = cv2.BORDER_REFLECT
            # 1-D passes with filter2D (faster than sepFilter2D with a unit kernel)
            cv2.filter2D(block, cv2.CV_32F, self.g[:, None], dst=sv, borderType=b)
            cv2.filter2D(block, cv2.CV_32F, self.g[None, :], dst=sh, borderType=b)
            cv2.filter2D(sv[lo:hi], cv2.CV_32F, self.d[None, :], dst=gx[lo:hi], borderType=b)
            cv2.filter2D(sh, cv2.CV_32F, self.d[:, None], dst=gy, borderType=b)
        else:
            b = cv2.BORDER_REPLICATE
            cv2.Sobel(block, cv2.CV_32F, 1, 0, dst=gx, ksize=1, scale=0.5, borderType=b)
            cv2.Sobel(block, cv2.CV_32F, 0, 1, dst=gy, ksize=1, scale=0.5, borderType=b)
        gradient_modulus(gx[lo:hi], gy[lo:hi], mod[lo:hi])
        return gx, gy, mod, sv, sh

    def rows_block(self, r0: int, r1: int) -> tuple[int, NDArray[Any]]:
        a0, a1 = max(0, r0 - self.margin), min(self.h, r1 + self.margin)
        return a0, self.img[a0:a1]

    def noise_bound_sample(self) -> tuple[Floats, Floats]:
        """The gradient at the noise samples of up to :data:`NOISE_BOUND_ROWS` evenly spread sample
        rows (bit-identical to the whole-image gradient there): each row is computed from a block
        of ``2 ceil(4 sigma) + 3`` image rows around it (mirrored at the image border), all blocks
        stacked into one image."""
        rows = self.noise_rows
        if rows.size > NOISE_BOUND_ROWS:
            rows = rows[:: int(np.ceil(rows.size / NOISE_BOUND_ROWS))]
        r = self.margin - 1  # ceil(4 sigma) + 1: the reach of the centred difference of the smoothing
        j = rows[:, None] + np.arange(-r, r + 1)[None, :]
        j = np.where(j < 0, -j - 1, j)
        j = np.where(j >= self.h, 2 * self.h - j - 1, j)
        j = np.clip(j, 0, self.h - 1)
        stack = np.ascontiguousarray(self.img[j.ravel()])
        gx, gy = self.gradient(stack)[:2]
        centre = np.arange(rows.size) * (2 * r + 1) + r
        cols = self.noise_cols
        out = gx[centre][:, cols].astype(np.float64), gy[centre][:, cols].astype(np.float64)
        self.local.bufs = None
        return out

    # ---------------------------------------------------------------- bands
    def band(self, r0: int, r1: int, low: float, sample: bool) -> tuple[_NmsPoints, Floats, Floats]:
        """Points of the rows ``[r0, r1)`` with modulus ``> low`` that the NMS keeps, and (when
        ``sample``) the gradient at the noise samples of these rows."""
        h, w = self.h, self.w
        a0, block = self.rows_block(r0, r1)
        o0, o1 = r0 - a0, r1 - a0
        gx, gy, mod, sv, sh = self.gradient(block, (o0 - 1, o1 + 1))  # the NMS looks one row up and down
        if sample:
            sr = self.noise_rows[(self.noise_rows >= r0) & (self.noise_rows < r1)] - a0
            sgx = gx[sr][:, self.noise_cols].astype(np.float64)
            sgy = gy[sr][:, self.noise_cols].astype(np.float64)
        else:
            sgx = sgy = np.empty((0, 0))
        mask = mod[o0:o1] > np.float32(low)  # bool: flatnonzero is ~6x faster than on uint8
        mask[:, :2] = False
        mask[:, -2:] = False
        lidx = np.flatnonzero(mask) + o0 * w  # flat index in the block
        del mask
        mflat = mod.ravel()
        gxf = gx.ravel()[lidx]
        gyf = gy.ravel()[lidx]
        m0 = mflat[lidx]
        ml = mflat[lidx - 1]
        mr = mflat[lidx + 1]
        mu = mflat[lidx - w]
        md = mflat[lidx + w]
        ax = np.abs(gxf)
        ay = np.abs(gyf)
        along_x = (ax >= ay) & (m0 > ml) & (m0 >= mr)
        along_y = ~along_x & (ay >= ax) & (m0 > mu) & (m0 >= md)
        keep = along_x | along_y
        along_x = along_x[keep]
        lidx = lidx[keep]
        m064 = m0[keep].astype(np.float64)
        a = np.where(along_x, ml[keep], mu[keep]).astype(np.float64)
        b = np.where(along_x, mr[keep], md[keep]).astype(np.float64)
        off = _peak_offset(a, m064, b, "parabola" if self.interpolation == "parabola" else "gaussian")
        grad = np.column_stack([gxf[keep], gyf[keep]]).astype(np.float64)
        u = np.full(lidx.shape, np.nan)
        if self.continuous and lidx.size:
            lr, c = np.divmod(lidx, w)
            ix = np.flatnonzero(along_x)
            u[ix] = _refine_continuous(sv, c[ix], lr[ix] * w, 1, w, off[ix], self.sigma)
            iy = np.flatnonzero(~along_x)
            u[iy] = _refine_continuous(sh, lr[iy] + a0, c[iy], w, 1, off[iy], self.sigma, size=h, origin=a0)
        pts = _NmsPoints(lidx + a0 * w, m064, grad, off, along_x, u)
        return pts, sgx, sgy

    def run(self, low: float, sample: bool) -> tuple[_NmsPoints, Floats, Floats]:
        """:meth:`band` over the rows ``[2, h - 2)`` by bands (by :data:`THREADS` threads on large
        images), concatenated in raster order."""
        rows = max(16, BAND_PX // max(self.w, 1))
        if self.sigma <= 0:
            rows = self.h  # one band: the unsmoothed gradient is cheap
        bands = [(a, min(a + rows, self.h - 2)) for a in range(2, self.h - 2, rows)]
        n_threads = THREADS if self.h * self.w >= PARALLEL_MIN_PX else 1
        groups = [bands[i::n_threads] for i in range(n_threads)]

        def work(group: list[tuple[int, int]]) -> list[tuple[_NmsPoints, Floats, Floats]]:
            out = [self.band(r0, r1, low, sample) for r0, r1 in group]
            self.local.bufs = None  # free this thread's buffers
            return out

        done = _threaded(work, groups)
        per_band = [done[i % n_threads][i // n_threads] for i in range(len(bands))]
        pts = _NmsPoints.concat([p[0] for p in per_band])
        if not sample:
            return pts, np.empty(0), np.empty(0)
        return pts, np.concatenate([p[1].ravel() for p in per_band]), np.concatenate([p[2].ravel() for p in per_band])


def _resolve_thresholds(
    low: float | None, high: float | None, auto: Callable[[], tuple[float, float]]
) -> tuple[float, float]:
    """Fill the ``None`` thresholds from ``auto()`` -> (low, high) and check them."""
    if low is None or high is None:
        alow, ahigh = auto()
        if high is not None:  # only low is None
            low = min(alow, float(high))
        elif low is not None:  # only high is None
            high = max(ahigh, float(low))
        else:
            low, high = alow, ahigh
    low = float(low)
    high = float(high)
    if not (np.isfinite(low) and np.isfinite(high)) or low < 0 or high < low:
        raise ValueError(f"invalid thresholds low={low}, high={high} (need 0 <= low <= high)")
    return low, high


def _nms_points(
    image: NDArray[Any], sigma: float, low: float | None, high: float | None, interpolation: str = "continuous"
) -> tuple[_NmsPoints, tuple[int, int], float]:
    """NMS points of the image with their continuous sub-pixel offsets, its shape and ``high``.

    With automatic thresholds, the threshold ``low`` comes from the noise of the gradient
    sampled over the whole image (:func:`gradient_noise`), which is only known when every band
    has been computed. The bands are therefore searched with a provisional lower threshold,
    :data:`NOISE_BOUND_FACTOR` times the noise of a few sample rows (computed first), and the
    points between it and ``low`` dropped at the end: the NMS of a point does not depend on the
    threshold, so the result is exactly that of the threshold ``low``. Should ``low`` come out
    below the provisional threshold, the bands are searched again with ``low``.
    """
    if not (np.isfinite(sigma) and sigma >= 0):
        raise ValueError(f"sigma must be >= 0, got {sigma}")
    img = np.asarray(image)
    check_image(img)
    raw = img
    if sigma <= 0 or img.dtype.type not in _CV_INPUT or not img.flags.c_contiguous:
        img = as_float_image(img)  # else OpenCV converts on the fly (saves a full pass)
    if interpolation not in ("continuous", "gaussian", "parabola"):
        raise ValueError(f"unknown interpolation {interpolation!r} (use 'continuous', 'gaussian' or 'parabola')")
    dense = _Dense(img, sigma, interpolation)
    auto = low is None or high is None
    if not auto:
        low, high = _resolve_thresholds(low, high, lambda: (0.0, 0.0))
        return dense.run(low, sample=False)[0], img.shape, high
    bgx, bgy = dense.noise_bound_sample()
    if dense.noise_rows.size <= NOISE_BOUND_ROWS:  # that was the whole sample: the exact threshold
        exact = noise_from_samples(bgx, bgy)
        low, high = _resolve_thresholds(low, high, lambda: thresholds_from_noise(raw, exact, sigma))
        return dense.run(low, sample=False)[0], img.shape, high
    noise = NOISE_BOUND_FACTOR * noise_from_samples(bgx, bgy)
    bound, _ = _resolve_thresholds(low, high, lambda: thresholds_from_noise(raw, noise, sigma))
    pts, sgx, sgy = dense.run(bound, sample=True)
    exact = noise_from_samples(sgx, sgy)
    low, high = _resolve_thresholds(low, high, lambda: thresholds_from_noise(raw, exact, sigma))
    if low < bound:
        pts = dense.run(low, sample=False)[0]
    else:
        pts = pts.select(pts.m0 > np.float32(low))
    return pts, img.shape, high


def _subpixel_xy(pts: _NmsPoints, w: int, refined: bool) -> Floats:
    """``(N, 2)`` sub-pixel points: the 3-point offsets, or (``refined``) the continuous ones where
    Newton succeeded."""
    r, c = np.divmod(pts.idx, w)
    off = pts.off
    if refined:
        off = np.where(np.isnan(pts.u), off, pts.u)
    x = c.astype(np.float64) + np.where(pts.along_x, off, 0.0)
    y = r.astype(np.float64) + np.where(pts.along_x, 0.0, off)
    return np.column_stack([x, y])


def edge_points(
    image: np.ndarray,
    sigma: float = 1.0,
    low: float | None = None,
    high: float | None = None,
    *,
    interpolation: str = "continuous",
) -> tuple[np.ndarray, np.ndarray]:
    """Unchained sub-pixel edge points (Canny/Devernay NMS, no hysteresis).

    Parameters
    ----------
    image : np.ndarray
        2-D grey image (uint8, uint16 or float).
    sigma : float
        Standard deviation of the Gaussian smoothing, pixels.
    low, high : float or None
        Gradient-modulus thresholds (grey levels per pixel). Points with
        modulus ``> low`` are returned; ``high`` is only used to resolve the
        automatic ``low`` when ``low`` is ``None``.
    interpolation : {"continuous", "gaussian", "parabola"}
        Sub-pixel model along the NMS axis (module docstring, step 4).

    Returns
    -------
    xy : np.ndarray
        ``(N, 2)`` float64 sub-pixel points ``(x, y)``, in raster order.
    grad : np.ndarray
        ``(N, 2)`` float64 gradient ``(gx, gy)`` at each point's pixel.

    References
    ----------
    .. [1] R. Grompone von Gioi, G. Randall, IPOL 7 (2017).
    .. [2] F. Devernay, INRIA RR-2724, 1995.
    """
    pts, shape, _ = _nms_points(image, sigma, low, high, interpolation)
    return _subpixel_xy(pts, shape[1], refined=True), pts.grad


def detect_edges(
    image: np.ndarray,
    sigma: float = 1.0,
    low: float | None = None,
    high: float | None = None,
    min_length: int = 2,
    *,
    interpolation: str = "continuous",
) -> list[EdgeChain]:
    """Detect sub-pixel edge chains (Canny/Devernay, IPOL 2017 variant).

    Parameters
    ----------
    image : np.ndarray
        2-D grey image: uint8, uint16 (any integer) or float.
    sigma : float
        Standard deviation (pixels) of the Gaussian smoothing; ``0`` disables it.
    low, high : float or None
        Hysteresis thresholds on the gradient modulus (grey levels per pixel,
        gradient by centred differences ``(L(x+1) - L(x-1)) / 2``). ``None``
        selects the automatic rule ``low = 4 sigma_g``, ``high = 8 sigma_g``
        from a robust estimate of the gradient noise (module docstring).
    min_length : int
        Chains with fewer points are dropped.
    interpolation : {"continuous", "gaussian", "parabola"}
        Sub-pixel model along the NMS axis (module docstring, step 4).

    Returns
    -------
    list of EdgeChain
        Chains ordered along the curve, sorted by decreasing length. Closed
        curves are opened at one point (first and last points are then
        neighbours).

    Notes
    -----
    Orientation convention: along every chain, ``t x g > 0`` where ``t`` is
    the direction to the next point and ``g`` the gradient, i.e.
    ``t_x g_y - t_y g_x > 0``. In array coordinates (x right, y down) this
    means that, looking at the image on screen and walking along the chain,
    the *bright* side is on the walker's right. The two edges of a dark
    string on a bright background have opposite gradients and so run in
    opposite directions; they are never linked to each other.

    Each point keeps the gradient of its own pixel (not interpolated).

    References
    ----------
    .. [1] R. Grompone von Gioi, G. Randall, "A Sub-Pixel Edge Detector: an
       Implementation of the Canny/Devernay Algorithm", IPOL 7 (2017).
    .. [2] F. Devernay, "A non-maxima suppression method for edge detection
       with sub-pixel accuracy", INRIA RR-2724, 1995.
    .. [3] J. Canny, "A computational approach to edge detection", IEEE TPAMI
       8(6), 1986.
    """
    # chaining and hysteresis use the 3-point sub-pixel positions; the continuous ones
    # (< 0.1 px away, computed in the bands) are those of the points kept
    pts, shape, high = _nms_points(image, sigma, low, high, interpolation)
    if pts.idx.shape[0] == 0:
        return []
    xy, grad, mod = _subpixel_xy(pts, shape[1], refined=False), pts.grad, pts.m0
    nxt, prv = link_points(xy, grad, pts.idx, shape)
    lab, order = order_chains(nxt, prv)
    ncomp = int(lab.max()) + 1
    strong = np.zeros(ncomp, bool)
    strong[lab[mod > high]] = True
    sizes = np.bincount(lab, minlength=ncomp)
    good = strong & (sizes >= max(int(min_length), 1))
    order = order[good[lab[order]]]
    lab_o = lab[order]
    if order.size == 0:
        return []
    cuts = np.nonzero(np.diff(lab_o))[0] + 1
    del xy
    xy_o = _subpixel_xy(pts.select(order), shape[1], refined=True)
    gr_o = grad[order]
    starts = np.concatenate([[0], cuts])
    ends = np.concatenate([cuts, [order.size]])
    chains = [EdgeChain(xy_o[a:b], gr_o[a:b]) for a, b in zip(starts, ends)]
    chains.sort(key=len, reverse=True)
    return chains
