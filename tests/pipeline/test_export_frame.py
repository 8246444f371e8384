"""Issue 20 items 7 and 8: one corrected image for harp undistort and every export, in their real consumers.

The corrected image (:mod:`pipeline.corrected_frame`) is checked against OpenCV's own
``getOptimalNewCameraMatrix`` on an OpenCV lens; each export's ``K, D, R, newK`` in its real consumer
(``cv2.initUndistortRectifyMap`` / ``cv2.fisheye``, Debian's ROS parser + image_geometry, mrcal) must
write harp undistort's corrected image (its maps) to within the export's stated conversion error, for
the default image, ``--alpha 1`` and ``--scale`` with ``--size``; the STMap pair (undistort with
``--overscan`` and redistort) takes a rendered photo there and back.
"""

import io

import cv2
import numpy as np
import pytest

from pipeline.corrected_frame import FrameChoice, corrected_frame
from pipeline.exports.lens import LensInfo
from pipeline.exports.maps import maps_from_stmap
from pipeline.exports.registry import write_export
from pipeline.exports.source import ExportOptions, ExportSource
from pipeline.models.opencv_model import OpenCVModel
from pipeline.undistort_maps import fast_undistortion_maps
from tests.pipeline.export_support import (
    WIDE,
    WIDE_H,
    WIDE_W,
    EquisolidLens,
    mrcal_in_consumer,
    real_model,
    ros_in_consumer,
)

REAL_LENS = LensInfo(focal_mm=50.0, pixel_pitch_um=11.4, camera_maker="Canon", camera_model="EOS 40D")
WIDE_SMALL = EquisolidLens(f=165.0, cx=161.0, cy=118.0)  # the 149 degree lens at 320 x 240
CHOICES = {
    "default": FrameChoice(),
    "alpha1": FrameChoice(alpha=1.0),
    "scale-size": FrameChoice(scale=0.8, size=(1500, 1000)),
}


@pytest.mark.parametrize("dist", [(-0.25, 0.08, 0.0, 0.0, 0.0), (0.15, 0.02, 0.0008, -0.0005, 0.0)])
@pytest.mark.parametrize("alpha", [0.0, 0.5, 1.0])
@pytest.mark.parametrize("size", [(640, 480), (800, 500)])
def test_alpha_is_opencvs_get_optimal_new_camera_matrix(dist, alpha, size):
    lens = OpenCVModel(fx=500.0, fy=500.0, cx=322.0, cy=236.5, dist=dist)  # the lens is an OpenCV model
    ours = corrected_frame(lens, 640, 480, FrameChoice(alpha=alpha, size=size)).new_camera_matrix(lens.fx)
    cv, _ = cv2.getOptimalNewCameraMatrix(lens.camera_matrix, np.array(dist), (640, 480), alpha, size)
    assert ours[0, 0] == pytest.approx(cv[0, 0], rel=2e-4) and ours[1, 1] == pytest.approx(cv[1, 1], rel=2e-4)
    assert ours[0, 2] == pytest.approx(cv[0, 2], abs=0.01) and ours[1, 2] == pytest.approx(cv[1, 2], abs=0.01)
    assert ours[0, 1] == 0.0


def test_alpha_zero_keeps_only_valid_pixels_and_one_every_pixel():
    w, h = WIDE_W, WIDE_H
    zero = fast_undistortion_maps(WIDE, w, h, frame=corrected_frame(WIDE, w, h, FrameChoice(alpha=0.0)))
    inside = (zero.map_x >= -0.01) & (zero.map_x <= w - 0.99) & (zero.map_y >= -0.01) & (zero.map_y <= h - 0.99)
    assert inside.all()  # every corrected pixel has a source
    one = corrected_frame(WIDE, w, h, FrameChoice(alpha=1.0))
    q = one.from_ideal(WIDE.undistort_points(np.stack(np.meshgrid(np.arange(w), np.arange(h)), -1).reshape(-1, 2)))
    assert q.min() >= -0.01 and q[:, 0].max() <= one.width - 0.99 and q[:, 1].max() <= one.height - 0.99


@pytest.fixture(scope="module")
def real(real_harp_dir):
    rm = real_model(1, str(real_harp_dir))
    return rm, ExportSource(rm.model, rm.width, rm.height, lens=REAL_LENS, holdout_d=rm.holdout_d)


@pytest.fixture(scope="module")
def real_exports(real):
    _, src = real
    pairs = [("opencv", c) for c in CHOICES] + [("ros", "default"), ("ros", "alpha1")]
    return {(f, c): write_export(f, src, ExportOptions(frame=CHOICES[c])) for f, c in pairs}


