"""External models (OpenCV, lensfun) and the exports of a harp correction to them."""

import xml.etree.ElementTree as ET

import cv2
import lensfunpy
import numpy as np
import pytest
import yaml

from pipeline.exports.conversion_error import conversion_error
from pipeline.exports.fit import fit_lensfun, fit_opencv
from pipeline.exports.lensfun import lensfun_text, read_lensfun_text
from pipeline.exports.opencv import opencv_text, read_opencv_text
from pipeline.exports.ros import ROS_FIELDS, read_ros_text, ros_text
from pipeline.exports.statement import Statement
from pipeline.models import LensfunModel, OpenCVModel, RadialModel
from pipeline.normalise import corner_homography, homography_from_4, image_corners, normalise_by_corners

W, H = 320, 240
RNG = np.random.default_rng(7)
PTS = np.column_stack([RNG.uniform(0, W - 1, 400), RNG.uniform(0, H - 1, 400)])
BARREL = RadialModel.for_image(W, H, k=(1.0, 0.0, 0.04, 0.0, -0.01))


def opencv_closed_form(m: OpenCVModel, xy):
    """Independent numpy implementation of OpenCV's projection (no tilt)."""
    d = np.zeros(12)
    d[: len(m.dist)] = m.dist
    k1, k2, p1, p2, k3, k4, k5, k6, s1, s2, s3, s4 = d
    x, y = (xy[:, 0] - m.cx) / m.fx, (xy[:, 1] - m.cy) / m.fy
    r2 = x * x + y * y
    rad = (1 + k1 * r2 + k2 * r2**2 + k3 * r2**3) / (1 + k4 * r2 + k5 * r2**2 + k6 * r2**3)
    xd = x * rad + 2 * p1 * x * y + p2 * (r2 + 2 * x * x) + s1 * r2 + s2 * r2**2
    yd = y * rad + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y + s3 * r2 + s4 * r2**2
    return np.column_stack([m.fx * xd + m.cx, m.fy * yd + m.cy])


@pytest.mark.parametrize(
    "dist",
    [
        (-0.21, 0.06, 1e-3, -2e-3, 0.01),
        (0.3, -0.1, 1e-3, 5e-4, 0.02, 0.5, -0.05, 0.03),
        (-0.1, 0.01, 0.0, 1e-3, 0.0, 0.0, 0.0, 0.0, 1e-3, -1e-4, 2e-3, 1e-4),
    ],
)
def test_opencv_model_is_opencvs_projection_and_inverts_it(dist):
    m = OpenCVModel(fx=400.0, fy=405.0, cx=161.0, cy=118.5, dist=dist)
    np.testing.assert_allclose(m.distort_points(PTS), opencv_closed_form(m, PTS), atol=1e-9)
    obj = np.column_stack([(PTS[:, 0] - m.cx) / m.fx, (PTS[:, 1] - m.cy) / m.fy, np.ones(len(PTS))])
    cv, _ = cv2.projectPoints(obj.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), m.camera_matrix, m.dist_coeffs)
    np.testing.assert_allclose(m.distort_points(PTS), cv.reshape(-1, 2), atol=1e-9)  # OpenCV's own projection
    u = m.undistort_points(PTS)
    assert np.all(np.isfinite(u))
    assert np.max(np.abs(m.distort_points(u) - PTS)) < 1e-8
    # OpenCV's own map agrees with our correction at pixel centres (float32 maps)
    mx, my = m.undistortion_maps(W, H)
    src = m.distort_points(np.array([[10.0, 20.0], [300.0, 200.0]]))
    np.testing.assert_allclose([mx[20, 10], my[20, 10]], src[0], atol=1e-4)
    np.testing.assert_allclose([mx[200, 300], my[200, 300]], src[1], atol=1e-4)


