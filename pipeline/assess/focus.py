"""The focus peak over a series of (focus setting, focus score) samples: the vertex of a parabola
fitted to the squared edge widths (:mod:`pipeline.assess`, end of *Sharpness of a string*)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np


@dataclass(frozen=True)
class FocusPeak:
    """Where the focus score peaks over a series of (focus setting, score) samples.

    ``focus``: the vertex of the parabola fitted to the squared edge widths
    ``1 / score^2`` around their minimum when the samples bracket it
    (``bracketed``), else the best sample's setting; ``score``: the score
    there (the parabola's, or the best sample's); ``samples``: how many
    samples entered.
    """

    focus: float
    score: float
    bracketed: bool
    samples: int

    def to_dict(self) -> dict[str, Any]:
        return {"focus": self.focus, "score": self.score, "bracketed": self.bracketed, "samples": self.samples}


def focus_peak(positions: Sequence[float], scores: Sequence[float]) -> FocusPeak | None:
    """The focus setting of best focus from a through-focus series (:mod:`pipeline.assess`).

    Parameters
    ----------
    positions, scores : sequences of float
        Focus settings and the focus scores measured there (1 / edge width);
        non-finite scores are ignored; repeated settings are averaged.

    Returns
    -------
    FocusPeak or None
        None without a finite sample.

    References
    ----------
    .. [1] M. Subbarao, J.-K. Tian, IEEE TPAMI 20(8), 1998.
    """
    f = np.asarray(positions, np.float64)
    sc = np.asarray(scores, np.float64)
    ok = np.isfinite(f) & np.isfinite(sc) & (sc > 0)
    if not ok.any():
        return None
    f, sc = f[ok], sc[ok]
    uf, inv = np.unique(f, return_inverse=True)
    w2 = np.bincount(inv, weights=1.0 / sc**2) / np.bincount(inv)
    best = int(np.argmin(w2))
    best_score = float(1.0 / math.sqrt(w2[best]))
    if len(uf) < 3 or best in (0, len(uf) - 1):
        return FocusPeak(float(uf[best]), best_score, False, int(ok.sum()))
    # the samples near the minimum: squared width within 4x of it (a width within 2x), at least 3
    near = np.nonzero(w2 <= 4.0 * w2[best])[0]
    lo, hi = best, best
    while lo - 1 >= 0 and lo - 1 in near:
        lo -= 1
    while hi + 1 < len(uf) and hi + 1 in near:
        hi += 1
    lo, hi = min(lo, best - 1), max(hi, best + 1)
    a, b, c = np.polyfit(uf[lo : hi + 1], w2[lo : hi + 1], 2)
    if not a > 0:
        return FocusPeak(float(uf[best]), best_score, False, int(ok.sum()))
    vertex = -b / (2.0 * a)
    if not uf[lo] <= vertex <= uf[hi]:
        return FocusPeak(float(uf[best]), best_score, False, int(ok.sum()))
    at = c - b * b / (4.0 * a)
    score = float(1.0 / math.sqrt(at)) if at > 0 else best_score
    return FocusPeak(float(vertex), score, True, int(ok.sum()))
