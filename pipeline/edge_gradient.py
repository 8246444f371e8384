"""The edge detector's input check, Gaussian smoothing and gradient (steps 1-2 of
:mod:`pipeline.edges`).

The image is smoothed by a sampled, normalised Gaussian kernel of standard deviation ``sigma``
pixels (OpenCV's, applied separably) and differentiated by centred differences
``gx(x, y) = (L(x+1, y) - L(x-1, y)) / 2`` (and in y); the modulus is
``sqrt(gx**2 + gy**2)`` in float32, each operation rounded on its own. The detector's dense
stage (:mod:`pipeline.edges`) and the automatic thresholds (:mod:`pipeline.edge_thresholds`)
compute the gradient with these functions.

References
----------
.. [1] R. Grompone von Gioi, G. Randall, "A Sub-Pixel Edge Detector: an
   Implementation of the Canny/Devernay Algorithm", Image Processing On Line
   7 (2017), pp. 347-372. https://doi.org/10.5201/ipol.2017.216
"""

from __future__ import annotations

import cv2
import numpy as np


def as_float_image(image: np.ndarray) -> np.ndarray:
    img = np.asarray(image)
    check_image(img)
    return np.ascontiguousarray(img, dtype=np.float32)


def check_image(img: np.ndarray) -> None:
    if img.ndim != 2:
        raise ValueError(f"expected a 2-D grey image, got shape {img.shape}")
    if img.shape[0] < 5 or img.shape[1] < 5:
        raise ValueError(f"image too small for edge detection: {img.shape}")
    if img.dtype == np.bool_ or not (np.issubdtype(img.dtype, np.integer) or np.issubdtype(img.dtype, np.floating)):
        raise ValueError(f"unsupported image dtype {img.dtype}")
    if np.issubdtype(img.dtype, np.floating) and not np.isfinite(img).all():
        raise ValueError("image contains NaN or infinite values")


def gauss_ksize(sigma: float) -> int:
    return 2 * int(np.ceil(4.0 * sigma)) + 1


def centred_gradient(smoothed: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Centred differences ``(L(x+1) - L(x-1)) / 2`` (and in y) and the modulus,
    for ``sigma = 0`` (no smoothing).

    ``cv2.Sobel`` with ``ksize=1`` is the plain ``[-1, 0, 1]`` kernel (no
    cross smoothing). Values on the outermost pixel ring depend on the border
    rule and are never used (points are only detected 2 pixels or more inside
    the image).
    """
    gx = cv2.Sobel(smoothed, cv2.CV_32F, 1, 0, ksize=1, scale=0.5, borderType=cv2.BORDER_REPLICATE)
    gy = cv2.Sobel(smoothed, cv2.CV_32F, 0, 1, ksize=1, scale=0.5, borderType=cv2.BORDER_REPLICATE)
    return gx, gy, gradient_modulus(gx, gy, np.empty_like(gx))


def gradient_modulus(gx: np.ndarray, gy: np.ndarray, out: np.ndarray) -> np.ndarray:
    """``out = sqrt(gx**2 + gy**2)`` in float32, each operation rounded on its own (no fused
    multiply-add), so that a pixel's modulus does not depend on where it lies in the array
    (``cv2.magnitude`` fuses some lanes and not others, depending on the array's length)."""
    np.multiply(gx, gx, out=out)
    out += gy * gy
    np.sqrt(out, out=out)
    return out


def gaussian_kernels(sigma: float) -> tuple[np.ndarray, np.ndarray]:
    """Sampled Gaussian (OpenCV's, normalised) and its centred difference, as
    correlation kernels: ``d[m] = (g[m-1] - g[m+1]) / 2``."""
    g = cv2.getGaussianKernel(gauss_ksize(sigma), sigma, cv2.CV_32F).ravel()
    gp = np.concatenate([[0.0, 0.0], g, [0.0, 0.0]])
    d = 0.5 * (gp[:-2] - gp[2:])
    return g.astype(np.float32), d.astype(np.float32)


def separable_gradient(
    img: np.ndarray, sigma: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Gradient of the Gaussian-smoothed image by centred differences.

    Returns ``gx, gy, mod, sv, sh`` where ``sv`` (``sh``) is the image
    smoothed in y (x) only: ``gx`` = centred x-difference of ``sv`` smoothed
    in x, i.e. exactly the centred difference of ``GaussianBlur(img)``.
    ``sv``/``sh`` let the sub-pixel step evaluate the gradient at continuous
    positions along x/y (:func:`_refine_continuous`).
    """
    g, d = gaussian_kernels(sigma)
    b = cv2.BORDER_REFLECT
    # 1-D passes with filter2D (faster than sepFilter2D with a unit kernel)
    sv = cv2.filter2D(img, cv2.CV_32F, g[:, None], borderType=b)
    sh = cv2.filter2D(img, cv2.CV_32F, g[None, :], borderType=b)
    gx = cv2.filter2D(sv, cv2.CV_32F, d[None, :], borderType=b)
    gy = cv2.filter2D(sh, cv2.CV_32F, d[:, None], borderType=b)
    return gx, gy, gradient_modulus(gx, gy, np.empty_like(gx)), sv, sh
