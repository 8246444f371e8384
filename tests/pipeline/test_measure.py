"""measure_image against synthetic harps with exact answers, and on the real photographs."""

import numpy as np
import pytest

from pipeline.measure import measure_image
from pipeline.models.radial import RadialModel
from pipeline.render import HarpScene, render_harp
from pipeline.straightness import straightness
from tests.pipeline._harp_truth import match_truth, true_measure

W, H = 1000, 750


# -- 1. undistorted: straight strings must measure straight ---------------------------------
@pytest.mark.parametrize("width,spacing", [(3.0, 60.0), (8.0, 80.0)])
@pytest.mark.parametrize("angle", [0.0, 30.0, 45.0, 60.0, 90.0, 120.0, 135.0, 150.0])
def test_undistorted_harp_measures_straight(angle, width, spacing):
    r = render_harp(
        W,
        H,
        HarpScene(angle_deg=angle, spacing_px=spacing, string_width_px=width),
        noise_sigma=1.5,
        bit_depth=8,
        seed=int(angle) + int(width),
    )
    m = measure_image(r.image)
    assert m.n_lines >= 14 and m.n_lines % 2 == 0
    assert m.d <= 0.01, f"d = {m.d:.5f} px"
    assert m.d_max <= 0.04
    for ln in m.lines:
        assert ln.angle_deg == pytest.approx(angle, abs=0.05) or abs(ln.angle_deg - angle) > 179.9
        assert ln.hf_rms < 0.05


def test_undistorted_16_bit():
    r = render_harp(W, H, HarpScene(angle_deg=75.0, spacing_px=60.0), noise_sigma=1.5, bit_depth=16, seed=4)
    assert r.image.dtype == np.uint16
    m = measure_image(r.image)
    assert m.n_lines >= 14 and m.d <= 0.01


# -- 2. distorted: measured d and d_max within 2 % of the exact values ---------------------
LENSES = {
    "barrel": dict(k=(1.0, 0.0, 0.012)),  # ~7.5 px at the corners
    "pincushion": dict(k=(1.0, 0.0, -0.012)),
    "decentred": dict(k=(1.0, 0.0, 0.015), center=(380.0, 290.0)),
}


@pytest.mark.parametrize("lens_name", sorted(LENSES))
@pytest.mark.parametrize("angle,width", [(20.0, 3.0), (100.0, 8.0)])
def test_distorted_harp_matches_ground_truth(lens_name, angle, width):
    lens = RadialModel.for_image(W, H, **LENSES[lens_name])
    r = render_harp(
        W, H, HarpScene(angle_deg=angle, spacing_px=60.0, string_width_px=width), lens=lens, noise_sigma=1.5, seed=21
    )
    # the lens moves the corners by several pixels
    corner = np.array([[0.0, 0.0], [W - 1.0, H - 1.0]])
    assert np.max(np.hypot(*(lens.undistort_points(corner) - corner).T)) > 5.0
    m = measure_image(r.image)
    matches = match_truth(r, m)
    truth = true_measure(r, m, matches)
    assert m.n_lines >= 20
    assert truth.d > 0.1  # a real bend to measure
    assert m.d == pytest.approx(truth.d, rel=0.02)
    assert m.d_max == pytest.approx(truth.d_max, rel=0.02)
    # per edge too: every edge is measured on the right curve
    for _ln, (_, _, dist) in zip(m.lines, matches):
        assert dist < 0.5  # gradient maxima sit ~0.3 px outside a 3 px string (blur), a constant offset


def test_distorted_harp_with_frame_dust_and_vignetting_matches_ground_truth():
    scene = HarpScene(
        angle_deg=150.0,
        spacing_px=45.0,
        string_width_px=3.0,
        frame=True,
        frame_side=-1,
        frame_depth_px=150.0,
        dust=40,
        dust_seed=6,
        vignetting=0.5,
    )
    r = render_harp(W, H, scene, lens=RadialModel.for_image(W, H, k=(1.0, 0.0, 0.04)), noise_sigma=1.5, seed=6)
    m = measure_image(r.image)
    matches = match_truth(r, m)  # every measured edge is a true string edge (not frame, not dust)
    truth = true_measure(r, m, matches)
    assert m.n_lines >= 30
    assert m.d == pytest.approx(truth.d, rel=0.02)
    assert m.d_max == pytest.approx(truth.d_max, rel=0.02)


def test_t_changes_the_sampling_not_the_answer():
    lens = RadialModel.for_image(W, H, k=(1.0, 0.0, 0.012))
    r = render_harp(W, H, HarpScene(angle_deg=50.0, spacing_px=60.0), lens=lens, noise_sigma=1.5, seed=5)
    m30, m10 = measure_image(r.image, t=30), measure_image(r.image, t=10)
    assert m30.t == 30 and m10.t == 10
    assert sum(len(ln.points) for ln in m10.lines) > 2.5 * sum(len(ln.points) for ln in m30.lines)
    for m in (m30, m10):
        truth = true_measure(r, m)
        assert m.d == pytest.approx(truth.d, rel=0.02)


