"""Synthetic harp edge point sets with an exact answer (test helper).

Ideal straight lines at given orientations, sampled every ``step`` px,
mapped through a true lens (``distort_points``: ideal -> distorted), kept
inside the image, plus Gaussian noise of the size t-smoothing leaves.
"""

from __future__ import annotations

import numpy as np


def harp_point_sets(lens, width, height, angles_deg, spacing=50.0, step=30.0, noise=0.005, seed=0, margin=5.0):
    """One list of (M, 2) edge point arrays per angle."""
    rng = np.random.default_rng(seed)
    cx, cy = (width - 1) / 2.0, (height - 1) / 2.0
    half = 0.5 * np.hypot(width, height)
    shots = []
    for k, ang in enumerate(angles_deg):
        t = np.radians(ang)
        d = np.array([np.cos(t), np.sin(t)])
        n = np.array([-d[1], d[0]])
        lines = []
        phase = (k * 0.37 % 1.0) * spacing
        for off in np.arange(-half + phase, half, spacing):
            s = np.arange(-half, half, step)
            ideal = np.array([cx, cy]) + off * n + s[:, None] * d
            dist = lens.distort_points(ideal)
            ok = (
                np.all(np.isfinite(dist), axis=1)
                & (dist[:, 0] > margin)
                & (dist[:, 0] < width - 1 - margin)
                & (dist[:, 1] > margin)
                & (dist[:, 1] < height - 1 - margin)
            )
            p = dist[ok]
            if len(p) >= 8:
                lines.append(p + rng.normal(0.0, noise, p.shape))
        shots.append(lines)
    return shots