def test_opencv_model_with_sensor_tilt_uses_opencv_and_inverts():
    m = OpenCVModel(
        fx=400.0, fy=400.0, cx=160.0, cy=120.0, dist=(-0.2, 0.05, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0.01, -0.005)
    )
    u = m.undistort_points(PTS)
    assert np.max(np.abs(m.distort_points(u) - PTS)) < 1e-8
    flat = OpenCVModel(fx=400.0, fy=400.0, cx=160.0, cy=120.0, dist=(-0.2, 0.05, 0, 0, 0))
    assert np.max(np.abs(m.distort_points(PTS) - flat.distort_points(PTS))) > 0.1  # the tilt is applied


def test_lensfun_model_follows_lensfun_normalisation_and_formulas():
    m = LensfunModel(kind="ptlens", terms=(0.01, -0.03, 0.02), width=W, height=H)
    # unit = half the shorter side between pixel centres, origin the image centre
    assert m.unit == 119.5 and m.origin == (159.5, 119.5)
    p = np.array([[159.5 + 119.5 * 0.6, 119.5 + 119.5 * 0.8]])  # R_u = 1 exactly
    a, b, c = m.terms
    assert np.allclose(m.distort_points(p), p)  # ptlens fixes R = 1: a + b + c + (1 - a - b - c) = 1
    q = np.array([[159.5 + 119.5 * 0.5, 119.5]])  # R_u = 0.5
    f = a * 0.125 + b * 0.25 + c * 0.5 + 1 - a - b - c
    np.testing.assert_allclose(m.distort_points(q), [[159.5 + 119.5 * 0.5 * f, 119.5]], atol=1e-12)
    m5 = LensfunModel(kind="poly5", terms=(-0.05, 0.01), width=W, height=H)
    np.testing.assert_allclose(
        m5.distort_points(q), [[159.5 + 119.5 * 0.5 * (1 - 0.05 * 0.25 + 0.01 * 0.0625), 119.5]], atol=1e-12
    )
    for mm in (m, m5, LensfunModel(kind="poly3", terms=(0.02,), width=W, height=H)):
        u = mm.undistort_points(PTS)
        assert np.max(np.abs(mm.distort_points(u) - PTS)) < 1e-9


def test_corner_normalisation_fixes_the_corners():
    q = image_corners(W, H)
    n = normalise_by_corners(BARREL, W, H)
    np.testing.assert_allclose(n.undistort_points(q), q, atol=1e-9)
    h = homography_from_4(q, q[[1, 2, 3, 0]])
    assert np.allclose(h @ np.array([0, 0, 1.0]) / (h @ np.array([0, 0, 1.0]))[2], [W - 1, 0, 1])
    assert corner_homography(BARREL, W, H).shape == (3, 3)


def test_opencv_fit_recovers_an_opencv_lens_exactly():
    truth = OpenCVModel(fx=400.0, fy=400.0, cx=165.0, cy=115.0, dist=(-0.25, 0.08, 1e-3, -5e-4, -0.01))
    got, err = fit_opencv(truth, W, H, n_coeffs=5, focal=400.0)
    assert err.rms_px < 1e-6 and err.max_px < 1e-5
    np.testing.assert_allclose([got.cx, got.cy], [165.0, 115.0], atol=1e-4)
    np.testing.assert_allclose(got.dist, truth.dist, atol=1e-6)


def test_lensfun_fit_recovers_a_lensfun_lens_exactly():
    truth = LensfunModel(kind="ptlens", terms=(0.012, -0.031, 0.004), width=W, height=H)
    got, err = fit_lensfun(truth, W, H, kind="ptlens")
    assert err.max_px < 1e-6
    np.testing.assert_allclose(got.terms, truth.terms, atol=1e-7)


def test_conversion_error_states_the_real_disagreement():
    """The stated error is what an independent comparison at random points finds."""
    got, err = fit_lensfun(BARREL, W, H, kind="poly3")  # poly3 cannot represent this lens
    assert 0.05 < err.rms_px < 1.0 and err.max_px >= err.rms_px and err.rms_mod_h_px <= err.rms_px + 1e-9
    a = normalise_by_corners(BARREL, W, H).undistort_points(PTS)
    b = normalise_by_corners(got, W, H).undistort_points(PTS)
    e = np.linalg.norm(a - b, axis=1)
    assert e.max() <= err.max_px * 1.0001
    assert abs(np.sqrt(np.mean(e**2)) - err.rms_px) < 0.15 * err.rms_px
    # a better family must give a smaller stated error
    _, err5 = fit_opencv(BARREL, W, H, n_coeffs=5)
    assert err5.rms_px < 0.1 * err.rms_px
    assert conversion_error(BARREL, BARREL, W, H).max_px < 1e-9