def test_no_strings_gives_zero_lines():
    rng = np.random.default_rng(1)
    img = np.clip(150 + rng.normal(0, 1.5, (300, 400)), 0, 255).astype(np.uint8)
    m = measure_image(img)
    assert m.n_lines == 0 and m.n_strings == 0
    assert np.isnan(m.d) and np.isnan(m.d_max)
    assert m.to_dict()["d"] is None


def test_result_is_consistent_with_straightness_of_its_points():
    r = render_harp(W, H, HarpScene(angle_deg=10.0), lens=RadialModel.for_image(W, H, k=(1.0, 0.0, 0.01)), seed=3)
    m = measure_image(r.image)
    st = straightness([ln.points for ln in m.lines])
    assert m.d == pytest.approx(st.d) and m.d_max == pytest.approx(st.d_max)
    d = m.to_dict()
    assert d["n_lines"] == m.n_lines == len(d["lines"])
    assert {"points", "rms", "p2p", "angle_deg", "length_px", "hf_rms"} <= set(d["lines"][0])


# -- 4. the real photographs -----------------------------------------------------------------
REAL = ("IMG_6931.pgm", "IMG_6950.pgm", "IMG_6964.pgm")


@pytest.fixture(scope="module")
def real_measurements(real_harp_dir):
    from station.imageio import read_grey

    return {name: measure_image(read_grey(real_harp_dir / name)) for name in REAL}


@pytest.mark.parametrize("name", REAL)
def test_real_photo_every_string_with_both_edges(real_measurements, name):
    m = real_measurements[name]
    assert 10 <= m.n_strings <= 16
    edges = {}
    for ln in m.lines:
        edges.setdefault(ln.string_id, []).append(ln)
    for sid, pair in edges.items():
        assert sorted(ln.polarity for ln in pair) == [-1, 1], f"string {sid} lacks an edge"
        # the two edges are a string width apart along their whole length
        a, b = pair
        assert abs(a.angle_deg - b.angle_deg) < 0.5
        assert 1.5 < a.width_px < 5.0
    # strings run parallel-ish (a frame edge or dust would not); none bent at high frequency
    ang = np.array([ln.angle_deg for ln in m.lines])
    spread = np.abs(((ang - np.median(ang)) + 90) % 180 - 90)
    assert spread.max() < 10.0
    assert max(ln.hf_rms for ln in m.lines) < 0.15
    # the full-length strings are all there: the longest edges span the image
    assert sum(ln.length_px > 0.6 * min(m.width, m.height) for ln in m.lines) >= 16


@pytest.mark.parametrize("name", REAL)
def test_real_photo_nothing_measured_on_frame_or_dust(real_measurements, name, real_harp_dir):
    from station.imageio import read_grey

    img = read_grey(real_harp_dir / name).astype(float)
    m = real_measurements[name]
    bg = np.percentile(img, 75)
    for ln in m.lines:
        # on both sides of every measured edge pair lies the bright sheet, not the dark frame:
        # sample 6 px outside the string, on the side away from the partner edge
        pts = ln.raw_points[::25]
        other = [o for o in m.lines if o.string_id == ln.string_id and o is not ln][0]
        c = np.mean(other.raw_points, axis=0) - np.mean(ln.raw_points, axis=0)
        d = np.diff(ln.raw_points[[0, -1]], axis=0)[0]
        nrm = np.array([-d[1], d[0]]) / np.hypot(*d)
        out = -np.sign(nrm @ c) * nrm
        q = np.rint(pts + 6 * out).astype(int)
        ok = (q[:, 0] >= 0) & (q[:, 0] < m.width) & (q[:, 1] >= 0) & (q[:, 1] < m.height)
        vals = img[q[ok, 1], q[ok, 0]]
        assert np.median(vals) > 0.6 * bg, f"string {ln.string_id} edge runs along a dark region"
    reasons = m.to_dict()["rejected"]
    assert reasons.get("curved", 0) + reasons.get("short fragment", 0) > 0  # dust etc. was seen and rejected


def test_real_photos_d(real_measurements):
    per_image = {n: (m.d, m.d_max) for n, m in real_measurements.items()}
    pooled = straightness([ln.points for m in real_measurements.values() for ln in m.lines])
    print("real photos d, d_max:", per_image, "pooled:", pooled.d, pooled.d_max)
    for d, d_max in per_image.values():
        assert 1.5 < d < 4.0 and 2 * d < d_max < 4 * d
    # over all edges of the three photos (as the seed paper pools its images)
    assert 2.0 < pooled.d < 2.8
