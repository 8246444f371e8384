"""Ground truth for measured harp edges: match each measured edge to its exact curve.

The exact distorted edge curves come from :func:`pipeline.render.visible_edges`.
Each measured edge is matched to the truth curve closest to its raw points;
the truth is then clipped to the arclength span the measurement covers, and
goes through the same smoothing (per contiguous piece of the measured edge)
and the same straightness measure, so that measured and true ``d``/``d_max``
describe exactly the same stretch of each string edge.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from pipeline.measure import BRIDGE_GAP_PX, ImageMeasurement
from pipeline.render import Rendered, visible_edges
from pipeline.resample import smooth_subsample
from pipeline.straightness import straightness


def match_truth(r: Rendered, m: ImageMeasurement, max_dist: float = 1.5):
    """For each measured line: ``(EdgeTruth, curve, median distance)`` of the closest true edge."""
    truth = visible_edges(r, margin=0.0, step=0.5, min_length_px=1.0)
    allpts = np.concatenate([c for _, c in truth])
    label = np.repeat(np.arange(len(truth)), [len(c) for _, c in truth])
    tree = cKDTree(allpts)
    out = []
    for ln in m.lines:
        q = ln.raw_points[:: max(1, len(ln.raw_points) // 100)]
        dist, idx = tree.query(q)
        k = int(np.bincount(label[idx]).argmax())
        med = float(np.median(cKDTree(truth[k][1]).query(q)[0]))
        assert med < max_dist, f"measured edge matches no true edge ({med:.2f} px off)"
        out.append((truth[k][0], truth[k][1], med))
    return out


def true_measure(r: Rendered, m: ImageMeasurement, matches=None):
    """Straightness of the true curves over the spans of the measured edges."""
    sets = []
    for ln, (_, curve, _) in zip(m.lines, matches or match_truth(r, m)):
        tree = cKDTree(curve)
        raw = ln.raw_points
        # the contiguous pieces of the measured edge (same rule as measure_grouping)
        gaps = np.nonzero(np.hypot(*np.diff(raw, axis=0).T) > BRIDGE_GAP_PX)[0]
        bounds = np.concatenate([[0], gaps + 1, [len(raw)]])
        parts = []
        for a, b in zip(bounds[:-1], bounds[1:]):
            _, i0 = tree.query(raw[a])
            _, i1 = tree.query(raw[b - 1])
            lo, hi = sorted((int(i0), int(i1)))
            seg = curve[lo : hi + 1]
            if i0 > i1:
                seg = seg[::-1]
            parts.append(smooth_subsample(seg, t=m.t))
        sets.append(np.concatenate(parts))
    return straightness(sets)
