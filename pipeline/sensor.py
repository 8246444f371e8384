r"""From irradiance to an image file: the sensor's electrons and noise, its colour filter
array, and the raw conversion (demosaicing, white balance, tone curve, 8 bits, JPEG).

Exposure and noise (:func:`expose`)
-----------------------------------
A sample of relative irradiance :math:`E` (1 = the lit sheet at its brightest, before
vignetting) behind a filter of relative response :math:`g_c` collects
:math:`N_e = E\,g_c\,x\,F` electrons, with :math:`x` the ``exposure`` (the fraction of the
full well :math:`F` that unit irradiance fills in the green channel). With
``shot_noise`` the count is Poisson, :math:`N_e \sim \mathcal P(E g_c x F)` (photon
statistics: variance = mean), plus Gaussian read noise of ``read_noise_e``; the ADC
converts :math:`F` electrons to its full scale :math:`2^{b} - 1` and clips. The full well of
the native pixels of a DSLR or machine-vision sensor of 4–6 µm is 15 000–40 000 e-,
its read noise 2–10 e- at base ISO (manufacturer data sheets; DxOMark and
photonstophotos.net measurements of APS-C Canon bodies): at 80 % of a 25 000 e- well the
lit sheet carries a shot-noise SNR of 141 per native pixel.

Colour filter array and raw conversion (:func:`develop`)
--------------------------------------------------------
A Bayer sensor samples one of R, G, B per pixel (``cfa`` = the 2x2 pattern, e.g.
``"RGGB"``: R at even rows and columns). The back-light's spectrum times each filter's
quantum efficiency gives the raw channel responses ``channel_response`` (R, G, B,
relative to G: a daylight or white-LED back-light on a CMOS sensor reads R 0.45–0.75,
B 0.5–0.85 of G, i.e. the raw converter's white-balance multipliers 1.3–2.2). The
converter then, as dcraw/LibRaw do:

1. reconstructs the three channels at every pixel: ``demosaic`` = ``"bilinear"``,
   ``"ea"`` (edge-aware) or ``"vng"`` (variable number of gradients; OpenCV runs it on
   8-bit data only, so the raw is scaled to 8 bits first) with
   ``cv2.cvtColor(raw, cv2.COLOR_Bayer..2BGR[_EA|_VNG])``, or ``"half-size"``: each 2x2
   quad becomes one output pixel (R, the mean of the two G, B: dcraw ``-h``, LibRaw
   ``half_size``; the output pixel's three colours come from points a quarter of an
   output pixel apart);
2. white-balances (divides each channel by its response: the sheet is neutral grey);
3. converts to grey with the luma weights of ``cv2.COLOR_BGR2GRAY``
   (:math:`0.299R + 0.587G + 0.114B`);
4. scales ``white_level`` of the full scale to white, applies the tone curve (``tone``:
   ``"linear"``; ``"bt709"``, the ITU-R BT.709 transfer function dcraw writes by
   default; ``"srgb"``, IEC 61966-2-1) and rounds to ``bit_depth`` bits;
5. optionally compresses to JPEG at ``jpeg_quality`` and decodes it again
   (``cv2.imencode`` / ``cv2.imdecode``, baseline libjpeg, grey = the luma plane only; a
   camera's "fine" JPEG is quality 90–97 on the libjpeg scale).

What each step does to an edge (measured on 3 px dark strings, sigma 0.7 px, against the
clean image of the same strings: ``tests/pipeline/test_sensor.py``): demosaicing
interpolates R and B from every other pixel and G from a quincunx, so its error at an
edge depends on where the edge falls between the samples, a bias periodic in the pixel
phase (0.01-0.015 px RMS along near-axis strings, 0.004 px at 37°), and widens a thin
dark string (bilinear by 0.07-0.11 px per edge, edge-aware by 0.03-0.09 px) without
moving its centre line; a half-size conversion leaves the edges alone but shifts the
whole image by minus the luma-weighted centroid of the quad, :math:`(0.046, 0.046)` px for
RGGB (R at :math:`(-1/4, -1/4)`, B at :math:`(+1/4, +1/4)`); a tone curve is not linear,
so it moves the gradient maximum of a blurred edge towards its dark side (BT.709 narrows
such a string by ~0.15 px per edge) by an amount that grows with the blur; JPEG
quantises the 8x8 DCT blocks, an error periodic with the block grid (quality 95: below
0.001 px; quality 75: 0.003-0.005 px RMS).

References
----------
.. [1] B. E. Bayer, "Color imaging array", US patent 3 971 065, 1976.
.. [2] ITU-R Recommendation BT.709-6, 2015 (the transfer function).
.. [3] IEC 61966-2-1:1999 (sRGB).
.. [4] D. Coffin, dcraw.c (``-h`` half-size, BT.709 output gamma by default);
   LibRaw ``half_size``.
.. [5] G. K. Wallace, "The JPEG still picture compression standard", IEEE Trans. Consumer
   Electronics 38(1), 1992.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

CFA_PATTERNS: tuple[str, ...] = ("RGGB", "BGGR", "GRBG", "GBRG")
"""The 2x2 Bayer patterns, read row by row from the top-left pixel."""
DEMOSAIC_METHODS: tuple[str, ...] = ("bilinear", "ea", "vng", "half-size")
"""The raw converter's ways of filling in the colours (module docstring, step 1)."""
TONE_CURVES: tuple[str, ...] = ("linear", "bt709", "srgb")
"""The transfer functions from linear light to the output code values."""
POISSON_AS_GAUSSIAN_E = 1000.0
"""Electron counts from which shot noise is drawn as a Gaussian of variance = mean (:func:`expose`)."""
LUMA = (0.299, 0.587, 0.114)
"""Weights of R, G, B in the grey image (``cv2.COLOR_BGR2GRAY``)."""

