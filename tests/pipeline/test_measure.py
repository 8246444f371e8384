"""measure_image against synthetic harps with exact answers, and on the real photographs.

The truth of every synthetic shot is the whole visible edge (tests/pipeline/_harp_truth.py):
exact curves through exact closed-form lens maps (tests/pipeline/lenses.py), over everything
visible in the image, sampled on the measurement's grid, never clipped to what was measured.
"""

import numpy as np
import pytest

from pipeline.edgeset import tls
from pipeline.measure import measure_image, point_sigmas
from pipeline.models.radial import RadialModel
from pipeline.render import HarpScene, render_harp
from pipeline.straightness import straightness
from tests.pipeline._harp_truth import compare
from tests.pipeline.lenses import ExactLens, mild_lenses, wide_lenses

W, H = 1000, 750
WW, WH = 1600, 1200  # wide-angle shots


def assert_whole_edges(r, m, d_rel=0.02, d_max_rel=0.03, min_coverage=0.98):
    """Issue 8 item 2: every true edge >= 10 % of the short side found once, each measured over
    >= 98 % of its true extent, d within 2 % and d_max within 3 % of the whole-edge truth."""
    c = compare(r, m)
    assert not c.missing, f"true edges not found: {[(te.edge.string_index, te.edge.side) for te in c.missing]}"
    assert not c.duplicated, f"true edges found more than once: {c.duplicated}"
    worst = min(c.matches, key=lambda mt: mt.coverage)
    assert worst.coverage >= min_coverage, f"line {worst.line} covers {worst.coverage:.3f} of its true edge"
    print(
        f"d {m.d:.4f} / true {c.true.d:.4f} ({m.d / c.true.d - 1:+.2%}), d_max {m.d_max:.4f} / "
        f"{c.true.d_max:.4f} ({m.d_max / c.true.d_max - 1:+.2%}), {m.n_lines} lines, coverage >= {worst.coverage:.3f}"
    )
    assert m.d == pytest.approx(c.true.d, rel=d_rel)
    assert m.d_max == pytest.approx(c.true.d_max, rel=d_max_rel)
    return c


# -- 1. undistorted: straight strings must measure straight, ends included -------------------
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
    # the edges are measured to their ends: the first and last smoothed points lie within a few px
    # of the trimmed image border (4 px) wherever the string crosses it
    ends = np.array([p for ln in m.lines for p in (ln.start, ln.end)])
    to_border = np.minimum.reduce([ends[:, 0], ends[:, 1], W - 1 - ends[:, 0], H - 1 - ends[:, 1]])
    assert np.all(to_border < 4.0 + 2.0)


def test_undistorted_16_bit():
    r = render_harp(W, H, HarpScene(angle_deg=75.0, spacing_px=60.0), noise_sigma=1.5, bit_depth=16, seed=4)
    assert r.image.dtype == np.uint16
    m = measure_image(r.image)
    assert m.n_lines >= 14 and m.d <= 0.01


# -- 2. distorted: d and d_max of the whole visible edges ------------------------------------
MILD = mild_lenses(W, H)


@pytest.mark.parametrize("lens_name", sorted(MILD))
@pytest.mark.parametrize("angle,width,spacing", [(20.0, 3.0, 60.0), (100.0, 8.0, 80.0)])
def test_distorted_harp_matches_whole_edge_truth(lens_name, angle, width, spacing):
    lens = MILD[lens_name]
    assert lens.corner_shift() > 5.0  # the lens moves the corners by several pixels
    r = render_harp(
        W,
        H,
        HarpScene(angle_deg=angle, spacing_px=spacing, string_width_px=width),
        lens=lens,
        noise_sigma=1.5,
        seed=21,
    )
    m = measure_image(r.image)
    c = assert_whole_edges(r, m)
    assert c.true.d > 0.3  # a real bend to measure
    for mt in c.matches:  # every edge is measured on the right curve
        assert mt.distance < 0.5  # gradient maxima sit ~0.3 px outside a 3 px string (blur), a constant offset


def test_distorted_harp_with_frame_dust_and_vignetting_matches_whole_edge_truth():
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
    r = render_harp(W, H, scene, lens=ExactLens("barrel", W, H, k=(0.04,)), noise_sigma=1.5, seed=6)
    m = measure_image(r.image)
    assert m.n_lines >= 30
    assert_whole_edges(r, m)  # every measured edge is a true string edge (not frame, not dust)


