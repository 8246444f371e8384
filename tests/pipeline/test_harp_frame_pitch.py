"""The harp's string pitch from the shots' edge offsets (``pipeline.harp_frame.shot_pitch``, one estimator for
the station's mm -> px scale, ``string_pitch``, and for the harp's frame, ``harp_frame``). Truth: the generator's
exact geometry (``tests.pipeline.harp_points.turning_harp_point_sets``: strings a known spacing apart about a known
axis, both edges of each) through a known lens, and that lens's exact maps."""

import numpy as np
import pytest

from pipeline.harp_frame import harp_frame, harp_pitch, shot_pitch, string_pitch
from pipeline.models import RadialModel
from tests.pipeline.harp_points import turning_harp_point_sets

W, H = 640, 480
SPACING, WIDTH = 37.3, 3.4
AXIS = (331.0, 247.0)
N_STRINGS = 25  # 895 px across: wider than the image's 800 px diagonal, the outer strings out of view
ANGLE0 = 20.0
# Tolerance on a pitch in ideal px (corrected edges): each edge's offset is the mean of some 20 points with
# 0.003 px of noise (0.0007 px), so the slope over 14-17 strings spanning as many pitches is good to about 5e-5 px;
# the normal, from the edges' mean angle (about 1e-6 rad) or the turntable's, moves an offset by its edge's middle
# along the strings (300 px or less) times that: 3e-4 px at most. 0.002 px is several times both, and 1/1000 of
# what a string's width or a missed string moves a pitch (a median gap between edges is the pitch less the 3.4 px
# width; a hidden string taken as a neighbour adds a pitch to one gap of ~15).
TOL_PX = 0.002


def _shots(lens, turns, seed=3):
    """Per shot the edges through ``lens`` with the string numbered 14 hidden (both its edges) and one edge of
    string 9 lost, and the drawn string of every kept edge (from the exact lens and the drawn frame)."""
    shots, offsets = turning_harp_point_sets(
        lens, W, H, turns, np.zeros((N_STRINGS, 3)), angle0=ANGLE0, axis=AXIS, spacing=SPACING, string_width=WIDTH,
        step=20.0, seed=seed,
    )  # fmt: skip
    kept, numbers = [], []
    for theta, shot in zip(turns, shots, strict=True):
        a = np.radians(ANGLE0 + theta)
        nrm = np.array([-np.sin(a), np.cos(a)])
        q = [float(np.median((lens.undistort_points(e) - AXIS) @ nrm)) for e in shot]
        k = [int(np.argmin(np.abs(offsets - v))) for v in q]
        lost = next(i for i, v in enumerate(k) if v == 9)
        keep = [i for i, v in enumerate(k) if v != 14 and i != lost]
        kept.append([shot[i] for i in keep])
        numbers.append([k[i] for i in keep])
    return kept, numbers


def _offsets(edges, theta):
    a = np.radians(ANGLE0 + theta)
    nrm = np.array([-np.sin(a), np.cos(a)])
    return np.array([float(np.mean(e @ nrm)) for e in edges])


def test_the_pitch_of_exact_edge_offsets_is_exact_whatever_is_missing():
    # string k at 12.5 + 41 k px, both edges 3 px apart, strings 0-2 and 17-19 out of view, 8 and 9 hidden, one edge
    # of 11 lost, the edges in no order: exactly 41
    rng = np.random.default_rng(1)
    centres = 12.5 + 41.0 * np.array([k for k in range(3, 17) if k not in (8, 9)])
    edges = np.concatenate([centres - 1.5, centres + 1.5])
    edges = np.delete(edges, int(np.flatnonzero(centres == 12.5 + 41.0 * 11)[0]))
    assert shot_pitch(rng.permutation(edges)) == pytest.approx(41.0, abs=1e-9)
    assert shot_pitch(np.concatenate([edges, edges[2:8]])) == pytest.approx(41.0, abs=1e-9)  # strings drawn twice
    # strings that show one edge each (a string's two edges merged), two missing side by side
    single = 12.5 + 41.0 * np.array([0, 1, 2, 5, 6, 7, 8, 9])
    assert shot_pitch(single) == pytest.approx(41.0, abs=1e-9)
    assert np.isnan(shot_pitch(np.array([10.0, 13.0])))  # one string's two edges, or two strings: not told
    assert np.isnan(harp_pitch([np.array([5.0])]))


def test_one_shot_lens_free_gives_the_drawn_spacing():
    lens = RadialModel.for_image(W, H)  # no distortion: distorted = ideal
    (shot,), (numbers,) = _shots(lens, (0,))
    drawn = set(numbers)
    assert 0 not in drawn and N_STRINGS - 1 not in drawn and 14 not in drawn  # missing at the borders, one hidden
    assert shot_pitch(_offsets(shot, 0)) == pytest.approx(SPACING, abs=TOL_PX)  # harp_frame's, per shot
    assert string_pitch([shot]) == pytest.approx(SPACING, abs=TOL_PX)  # the station's, no angle given


def test_several_shots_through_a_mild_lens_give_the_drawn_spacing_to_both_callers():
    lens = RadialModel.for_image(W, H, k=(1.0, 0.0, 0.02), center=(325.0, 236.0), tangential=(3e-4, -2e-4))
    turns = (0, 40, 95, 140)
    shots, _ = _shots(lens, turns)
    corrected = [[lens.undistort_points(e) for e in s] for s in shots]  # the exact lens: ideal px
    assert string_pitch(corrected) == pytest.approx(SPACING, abs=TOL_PX)
    framed = harp_frame(corrected, turns, W, H)
    assert framed, framed
    assert framed[0].pitch_px == pytest.approx(SPACING, abs=TOL_PX)
    assert np.hypot(*(np.array(framed[0].centre) - AXIS)) < 1.0
    # as measured (the station's scale): the spacing times the lens's local scale across the strings somewhere in
    # the image, from the exact lens at ideal points whose images lie in it
    g = np.stack(np.meshgrid(np.linspace(-40, W + 40, 25), np.linspace(-40, H + 40, 19)), -1).reshape(-1, 2)
    scale = []
    for theta in turns:
        a = np.radians(ANGLE0 + theta)
        nrm = np.array([-np.sin(a), np.cos(a)])
        d0, d1 = lens.distort_points(g), lens.distort_points(g + nrm)
        inside = np.all((d0 >= 0) & (d0 <= [W - 1, H - 1]), axis=1)
        scale.append(np.hypot(*(d1 - d0)[inside].T))
    lo, hi = float(np.min(np.concatenate(scale))), float(np.max(np.concatenate(scale)))
    assert hi - lo > 0.01  # the lens does change the scale (over 1 %)
    assert lo * SPACING < string_pitch(shots) < hi * SPACING
