r"""Lateral chromatic aberration (TCA): where a colour channel sees what green sees.

Through a lens with lateral chromatic aberration each colour has its own
magnification (and, in a decentred lens, its own small shift and tilt): the red and
blue images of a string lie beside the green one, by up to a few pixels towards the
corners. Green is the reference (it has the most samples on a Bayer sensor and sits
in the middle of the spectrum); each other channel ``c`` has a map from its own
pixels to green's, and the per-channel distortion correction is green's correction
after it: :math:`U_c = U_g \circ T_c`.

:class:`TcaField` — the full field, channel -> reference
--------------------------------------------------------
With :math:`c_0 = ((W-1)/2, (H-1)/2)` the image centre, :math:`R_0` the half
diagonal, :math:`v = (x - c_0)/R_0 = (\xi, \eta)` and :math:`\rho = |v|`:

.. math::
    T(x) = x + R_0 \Bigl[\, v \sum_{k \in K} a_k \rho^k
        + \sum_{i + j \le D} \bigl(b_{ij}, e_{ij}\bigr)\, \xi^i \eta^j \Bigr],
    \qquad K = \{1, 3, \dots\} \text{ (odd, } k \le D)

The bivariate polynomial of total degree :math:`D` holds a shift, a rotation, the
even radial terms (:math:`v\rho^{2m}` is a polynomial) and every non-radial term a
decentred lens adds; the odd radial terms :math:`v\rho^k` are the ones a polynomial
cannot hold (lensfun's poly3 TCA has one, :math:`c\,R`). The map is linear in its
parameters, so it is fitted by linear least squares (:mod:`pipeline.tca`). Its
inverse, reference -> channel (:meth:`TcaField.from_reference`), is a fixed-point
iteration :math:`x \leftarrow y - \Delta(x)`, which converges because the field's
slope is far below 1 (1e-3 for a strong TCA).

:class:`LensfunTca` — lensfun's radial TCA models
-------------------------------------------------
Lensfun describes TCA as a radial map from the corrected (green) image to the
channel, per channel red and blue, in its normalised coordinates (those of
:class:`~pipeline.models.lensfun_model.LensfunModel`: origin at the image centre
plus the lens's ``<center>``, unit half the shorter side between pixel centres).
With :math:`R_u` the radius of the green point and :math:`R_d` that of the same
point in the channel (on the same ray):

.. math::
    \text{linear:}\quad & R_d = k\, R_u \\
    \text{poly3:}\quad & R_d = R_u\,(b R_u^2 + c R_u + v)

with ``kr`` / ``kb`` (linear) or ``vr, cr, br`` / ``vb, cb, bb`` (poly3) in the
``<tca>`` element. Checked against liblensfun itself, through lensfunpy
(``tests/pipeline/test_tca.py``).

References
----------
.. [1] Lensfun, "lfTCAModel" and the lens database format,
   https://lensfun.github.io/manual/latest/ (``libs/lensfun/mod-subpix.cpp``).
.. [2] J. Mallon, P. F. Whelan, "Calibration and removal of lateral chromatic
   aberration in images", Pattern Recognition Letters 28(1), 2007.
.. [3] S. B. Kang, "Automatic removal of chromatic aberration from a single
   image", CVPR 2007.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pipeline.models.base import DistortionModel, model_from_dict

Floats = NDArray[np.float64]

TCA_DEGREE_BOUNDS = (1, 7)
"""Allowed total degrees ``D`` of :class:`TcaField`."""
LENSFUN_TCA_TERMS = {"linear": ("k",), "poly3": ("v", "c", "b")}
"""Lensfun's TCA models and their terms per channel (``kr``, ``vr``, ``cr``, ``br``, ...)."""
FIXED_POINT_TOL_PX = 1e-10


def tca_exponents(degree: int) -> list[tuple[int, int]]:
    """``(i, j)`` of the monomials :math:`\\xi^i \\eta^j`, ``i + j <= degree``, by degree then ``j``."""
    return [(n - j, j) for n in range(degree + 1) for j in range(n + 1)]


def radial_powers(degree: int) -> list[int]:
    """The odd radial powers ``k`` of :class:`TcaField` of total degree ``degree``: ``1, 3, .. <= degree``."""
    return list(range(1, degree + 1, 2))


