"""Shared truth and helpers of the harp's frame and shape tests (``test_harp_frame.py``, ``test_harp_shape.py``): the
image size, the exact lens the shots are drawn through, and a drawn harp's shots corrected by it."""

import numpy as np

from pipeline.harp_scene import HarpMount, draw_harp
from pipeline.models import RadialModel
from tests.pipeline.harp_points import drawn_harp_point_sets

W, H = 1000, 750
LENS = RadialModel.for_image(
    W, H, k=(1.0, 0.0, 0.03, 0.0, 0.004), center=(512, 366), tangential=(8e-4, -5e-4), prism=(4e-4, 0.0, -3e-4, 0.0)
)


def drawn_corrected(turns, n_strings, pitch, axis_off, seed=1):
    """Shots of a drawn harp (bows, kinks, twist) through LENS, corrected by the exact LENS, with the drawn axis
    (ideal px) and the drawn string of every edge (``pipeline.harp_scene`` geometry, not ``harp_frame``'s)."""
    axis = ((W - 1) / 2.0 + axis_off[0] * pitch, (H - 1) / 2.0 + axis_off[1] * pitch)
    harp = draw_harp(seed, n_strings, pitch, 3.0, 1.5 * np.hypot(W, H), material="nylon", visible_px=600.0)
    shots, strings = drawn_harp_point_sets(LENS, W, H, turns, harp, HarpMount(axis, 20.0), step=20.0, seed=seed)
    return [[LENS.undistort_points(e) for e in s] for s in shots], strings, np.array(axis)
