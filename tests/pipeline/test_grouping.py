"""Grouping of edge chains into string edges, against rendered harps with exact truth."""

import numpy as np
import pytest

from pipeline.edges import detect_edges
from pipeline.grouping import REJECT_REASONS, group_string_edges
from pipeline.measure import measure_grouping
from pipeline.models.radial import RadialModel
from pipeline.render import HarpScene, render_harp
from tests.pipeline._harp_truth import compare

W, H = 800, 600


def _group(r):
    return group_string_edges(detect_edges(r.image), r.image.shape)


def _check_complete(r, g, min_len=0.3 * min(W, H)):  # noqa: B008 (constants)
    """Every true edge longer than min_len is found exactly once, paired with its own string's other edge."""
    m = measure_grouping(g, r.width, r.height, t=1)  # t=1: raw points, no length lost
    c = compare(r, m, max_dist=0.8)
    found = {}
    for mt in c.matches:
        found.setdefault(mt.truth, []).append(mt.line)
    for k, te in enumerate(c.truths):
        if te.length >= min_len:
            assert len(found.get(k, [])) == 1, (
                f"true edge {te.edge.string_index}{te.edge.side:+d} ({te.length:.0f} px) found {len(found.get(k, []))} times"
            )
    # the two edges of each measured string are the two sides of one true string
    by_string = {}
    for mt in c.matches:
        e = c.truths[mt.truth].edge
        by_string.setdefault(m.lines[mt.line].string_id, []).append((e.string_index, e.side, m.lines[mt.line].polarity))
    for sid, members in by_string.items():
        assert len(members) == 2, f"string {sid} has {len(members)} edges"
        (k1, s1, p1), (k2, s2, p2) = members
        assert k1 == k2 and {s1, s2} == {-1, 1} and {p1, p2} == {-1, 1}
    return m


@pytest.mark.parametrize("angle", [0.0, 45.0, 90.0, 135.0, 178.0])
def test_every_string_edge_found_once_and_paired(angle):
    r = render_harp(W, H, HarpScene(angle_deg=angle, spacing_px=55.0, string_width_px=3.0), noise_sigma=1.5, seed=11)
    g = _group(r)
    _check_complete(r, g)
    assert g.dark_strings
    # measured width between gradient maxima: the true width widened by the blur
    assert 3.0 <= g.string_width_px <= 4.5
    # points ordered along the common harp direction, the edges of a string in (-1, +1) order
    ang = np.radians(np.median([np.degrees(np.arctan2(*(e.xy[-1] - e.xy[0])[::-1])) % 180 for e in g.edges]))
    u = np.array([np.cos(ang), np.sin(ang)])
    for e in g.edges:
        proj = e.xy @ u
        assert np.all(np.diff(proj) > -1.0), "points not ordered along the edge"
    pols = [(e.string_id, e.polarity) for e in g.edges]
    assert pols == sorted(pols)


@pytest.mark.parametrize("width,spacing", [(2.0, 30.0), (15.0, 90.0)])
def test_string_width_range(width, spacing):
    r = render_harp(
        W, H, HarpScene(angle_deg=60.0, spacing_px=spacing, string_width_px=width, blur_px=0.6), noise_sigma=1.5, seed=5
    )
    g = _group(r)
    _check_complete(r, g)
    assert abs(g.string_width_px - width) < 1.5


def test_thirty_strings_at_small_spacing():
    r = render_harp(W, H, HarpScene(angle_deg=95.0, spacing_px=26.0, string_width_px=3.0), noise_sigma=1.5, seed=7)
    g = _group(r)
    m = _check_complete(r, g)
    assert m.n_strings >= 30


def test_frame_and_dust_are_rejected_not_measured():
    scene = HarpScene(
        angle_deg=20.0,
        spacing_px=60.0,
        string_width_px=3.0,
        frame=True,
        frame_depth_px=120.0,
        dust=12,
        dust_seed=4,
        vignetting=0.5,
    )
    r = render_harp(W, H, scene, noise_sigma=1.5, seed=2)
    g = _group(r)
    _check_complete(r, g)
    n = np.asarray(scene.normal)
    side = scene.frame_side * (np.concatenate([e.xy for e in g.edges]) @ n - r.frame_offset)
    assert side.max() < -2.0, "a measured edge lies on the harp frame"
    # the frame's edge is there, and rejected as not a string
    on_frame = [x for x in g.rejected if np.median(np.abs(x.xy @ n - r.frame_offset)) < 1.5 and x.n_points > 100]
    assert on_frame and all(x.reason in ("unpaired edge", "wrong width") for x in on_frame)
    assert {x.reason for x in g.rejected} <= set(REJECT_REASONS)


def test_string_cut_by_a_gap_is_rejoined():
    scene = HarpScene(angle_deg=70.0, spacing_px=60.0, string_width_px=3.0)
    r = render_harp(W, H, scene, noise_sigma=1.5, seed=3)
    img = r.image.copy()
    n, u = np.array(scene.normal), np.array(scene.direction)
    c = np.array([(W - 1) / 2, (H - 1) / 2])
    yy, xx = np.mgrid[0:H, 0:W]
    P = np.stack([xx, yy], -1).astype(float)
    q, s = (P - c) @ n, (P - c) @ u
    # erase 40 px of string 1 (centred at q = 60) with the background from half a spacing away
    ys, xs = np.nonzero((np.abs(q - 60) < 6) & (np.abs(s - 50) < 20))
    sh = np.rint(30 * n).astype(int)
    img[ys, xs] = img[ys + sh[1], xs + sh[0]]
    g0 = _group(r)
    g = group_string_edges(detect_edges(img), img.shape)
    assert g.n_strings == g0.n_strings
    cut = [e for e in g.edges if len(e.pieces) > 1]
    assert len(cut) == 2 and cut[0].string_id == cut[1].string_id
    for e in cut:
        (a0, b0), (a1, b1) = e.pieces
        gap = np.hypot(*(e.xy[a1] - e.xy[b0 - 1]))
        assert 35 < gap < 80  # 40 px erased, plus the rounded ends of the cut