def _agree(consumer_x, consumer_y, harp, err, label):
    """A consumer's maps against harp undistort's, over the corrected pixels that read the photo."""
    h, w = harp.map_x.shape
    assert consumer_x.shape == (h, w), label
    ok = (harp.map_x >= 0) & (harp.map_x <= w - 1) & (harp.map_y >= 0) & (harp.map_y <= h - 1)
    e = np.hypot(consumer_x - harp.map_x, consumer_y - harp.map_y)[ok]
    rms, mx = float(np.sqrt(np.mean(e**2))), float(e.max())
    print(
        f"{label}: consumer vs harp undistort RMS {rms:.4f} max {mx:.4f} px; stated {err.rms_mod_h_px:.4f} / "
        f"{err.max_mod_h_px:.4f} px"
    )
    assert rms <= 1.3 * err.rms_mod_h_px + 1e-3 and mx <= 1.3 * err.max_mod_h_px + 2e-3, label
    return rms, mx


def _file_matrices(data: bytes):
    fs = cv2.FileStorage(data.decode(), cv2.FILE_STORAGE_READ | cv2.FILE_STORAGE_MEMORY)
    out = [
        fs.getNode(n).mat()
        for n in ("camera_matrix", "distortion_coefficients", "rectification_matrix", "new_camera_matrix")
    ]
    size = (int(fs.getNode("new_image_width").real()), int(fs.getNode("new_image_height").real()))
    fs.release()
    return (*out, size)


@pytest.mark.parametrize("choice", list(CHOICES))
def test_opencv_with_the_files_k_r_newk_writes_harp_undistorts_image(real, real_exports, choice):
    rm, _ = real
    ex = real_exports[("opencv", choice)]
    k, d, r, new_k, size = _file_matrices(ex.data)
    frame = corrected_frame(rm.model, rm.width, rm.height, CHOICES[choice])
    assert size == (frame.width, frame.height)
    harp = fast_undistortion_maps(rm.model, rm.width, rm.height, frame=frame)  # what harp undistort remaps with
    mx, my = cv2.initUndistortRectifyMap(k, d, r, new_k, size, cv2.CV_32FC1)
    _agree(mx, my, harp, ex.error, f"opencv {choice}")


def test_every_export_states_the_same_new_camera_matrix(real, real_exports):
    rm, src = real
    fe = write_export("opencv-fisheye", src)
    mrcal = write_export("mrcal", src, ExportOptions(coeffs=8))
    import ast

    import yaml

    ks = [_file_matrices(real_exports[("opencv", "default")].data)[3], _file_matrices(fe.data)[3]]
    ros = yaml.safe_load(real_exports[("ros", "default")].data.decode())
    ks.append(np.array(ros["projection_matrix"]["data"]).reshape(3, 4)[:, :3])
    ks.append(np.array(ast.literal_eval(mrcal.data.decode().strip())["harp_new_camera_matrix"]))
    for k in ks:
        np.testing.assert_allclose(k, ks[0], atol=1e-9)
    assert ks[0][0, 2] == pytest.approx(rm.model.center[0]) and ks[0][1, 2] == pytest.approx(rm.model.center[1])
    assert ks[0][0, 0] == pytest.approx(50.0 / 0.0114)  # nominal: 50 mm / 11.4 um


@pytest.mark.parametrize("choice", ["default", "alpha1"])
def test_ros_image_geometry_writes_harp_undistorts_image(real, real_exports, choice, tmp_path):
    rm, _ = real
    ex = real_exports[("ros", choice)]
    path = tmp_path / "camera.yaml"
    path.write_bytes(ex.data)
    got = ros_in_consumer(path, rectify=True)
    frame = corrected_frame(rm.model, rm.width, rm.height, CHOICES[choice])
    harp = fast_undistortion_maps(rm.model, rm.width, rm.height, frame=frame)
    _agree(got["mapx"], got["mapy"], harp, ex.error, f"ros image_geometry {choice}")


def test_ros_refuses_a_corrected_image_of_another_size(real):
    _, src = real
    with pytest.raises(ValueError, match="ROS rectifies to the raw image's size"):
        write_export("ros", src, ExportOptions(frame=CHOICES["scale-size"]))


def test_mrcal_rays_through_the_files_r_and_newk_land_where_harp_undistort_puts_them(real, tmp_path):
    import ast

    rm, src = real
    ex = write_export("mrcal", src, ExportOptions(frame=CHOICES["alpha1"]))
    path = tmp_path / "lens.cameramodel"
    path.write_bytes(ex.data)
    doc = ast.literal_eval(ex.data.decode().strip())
    r, new_k = np.array(doc["harp_rectification_matrix"]), np.array(doc["harp_new_camera_matrix"])
    _, _, q, p = mrcal_in_consumer(path, rm.width, rm.height)  # p: mrcal's pin-hole pixels (its own K)
    k = np.array(
        [[doc["intrinsics"][0], 0, doc["intrinsics"][2]], [0, doc["intrinsics"][1], doc["intrinsics"][3]], [0, 0, 1]]
    )
    v = np.linalg.solve(k, np.column_stack([p, np.ones(len(p))]).T)  # mrcal's rays
    x = new_k @ r @ v
    got = (x[:2] / x[2]).T
    frame = corrected_frame(rm.model, rm.width, rm.height, CHOICES["alpha1"])
    want = frame.from_ideal(rm.model.undistort_points(q))  # where harp undistort puts the photo's pixel q
    e = np.hypot(*(got - want).T)
    print(
        f"mrcal alpha 1: RMS {np.sqrt(np.mean(e**2)):.4f} max {e.max():.4f} px; stated {ex.error.rms_mod_h_px:.4f} / {ex.error.max_mod_h_px:.4f}"
    )
    assert np.sqrt(np.mean(e**2)) <= 1.3 * ex.error.rms_mod_h_px * frame.sx + 1e-3
    assert e.max() <= 1.3 * ex.error.max_mod_h_px + 2e-3


