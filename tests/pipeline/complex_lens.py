"""An exact lens written in complex form, independent of :mod:`pipeline.models` (test and benchmark helper).

``z_d = z + k1 |z|^2 z + s |z|^2 + t conj(z)^2`` with ``z = (x - c) / f``: a radial term, the thin-prism
term ``s`` and the three-fold term ``t`` (complex numbers), the truth of ``tests/pipeline/test_trefoil.py``
and ``benchmarks/quadratic_sector.py``.
"""

from __future__ import annotations

import numpy as np


class ComplexLens:
    """Ideal -> distorted: ``z_d = z + k1 |z|^2 z + s |z|^2 + t conj(z)^2`` about ``centre``, ``z`` in units of ``f`` px."""

    def __init__(self, k1: float, s: complex, t: complex, centre: tuple[float, float], f: float = 1000.0) -> None:
        self.k1, self.s, self.t, self.c, self.f = k1, complex(s), complex(t), complex(*centre), float(f)

    def distort_points(self, xy: np.ndarray) -> np.ndarray:
        z = ((xy[:, 0] + 1j * xy[:, 1]) - self.c) / self.f
        zd = z + self.k1 * abs(z) ** 2 * z + self.s * abs(z) ** 2 + self.t * np.conj(z) ** 2
        out = self.c + self.f * zd
        return np.c_[out.real, out.imag]


def worst_d(model, shots) -> float:
    """Largest d (px) over ``shots`` (per shot, its edges) corrected by ``model``."""
    from pipeline.straightness import straightness

    return max(straightness([model.undistort_points(p) for p in lines]).d for lines in shots)
