"""The physical harp: string shapes in harp coordinates, the turntable, the back-lit sheet.

Expected values come from the physics written out here (sag, stiffness length, rotation
matrices), not from the module under test.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from pipeline.backlight import Backlight
from pipeline.harp_scene import (
    Harp,
    HarpMount,
    StringShape,
    draw_harp,
)
from pipeline.optics import Vignetting
from pipeline.realism import Effects, render_shot
from pipeline.sensor import Development
from pipeline.string_materials import MATERIALS, string_physics


def test_sag_and_stiffness_length_follow_the_textbook_formulas():
    nylon = MATERIALS["nylon"]
    ph = string_physics(nylon, diameter_mm=0.3, tension_n=20.0, span_mm=250.0)
    mu = 1140.0 * math.pi * 0.15e-3**2  # kg/m
    assert ph["linear_density_kg_m"] == pytest.approx(mu, rel=1e-12)
    assert ph["sag_mm"] == pytest.approx(1e3 * mu * 9.80665 * 0.25**2 / (8 * 20.0), rel=1e-12)
    assert ph["sag_mm"] == pytest.approx(3.09e-4, rel=0.01)  # 0.3 um: a taut nylon line hardly sags
    ei = 2.5e9 * math.pi * 0.3e-3**4 / 64
    assert ph["stiffness_length_mm"] == pytest.approx(1e3 * math.sqrt(ei / 20.0), rel=1e-12)
    steel = string_physics(MATERIALS["steel"], 0.3, 60.0, 250.0)
    assert steel["stiffness_length_mm"] > 5 * ph["stiffness_length_mm"]  # a steel wire is far stiffer


def test_each_deviation_term_has_its_documented_shape():
    a = np.linspace(-500.0, 500.0, 2001)
    z = a / 500.0
    bow = StringShape(0, 10.0, 1.5, half_span_px=500.0, bow_px=(0.2, 0.0, 0.0))
    assert np.allclose(bow.deviation(a), 0.2 * np.cos(0.5 * math.pi * z), atol=1e-12)  # 0 at both anchors
    assert np.allclose(bow.centreline(a), 10.0 + bow.deviation(a))
    sag = StringShape(0, 0.0, 1.5, half_span_px=500.0, sag_px=0.01)
    assert np.allclose(sag.deviation(a), 0.0)  # no gravity across the string: no sag
    assert np.allclose(sag.deviation(a, gravity_cos=-0.5), -0.005 * (1 - z * z), atol=1e-15)
    kink = StringShape(0, 0.0, 1.5, kink_at_px=100.0, kink_px=0.05, kink_length_px=4.0)
    d = kink.deviation(np.array([100.0, 104.0, 96.0, 140.0]))
    assert d == pytest.approx([0.05, 0.05 / math.e, 0.05 / math.e, 0.05 * math.exp(-10)], rel=1e-12)
    twist = StringShape(0, 0.0, 1.5, ovality_px=0.02, twist_period_px=400.0)
    hw = twist.half_width(a, -1)
    assert np.allclose(hw, 1.5 + 0.02 * np.cos(4 * math.pi * a / 400.0))  # period P/2, both sides alike
    assert np.allclose(twist.half_width(a, 1), hw)
    assert np.allclose(twist.deviation(a), 0.0)  # an oval section twisting changes the width, not the centre
    # the two edges of a twisted oval string move in opposite directions
    assert np.allclose(twist.edge_deviation(a, -1), -twist.edge_deviation(a, 1))
    pick = StringShape(0, 0.0, 1.5, pick_px=0.03, pick_period_px=9.0, pick_phases=(0.0, math.pi))
    assert np.allclose(pick.half_width(a, -1) - 1.5, -(pick.half_width(a, 1) - 1.5))


def test_a_string_keeps_its_shape_as_the_harp_turns():
    harp = draw_harp(5, 9, 60.0, 3.0, 3000.0, material="steel")
    mount = HarpMount((310.0, 240.0), angle0_deg=20.0, direction=-1)
    p1, p2 = mount.pose(0.0), mount.pose(75.0)
    assert p2.angle_deg == pytest.approx(20.0 - 75.0 + 360.0)
    turn = math.radians(p2.angle_deg - p1.angle_deg)
    rot = np.array([[math.cos(turn), -math.sin(turn)], [math.sin(turn), math.cos(turn)]])
    c = np.array(mount.centre)
    s = np.linspace(-600.0, 600.0, 301)
    e1, e2 = harp.edges(p1), harp.edges(p2)
    for a, b in zip(e1, e2):
        assert (a.string_index, a.side) == (b.string_index, b.side)
        string = harp.strings[a.string_index]
        sag = string.deviation(s, 1.0) - string.deviation(s, 0.0)  # the only term that follows gravity
        # the same harp points: the ideal curve at pose 1, less its sag, turned about the axis...
        q1 = a.ideal_points(s + p1.along_origin) - (p1.gravity_cos * sag)[:, None] * np.asarray(a.normal)
        q2 = b.ideal_points(s + p2.along_origin) - (p2.gravity_cos * sag)[:, None] * np.asarray(b.normal)
        assert np.abs((q1 - c) @ rot.T + c - q2).max() < 1e-9
    # ... and in harp coordinates the edge lies at b_k + side r_k + its deviation
    e = e2[7]
    st = harp.strings[e.string_index]
    a_h, b_h = p2.to_harp(e.ideal_points(s))
    assert np.allclose(b_h, st.position_px + e.side * st.radius_px + st.edge_deviation(a_h, e.side, p2.gravity_cos))
    assert np.allclose(p2.to_image(a_h, b_h), e.ideal_points(s))


@pytest.mark.parametrize(
    ("angle", "gravity_deg", "expected"),
    [
        (0.0, 90.0, 1.0),
        (90.0, 90.0, 0.0),
        (180.0, 90.0, -1.0),
        (30.0, 90.0, math.cos(math.radians(30))),
        (0.0, 0.0, 0.0),
    ],
)
def test_gravity_bends_a_string_by_its_normal_component(angle, gravity_deg, expected):
    pose = HarpMount((0.0, 0.0), angle0_deg=angle, gravity_deg=gravity_deg).pose(0.0)
    g = (math.cos(math.radians(gravity_deg)), math.sin(math.radians(gravity_deg)))
    assert pose.gravity_cos == pytest.approx(expected, abs=1e-12)
    assert pose.gravity_cos == pytest.approx(pose.normal[0] * g[0] + pose.normal[1] * g[1], abs=1e-12)


def test_drawn_harps_are_seeded_and_physical():
    a = draw_harp(11, 15, 120.0, 2.7, 3500.0)
    b = draw_harp(11, 15, 120.0, 2.7, 3500.0)
    c = draw_harp(12, 15, 120.0, 2.7, 3500.0)
    assert a == b and np.array_equal(a.table, b.table)
    assert not np.array_equal(a.table, c.table)
    for seed in range(12):
        h = draw_harp(seed, 15, 120.0, 2.7, 3500.0)
        mat = MATERIALS[h.material]
        diameter = h.mm_per_px * 2.7
        assert mat.diameter_mm[0] <= diameter <= mat.diameter_mm[1]
        span_mm = 3500.0 * h.mm_per_px
        for st in h.strings:
            # the string's tension is within 30 % of the harp's: its sag and stiffness follow
            lo = string_physics(mat, diameter, 1.3 * h.tension_n, span_mm)
            hi = string_physics(mat, diameter, 0.7 * h.tension_n, span_mm)
            assert lo["sag_mm"] <= st.sag_px * h.mm_per_px <= hi["sag_mm"]
            lam = st.kink_length_px * h.mm_per_px
            assert lo["stiffness_length_mm"] <= lam * (1 + 1e-9) and lam <= hi["stiffness_length_mm"] * (1 + 1e-9)
            assert abs(st.kink_px) <= 0.5 * 0.05 * lam / h.mm_per_px + 1e-12  # alpha lambda / 2, alpha <= 0.05
            assert st.ovality_px <= 0.25 * 2.7 * mat.ovality[1] + 1e-12
        pos = np.array([s.position_px for s in h.strings])
        assert np.all(np.abs(np.diff(pos) - 120.0) < 0.5 / h.mm_per_px)  # placement errors of ~0.05 mm


def test_straight_harp_and_bad_harps():
    h = Harp.straight(5, 40.0, 3.0, offset_px=7.0)
    assert [s.position_px for s in h.strings] == [-73.0, -33.0, 7.0, 47.0, 87.0]
    assert h.first_position_px == pytest.approx(-73.0)
    assert list(h.nearest(np.array([-200.0, -50.0, 20.0, 500.0]))) == [0, 1, 2, 4]
    with pytest.raises(ValueError, match="order"):
        Harp((StringShape(0, 5.0, 1.0), StringShape(1, 0.0, 1.0)), 5.0)
    with pytest.raises(ValueError, match="radius_px"):
        StringShape(0, 0.0, 0.0)
    with pytest.raises(ValueError, match="direction"):
        HarpMount((0.0, 0.0), direction=2)
    with pytest.raises(ValueError, match="material"):
        draw_harp(0, 3, 40.0, 3.0, 1000.0, material="silk")


def _sheet(turntable_deg: float, effects: Effects, mount: HarpMount) -> np.ndarray:
    far = Harp.straight(1, 100.0, 3.0, offset_px=1e5)  # no string in the image: only the sheet
    return render_shot(None, far, mount, turntable_deg, 200, 160, effects).image.astype(np.float64)


def test_the_backlight_turns_with_the_harp_and_the_vignetting_does_not():
    mount = HarpMount((101.0, 77.0), angle0_deg=10.0)
    light = Backlight(lamp_px=(30.0, -20.0), lamp_distance_px=150.0, mottle=0.02, mottle_scale_px=9.0, seed=3)
    eff = Effects(backlight=light, development=Development(bit_depth=16))
    one, two = _sheet(0.0, eff, mount), _sheet(40.0, eff, mount)
    assert np.abs(one - two).max() > 0.05 * one.max()  # the pattern moved
    # pixel p at pose 1 is the harp point that pose 2 shows at c + R(40 deg)(p - c)
    t = math.radians(40.0)
    yy, xx = np.mgrid[40:120:7, 50:150:7].astype(np.float64)
    dx, dy = xx - 101.0, yy - 77.0
    x2, y2 = 101.0 + math.cos(t) * dx - math.sin(t) * dy, 77.0 + math.sin(t) * dx + math.cos(t) * dy
    i, j = np.floor(y2).astype(int), np.floor(x2).astype(int)
    fy, fx = y2 - i, x2 - j
    interp = (1 - fy) * ((1 - fx) * two[i, j] + fx * two[i, j + 1]) + fy * (
        (1 - fx) * two[i + 1, j] + fx * two[i + 1, j + 1]
    )
    assert np.abs(interp / one[yy.astype(int), xx.astype(int)] - 1).max() < 0.004  # bilinear error of a 9 px texture
    # the lamp's cos^3 law, at its foot and half its distance away (mottle off)
    plain = Backlight(lamp_px=(0.0, 0.0), lamp_distance_px=150.0)
    assert plain.at(np.array([0.0, 75.0]), np.array([0.0, 0.0])) == pytest.approx([1.0, 1.25**-1.5])
    # vignetting is fixed to the sensor: the same image at every turntable angle
    vig = Effects(vignetting=Vignetting(0.3), development=Development(bit_depth=16))
    assert np.array_equal(_sheet(0.0, vig, mount), _sheet(40.0, vig, mount))


def test_the_mottle_has_its_rms_and_correlation_length():
    light = Backlight(mottle=0.015, mottle_scale_px=12.0, seed=8)
    a = np.arange(0.0, 3000.0, 1.0)
    m = light.at(a, np.full_like(a, 55.5)) - 1.0
    assert m.std() == pytest.approx(0.015, rel=0.15)
    r = [np.corrcoef(m[:-k], m[k:])[0, 1] for k in (3, 12, 48)]
    assert r[0] > 0.8 and 0.1 < r[1] < 0.7 and abs(r[2]) < 0.15
    assert np.array_equal(light.at(a, a), Backlight(mottle=0.015, mottle_scale_px=12.0, seed=8).at(a, a))