def test_strong_distortion_keeps_each_edge_whole():
    lens = RadialModel.for_image(W, H, k=(1.0, 0.0, 0.08))  # ~40 px at the corners
    r = render_harp(
        W, H, HarpScene(angle_deg=10.0, spacing_px=60.0, string_width_px=3.0), lens=lens, noise_sigma=1.5, seed=8
    )
    g = _group(r)
    _check_complete(r, g)


def test_bright_strings_on_dark_background():
    r = render_harp(W, H, HarpScene(angle_deg=30.0, spacing_px=60.0, string_width_px=4.0), noise_sigma=1.5, seed=9)
    g_dark = _group(r)
    inv = 255 - r.image
    g = group_string_edges(detect_edges(inv), inv.shape)
    assert g_dark.dark_strings and not g.dark_strings
    assert g.n_strings == g_dark.n_strings > 8


def test_no_strings_gives_no_edges():
    rng = np.random.default_rng(0)
    img = np.clip(128 + rng.normal(0, 1.5, (300, 400)), 0, 255).astype(np.uint8)
    g = group_string_edges(detect_edges(img), img.shape)
    assert g.edges == () and g.n_strings == 0
    # a single thick dark bar (a frame, no string) is not a string either
    img[:, 150:260] = 20
    g = group_string_edges(detect_edges(img), img.shape)
    assert g.edges == ()
    assert any(x.reason in ("unpaired edge", "wrong width") for x in g.rejected)


@pytest.mark.parametrize("gap,measured", [(3.0, False), (25.0, True)])
def test_string_right_beside_a_dark_bar(gap, measured):
    """A string a few px from the frame is biased by it and must not be measured; 25 px away it is fine."""
    from scipy.special import ndtr

    r = render_harp(W, H, HarpScene(angle_deg=0.0, spacing_px=60.0, string_width_px=3.0), noise_sigma=0.0, seed=1)
    c = (H - 1) / 2.0
    lower_edge = c + 120 + 1.5  # lower edge of string k = 2
    y = np.arange(H, dtype=float)[:, None]
    bar = 1.0 - 0.9 * ndtr((y - (lower_edge + gap)) / 1.0) * ndtr(((lower_edge + gap + 80) - y) / 1.0)
    rng = np.random.default_rng(0)
    img = np.clip(np.rint(r.image * bar + rng.normal(0, 1.5, r.image.shape)), 0, 255).astype(np.uint8)
    g = group_string_edges(detect_edges(img), img.shape)
    near = [e for e in g.edges if abs(np.median(e.xy[:, 1]) - (c + 120)) < 5]
    assert len(near) == (2 if measured else 0)
    if not measured:
        assert any(x.reason == "crowded" and abs(np.median(x.xy[:, 1]) - lower_edge) < 2 for x in g.rejected)
    # the other strings are all there: 9 in the image, one (k = 3) hidden under the bar
    assert g.n_strings == (8 if measured else 7)


@pytest.mark.parametrize("bright", [False, True])
def test_wide_strings_at_40_percent_duty_cycle(bright):
    """12 px strings 30 px apart: both marching directions find an opposite edge in reach; the
    string is the narrower band (12 px), whether dark on bright or bright on dark."""
    scene = HarpScene(angle_deg=35.0, spacing_px=30.0, string_width_px=12.0)
    if bright:
        scene = HarpScene(angle_deg=35.0, spacing_px=30.0, string_width_px=12.0, background=30.0, string_level=200.0)
    r = render_harp(W, H, scene, noise_sigma=1.5, seed=4)
    g = _group(r)
    assert g.dark_strings == (not bright)
    assert abs(g.string_width_px - 12.0) < 1.0
    m = _check_complete(r, g)
    assert m.n_strings >= 25


class _Chain:
    def __init__(self, xy, grad):
        self.xy, self.grad = xy, grad


def _arc(radius, length, centre=(400.0, 300.0)):
    phi = np.arange(0.0, length, 1.0) / radius
    xy = np.column_stack([centre[0] + radius * np.cos(phi), centre[1] + radius * np.sin(phi)])
    grad = -np.column_stack([np.cos(phi), np.sin(phi)]) * 40.0  # gradient towards the centre
    return _Chain(xy, grad)


def test_local_curvature_limit_not_total_turn():
    """A ring of dust (radius 60 px) bends more than any string and is rejected as curved; the image
    of a string through a wide-angle lens may turn by 40 degrees in total over 1400 px (radius
    2000 px) and is not (here it is unpaired: it is alone)."""
    big = 3000
    ring = _arc(60.0, 300.0, centre=(1500.0, 1500.0))
    bow = _arc(2000.0, 1400.0, centre=(-500.0, 1500.0))
    g = group_string_edges([ring, bow], (big, big))
    by_reason = {}
    for x in g.rejected:
        by_reason.setdefault(x.reason, []).append(x)
    assert sum(x.n_points for x in by_reason["curved"]) >= 280
    assert all(np.hypot(*(x.xy - [1500.0, 1500.0]).T).max() < 61 for x in by_reason["curved"])
    assert [x.n_points for x in by_reason["unpaired edge"]] == [1400]