def test_opencv_file_loads_unchanged_with_cv2_filestorage(tmp_path):
    m, err = fit_opencv(BARREL, W, H, n_coeffs=5)
    path = tmp_path / "calib.yaml"
    path.write_text(opencv_text(m, W, H, Statement(err)))
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    assert fs.isOpened()
    np.testing.assert_array_equal(fs.getNode("camera_matrix").mat(), m.camera_matrix)
    np.testing.assert_array_equal(fs.getNode("distortion_coefficients").mat(), m.dist_coeffs.reshape(1, 5))
    assert int(fs.getNode("image_width").real()) == W and int(fs.getNode("image_height").real()) == H
    assert fs.getNode("conversion_rms_px").real() == err.rms_px and fs.getNode("conversion_d_px").real() == err.d_px
    fs.release()
    back, size = read_opencv_text(path.read_text(), str(path))
    assert back == m and size == (W, H)
    # an OpenCV XML written by OpenCV itself is read too
    fs = cv2.FileStorage("c.xml", cv2.FILE_STORAGE_WRITE | cv2.FILE_STORAGE_MEMORY)
    fs.write("cameraMatrix", m.camera_matrix)
    fs.write("distCoeffs", m.dist_coeffs)
    back, size = read_opencv_text(fs.releaseAndGetString())
    assert back == m and size is None
    with pytest.raises(ValueError, match="^x.yml: OpenCV file without camera_matrix"):
        read_opencv_text("%YAML:1.0\n---\nfoo: 1\n", "x.yml")


@pytest.mark.parametrize("n, name", [(5, "plumb_bob"), (8, "rational_polynomial")])
def test_ros_camera_info_has_exactly_the_camera_info_fields(n, name):
    m = OpenCVModel(fx=400.0, fy=400.0, cx=160.0, cy=120.0, dist=tuple(np.linspace(-0.1, 0.1, n)))
    text = ros_text(m, W, H, camera_name="harp_cam")
    doc = yaml.safe_load(text)
    assert set(doc) == set(ROS_FIELDS)
    assert doc["distortion_model"] == name and doc["camera_name"] == "harp_cam"
    assert (doc["image_width"], doc["image_height"]) == (W, H)
    assert [
        len(doc[k]["data"])
        for k in ("camera_matrix", "distortion_coefficients", "rectification_matrix", "projection_matrix")
    ] == [9, n, 9, 12]
    assert doc["distortion_coefficients"] == {"rows": 1, "cols": n, "data": list(m.dist)}
    assert doc["projection_matrix"]["data"] == [400.0, 0.0, 160.0, 0.0, 0.0, 400.0, 120.0, 0.0, 0.0, 0.0, 1.0, 0.0]
    assert read_ros_text(text) == (m, (W, H))


