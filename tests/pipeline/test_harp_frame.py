"""The harp's frame in the shots (issue 19 item 4): the turntable axis and each edge's string, one number per string
across the shots, about one axis (``harp_frame``) and about several (``group_frames``); truth: the generator's drawn
geometry (``tests.pipeline.harp_points``) through the exact lens map."""

import numpy as np

from pipeline.harp_frame import group_frames, harp_frame
from tests.pipeline.harp_points import turning_harp_point_sets
from tests.pipeline.harp_support import LENS, H, W, drawn_corrected


# ------------------------------------------------------------------ the harp's frame (harp_frame)
def _one_number_per_string(numbers, strings):
    pairs = {(t, n) for ts, ns in zip(strings, numbers) for t, n in zip(ts, ns)}
    return len(pairs) == len({t for t, _ in pairs}) == len({n for _, n in pairs})


def test_the_axis_is_found_two_pitches_off_the_image_centre():
    turns = (0, 30, 60, 90, 120, 150)
    corrected, strings, axis = drawn_corrected(turns, 13, 45.0, (1.5, -1.2))
    framed = harp_frame(corrected, turns, W, H)
    assert framed, framed
    frame, numbers = framed
    assert np.hypot(*(np.array(frame.centre) - axis)) < 1.0
    assert _one_number_per_string(numbers, strings)


def test_three_shots_of_a_harp_wider_than_the_image_cannot_place_the_axis_and_say_so():
    # three angles: the strings' distances agree about a lattice of points (group_frames), and with
    # the harp's ends out of view nothing tells them apart: refused with the reason, not numbered wrongly
    turns = (0, 60, 120)
    corrected, _, _ = drawn_corrected(turns, 29, 50.0, (0.7, 0.4), seed=2)
    framed = harp_frame(corrected, turns, W, H)
    assert not framed and "axis is ambiguous with these turntable angles" in framed.reason


def test_three_shots_of_a_harp_whose_ends_are_in_view_place_the_axis():
    # the same three angles, the whole harp in view: about a wrong lattice point the shots' strings shift by
    # whole pitches against each other, which makes more strings than the harp has
    turns = (0, 60, 120)
    corrected, strings, axis = drawn_corrected(turns, 9, 50.0, (0.7, 0.4), seed=2)
    framed = harp_frame(corrected, turns, W, H)
    assert framed, framed
    frame, numbers = framed
    assert np.hypot(*(np.array(frame.centre) - axis)) < 1.0
    assert _one_number_per_string(numbers, strings)


# ------------------------------------------------------------------ axis groups without shifts (group_frames)
def _two_places(left_turns, right_turns, n=23):
    """Shots of a 23-string harp 60 px apart (wider than the image) about two axes 168 px either side of the
    distortion centre, corrected by the exact LENS, with the drawn axes and each edge's drawn string (its offset
    from its own drawn axis in the generator's frame, nearest drawn offset)."""
    centre, shift = np.array(LENS.center), np.array([150.0, 75.0])
    shots, strings, turns = [], [], []
    for axis, angles, seed in ((centre - shift, left_turns, 5), (centre + shift, right_turns, 6)):
        drawn, offsets = turning_harp_point_sets(LENS, W, H, angles, np.zeros((n, 3)), axis=axis, step=40, seed=seed)
        for t, shot in zip(angles, drawn):
            a = np.radians(20.0 + t)
            nrm = np.array([-np.sin(a), np.cos(a)])
            corrected = [LENS.undistort_points(e) for e in shot]
            shots.append(corrected)
            strings.append([int(np.argmin(np.abs(offsets - np.mean((e - axis) @ nrm)))) for e in corrected])
            turns.append(t)
    return shots, strings, turns, (centre - shift, centre + shift)


def test_two_groups_of_four_angles_45_degrees_apart_place_each_other_without_shifts():
    # each group alone agrees as well about places 1.85 pitches off its axis, some with a string fewer (a harp wider
    # than the image): about two axes only the drawn pair makes all the shots one harp. On the comb search each
    # group's axis was put 5.5 pitches off and the 23 strings numbered as 37.
    turns = (0, 45, 90, 135)
    shots, strings, angles, axes = _two_places(turns, turns)
    placed = group_frames(shots, angles, ["L"] * 4 + ["R"] * 4, W, H)
    assert placed, placed
    frames, numbers = placed
    for g, drawn in zip("LR", axes, strict=True):
        assert np.hypot(*(np.array(frames[g].centre) - drawn)) < 1.0
    assert _one_number_per_string(numbers, strings)


def test_two_groups_of_three_angles_cannot_place_their_axes_without_shifts_and_say_so():
    # three angles: the distances agree about a lattice of places about each axis (and pairs of them about both),
    # and with a string left out of a shot a wrong one can agree better than the axis: refused, not numbered wrongly
    shots, _, angles, _ = _two_places((0, 60, 120), (30, 90, 150))
    placed = group_frames(shots, angles, ["L"] * 3 + ["R"] * 3, W, H)
    assert not placed and "axis group 'L': 3 turntable angles cannot place its axis without a shift" in placed.reason
    shots, _, angles, _ = _two_places((0, 45, 90, 135), (0, 60, 120))
    placed = group_frames(shots, angles, ["L"] * 4 + ["R"] * 3, W, H)
    assert not placed and "axis group 'R': 3 turntable angles" in placed.reason