# OpenCV names a Bayer pattern by the second row's second and third pixels
_CV_PATTERN = {"RGGB": "BG", "BGGR": "RG", "GRBG": "GB", "GBRG": "GR"}


@dataclass(frozen=True)
class Sensor:
    """The sensor (module docstring, *Exposure and noise*).

    Parameters
    ----------
    exposure : fraction of the full well that unit irradiance fills in the green channel.
    shot_noise : Poisson photon noise (off: the electron count is its mean).
    full_well_e : electrons at the ADC's full scale.
    read_noise_e : Gaussian read noise, electrons.
    adc_bits : the raw's bit depth.
    cfa : the Bayer pattern (one of :data:`CFA_PATTERNS`) or None for a monochrome sensor.
    channel_response : raw response of R, G, B to the back-light, relative (G = 1).
    """

    exposure: float = 0.8
    shot_noise: bool = False
    full_well_e: float = 25000.0
    read_noise_e: float = 0.0
    adc_bits: int = 14
    cfa: str | None = None
    channel_response: tuple[float, float, float] = (1.0, 1.0, 1.0)

    def __post_init__(self) -> None:
        if not (self.exposure > 0 and self.full_well_e > 0 and self.read_noise_e >= 0):
            raise ValueError("Sensor: exposure and full_well_e must be > 0, read_noise_e >= 0")
        if not 8 <= self.adc_bits <= 16:
            raise ValueError(f"Sensor: adc_bits must be in 8..16, got {self.adc_bits}")
        if self.cfa is not None and self.cfa not in CFA_PATTERNS:
            raise ValueError(f"Sensor: cfa must be one of {', '.join(CFA_PATTERNS)} or None, got {self.cfa!r}")
        if not all(g > 0 for g in self.channel_response):
            raise ValueError("Sensor: channel_response must be > 0")

    @property
    def full_scale(self) -> float:
        """The ADC's largest code, :math:`2^b - 1`."""
        return float(2**self.adc_bits - 1)

    def response_mosaic(self, height: int, width: int) -> NDArray[np.float64]:
        """The relative response of every pixel: its filter's ``channel_response`` (1 without a CFA)."""
        if self.cfa is None:
            return np.ones((height, width))
        idx = {"R": 0, "G": 1, "B": 2}
        tile = np.array(
            [
                [self.channel_response[idx[c]] for c in self.cfa[:2]],
                [self.channel_response[idx[c]] for c in self.cfa[2:]],
            ]
        )
        return np.tile(tile, ((height + 1) // 2, (width + 1) // 2))[:height, :width]


@dataclass(frozen=True)
class Development:
    """The raw conversion (module docstring, steps 1-5).

    Parameters
    ----------
    demosaic : one of :data:`DEMOSAIC_METHODS` (used only with a CFA).
    white_balance : divide each channel by its response (the sheet made neutral).
    tone : one of :data:`TONE_CURVES`.
    white_level : the fraction of the raw full scale that becomes white.
    bit_depth : 8 or 16.
    jpeg_quality : JPEG quality 1-100 (8-bit output only), or None for none.
    """

    demosaic: str = "bilinear"
    white_balance: bool = True
    tone: str = "linear"
    white_level: float = 1.0
    bit_depth: int = 8
    jpeg_quality: int | None = None

    def __post_init__(self) -> None:
        if self.demosaic not in DEMOSAIC_METHODS:
            raise ValueError(f"demosaic must be one of {', '.join(DEMOSAIC_METHODS)}, got {self.demosaic!r}")
        if self.tone not in TONE_CURVES:
            raise ValueError(f"tone must be one of {', '.join(TONE_CURVES)}, got {self.tone!r}")
        if self.bit_depth not in (8, 16):
            raise ValueError(f"bit_depth must be 8 or 16, got {self.bit_depth}")
        if not self.white_level > 0:
            raise ValueError(f"white_level must be > 0, got {self.white_level}")
        if self.jpeg_quality is not None:
            if self.bit_depth != 8 or not 1 <= int(self.jpeg_quality) <= 100:
                raise ValueError("jpeg_quality must be in 1..100 and needs bit_depth 8")


def raw_scale(sensor: Sensor, development: Development) -> int:
    """How many raw samples per output pixel and axis: 2 for a half-size conversion, else 1."""
    return 2 if sensor.cfa is not None and development.demosaic == "half-size" else 1


def expose(irradiance: NDArray[np.float64], sensor: Sensor, rng: np.random.Generator) -> NDArray[np.float64]:
    """The raw image in ADC codes (float, integral values in ``[0, full_scale]``) of an irradiance image."""
    electrons = irradiance * sensor.response_mosaic(*irradiance.shape) * (sensor.exposure * sensor.full_well_e)
    np.clip(electrons, 0.0, None, out=electrons)
    if sensor.shot_noise:
        # Poisson; above POISSON_AS_GAUSSIAN_E electrons drawn as the Gaussian of the same mean and
        # variance (the Poisson's skewness there is < 0.03: indistinguishable, five times faster)
        big = electrons >= POISSON_AS_GAUSSIAN_E
        small = ~big
        noisy = electrons + np.sqrt(electrons) * rng.standard_normal(electrons.shape)
        if small.any():
            noisy[small] = rng.poisson(electrons[small])
        electrons = noisy
    if sensor.read_noise_e > 0:
        electrons += rng.standard_normal(electrons.shape) * sensor.read_noise_e
    raw = np.rint(electrons * (sensor.full_scale / sensor.full_well_e))
    np.clip(raw, 0.0, sensor.full_scale, out=raw)
    return raw


def tone_curve(linear: NDArray[np.float64], tone: str) -> NDArray[np.float64]:
    """The transfer function ``tone`` (:data:`TONE_CURVES`) of linear values in ``[0, 1]``."""
    x = np.clip(linear, 0.0, 1.0)
    if tone == "linear":
        return x
    if tone == "bt709":
        out: NDArray[np.float64] = np.where(x < 0.018, 4.5 * x, 1.099 * np.power(x, 0.45) - 0.099)
        return out
    if tone == "srgb":
        out = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1.0 / 2.4) - 0.055)
        return out
    raise ValueError(f"unknown tone curve {tone!r}; known: {', '.join(TONE_CURVES)}")


