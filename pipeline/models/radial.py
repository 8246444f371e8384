"""Radial polynomial correction with free centre, plus Brown–Conrady terms."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from pipeline.models.base import DistortionModel


@dataclass(frozen=True)
class RadialModel(DistortionModel):
    r"""Radial polynomial correction with a free centre (Tang et al. 2012, eq. 1),
    optionally with decentering (tangential) and thin-prism terms (Brown–Conrady).

    Maps distorted pixels :math:`(x_d, y_d)` to ideal pixels :math:`(x_u, y_u)`.
    With the normalised offsets :math:`\xi = (x_d - c_x)/s`,
    :math:`\eta = (y_d - c_y)/s`, :math:`\rho^2 = \xi^2 + \eta^2`:

    .. math::
        f(\rho) &= k_0 + k_1 \rho + k_2 \rho^2 + \dots + k_N \rho^N \\
        \xi_u &= f(\rho)\,\xi + 2 p_1 \xi\eta + p_2(\rho^2 + 2\xi^2) + s_1\rho^2 + s_2\rho^4 \\
        \eta_u &= f(\rho)\,\eta + p_1(\rho^2 + 2\eta^2) + 2 p_2 \xi\eta + s_3\rho^2 + s_4\rho^4 \\
        x_u &= c_x + s\,\xi_u, \quad y_u = c_y + s\,\eta_u

    ``s`` (``scale``) is a fixed normalisation, by convention half the image
    diagonal, so that the coefficients do not depend on the image size.

    Parameter order (as in :meth:`params`): ``cx, cy, k0 … kN, p1, p2, s1 … s4``
    (``p`` and ``s`` present only when enabled).

    References
    ----------
    .. [1] Z. Tang et al., "High-precision camera distortion measurements
       with a calibration harp", JOSA A 29(10), 2012.
    .. [2] D. C. Brown, "Decentering distortion of lenses", Photogrammetric
       Engineering 32(3), 1966.
    """

    center: tuple[float, float]
    k: tuple[float, ...] = (1.0,)
    scale: float = 1000.0
    tangential: tuple[float, float] | None = None
    prism: tuple[float, float, float, float] | None = None
    name: str = field(default="radial", init=False, repr=False)

    def __post_init__(self):
        object.__setattr__(self, "center", tuple(float(v) for v in self.center))
        object.__setattr__(self, "k", tuple(float(v) for v in self.k))
        if self.tangential is not None:
            object.__setattr__(self, "tangential", tuple(float(v) for v in self.tangential))
        if self.prism is not None:
            object.__setattr__(self, "prism", tuple(float(v) for v in self.prism))
        if not self.k:
            raise ValueError("RadialModel needs at least k0")
        if not self.scale > 0:
            raise ValueError(f"RadialModel scale must be > 0, got {self.scale}")

    @classmethod
    def for_image(cls, width: int, height: int, k=(1.0,), center=None, **kw) -> RadialModel:
        """Model with ``scale`` = half diagonal and centre (default) at the image centre."""
        if center is None:
            center = ((width - 1) / 2.0, (height - 1) / 2.0)
        return cls(center=center, k=tuple(k), scale=0.5 * float(np.hypot(width, height)), **kw)

    def params(self) -> np.ndarray:
        """Parameter vector in the documented order."""
        p = [*self.center, *self.k]
        if self.tangential is not None:
            p += list(self.tangential)
        if self.prism is not None:
            p += list(self.prism)
        return np.asarray(p, dtype=np.float64)

    def undistort_points(self, xy: np.ndarray) -> np.ndarray:
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        s = self.scale
        xi = (xy[:, 0] - self.center[0]) / s
        eta = (xy[:, 1] - self.center[1]) / s
        rho2 = xi * xi + eta * eta
        rho = np.sqrt(rho2)
        f = np.polynomial.polynomial.polyval(rho, np.asarray(self.k))
        xu = f * xi
        yu = f * eta
        if self.tangential is not None:
            p1, p2 = self.tangential
            xu = xu + 2 * p1 * xi * eta + p2 * (rho2 + 2 * xi * xi)
            yu = yu + p1 * (rho2 + 2 * eta * eta) + 2 * p2 * xi * eta
        if self.prism is not None:
            s1, s2, s3, s4 = self.prism
            xu = xu + s1 * rho2 + s2 * rho2 * rho2
            yu = yu + s3 * rho2 + s4 * rho2 * rho2
        return np.stack([self.center[0] + s * xu, self.center[1] + s * yu], axis=1)

    def to_dict(self) -> dict:
        d = {"model": self.name, "center": list(self.center), "k": list(self.k), "scale": self.scale}
        if self.tangential is not None:
            d["tangential"] = list(self.tangential)
        if self.prism is not None:
            d["prism"] = list(self.prism)
        return d

    @classmethod
    def from_dict(cls, d: dict) -> RadialModel:
        return cls(
            center=tuple(d["center"]),
            k=tuple(d["k"]),
            scale=float(d["scale"]),
            tangential=tuple(d["tangential"]) if d.get("tangential") is not None else None,
            prism=tuple(d["prism"]) if d.get("prism") is not None else None,
        )
