"""The Metashape calibration XML read back with ElementTree and evaluated with Metashape's documented equations.

No Metashape installed (commercial software): the consumer here is the XML parsed as a calibration file and
the frame and fisheye camera equations of Metashape's user manual (appendix "Camera models") written out in
``tests/pipeline/metashape_equations.py``: its own pixel origin (the image's top-left corner), ``cx, cy``
from the image centre, its ``P1, P2`` (OpenCV's ``p2, p1``) and ``B1`` affinity. Truth: the harp model
(``undistort_points``), independent of the writer, compared modulo homography as every export; for the
fisheye camera, the exact fisheye model written.
"""

import numpy as np
import pytest

from pipeline.compare import fit_homography
from pipeline.exports.metashape import metashape_text, read_metashape_text
from pipeline.exports.registry import read_correction, write_export
from pipeline.exports.source import ExportSource
from pipeline.models import RadialModel
from pipeline.models.homography import apply_homography
from pipeline.models.opencv_fisheye_model import OpenCVFisheyeModel
from tests.pipeline.export_support import mod_h
from tests.pipeline.metashape_equations import metashape_camera, project, unproject

STAMP = "FAILED QA: profile #7 at focus 0 was judged FAIL (test stamp) -- with a double dash"
W, H = 400, 300
#: a strong pin-hole lens with decentering (so that the p1/p2 swap matters) and thin prism
PINHOLE = RadialModel.for_image(
    W, H, k=(1.0, 0.0, 0.06, 0.0, -0.012), center=(207.0, 146.0), tangential=(3e-3, -2e-3), prism=(2e-3, 0, -1.5e-3, 0)
)


@pytest.fixture(scope="module")
def frame():
    return write_export("metashape", ExportSource(PINHOLE, W, H, stamp=(STAMP,)))


def grid(width, height, nx=64):
    ny = int(round(nx * height / width))
    xs, ys = np.linspace(0, width - 1, nx), np.linspace(0, height - 1, ny)
    return np.stack(np.meshgrid(xs, ys), axis=-1).reshape(-1, 2)


def figures(data, ours, q):
    """Metashape's unprojection of harp pixels ``q`` against ``ours`` modulo homography, and its projection."""
    proj, w, h, p = metashape_camera(data)
    x = unproject(proj, w, h, p, q + 0.5)  # Metashape's pixels: the top-left pixel's centre at (0.5, 0.5)
    rms, mx = mod_h(x, ours)
    hom, _ = fit_homography(x, ours)
    e = np.hypot(*(project(proj, w, h, p, apply_homography(np.linalg.inv(hom), ours)) - 0.5 - q).T)
    return rms, mx, float(np.sqrt(np.mean(e**2))), float(e.max())


def test_the_frame_camera_in_metashapes_equations_within_the_stated_error(frame):
    proj, w, h, p = metashape_camera(frame.data)
    assert (proj, w, h) == ("frame", W, H) and p["k4"] == 0.0 and p["b2"] == 0.0
    err = frame.error
    q = grid(W, H)
    rms, mx, rms_p, mx_p = figures(frame.data, PINHOLE.undistort_points(q), q)
    print(
        f"\nmetashape frame (the manual's equations, no Metashape installed): stated RMS {err.rms_mod_h_px:.3g} / max "
        f"{err.max_mod_h_px:.3g} px mod H; unprojection RMS {rms:.3g} / max {mx:.3g} px; projection RMS "
        f"{rms_p:.3g} / max {mx_p:.3g} px"
    )
    assert rms <= 1.3 * err.rms_mod_h_px + 5e-4 and mx <= 1.3 * err.max_mod_h_px + 5e-4
    assert abs(rms - err.rms_mod_h_px) <= 0.3 * err.rms_mod_h_px + 5e-4
    assert rms_p <= 1.3 * err.rms_mod_h_px + 5e-4 and mx_p <= 1.3 * err.max_mod_h_px + 5e-4
    # the swap is real: the same file with p1, p2 in OpenCV's order is far off
    text = frame.data.decode()
    p1, p2 = (text.split(f"<{k}>")[1].split("<")[0] for k in ("p1", "p2"))
    unswapped = (
        text.replace(f"<p1>{p1}<", "<p1>P2<").replace(f"<p2>{p2}<", f"<p2>{p1}<").replace("<p1>P2<", f"<p1>{p2}<")
    )
    assert figures(unswapped.encode(), PINHOLE.undistort_points(q), q)[1] > 5 * max(mx, 1e-3)


def test_the_statement_leads_in_comments_and_the_file_reads_back(frame):
    text = frame.data.decode()
    lines = text.splitlines()
    assert lines[1].startswith("<!-- Agisoft Metashape camera calibration") and lines[2] == (
        "<!-- FAILED QA: profile #7 at focus 0 was judged FAIL (test stamp) - - with a double dash -->"
    )
    assert "p1 and p2 are OpenCV's p2 and p1 (swapped)" in text and frame.notes[0].startswith("metashape: frame")
    c = read_correction(frame.data, "calib.xml", W, H)
    assert c.kind == "metashape:frame" and c.size == (W, H)
    q = grid(W, H, 30)
    assert np.allclose(c.model.undistort_points(q), frame.converted.undistort_points(q), atol=1e-9)


def test_the_fisheye_camera_is_opencvs_fisheye_in_metashapes_equations():
    # the writer's mapping of a fisheye model (the choice between the two is the registry's, tested with COLMAP)
    m = OpenCVFisheyeModel(fx=331.0, fy=329.0, cx=321.3, cy=238.9, dist=(-0.041, 0.006, -0.002, 0.0004))
    data = metashape_text(m, 640, 480).encode()
    proj, w, h, p = metashape_camera(data)
    assert proj == "fisheye" and p["p1"] == p["p2"] == 0.0
    rng = np.random.default_rng(5)
    xy = rng.uniform(-1.5, 1.5, (200, 2))  # rays up to 65 degrees off the axis
    ideal = xy * [m.fx, m.fy] + [m.cx, m.cy]
    assert np.allclose(project(proj, w, h, p, xy) - 0.5, m.distort_points(ideal), atol=1e-9)
    back, size, kind = read_metashape_text(data.decode(), "fe.xml")
    assert kind == "fisheye" and size == (640, 480) and back.dist == m.dist
    assert (back.fx, back.fy, back.cx, back.cy) == pytest.approx((m.fx, m.fy, m.cx, m.cy), abs=1e-9)


@pytest.mark.parametrize(
    "change, why",
    [
        (("<projection>frame<", "<projection>spherical<"), "projection 'spherical' not read"),
        (("<k4>0.0<", "<k4>0.1<"), "<k4> of a frame camera is not read"),
        (("<b2>0.0<", "<b2>2.0<"), r"<b2> \(skew\) 2 is not read"),
        (("<f>", "<f>x"), "<f> is not a number"),
        (("<calibration>", "<calibration"), "not a Metashape calibration XML"),
    ],
)
def test_bad_metashape_files_name_the_file_and_the_field(frame, change, why):
    bad = frame.data.decode().replace(*change)
    with pytest.raises(ValueError, match=f"^calib.xml: .*{why}"):
        read_metashape_text(bad, "calib.xml")