def test_lensfun_xml_uses_the_lensfun_schema_and_reads_back():
    m, err = fit_lensfun(BARREL, W, H, kind="ptlens")  # centre fitted: written as <center>
    text = lensfun_text(m, err, focal=35.0)
    root = ET.fromstring(text)
    assert root.tag == "lensdatabase"
    lens = root.find("lens")
    assert [c.tag for c in lens] == ["maker", "model", "mount", "cropfactor", "aspect-ratio", "center", "calibration"]
    assert [float(lens.find("center").get(a)) for a in "xy"] == list(m.center)
    d = lens.find("calibration/distortion")
    assert set(d.attrib) == {"model", "focal", "a", "b", "c"}
    assert d.get("model") == "ptlens" and float(d.get("focal")) == 35.0
    assert [float(d.get(t)) for t in "abc"] == list(m.terms)
    assert "conversion error" in text
    assert read_lensfun_text(text, W, H) == m
    # images of another aspect ratio: lensfun's coordinate correction sqrt(ar_c^2+1)/sqrt(ar_i^2+1)
    square = read_lensfun_text(text, 300, 300)
    assert square.coord_scale == pytest.approx(np.hypot(319 / 239, 1) / np.sqrt(2), rel=1e-12)
    assert square.unit == pytest.approx(149.5 / square.coord_scale)
    three_two = read_lensfun_text(text.replace(repr(319 / 239), "3:2"), W, H)
    assert three_two.coord_scale == pytest.approx(np.hypot(1.5, 1) / np.hypot(319 / 239, 1))
    again = read_lensfun_text(lensfun_text(three_two), W, H)
    assert again.coord_scale == pytest.approx(three_two.coord_scale, rel=1e-12)
    with pytest.raises(ValueError, match="^f.xml: not a lensfun database"):
        read_lensfun_text("<foo/>", W, H, "f.xml")


@pytest.mark.parametrize(
    "model",
    [
        LensfunModel(kind="ptlens", terms=(0.012, -0.031, 0.004), width=W + 1, height=H + 1, center=(0.05, -0.03)),
        LensfunModel(kind="poly5", terms=(-0.05, 0.01), width=W, height=H),
        LensfunModel(kind="poly3", terms=(0.02,), width=H, height=W),  # portrait
    ],
    ids=lambda m: m.kind,
)
def test_lensfun_itself_loads_the_xml_and_applies_our_model(model):
    """The lensfun library (via lensfunpy) reads the export and maps pixels exactly as LensfunModel."""
    db = lensfunpy.Database(xml=lensfun_text(model, focal=35.0), load_common=False, load_bundled=False)
    (lens,) = db.lenses
    mod = lensfunpy.Modifier(lens, 1.0, model.width, model.height)
    mod.initialize(35.0, 2.8, 1000.0, scale=1.0, flags=lensfunpy.ModifyFlags.DISTORTION)
    pts = np.column_stack([RNG.uniform(0, model.width - 1, 60), RNG.uniform(0, model.height - 1, 60)])
    # per pixel: lensfun's whole-row call accumulates float32 steps (up to 0.05 px along a row)
    got = np.array([mod.apply_geometry_distortion(float(x), float(y), 1, 1)[0, 0] for x, y in pts])
    ours = model.distort_points(pts)
    assert np.abs(ours - pts).max() > 1.0  # a real distortion
    assert np.abs(got - ours).max() < 2e-4  # lensfun computes in float32


def test_auto_tries_the_fisheye_for_a_wide_angle_calibration_and_keeps_the_closer():
    import re

    from pipeline.exports.auto_rule import consumer_max_px
    from pipeline.exports.registry import write_export
    from pipeline.exports.source import ExportOptions, ExportSource

    # a calibration that chose a wide-angle model: both are fitted (the pin-hole with 5 coefficients,
    # quicker), and the export is the one closer in max as its consumer sees it (maps and OpenCV's
    # default point solver), with both figures stated
    five = ExportOptions(coeffs=5)
    e = write_export("auto", ExportSource(BARREL, W, H, holdout_d=0.1, wide_angle=True), five)
    m = re.search(r"pin-hole \(5\) RMS [\d.]+ / max ([\d.]+) px .*, fisheye RMS [\d.]+ / max ([\d.]+) px", e.notes[0])
    assert m and "the calibration chose a wide-angle model" in e.notes[0], e.notes
    pin, fe = float(m.group(1)), float(m.group(2))
    assert e.format == ("opencv-fisheye" if fe < pin else "opencv")
    assert f"{consumer_max_px(e):.4f}" == f"{min(pin, fe):.4f}"
    # not wide-angle and within the holdout d: the fisheye model is not tried
    e = write_export("auto", ExportSource(BARREL, W, H, holdout_d=0.1), five)
    assert e.format == "opencv" and "fisheye not tried" in e.notes[0]