def _channels(raw: NDArray[np.float64], sensor: Sensor, development: Development) -> NDArray[np.float64]:
    """R, G, B planes ``(h, w, 3)`` in units of the full scale, before white balance."""
    import cv2

    assert sensor.cfa is not None
    full = sensor.full_scale
    if development.demosaic == "half-size":
        h, w = raw.shape[0] // 2, raw.shape[1] // 2
        quad = {(r, c): raw[r : 2 * h : 2, c : 2 * w : 2] for r in (0, 1) for c in (0, 1)}
        names = [[sensor.cfa[0], sensor.cfa[1]], [sensor.cfa[2], sensor.cfa[3]]]
        planes = {"R": np.zeros((h, w)), "G": np.zeros((h, w)), "B": np.zeros((h, w))}
        count = {"R": 0, "G": 0, "B": 0}
        for (r, c), q in quad.items():
            planes[names[r][c]] += q
            count[names[r][c]] += 1
        return np.stack([planes[c] / count[c] for c in "RGB"], axis=-1) / full
    method = {"bilinear": "", "ea": "_EA", "vng": "_VNG"}[development.demosaic]
    code = getattr(cv2, f"COLOR_Bayer{_CV_PATTERN[sensor.cfa]}2BGR{method}")
    if development.demosaic == "vng":  # OpenCV's VNG takes 8-bit data only
        bgr = cv2.cvtColor(np.rint(raw * (255.0 / full)).astype(np.uint8), code).astype(np.float64) / 255.0
    else:
        bgr = cv2.cvtColor(raw.astype(np.uint16), code).astype(np.float64) / full
    out: NDArray[np.float64] = bgr[..., ::-1]
    return out


