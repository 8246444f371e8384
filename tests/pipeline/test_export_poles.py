"""Issue 20 item 1: the pin-hole exports have no pole and no fold out to 1.5x the corner radius.

Each shipped lens (the real camera of the photographs at its nominal focal, the demo lens at the end
of its focus range where the margins bind, at the demo configuration's nominal focal) and three wide lenses (93, 115
and 149 degrees) is exported as OpenCV (12 coefficients), ROS (8) and mrcal (12), and fitted with
14 coefficients; the real consumers then work beyond the image: ``cv2.projectPoints`` of rays out
to 1.5x the corner radius is finite and increases with the radius, ``cv2.initUndistortRectifyMap``
onto a canvas 1.5x the ideal image is monotonic along every row and column (no scattered pixel),
and Debian's mrcal projects the same rays to the same pixels. The corner radius is found by
OpenCV's own inverse (``cv2.undistortPointsIter``) from the file's coefficients.
"""

import ast

import cv2
import numpy as np
import pytest
import yaml

from drivers.sim.lens import lens_for_focus
from pipeline.exports.fit import fit_opencv
from pipeline.exports.lens import LensInfo
from pipeline.exports.mrcal import mrcal_text
from pipeline.exports.registry import write_export
from pipeline.exports.source import Export, ExportSource
from pipeline.models.opencv_model import OpenCVModel
from tests.pipeline.export_support import WIDE, WIDE_H, WIDE_W, real_model, system_python, wide_radial

EXTRA = 1.5  # the radius, in corner radii
ANGLES = np.radians(np.arange(0.0, 360.0, 15.0) + 7.0)

REAL_LENS = LensInfo(focal_mm=50.0, pixel_pitch_um=11.4)  # the photographs' camera (test_export_consumers)
DEMO_LENS = LensInfo(focal_mm=12.0, pixel_pitch_um=3.75)  # configs/demo.yaml


def _lenses(real_harp_dir):
    rm = real_model(1, str(real_harp_dir))
    return {
        "real": (rm.model, rm.width, rm.height, REAL_LENS),
        "demo-focus1": (lens_for_focus(1.0, 1280, 960), 1280, 960, DEMO_LENS),
        "wide93": (wide_radial(93.0, 1200, 900), 1200, 900, LensInfo()),
        "wide115": (wide_radial(115.0, 1200, 900), 1200, 900, LensInfo()),
        "wide149": (WIDE, WIDE_W, WIDE_H, LensInfo()),
    }


@pytest.fixture(scope="module")
def files(real_harp_dir):
    """``{(lens, format): (K, D, width, height, file bytes)}`` for opencv / ros / mrcal, read from the files."""
    out = {}
    for name, (model, w, h, lens) in _lenses(real_harp_dir).items():
        src = ExportSource(model, w, h, lens=lens)
        written = {fmt: write_export(fmt, src) for fmt in ("opencv", "ros")}
        # the mrcal export is the same 12-coefficient fit as the OpenCV one: its text, from that fit
        m = written["opencv"].converted
        assert isinstance(m, OpenCVModel)
        written["mrcal"] = Export("mrcal", mrcal_text(m, w, h).encode())
        for fmt, ex in written.items():
            data = ex.data
            if fmt == "opencv":
                fs = cv2.FileStorage(data.decode(), cv2.FILE_STORAGE_READ | cv2.FILE_STORAGE_MEMORY)
                k, d = fs.getNode("camera_matrix").mat(), fs.getNode("distortion_coefficients").mat().ravel()
                fs.release()
            elif fmt == "ros":
                doc = yaml.safe_load(data.decode())
                k = np.array(doc["camera_matrix"]["data"]).reshape(3, 3)
                d = np.array(doc["distortion_coefficients"]["data"])
            else:  # a Python dict literal with comments
                intr = ast.literal_eval(data.decode().strip())["intrinsics"]
                k = np.array([[intr[0], 0, intr[2]], [0, intr[1], intr[3]], [0, 0, 1.0]])
                d = np.array(intr[4:])
            out[(name, fmt)] = (k, d, w, h, data)
    return out


@pytest.fixture(scope="module")
def fourteen(real_harp_dir):
    """The 14-coefficient fits (no file format of ours holds them but OpenCV's) of the shipped lenses."""
    out = {}
    for name, (model, w, h, lens) in _lenses(real_harp_dir).items():
        if name.startswith(("real", "demo")):
            m, _ = fit_opencv(model, w, h, n_coeffs=14, focal=lens.nominal_focal_px(w))
            out[name] = (m.camera_matrix, m.dist_coeffs, w, h, b"")
    return out


def _undistort(k, d, q):
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-15)
    q = np.asarray(q, dtype=np.float64).reshape(-1, 1, 2)
    if hasattr(cv2, "undistortPointsIter"):  # OpenCV 4
        return cv2.undistortPointsIter(q, k, d, None, None, crit).reshape(-1, 2)
    return cv2.undistortPoints(q, k, d, R=None, P=None, criteria=crit).reshape(-1, 2)  # OpenCV 5


def corner_radius(k, d, w, h):
    """Normalised radius of the farthest corner's ideal image, by OpenCV's own inverse."""
    corners = np.array([[0, 0], [w - 1, 0], [0, h - 1], [w - 1, h - 1]], dtype=np.float64)
    n = _undistort(k, d, corners)
    back, _ = cv2.projectPoints(np.column_stack([n, np.ones(4)]), np.zeros(3), np.zeros(3), k, d)
    assert np.abs(back.reshape(-1, 2) - corners).max() < 1e-6  # the inverse converged
    return float(np.hypot(n[:, 0], n[:, 1]).max())


