"""Boards: labels, the corners found in rendered shots against the exact lens, and shots rejected with their reason."""

import numpy as np
import pytest

from pipeline.board import BoardRejected, detect_board, parse_board
from tests.pipeline import board_shots as bs


def test_labels_read_back_and_bad_ones_name_what_is_wrong():
    assert parse_board("charuco:7x5:30:21").label == "charuco:7x5:30:21:DICT_5X5_100"
    assert parse_board("chessboard:10X7:25").label == "chessboard:10x7:25"
    assert parse_board("charuco:7x5:30:21:dict_4x4_50").dictionary == "DICT_4X4_50"
    for bad, words in [
        ("circles:7x5:30", "unknown kind"),
        ("charuco:7x5:30", "expected"),
        ("charuco:7x5:30:35", "marker side"),
        ("charuco:2x5:30:21", "at least 3x3"),
        ("charuco:7x5:30:21:DICT_NOPE", "unknown ArUco dictionary"),
        ("chessboard:7x5:-3", "square side"),
    ]:
        with pytest.raises(ValueError, match=words) as e:
            parse_board(bad)
        assert "\n" not in str(e.value) and bad in str(e.value)


def test_board_corners_are_opencvs_charuco_corners():
    s = parse_board("charuco:7x5:30:21")
    assert np.array_equal(s.corners(), np.asarray(s.cv_board().getChessboardCorners(), np.float64))


def test_corners_found_within_hundredths_of_a_pixel_of_the_exact_lens():
    errs = []
    for i in range(bs.N_VIEWS):
        v = detect_board(bs.shot(i), bs.spec(), name=f"view{i}")
        assert v, v
        assert v.n >= 12 and 1.2 < v.edge_width_px < 3.0
        truth = bs.exact_corners(bs.poses()[i])[v.ids]
        assert np.array_equal(v.object_points, bs.spec().corners()[v.ids])
        errs.append(v.image_points - truth)
    e = np.concatenate(errs)
    rms = float(np.sqrt(np.mean(np.sum(e**2, axis=1))))
    print(f"corner error over {len(e)} corners: RMS {rms:.4f} px, max {np.abs(e).max():.4f} px")
    assert rms < 0.03 and np.abs(e).max() < 0.1
    assert np.all(np.abs(e.mean(axis=0)) < 0.01)  # no bias


def test_bad_shots_are_rejected_with_their_reason():
    got = detect_board(bs.blank_shot(), bs.spec(), name="blank.png")
    assert isinstance(got, BoardRejected) and not got
    assert got.name == "blank.png" and got.reason == "no charuco board 7x5 found"
    few = detect_board(bs.off_image_shot(), bs.spec())
    assert not few and few.reason.startswith("too few board corners")
    blurred = detect_board(bs.shot(0, blur=2.5), bs.spec())
    assert not blurred and blurred.reason.startswith("blurred: board edges")
    # the same view, sharp enough, is kept; its measured edge width grows with the blur (2.5 sigma)
    soft = detect_board(bs.shot(0, blur=1.4), bs.spec())
    sharp = detect_board(bs.shot(0), bs.spec())
    assert soft and sharp and 3.0 < soft.edge_width_px < 4.0 and sharp.edge_width_px < 2.5


def test_coverage_names_the_image_regions_without_a_corner():
    from pipeline.board import BoardView, board_coverage

    def view(points):
        p = np.asarray(points, np.float64)
        return BoardView(np.arange(len(p)), p, np.zeros((len(p), 3)), 2.0)

    w, h = 800, 600
    only_left = view([[10 + 100 * i, 10 + 100 * j] for i in range(4) for j in range(6)])  # x < 400: left half
    cov = board_coverage([only_left], w, h)
    assert cov.fraction == 0.5 and cov.covered[:, :4].all() and not cov.covered[:, 4:].any()
    assert cov.missing() == [
        "top edge",
        "top-right corner",
        "centre",
        "right edge",
        "bottom edge",
        "bottom-right corner",
    ]
    full = board_coverage([only_left, view([[410 + 100 * i, 10 + 100 * j] for i in range(4) for j in range(6)])], w, h)
    assert full.fraction == 1.0 and full.missing() == []