def test_fisheye_file_in_cv2_fisheye_writes_harp_undistorts_overscan_image():
    src = ExportSource(WIDE, WIDE_W, WIDE_H)
    ex = write_export("opencv-fisheye", src, ExportOptions(frame=FrameChoice(overscan=True)))
    k, d, r, new_k, size = _file_matrices(ex.data)
    frame = corrected_frame(WIDE, WIDE_W, WIDE_H, FrameChoice(overscan=True))
    assert size == (frame.width, frame.height) and frame.width > WIDE_W and frame.height > WIDE_H
    mx, my = cv2.fisheye.initUndistortRectifyMap(k, d, r, new_k, size, cv2.CV_32FC1)
    harp = fast_undistortion_maps(WIDE, WIDE_W, WIDE_H, frame=frame)
    _agree(mx, my, harp, ex.error, "opencv-fisheye overscan, 149 deg lens")


def _exr(data):
    import OpenEXR

    with OpenEXR.File(io.BytesIO(data), separate_channels=True) as f:
        ch = f.channels()
        return {k: np.asarray(v.pixels, np.float64) for k, v in ch.items()}, str(f.header().get("comments", ""))


def test_stmap_pair_takes_a_rendered_photo_to_the_overscan_image_and_back():
    from pipeline.render import HarpScene, render_harp

    w, h = 320, 240
    lens = WIDE_SMALL
    photo = render_harp(w, h, HarpScene(angle_deg=20.0, spacing_px=14.0), lens=lens, noise_sigma=0.0, seed=1).image
    src = ExportSource(lens, w, h)
    opt = ExportOptions(frame=FrameChoice(overscan=True))
    und, red = write_export("stmap", src, opt), write_export("stmap-redistort", src, opt)
    (uch, _), (rch, _) = _exr(und.data), _exr(red.data)
    frame = corrected_frame(lens, w, h, FrameChoice(overscan=True))
    assert uch["R"].shape == (frame.height, frame.width) and rch["R"].shape == (h, w)
    # Nuke's STMap node: source pixel = (R * W_in - 0.5, (1 - G) * H_in - 0.5), here in OpenCV
    ux, uy = uch["R"] * w - 0.5, (1 - uch["G"]) * h - 0.5
    # the undistort STMap's alpha is 1 exactly where its source is on the photo
    on = (ux >= -0.5) & (ux <= w - 0.5) & (uy >= -0.5) & (uy <= h - 0.5)
    assert np.array_equal(uch["A"] > 0.5, on)
    img = photo.astype(np.float32)
    corrected = cv2.remap(
        img, ux.astype(np.float32), uy.astype(np.float32), cv2.INTER_CUBIC, borderMode=cv2.BORDER_REPLICATE
    )
    rx, ry = rch["R"] * frame.width - 0.5, (1 - rch["G"]) * frame.height - 0.5
    assert rch["A"].min() == 1.0  # overscan: every photo pixel has a source in the corrected image
    back = cv2.remap(corrected, rx.astype(np.float32), ry.astype(np.float32), cv2.INTER_CUBIC)
    inner = np.s_[4:-4, 4:-4]
    diff = np.abs(back[inner] - img[inner])
    print(f"STMap pair round trip: mean |diff| {diff.mean():.3f}, max {diff.max():.1f} grey levels")
    assert diff.mean() < 2.0  # two cubic resamplings of a sharp harp image
    # the round trip of the coordinates themselves is exact to the interpolation
    mx, my = maps_from_stmap(uch["R"], uch["G"], (w, h))
    gx = cv2.remap(rx.astype(np.float32), mx.astype(np.float32), my.astype(np.float32), cv2.INTER_LINEAR)
    _, xx = np.mgrid[0 : frame.height, 0 : frame.width]
    sel = on & (ux > 2) & (ux < w - 3) & (uy > 2) & (uy < h - 3)
    # cv2.remap's bilinear weights are in 1/32 px steps; the correction magnifies up to ~4x at this lens's border
    e = np.abs(gx[sel] - xx[sel])
    assert np.sqrt(np.mean(e**2)) < 0.03 and e.max() < 0.15
