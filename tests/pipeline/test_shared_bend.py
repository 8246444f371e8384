"""The residual shared by every string edge of a shot and each edge's own part (:mod:`pipeline.shared_bend`).

Truth: edge points of a harp whose strings carry known bends (``turning_harp_point_sets``, a
perfect lens), the bend written out here from its Legendre terms and each edge's own least-squares
line removed with numpy, not with the code under test."""

import numpy as np
import pytest

from pipeline.models.base import IdentityModel
from pipeline.shared_bend import shared_bend
from tests.pipeline.harp_points import turning_harp_point_sets

W, H = 1000, 750
HALF = 0.5 * np.hypot(W, H)


def _bend_left_by_lines(coef: float, shots) -> float:
    """RMS over the points of ``coef P2(u)`` minus each edge's own least-squares line in ``u``:
    what a bend every string shares leaves after the regression lines (angle0 = 20 deg, axis at the centre)."""
    a = np.radians(20.0)
    d = np.array([np.cos(a), np.sin(a)])
    c = np.array([(W - 1) / 2.0, (H - 1) / 2.0])
    out = []
    for p in shots[0]:
        u = (p - c) @ d / HALF
        dev = coef * 0.5 * (3 * u**2 - 1)
        out.append(dev - np.polyval(np.polyfit(u, dev, 1), u))
    return float(np.sqrt(np.mean(np.concatenate(out) ** 2)))


def test_a_bend_every_string_shares_is_shared_and_noise_is_each_edges_own():
    shots, _ = turning_harp_point_sets(IdentityModel(), W, H, [0.0], [(0.05, 0.0, 0.0)] * 12, noise=0.003, seed=1)
    sb = shared_bend(shots[0])
    assert sb is not None and sb.n_edges == 24 and sb.direction_deg == pytest.approx(20.0, abs=0.5)
    truth = _bend_left_by_lines(0.05, shots)
    assert np.hypot(sb.shared_px, sb.own_px) == pytest.approx(truth, rel=0.15)
    # mostly shared: what is left to each edge is the noise, the bins' steps, and the lines of
    # shorter strings (near the corners) taking another part of the same bow
    assert sb.shared_px > 1.5 * sb.own_px
    # a bow, curved the same way along every edge: ends one side, middle the other
    prof = np.array(sb.profile_px)
    assert np.sign(prof[0]) == np.sign(prof[-1]) == -np.sign(prof[len(prof) // 2])


def test_bends_that_differ_from_string_to_string_are_their_own():
    rng = np.random.default_rng(7)
    bends = [(float(b), 0.0, 0.0) for b in rng.choice([-1.0, 1.0], 12) * 0.05]
    bends = [(b - np.mean([x[0] for x in bends]), 0.0, 0.0) for b, _, _ in bends]  # none shared
    shots, _ = turning_harp_point_sets(IdentityModel(), W, H, [0.0], bends, noise=0.003, seed=2)
    sb = shared_bend(shots[0])
    assert sb is not None
    assert sb.own_px > 4 * sb.shared_px
    assert sb.own_px == pytest.approx(_bend_left_by_lines(0.05, shots), rel=0.2)


def test_noise_alone_is_each_edges_own():
    shots, _ = turning_harp_point_sets(IdentityModel(), W, H, [0.0], [(0.0, 0.0, 0.0)] * 12, noise=0.01, seed=4)
    sb = shared_bend(shots[0])
    assert sb is not None
    assert sb.own_px == pytest.approx(0.01, rel=0.1) and sb.shared_px < 0.3 * sb.own_px


def test_too_few_edges_give_no_profile():
    shots, _ = turning_harp_point_sets(IdentityModel(), W, H, [0.0], [(0.05, 0.0, 0.0)] * 1, noise=0.003, seed=3)
    assert shared_bend(shots[0]) is None  # 2 edges
    with pytest.raises(ValueError, match="n_bins"):
        shared_bend(shots[0], n_bins=0)