def n_tca_params(degree: int) -> int:
    """Parameters of a :class:`TcaField` of total degree ``degree``."""
    return 2 * len(tca_exponents(degree)) + len(radial_powers(degree))


@dataclass(frozen=True)
class TcaField:
    """A channel's map to the reference channel (module docstring, equation of :math:`T`).

    ``coefficients`` in the order of :func:`tca_basis` (``a_k`` for the odd radial
    powers, then ``b_ij``, then ``e_ij`` in :func:`tca_exponents` order).
    """

    width: int
    height: int
    degree: int
    coefficients: tuple[float, ...]

    def __post_init__(self) -> None:
        lo, hi = TCA_DEGREE_BOUNDS
        if not lo <= int(self.degree) <= hi:
            raise ValueError(f"TCA field degree must be {lo}..{hi}, got {self.degree}")
        coef = tuple(float(v) for v in self.coefficients)
        if len(coef) != n_tca_params(int(self.degree)):
            raise ValueError(f"a degree-{self.degree} TCA field has {n_tca_params(int(self.degree))} coefficients")
        object.__setattr__(self, "degree", int(self.degree))
        object.__setattr__(self, "coefficients", coef)

    @classmethod
    def zero(cls, width: int, height: int, degree: int = 5) -> TcaField:
        """The identity (a channel that sees exactly what the reference sees)."""
        return cls(width, height, degree, (0.0,) * n_tca_params(degree))

    @property
    def center(self) -> tuple[float, float]:
        return ((self.width - 1) / 2.0, (self.height - 1) / 2.0)

    @property
    def r0(self) -> float:
        return 0.5 * float(np.hypot(self.width, self.height))

    def shift(self, xy: Floats) -> Floats:
        """:math:`T(x) - x`, pixels, for ``(N, 2)`` channel points."""
        a = tca_basis(xy, self.width, self.height, self.degree)
        out: Floats = (a @ np.asarray(self.coefficients)).reshape(2, -1).T
        return out

    def to_reference(self, xy: Floats) -> Floats:
        """:math:`T(x)`: channel pixels to reference pixels."""
        p = np.asarray(xy, np.float64).reshape(-1, 2)
        return p + self.shift(p)

    def from_reference(self, xy: Floats, max_iter: int = 50) -> Floats:
        """:math:`T^{-1}(y)`: reference pixels to channel pixels (fixed point, to 1e-10 px)."""
        y = np.asarray(xy, np.float64).reshape(-1, 2)
        x = y.copy()
        for _ in range(max_iter):
            nxt = y - self.shift(x)
            done = float(np.max(np.abs(nxt - x), initial=0.0)) < FIXED_POINT_TOL_PX
            x = nxt
            if done:
                break
        return x

    def to_dict(self) -> dict[str, Any]:
        return {
            "model": "tca_field",
            "image_size": [self.width, self.height],
            "degree": self.degree,
            "coefficients": list(self.coefficients),
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> TcaField:
        w, h = d["image_size"]
        return cls(int(w), int(h), int(d["degree"]), tuple(float(v) for v in d["coefficients"]))


def tca_basis(xy: Floats, width: int, height: int, degree: int) -> Floats:
    """The linear map from the coefficients to the shifts: ``(2N, P)``, x rows then y rows, pixels."""
    p = np.asarray(xy, np.float64).reshape(-1, 2)
    c = np.array([(width - 1) / 2.0, (height - 1) / 2.0])
    r0 = 0.5 * float(np.hypot(width, height))
    v = (p - c) / r0
    xi, eta = v[:, 0], v[:, 1]
    rho = np.hypot(xi, eta)
    n = len(p)
    ks = radial_powers(degree)
    ex = tca_exponents(degree)
    a = np.zeros((2 * n, len(ks) + 2 * len(ex)))
    for col, k in enumerate(ks):
        rk = rho**k
        a[:n, col] = r0 * xi * rk
        a[n:, col] = r0 * eta * rk
    mono = np.column_stack([xi**i * eta**j for i, j in ex]) * r0
    a[:n, len(ks) : len(ks) + len(ex)] = mono
    a[n:, len(ks) + len(ex) :] = mono
    return a


@dataclass(frozen=True)
class LensfunTca:
    """Lensfun's radial TCA of the red and blue channels (module docstring).

    ``red`` and ``blue`` hold the terms of :data:`LENSFUN_TCA_TERMS` ``[kind]``;
    ``center`` is the lens's ``<center>`` (lensfun normalised units).
    """

    kind: str
    red: tuple[float, ...]
    blue: tuple[float, ...]
    width: int
    height: int
    center: tuple[float, float] = (0.0, 0.0)

    def __post_init__(self) -> None:
        if self.kind not in LENSFUN_TCA_TERMS:
            raise ValueError(f"unsupported lensfun TCA model {self.kind!r}; supported: {sorted(LENSFUN_TCA_TERMS)}")
        n = len(LENSFUN_TCA_TERMS[self.kind])
        for name in ("red", "blue"):
            terms = tuple(float(v) for v in getattr(self, name))
            if len(terms) != n:
                raise ValueError(f"lensfun {self.kind} TCA needs {n} terms per channel, got {len(terms)} for {name}")
            object.__setattr__(self, name, terms)

    @property
    def unit(self) -> float:
        """Pixels per lensfun normalised unit (half the shorter side between pixel centres)."""
        return min(self.width - 1, self.height - 1) / 2.0

    @property
    def origin(self) -> tuple[float, float]:
        s = self.unit
        return ((self.width - 1) / 2.0 + s * self.center[0], (self.height - 1) / 2.0 + s * self.center[1])

    def terms(self, channel: str) -> tuple[float, ...]:
        if channel not in ("R", "B"):
            raise ValueError(f"lensfun TCA has red and blue channels, not {channel!r}")
        return self.red if channel == "R" else self.blue

    def factor(self, channel: str, ru: Floats) -> Floats:
        """``R_d / R_u`` of a channel at the reference radius ``ru``."""
        t = self.terms(channel)
        if self.kind == "linear":
            return np.full_like(np.asarray(ru, np.float64), t[0])
        v, c, b = t
        return (b * ru + c) * ru + v

    def from_reference(self, channel: str, xy: Floats) -> Floats:
        """Reference (corrected) pixels to the channel's pixels: what lensfun reads for that channel."""
        p = np.asarray(xy, np.float64).reshape(-1, 2)
        o = np.asarray(self.origin)
        s = self.unit
        q = (p - o) / s
        f = self.factor(channel, np.hypot(q[:, 0], q[:, 1]))
        out: Floats = o + s * f[:, None] * q
        return out

    def element_attributes(self, focal: float) -> dict[str, str]:
        """The attributes of lensfun's ``<tca>`` element at ``focal`` mm."""
        attrs = {"model": self.kind, "focal": repr(float(focal))}
        for suffix, values in (("r", self.red), ("b", self.blue)):
            attrs.update({f"{t}{suffix}": repr(float(x)) for t, x in zip(LENSFUN_TCA_TERMS[self.kind], values)})
        return attrs


@dataclass(frozen=True)
class ChannelModel(DistortionModel):
    r"""The distortion correction of one colour channel: the reference's after the TCA map.

    .. math:: U_c(x) = U_g\bigl(T_c(x)\bigr)

    ``reference`` is green's correction (any :class:`DistortionModel`), ``tca`` the
    channel's :class:`TcaField`. Not written to model files by itself: a model file
    holds the reference model and the fields (:mod:`pipeline.tca`).
    """

    reference: DistortionModel
    tca: TcaField
    name: str = field(default="channel", init=False, repr=False)

    def undistort_points(self, xy: np.ndarray) -> np.ndarray:
        return self.reference.undistort_points(self.tca.to_reference(xy))

    def distort_points(self, xy: np.ndarray, max_iter: int = 50) -> np.ndarray:
        return self.tca.from_reference(self.reference.distort_points(xy, max_iter), max_iter)

    def to_dict(self) -> dict[str, Any]:
        return {"model": self.name, "reference": self.reference.to_dict(), "tca": self.tca.to_dict()}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> ChannelModel:
        return cls(model_from_dict(d["reference"]), TcaField.from_dict(d["tca"]))