def rays(r_max, n=600):
    """Unit-depth rays at ANGLES, ``n`` radii each from 0 to ``r_max``: shape (len(ANGLES), n, 3)."""
    r = np.linspace(0.0, r_max, n)
    return np.stack([np.cos(ANGLES)[:, None] * r, np.sin(ANGLES)[:, None] * r, np.ones((len(ANGLES), n))], axis=-1)


def _assert_increasing_along_rays(p, k, label):
    assert np.all(np.isfinite(p)), f"{label}: non-finite projection"
    rad = np.hypot(p[..., 0] - k[0, 2], p[..., 1] - k[1, 2])
    steps = np.diff(rad, axis=1)
    assert steps.min() > 0, f"{label}: the projected radius decreases (a fold or a pole), step {steps.min():.3g} px"


CASES = [(n, f) for n in ("real", "demo-focus1", "wide93", "wide115", "wide149") for f in ("opencv", "ros")]


@pytest.mark.parametrize("lens, fmt", CASES, ids=[f"{n}-{f}" for n, f in CASES])
def test_projectpoints_beyond_the_image_is_finite_and_increases_with_the_radius(files, lens, fmt):
    k, d, w, h, _ = files[(lens, fmt)]
    assert len(d) == (12 if fmt == "opencv" else 8)
    rc = corner_radius(k, d, w, h)
    v = rays(EXTRA * rc)
    p, _ = cv2.projectPoints(v.reshape(-1, 3), np.zeros(3), np.zeros(3), k, d)
    p = p.reshape(v.shape[0], v.shape[1], 2)
    print(
        f"{lens} {fmt}: corner radius {rc:.4f}, projection at {EXTRA}x: max radius "
        f"{np.hypot(p[..., 0] - k[0, 2], p[..., 1] - k[1, 2]).max():.1f} px"
    )
    _assert_increasing_along_rays(p, k, f"{lens} {fmt}")


@pytest.mark.parametrize("lens", ["real", "demo-focus1"])
def test_fourteen_coefficient_fits_are_pole_free_too(fourteen, lens):
    k, d, w, h, _ = fourteen[lens]
    v = rays(EXTRA * corner_radius(k, d, w, h))
    p, _ = cv2.projectPoints(v.reshape(-1, 3), np.zeros(3), np.zeros(3), k, d)
    _assert_increasing_along_rays(p.reshape(v.shape[0], v.shape[1], 2), k, f"{lens} 14")


def canvas(k, d, w, h):
    """A camera matrix and size whose canvas holds 1.5x the ideal image (about the principal point)."""
    corners = np.array([[0, 0], [w - 1, 0], [0, h - 1], [w - 1, h - 1]], dtype=np.float64)
    n = _undistort(k, d, corners)
    half = EXTRA * np.abs(n).max(axis=0) * [k[0, 0], k[1, 1]]
    size = (int(np.ceil(2 * half[0])) + 1, int(np.ceil(2 * half[1])) + 1)
    k2 = k.copy()
    k2[0, 2], k2[1, 2] = (size[0] - 1) / 2.0, (size[1] - 1) / 2.0
    return k2, size


@pytest.mark.parametrize("lens, fmt", CASES, ids=[f"{n}-{f}" for n, f in CASES])
def test_undistort_maps_onto_a_larger_canvas_do_not_scatter(files, lens, fmt):
    """Every row of map_x and every column of map_y increases: neighbouring output pixels read
    neighbouring source pixels, in order, over the whole 1.5x canvas."""
    k, d, w, h, _ = files[(lens, fmt)]
    k2, size = canvas(k, d, w, h)
    mx, my = cv2.initUndistortRectifyMap(k, d, None, k2, size, cv2.CV_32FC1)
    assert np.all(np.isfinite(mx)) and np.all(np.isfinite(my))
    dx, dy = np.diff(mx, axis=1), np.diff(my, axis=0)
    print(f"{lens} {fmt}: canvas {size[0]}x{size[1]} (image {w}x{h}): min steps {dx.min():.3g} / {dy.min():.3g} px")
    assert dx.min() > 0 and dy.min() > 0
    # and the image itself is in it, where it should be: the source corners are read near the canvas' ideal corners
    inside = (mx >= 0) & (mx <= w - 1) & (my >= 0) & (my <= h - 1)
    assert inside.sum() > 0.2 * w * h


MRCAL_PROJECT = r"""
import json, sys
import numpy as np
import mrcal
req = json.load(sys.stdin)
m = mrcal.cameramodel(req["path"])
lensmodel, intr = m.intrinsics()
p = mrcal.project(np.array(req["v"], dtype=float), lensmodel, intr)
print(json.dumps({"lensmodel": lensmodel, "p": np.asarray(p).tolist()}))
"""


@pytest.mark.parametrize("lens", ["real", "demo-focus1", "wide93", "wide115", "wide149"])
def test_mrcal_projects_the_rays_beyond_the_image_like_opencv(files, lens, tmp_path):
    k, d, w, h, data = files[(lens, "mrcal")]
    path = tmp_path / "lens.cameramodel"
    path.write_bytes(data)
    v = rays(EXTRA * corner_radius(k, d, w, h), n=200)
    got = system_python(MRCAL_PROJECT, {"path": str(path), "v": v.reshape(-1, 3).tolist()})
    assert got["lensmodel"] == "LENSMODEL_OPENCV12"
    p = np.array(got["p"]).reshape(v.shape[0], v.shape[1], 2)
    _assert_increasing_along_rays(p, k, f"{lens} mrcal")
    cv, _ = cv2.projectPoints(v.reshape(-1, 3), np.zeros(3), np.zeros(3), k, d)
    assert np.abs(cv.reshape(p.shape) - p).max() < 1e-6 * max(w, h)
