"""A held-out shot's own axis shift and two shots at one angle (pipeline.own_shift), against exact lens maps: the shots
drawn through the same lens with its distortion centre moved by a hand-chosen vector, through the lens itself, or
through a lens with a term the correction lacks."""

import numpy as np

from pipeline.models import RadialModel
from pipeline.own_shift import own_axis_shift, twin_shift

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


def _moved(move: tuple[float, float]) -> RadialModel:
    return RadialModel((600.0 + move[0], 400.0 + move[1]), LENS.k, LENS.scale, tangential=LENS.tangential)


def test_twins_of_a_lens_that_moved_each_want_their_own_shift():
    """The second twin through the lens moved by a hand-chosen vector: a shift each straightens both to the noise,
    one for both cannot, and the move across the strings comes back."""
    for angle, move in ((20.0, (4.0, -3.0)), (110.0, (-3.0, -2.0))):
        got = twin_shift(LENS, _shot(LENS, angle, seed=1, noise_px=0.002), _shot(_moved(move), angle, 2, 0.002))
        assert got.d_common > 0.005 and got.d_each < 0.0022 and got.ratio < 0.4, got
        assert abs(abs(got.move_px) - abs(float(np.dot(move, got.normal)))) < 0.03 * np.hypot(*move), got
        a = np.radians(angle)
        assert abs(float(np.dot(got.normal, (np.cos(a), np.sin(a))))) < 0.01, got  # across the strings


def test_twins_through_a_lens_term_the_correction_lacks_want_one_shift():
    """Both twins through a lens whose decentering the correction lacks (p1, p2 three times the model's): each twin
    alone has a term of its own (own_axis_shift takes most of its d), the pair shares it (one shift does as well as
    two): a term of the lens, not a move."""
    term = RadialModel(LENS.center, LENS.k, LENS.scale, tangential=(6e-4, -3e-4))
    a, b = _shot(term, 55.0, seed=4, noise_px=0.002), _shot(term, 55.0, seed=5, noise_px=0.002)
    assert own_axis_shift(LENS, a).ratio < 0.5 and own_axis_shift(LENS, b).ratio < 0.5
    got = twin_shift(LENS, a, b)
    assert got.d_model > 0.01 and got.ratio > 0.97 and abs(got.move_px) < 0.3, got


def test_twins_without_an_edge_are_nan():
    got = twin_shift(LENS, [np.zeros((2, 2))], _shot(LENS, 10.0, seed=1, noise_px=0.002))
    assert np.isnan(got.ratio) and np.isnan(got.move_px)