def test_the_papers_plain_gaussian_loses_the_ends():
    """The option ``smoothing="gaussian"`` keeps the paper's valid-mode blur: 3 sigma (72 px) lost
    at each end, and d, d_max too low against the whole-edge truth -- what the default fixes."""
    r = render_harp(W, H, HarpScene(angle_deg=20.0, spacing_px=60.0), lens=MILD["barrel"], noise_sigma=1.5, seed=21)
    m = measure_image(r.image, smoothing="gaussian")
    assert m.smoothing == "gaussian"
    c = compare(r, m)
    assert max(mt.coverage for mt in c.matches) < 0.9
    assert m.d < 0.95 * c.true.d and m.d_max < 0.95 * c.true.d_max
    with pytest.raises(ValueError, match="unknown smoothing"):
        measure_image(r.image, smoothing="box")


def test_t_changes_the_sampling_not_the_answer():
    r = render_harp(W, H, HarpScene(angle_deg=50.0, spacing_px=60.0), lens=MILD["division"], noise_sigma=1.5, seed=5)
    m30, m10 = measure_image(r.image, t=30), measure_image(r.image, t=10)
    assert m30.t == 30 and m10.t == 10
    assert sum(len(ln.points) for ln in m10.lines) > 2.5 * sum(len(ln.points) for ln in m30.lines)
    for m in (m30, m10):
        assert_whole_edges(r, m)


# -- 3. wide-angle lenses, wide strings, bright strings ---------------------------------------
WIDE = wide_lenses(WW, WH)


@pytest.mark.parametrize(
    "lens_name,angle,width,spacing",
    [
        ("wide-division", 0.0, 3.0, 60.0),  # horizontal strings bow out of the image and come back
        ("wide-division", 100.0, 8.0, 80.0),
        ("wide-fisheye", 45.0, 3.0, 60.0),
        ("wide-fisheye", 90.0, 8.0, 80.0),
    ],
)
def test_wide_angle_lens_whole_edges(lens_name, angle, width, spacing):
    """Issue 8 item 3: ~25-30 % of the half-diagonal at the corners (about 300 px on 1600x1200)."""
    lens = WIDE[lens_name]
    assert 250.0 <= lens.corner_shift() <= 320.0
    r = render_harp(
        WW,
        WH,
        HarpScene(angle_deg=angle, spacing_px=spacing, string_width_px=width),
        lens=lens,
        noise_sigma=1.5,
        seed=8,
    )
    m = measure_image(r.image)
    c = assert_whole_edges(r, m)
    # strings that leave the image and come back are one edge of several pieces, found as such
    split = [k for k, te in enumerate(c.truths) if len(te.dense) > 1 and te.length >= 0.1 * WH]
    if angle in (0.0, 90.0):
        assert len(split) >= 4
    for mt in c.matches:
        if mt.truth in split:
            assert len(m.lines[mt.line].point_pieces) == len(c.truths[mt.truth].dense)


@pytest.mark.parametrize(
    "lens_name,scene",
    [
        ("barrel", HarpScene(angle_deg=20.0, spacing_px=30.0, string_width_px=12.0)),  # 40 % duty cycle
        (
            "mustache",
            HarpScene(angle_deg=110.0, spacing_px=30.0, string_width_px=12.0, background=30.0, string_level=200.0),
        ),
        (
            "tangential",
            HarpScene(angle_deg=60.0, spacing_px=60.0, string_width_px=3.0, background=30.0, string_level=200.0),
        ),
    ],
    ids=["wide-12px-dark", "wide-12px-bright", "bright-3px"],
)
def test_wide_and_bright_strings_whole_edges(lens_name, scene):
    r = render_harp(W, H, scene, lens=MILD[lens_name], noise_sigma=1.5, seed=3)
    m = measure_image(r.image)
    assert m.dark_strings == (scene.string_level < scene.background)
    assert m.string_width_px == pytest.approx(scene.string_width_px, abs=1.0)
    assert_whole_edges(r, m)


# -- misc --------------------------------------------------------------------------------------
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
    assert {"points", "rms", "p2p", "angle_deg", "length_px", "hf_rms", "start", "end"} <= set(d["lines"][0])
    for ln, dl in zip(m.lines, d["lines"]):
        assert dl["start"] == list(ln.points[0]) and dl["end"] == list(ln.points[-1])
        # the pieces partition both point arrays, in order
        assert ln.raw_pieces[0, 0] >= 0 and ln.raw_pieces[-1, 1] <= len(ln.raw_points)
        assert ln.point_pieces[0, 0] == 0 and ln.point_pieces[-1, 1] == len(ln.points)
        assert np.all(ln.point_pieces[1:, 0] == ln.point_pieces[:-1, 1])


