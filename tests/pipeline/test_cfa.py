"""Edges measured per CFA plane on the raw mosaic, each plane at its own sample positions.

Truth: the exact ideal string edges (:func:`pipeline.render.string_edges`) of a mosaic
rendered through a known per-channel map (a pure lateral shift of red and blue), never
the measurement itself.
"""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.cfa import CFA_PATTERNS, cfa_planes, measure_mosaic, mosaic_luma, plane_offsets, plane_to_mosaic
from pipeline.models.base import IdentityModel
from pipeline.render import HarpScene, string_edges
from pipeline.render_colour import render_mosaic
from tests.pipeline.colour_lenses import ChannelLens, ExactTca

W, H = 320, 240


class _Identity:
    def undistort_points(self, xy):
        return np.asarray(xy, np.float64).reshape(-1, 2).copy()


@pytest.mark.parametrize("pattern", CFA_PATTERNS)
def test_planes_sample_their_own_sites(pattern):
    mosaic = np.arange(8 * 6).reshape(6, 8)
    planes = {p.name: p for p in cfa_planes(mosaic, pattern)}
    offs = plane_offsets(pattern)
    assert sorted(offs.values()) == [(0, 0), (0, 1), (1, 0), (1, 1)]
    for name, p in planes.items():
        ox, oy = offs[name]
        assert pattern[2 * oy + ox] == name[0]  # the colour at that site of the pattern
        # plane pixel (row i, column j) is mosaic pixel (x = 2j + ox, y = 2i + oy)
        assert p.image[1, 2] == mosaic[2 + oy, 4 + ox]
        np.testing.assert_array_equal(plane_to_mosaic(np.array([[2.0, 1.0]]), p.offset), [[4.0 + ox, 2.0 + oy]])


def test_bad_pattern_and_shape():
    with pytest.raises(ValueError, match="unknown CFA pattern"):
        plane_offsets("RGBG")
    with pytest.raises(ValueError, match="2-D"):
        cfa_planes(np.zeros((4, 4, 3)), "RGGB")


def test_mosaic_pixels_are_each_channel_through_its_own_lens():
    """Each site of the mosaic holds its channel's image: red through red's map, not green's."""
    shift = ExactTca(W, H, shift=(0.7, -0.4))
    lenses = {"R": ChannelLens(_Identity(), shift), "G": IdentityModel(), "B": None}
    scene = HarpScene(angle_deg=30.0, spacing_px=30.0, string_width_px=6.0, blur_px=1.0)
    r = render_mosaic(W, H, scene, lenses, "GRBG", gains={"R": 0.5}, noise_sigma=0.0)
    from pipeline.render import render_harp

    red = render_harp(W, H, scene, lens=lenses["R"], noise_sigma=0.0, bit_depth=16, exposure=0.5)
    red = red.image.astype(float)
    green = render_harp(W, H, scene, noise_sigma=0.0, bit_depth=16).image.astype(float)
    # GRBG: red at (x odd, y even)
    vignetting_free = r.image[0::2, 1::2].astype(float)
    # the renderer's own vignetting is off in render_mosaic; render_harp's default is on: divide it out
    yy, xx = np.mgrid[0:H:2, 1:W:2]
    c = ((W - 1) / 2, (H - 1) / 2)
    a = ((1 - scene.vignetting) ** -0.5 - 1) / (c[0] ** 2 + c[1] ** 2)
    v = (1 + a * ((xx - c[0]) ** 2 + (yy - c[1]) ** 2)) ** -2
    assert np.abs(vignetting_free - red[0::2, 1::2] / v).max() <= 1.5  # 16-bit rounding, twice
    assert np.abs(vignetting_free - 0.5 * green[0::2, 1::2] / v).max() > 1000  # not green's image


@pytest.mark.parametrize("pattern", ["RGGB", "GBRG"])
def test_plane_edges_lie_on_the_exact_edges(pattern):
    """Each plane's edges, in mosaic coordinates, where its own channel's exact edges are.

    The gradient maximum of a string edge lies a constant distance outside the geometric
    edge (:func:`pipeline.render.edge_peak_offset`), the same for both edges of a string:
    the string's centre line (the mean of its two edges) is compared with the exact one,
    and the outward offset must be the same in every plane (same blur).
    """
    shift = {"R": (0.6, -0.35), "B": (-0.45, 0.5)}
    lenses = {c: ChannelLens(_Identity(), ExactTca(W, H, shift=s)) for c, s in shift.items()}
    lenses["G"] = IdentityModel()
    scene = HarpScene(angle_deg=37.0, spacing_px=36.0, string_width_px=8.0, phase_px=2.5, blur_px=1.0)
    r = render_mosaic(W, H, scene, lenses, pattern, gains={"R": 0.6, "B": 0.5}, noise_sigma=0.5, seed=3)
    m = measure_mosaic(r.image, pattern, t=20)
    truth = {(e.string_index, e.side): e.offset for e in string_edges(scene, IdentityModel(), W, H)}
    centres = {k: 0.5 * (truth[k, -1] + truth[k, 1]) for k, _ in truth}
    n = np.asarray(scene.normal)
    outward = {}
    for name, meas in m.planes.items():
        assert meas.width == W and meas.height == H
        assert meas.n_strings >= 6, name
        # the channel sees the ideal point p + delta: its edges are n . (p + delta) = offset
        delta = np.asarray(shift.get(name[0], (0.0, 0.0)))
        by_string: dict[int, dict[int, float]] = {}
        for ln in meas.lines:
            by_string.setdefault(ln.string_id, {})[ln.polarity] = float(np.mean(ln.points @ n + n @ delta))
        errs, half = [], []
        for edges in by_string.values():
            if len(edges) < 2:
                continue
            mid = 0.5 * sum(edges.values())
            k = min(centres, key=lambda j: abs(centres[j] - mid))
            errs.append(mid - centres[k])
            half.append(0.5 * abs(max(edges.values()) - min(edges.values())) - 0.5 * scene.string_width_px)
        assert len(errs) >= 6
        assert np.abs(errs).max() < 0.01, (name, errs)  # a wrong site offset would be 0.3-0.8 px
        outward[name] = float(np.mean(half))
    assert max(outward.values()) - min(outward.values()) < 0.003, outward


@pytest.mark.parametrize("pattern", CFA_PATTERNS)
def test_mosaic_luma_weighs_the_colours_alike_on_every_site(pattern):
    """A mosaic of a flat colour (R, G, B) and of a linear ramp of it: the luma is R/4 + G/2 + B/4 on every
    pixel (borders mirrored), and a ramp stays where it was (no shift)."""
    h, w = 12, 16
    colour = {"R": 40.0, "G": 100.0, "B": 20.0}
    ramp = np.add.outer(np.zeros(h), np.arange(w, dtype=float))  # x
    flat, sloped = np.zeros((h, w)), np.zeros((h, w))
    for name, (ox, oy) in plane_offsets(pattern).items():
        flat[oy::2, ox::2] = colour[name[0]]
        sloped[oy::2, ox::2] = colour[name[0]] * (1 + 0.01 * ramp[oy::2, ox::2])
    np.testing.assert_allclose(mosaic_luma(flat), 0.25 * 40 + 0.5 * 100 + 0.25 * 20)
    want = (0.25 * 40 + 0.5 * 100 + 0.25 * 20) * (1 + 0.01 * ramp)
    np.testing.assert_allclose(mosaic_luma(sloped)[1:-1, 1:-1], want[1:-1, 1:-1], rtol=1e-12)
