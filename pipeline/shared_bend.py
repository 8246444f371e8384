"""The part of a shot's residual bend that every string edge shares, and the part each edge has alone.

After a correction, each edge of a shot still departs from its regression line by a residual
``S`` (:func:`pipeline.straightness.fit_line`). Two causes leave different marks:

* a term of the lens the correction lacks, or one the fitted shots left undetermined (with two
  orientations a three-fold term, :class:`~pipeline.models.radial.RadialModel`'s ``trefoil``, is taken
  up by the thin-prism and decentering terms and bends a third orientation), bends **every** edge
  of a shot the same way where they pass through the same part of the field — as does a bend the
  whole harp shares;
* a string's own bend, its twist and the measurement's noise differ from edge to edge, and so
  does a lens term that changes across the field (a radial bow changes sign across the centre):
  these are the **own** part.

The shared part is the **common profile**: the mean over the edges of each edge's mean residual
in each of ``n_bins`` equal bins of position along the strings (the shot's mean direction), with
each edge's normal oriented alike. It is what an edge's residual would be if it were only the
shared cause; the rest is each edge's own. On the real photographs fitted on two shots
(radial4+tangential+prism), IMG_6964, the orientation left out, is left with d 0.069 px: 0.061 px
RMS shared by every string, 0.033 px each edge's own; the same shot in a fit of all three keeps
0.010 px shared and 0.023 px own (``harp calibrate IMG_6931.pgm IMG_6950.pgm --out two.yaml``, then
``harp evaluate two.yaml IMG_6964.pgm``). The shared part was a
quadratic term the two orientations could not tell from the thin-prism terms, not the strings: with the
three-fold term, all three shots fitted keep 0.005-0.009 px shared instead of 0.010-0.013
(``benchmarks/quadratic_sector.py``).

References
----------
.. [1] Tang, Grompone von Gioi, Monasse, Morel, "High-precision camera distortion measurements
   with a calibration harp", JOSA A 29(10), 2012: d, the RMS distance to each edge's regression line.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from pipeline.orientations import shot_orientation
from pipeline.straightness import fit_line

MIN_EDGES = 4
"""Fewest edges (of at least :data:`MIN_POINTS` points) for a common profile: with fewer, their mean is
mostly each one's own bend."""

MIN_POINTS = 8
"""Fewest points of an edge taken into the profile."""

N_BINS = 10
"""Bins of position along the strings: a tenth of the shot's extent each, finer than the lowest
terms a correction lacks (a bow, an S) and coarse enough to hold points of most edges."""


@dataclass(frozen=True)
class SharedBend:
    """A shot's residual split into the profile its edges share and what each edge has alone.

    Attributes
    ----------
    shared_px : RMS over the points of the common profile at each point's bin.
    own_px : RMS over the points of the residual minus the common profile.
    profile_px : the common profile, one value per bin along the strings (NaN: no edge there),
        signed along the shot's normal (its direction turned +90 degrees).
    direction_deg : the shot's mean string direction, in [0, 180).
    n_edges : edges taken into the profile.
    """

    shared_px: float
    own_px: float
    profile_px: tuple[float, ...]
    direction_deg: float
    n_edges: int

    def to_dict(self) -> dict[str, object]:
        return {
            "shared_px": self.shared_px,
            "own_px": self.own_px,
            "profile_px": [None if not np.isfinite(v) else float(v) for v in self.profile_px],
            "direction_deg": self.direction_deg,
            "n_edges": self.n_edges,
        }


def shared_bend(point_sets: Sequence[NDArray[np.float64]], n_bins: int = N_BINS) -> SharedBend | None:
    """Split the residual of one shot's edges (corrected points) into a common profile and the rest.

    Parameters
    ----------
    point_sets : (M, 2) arrays, the corrected points of each edge of one shot (x = column, y = row).
    n_bins : bins of position along the strings.

    Returns
    -------
    SharedBend, or None when fewer than :data:`MIN_EDGES` edges have :data:`MIN_POINTS` points.
    """
    if n_bins < 1:
        raise ValueError(f"n_bins must be >= 1, got {n_bins}")
    edges = []
    for p in point_sets:
        q = np.asarray(p, dtype=np.float64).reshape(-1, 2)
        q = q[np.all(np.isfinite(q), axis=1)]
        if len(q) >= MIN_POINTS:
            edges.append((q, fit_line(q)))
    if len(edges) < MIN_EDGES:
        return None
    direction_deg = shot_orientation([q for q, _ in edges])  # the length-weighted mean on doubled angles
    mean = np.radians(direction_deg)
    along = np.array([np.cos(mean), np.sin(mean)])
    normal = np.array([-along[1], along[0]])
    pos = [q @ along for q, _ in edges]
    lo = min(float(s.min()) for s in pos)
    hi = max(float(s.max()) for s in pos)
    span = max(hi - lo, 1e-9)
    bins = [np.minimum((n_bins * (s - lo) / span).astype(int), n_bins - 1) for s in pos]
    res = [f.S if float(f.normal @ normal) >= 0.0 else -f.S for _, f in edges]
    means = np.full((len(edges), n_bins), np.nan)
    for i, (b, r) in enumerate(zip(bins, res)):
        count = np.bincount(b, minlength=n_bins)
        total = np.bincount(b, weights=r, minlength=n_bins)
        seen = count > 0
        means[i, seen] = total[seen] / count[seen]
    seen_by = np.sum(np.isfinite(means), axis=0)
    profile = np.full(n_bins, np.nan)
    ok = seen_by > 0
    profile[ok] = np.nansum(means[:, ok], axis=0) / seen_by[ok]
    shared = np.concatenate([profile[b] for b in bins])
    own = np.concatenate([r - profile[b] for b, r in zip(bins, res)])
    return SharedBend(
        shared_px=float(np.sqrt(np.mean(shared**2))),
        own_px=float(np.sqrt(np.mean(own**2))),
        profile_px=tuple(float(v) for v in profile),
        direction_deg=direction_deg,
        n_edges=len(edges),
    )