def test_point_sigmas_are_the_scatter_of_a_straight_harp():
    """On an undistorted (straight) harp every residual of the measured points is noise: the
    predicted sigmas (one per point) match its RMS in the middle of the edges and at their ends,
    where the smoother's one-sided window makes it 2-3 times larger."""
    r = render_harp(
        640, 480, HarpScene(angle_deg=30.0, spacing_px=60.0, string_width_px=3.0), noise_sigma=1.5, bit_depth=8, seed=3
    )
    m = measure_image(r.image)
    sig = point_sigmas(m)
    assert [len(s) for s in sig] == [len(ln.points) for ln in m.lines]
    pts = [ln.points for ln in m.lines]
    counts = np.array([len(p) for p in pts])
    res = tls(np.concatenate(pts), np.concatenate([[0], np.cumsum(counts)[:-1]]), counts)[0]
    end = np.concatenate([np.r_[True, np.zeros(len(p) - 2, bool), True] for p in pts])
    s = np.concatenate(sig)
    for sel in (~end, end):
        assert np.sqrt(np.mean(s[sel] ** 2)) == pytest.approx(np.sqrt(np.mean(res[sel] ** 2)), rel=0.25)
    assert np.median(s[end]) > 2 * np.median(s[~end])


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


def _darkness_centroid_straightness(img, m, step=30, half=6):
    """Independent d, d_max of the real strings: per image column (near-horizontal strings) or row
    (near-vertical), the darkness-weighted centroid of each string across a 13 px window, over the
    whole extent of its raw edge points; every step-th centroid; TLS line per string from numpy."""
    img = img.astype(float)
    h, w = img.shape
    s_all, p2p = [], []
    for sid in sorted({ln.string_id for ln in m.lines}):
        raw = np.concatenate([ln.raw_points for ln in m.lines if ln.string_id == sid])
        ext = raw.max(0) - raw.min(0)
        ax = 0 if ext[0] >= ext[1] else 1  # sample along x or along y
        o = 1 - ax
        r = raw[np.argsort(raw[:, ax])]
        ts = np.arange(np.ceil(r[0, ax]), np.floor(r[-1, ax]) + 1)
        seed = np.interp(ts, r[:, ax], r[:, o])  # where to look for the string (location only)
        pts = []
        for t, c in zip(ts, seed):
            k = np.arange(int(round(c)) - half, int(round(c)) + half + 1)
            if k[0] < 0 or k[-1] >= (h if o == 1 else w):
                continue
            prof = img[k, int(t)] if o == 1 else img[int(t), k]
            bg = 0.5 * (prof[:2].mean() + prof[-2:].mean())
            wgt = np.clip(bg - prof, 0, None) if m.dark_strings else np.clip(prof - bg, 0, None)
            if wgt.sum() > 0:
                cc = float((wgt * k).sum() / wgt.sum())
                pts.append((t, cc) if ax == 0 else (cc, t))
        q = np.array(pts)[::step]
        q = q - q.mean(0)
        _, v = np.linalg.eigh(q.T @ q)
        s = q @ v[:, 0]
        s_all.append(s)
        p2p.append(s.max() - s.min())
    s = np.concatenate(s_all)
    return float(np.sqrt(np.mean(s**2))), float(np.sqrt(np.mean(np.square(p2p))))


def test_real_photos_d(real_measurements, real_harp_dir):
    """The uncorrected d, d_max of the real photos over the whole visible strings, checked against an
    independent method (darkness centroids, above). Measured (issue 8, ends kept): d 2.45 / 2.06 /
    3.91 px (IMG_6931 / 6950 / 6964), pooled 2.91 px; the centroids give 2.37 / 2.05 / 3.88 px. The
    measurement before issue 8 dropped 72 px at each end of every edge: 1.95 / 1.74 / 3.48 px,
    10-18 % below the centroids."""
    from station.imageio import read_grey

    per_image = {n: (m.d, m.d_max) for n, m in real_measurements.items()}
    pooled = straightness([ln.points for m in real_measurements.values() for ln in m.lines])
    print("real photos d, d_max:", per_image, "pooled:", pooled.d, pooled.d_max)
    for name, m in real_measurements.items():
        d_c, d_max_c = _darkness_centroid_straightness(read_grey(real_harp_dir / name), m)
        print(f"{name}: d {m.d:.4f} (centroids {d_c:.4f}), d_max {m.d_max:.4f} (centroids {d_max_c:.4f})")
        assert m.d == pytest.approx(d_c, rel=0.05)
        assert m.d_max == pytest.approx(d_max_c, rel=0.05)
        assert 2 * m.d < m.d_max < 4 * m.d
    # over all edges of the three photos (as the seed paper pools its images)
    assert 2.6 < pooled.d < 3.2