def develop(raw: NDArray[np.float64], sensor: Sensor, development: Development) -> NDArray[Any]:
    """The image a raw converter writes from ``raw`` (module docstring, steps 1-5).

    A monochrome sensor's raw is only scaled, toned and rounded; a Bayer raw of
    ``(2h, 2w)`` samples becomes an ``(h, w)`` image with ``demosaic="half-size"``.
    """
    if sensor.cfa is None:
        grey = raw / sensor.full_scale
    else:
        rgb = _channels(raw, sensor, development)
        if development.white_balance:
            rgb = rgb / np.asarray(sensor.channel_response)[None, None, :]
        grey = rgb @ np.asarray(LUMA)
    top = 255.0 if development.bit_depth == 8 else 65535.0
    coded = np.rint(tone_curve(grey / development.white_level, development.tone) * top)
    if development.bit_depth == 16:
        return coded.astype(np.uint16)
    image = coded.astype(np.uint8)
    if development.jpeg_quality is not None:
        image = jpeg_roundtrip(image, int(development.jpeg_quality))
    return image


def jpeg_roundtrip(image: NDArray[np.uint8], quality: int) -> NDArray[np.uint8]:
    """``image`` compressed to JPEG at ``quality`` (libjpeg scale, 1-100) and decoded again."""
    import cv2

    ok, buf = cv2.imencode(".jpg", image, [int(cv2.IMWRITE_JPEG_QUALITY), int(quality)])
    if not ok:
        raise ValueError(f"JPEG encoding failed for an image of shape {image.shape}")
    out = cv2.imdecode(buf, cv2.IMREAD_GRAYSCALE)
    if out is None:
        raise ValueError("JPEG decoding failed")
    return np.asarray(out, np.uint8)


def shot_noise_snr(sensor: Sensor, irradiance: float = 1.0) -> float:
    """The shot-noise signal-to-noise ratio of one green sample at ``irradiance`` (read noise included)."""
    e = irradiance * sensor.exposure * sensor.full_well_e
    return e / math.sqrt(e + sensor.read_noise_e**2)
