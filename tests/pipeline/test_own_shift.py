"""A held-out shot's own axis shift (pipeline.own_shift), against exact lens maps: the shot drawn through the same
lens with its distortion centre moved by a hand-chosen vector, or through the lens itself."""

import numpy as np

from pipeline.models import RadialModel
from pipeline.own_shift import own_axis_shift

W, H = 1200, 800
LENS = RadialModel((600.0, 400.0), (1.0, -0.08, 0.02), 721.1, tangential=(2e-4, -1e-4))


def _shot(lens: RadialModel, angle_deg: float, seed: int, noise_px: float) -> list[np.ndarray]:
    """Edges of parallel straight strings at ``angle_deg``, 60 px apart across the image (ideal lines), drawn
    through ``lens`` (the ideal points' distorted positions) with seeded noise."""
    rng = np.random.default_rng(seed)
    a = np.radians(angle_deg)
    d, n = np.array([np.cos(a), np.sin(a)]), np.array([-np.sin(a), np.cos(a)])
    c = np.array([W / 2, H / 2])
    out = []
    for off in np.arange(-540.0, 541.0, 60.0):
        s = np.arange(-800.0, 801.0, 10.0)
        ideal = c + off * n + s[:, None] * d
        p = lens.distort_points(ideal)
        inside = np.isfinite(p).all(axis=1) & (p[:, 0] > 5) & (p[:, 0] < W - 6) & (p[:, 1] > 5) & (p[:, 1] < H - 6)
        if inside.sum() >= 20:
            out.append(p[inside] + rng.normal(0.0, noise_px, p[inside].shape))
    return out


def test_a_shot_through_the_lens_moved_takes_back_the_move_across_its_strings():
    """Three angles, three moves (px, chosen by hand): the correction moved by the fitted shift straightens the shot
    to its noise, and the shift's component across the strings is the move's (its component along them moves each
    line along itself, which d cannot see)."""
    for angle, move in ((20.0, (4.0, -3.0)), (75.0, (-2.5, 1.5)), (130.0, (6.0, 2.0))):
        moved = RadialModel((600.0 + move[0], 400.0 + move[1]), LENS.k, LENS.scale, tangential=LENS.tangential)
        got = own_axis_shift(LENS, _shot(moved, angle, seed=7, noise_px=0.002))
        a = np.radians(angle)
        across = np.array([-np.sin(a), np.cos(a)])
        assert got.d_held > 0.01, got  # the move bends the strings five times the noise (0.002 px) or more
        assert got.d_own < 0.0022 and got.ratio < 0.2, got  # back to the noise
        assert abs(np.dot(got.shift_px, across) - np.dot(move, across)) < 0.02 * np.linalg.norm(move), got


def test_a_shot_through_the_same_lens_has_nothing_of_its_own():
    got = own_axis_shift(LENS, _shot(LENS, 40.0, seed=3, noise_px=0.01))
    assert 0.008 < got.d_held < 0.012 and got.ratio > 0.98, got  # two parameters take only their share of noise
    assert np.hypot(*got.shift_px) < 1.0, got


def test_no_edge_is_nan():
    got = own_axis_shift(LENS, [np.zeros((2, 2))])
    assert np.isnan(got.d_held) and np.isnan(got.ratio) and got.points == 0
