"""Every export loaded by its real consumer and compared with the harp model on a dense grid (modulo homography).

Consumers: OpenCV (cv2.FileStorage + cv2.initUndistortRectifyMap / cv2.fisheye), Debian's ROS
camera_calibration_parsers + image_geometry and mrcal (under /usr/bin/python3), lensfun (lensfunpy),
numpy + cv2.remap for the maps, the OpenEXR library and its exrheader tool for the STMap.
Real-photo model: radial4 + tangential + prism fitted on IMG_6931 + IMG_6950 (IMG_6964 held out).
"""

import io
import subprocess

import cv2
import lensfunpy
import numpy as np
import pytest

from pipeline.exports.lens import LensInfo
from pipeline.exports.registry import FORMATS, read_correction, write_export
from pipeline.exports.source import ExportOptions, ExportSource
from pipeline.undistort_maps import fast_undistortion_maps
from tests.pipeline.export_support import (
    WIDE,
    WIDE_H,
    WIDE_W,
    compare_map,
    fisheye_maps_of_ros,
    mod_h,
    mrcal_in_consumer,
    real_model,
    ros_in_consumer,
)

LENS = LensInfo(
    lens_maker="Canon",
    lens_model="EF 50mm f/1.8 II",
    lens_serial="4711",
    camera_maker="Canon",
    camera_model="EOS 40D",
    mount="Canon EF",
    crop_factor=1.611,
    focal_mm=50.0,
    pixel_pitch_um=11.4,  # 5.7 um sensor pixels, images at half resolution
    focus=0.3,
)


@pytest.fixture(scope="module")
def real(real_harp_dir):
    rm = real_model(1, str(real_harp_dir))
    src = ExportSource(rm.model, rm.width, rm.height, lens=LENS, holdout_d=rm.holdout_d, edges=rm.edges)
    return rm, src


@pytest.fixture(scope="module")
def exports(real):
    _, src = real
    return {f: write_export(f, src) for f in ("opencv", "ros", "mrcal", "lensfun", "maps", "stmap")}


@pytest.fixture(scope="module")
def wide():
    src = ExportSource(WIDE, WIDE_W, WIDE_H)
    return src, {f: write_export(f, src) for f in ("opencv-fisheye", "ros-equidistant", "auto")}


def _figures(name, rms, mx, err):
    print(
        f"{name}: consumer vs harp model mod H RMS {rms:.4f} max {mx:.4f} px; stated RMS {err.rms_mod_h_px:.4f} "
        f"max {err.max_mod_h_px:.4f} px, residual d {err.d_px:.4f} px"
    )


def _agrees(rms, mx, err, rel=0.3, abs_px=5e-4):
    """The consumer finds the stated conversion error (different grids: agreement within ``rel``)."""
    assert abs(rms - err.rms_mod_h_px) <= rel * err.rms_mod_h_px + abs_px
    assert mx <= err.max_mod_h_px * (1 + rel) + abs_px


# ----------------------------------------------------------------- OpenCV
def test_opencv_loads_the_default_export_and_it_meets_the_target(real, exports, tmp_path):
    rm, _ = real
    ex = exports["opencv"]
    path = tmp_path / "lens.yml"
    path.write_bytes(ex.data)
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    k, d = fs.getNode("camera_matrix").mat(), fs.getNode("distortion_coefficients").mat()
    assert (
        fs.getNode("distortion_model").string() == "pinhole" and fs.getNode("camera_matrix_kind").string() == "nominal"
    )
    fs.release()
    assert d.shape == (1, 12)
    assert k[0, 0] == pytest.approx(50.0 / 0.0114)  # nominal: 50 mm / 11.4 um
    mx, my = cv2.initUndistortRectifyMap(k, d, None, k, (rm.width, rm.height), cv2.CV_32FC1)
    rms, mxe, n = compare_map(rm.model, mx, my, step=6)
    _figures("opencv (12)", rms, mxe, ex.error)
    assert n > 50000
    assert rms <= 0.01 and mxe <= 0.05  # issue 10 target for the default OpenCV export
    _agrees(rms, mxe, ex.error)
    assert not ex.warnings


def test_opencv_fisheye_export_in_cv2_fisheye(wide, tmp_path):
    src, ex = wide
    e = ex["opencv-fisheye"]
    fs = cv2.FileStorage(e.data.decode(), cv2.FILE_STORAGE_READ | cv2.FILE_STORAGE_MEMORY)
    k, d = fs.getNode("camera_matrix").mat(), fs.getNode("distortion_coefficients").mat()
    assert fs.getNode("distortion_model").string() == "fisheye" and fs.getNode("camera_matrix_kind").string()
    fs.release()
    mx, my = cv2.fisheye.initUndistortRectifyMap(k, d, np.eye(3), k, (WIDE_W, WIDE_H), cv2.CV_32FC1)
    rms, mxe, _ = compare_map(WIDE, mx, my, step=4)
    _figures("opencv-fisheye (wide lens)", rms, mxe, e.error)
    assert rms < 2e-3 and mxe < 0.01  # float32 maps of an exact conversion
    assert "PLACEHOLDER" in e.data.decode()  # no nominal focal: K is said to be a placeholder


def test_auto_chooses_the_fisheye_export_for_the_wide_angle_lens(wide):
    # the pin-hole 12 export holds RMS 0.0026 px but 0.09 px at the corners: beyond the bar, so the
    # fisheye model is fitted too, and it is the closer one
    _, ex = wide
    e = ex["auto"]
    assert e.format == "opencv-fisheye", e.notes
    assert e.notes[0].startswith("auto: opencv-fisheye (the pin-hole is less exact than 0.0100 px RMS")
    assert e.data == ex["opencv-fisheye"].data  # the file --format opencv-fisheye writes


# -------------------------------------------------------------------- ROS


def test_ros_parsers_and_image_geometry_rectify_with_the_export(real, exports, tmp_path):
    rm, _ = real
    ex = exports["ros"]
    path = tmp_path / "camera.yaml"
    path.write_bytes(ex.data)
    got = ros_in_consumer(path, rectify=True)
    assert got["camera_name"] == "canon_eos_40d" and got["model"] == "rational_polynomial" and len(got["D"]) == 8
    assert (got["width"], got["height"]) == (rm.width, rm.height)
    rms, mxe, _ = compare_map(rm.model, got["mapx"], got["mapy"], step=6)
    _figures("ros (rational_polynomial, image_geometry)", rms, mxe, ex.error)
    _agrees(rms, mxe, ex.error)
    assert rms < 0.05  # 8 coefficients cannot hold the thin-prism terms: stated, and below the holdout d


def test_ros_equidistant_export_is_read_by_the_ros_parser(wide, tmp_path):
    src, ex = wide
    e = ex["ros-equidistant"]
    path = tmp_path / "fisheye.yaml"
    path.write_bytes(e.data)
    got = ros_in_consumer(path)
    assert got["model"] == "equidistant" and len(got["D"]) == 4
    # Debian's image_geometry 1.16 rectifies only plumb_bob / rational_polynomial; ROS 2 rectifies
    # equidistant with cv::fisheye, which is what we apply to the parsed message here
    mx, my = fisheye_maps_of_ros(got, WIDE_W, WIDE_H)
    rms, mxe, _ = compare_map(WIDE, mx, my, step=4)
    _figures("ros-equidistant (wide lens)", rms, mxe, e.error)
    assert rms < 2e-3 and mxe < 0.01


# ------------------------------------------------------------------ mrcal


def test_mrcal_reads_the_cameramodel_and_unprojects_like_the_model(real, exports, tmp_path):
    rm, _ = real
    ex = exports["mrcal"]
    path = tmp_path / "lens.cameramodel"
    path.write_bytes(ex.data)
    lensmodel, size, q, p = mrcal_in_consumer(path, rm.width, rm.height)
    assert lensmodel == "LENSMODEL_OPENCV12" and size == [rm.width, rm.height]
    rms, mxe = mod_h(p, rm.model.undistort_points(q))
    _figures("mrcal (OPENCV12)", rms, mxe, ex.error)
    assert rms <= 0.01 and mxe <= 0.05
    _agrees(rms, mxe, ex.error)


# ---------------------------------------------------------------- lensfun
def test_lensfun_finds_the_lens_among_several_and_corrects_like_the_model_at_the_crop(real, exports):
    rm, src = real
    other = LensInfo(lens_maker="Sigma", lens_model="18-35mm F1.8 DC HSM", mount="Canon EF", crop_factor=1.611)
    first = write_export("lensfun", src)  # lens A at 50 mm
    src_b = ExportSource(rm.model, rm.width, rm.height, lens=other.with_overrides(focal_mm=24.0))
    both = write_export("lensfun", src_b, ExportOptions(existing=first.data))
    again = write_export("lensfun", src, ExportOptions(existing=both.data))  # the same lens again: replaced
    assert any("replaced" in w for w in again.warnings)  # replacing a calibration in a user's file is warned of
    db = lensfunpy.Database(xml=again.data.decode(), load_common=False, load_bundled=False)
    assert len(db.lenses) == 2
    (cam,) = db.find_cameras("Canon", "EOS 40D")
    assert cam.crop_factor == pytest.approx(1.611) and cam.mount == "Canon EF"
    (lens,) = db.find_lenses(cam, "Canon", "EF 50mm f/1.8 II")
    assert lens.crop_factor == pytest.approx(1.611) and lens.mounts == ["Canon EF"]
    mod = lensfunpy.Modifier(lens, cam.crop_factor, rm.width, rm.height)
    mod.initialize(50.0, 2.8, 1000.0, scale=1.0, flags=lensfunpy.ModifyFlags.DISTORTION)
    xs, ys = np.linspace(0, rm.width - 1, 40), np.linspace(0, rm.height - 1, 27)
    p = np.stack(np.meshgrid(xs, ys), axis=-1).reshape(-1, 2)
    q = np.array([mod.apply_geometry_distortion(float(x), float(y), 1, 1)[0, 0] for x, y in p], dtype=np.float64)
    ok = (q[:, 0] >= 0) & (q[:, 0] <= rm.width - 1) & (q[:, 1] >= 0) & (q[:, 1] <= rm.height - 1)
    rms, mxe = mod_h(p[ok], rm.model.undistort_points(q[ok]))
    err = exports["lensfun"].error
    _figures("lensfun (ptlens, crop 1.611)", rms, mxe, err)
    _agrees(rms, mxe, err)
    assert "focus setting 0.3" in again.data.decode()


# ------------------------------------------------------------ maps, STMap
def test_maps_npz_equal_harp_undistort_and_are_exact(real, exports):
    rm, _ = real
    with np.load(io.BytesIO(exports["maps"].data)) as z:
        map_x, map_y = z["map_x"], z["map_y"]
        assert map_x.dtype == np.float32 and map_x.shape == (rm.height, rm.width)
        assert float(z["interp_max_px"]) <= 0.01
    ref = fast_undistortion_maps(rm.model, rm.width, rm.height)  # what harp undistort remaps with
    img = np.random.default_rng(3).integers(0, 255, (rm.height, rm.width), dtype=np.uint8)
    a = cv2.remap(img, map_x, map_y, cv2.INTER_LANCZOS4, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    b = cv2.remap(img, ref.map_x, ref.map_y, cv2.INTER_LANCZOS4, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    assert np.array_equal(a, b)
    # against the exact inverse, at random pixels and along the borders
    rng = np.random.default_rng(5)
    px = np.concatenate([rng.integers(0, rm.width, 4000), np.arange(rm.width), np.zeros(rm.height, int)])
    py = np.concatenate([rng.integers(0, rm.height, 4000), np.full(rm.width, rm.height - 1), np.arange(rm.height)])
    exact = rm.model.distort_points(np.stack([px, py], axis=1).astype(np.float64))
    e = np.hypot(map_x[py, px] - exact[:, 0], map_y[py, px] - exact[:, 1])
    print(f"maps: interpolation error RMS {np.sqrt(np.mean(e**2)):.2e} max {e.max():.2e} px")
    assert np.sqrt(np.mean(e**2)) <= 0.002 and e.max() <= 0.01


def test_stmap_exr_is_float32_with_the_nuke_convention(real, exports, tmp_path):
    import OpenEXR

    rm, _ = real
    path = tmp_path / "lens.exr"
    path.write_bytes(exports["stmap"].data)
    # OpenEXR's own header tool (Debian's openexr, installed by scripts/setup.sh)
    head = subprocess.run(["exrheader", str(path)], capture_output=True, text=True, check=True).stdout
    assert "R, 32-bit floating-point" in head and "G, 32-bit floating-point" in head
    assert "Nuke" in head  # the convention is stated in the header's comments
    with OpenEXR.File(str(path), separate_channels=True) as f:
        ch = f.channels()
        r, g = ch["R"].pixels, ch["G"].pixels
    assert r.dtype == np.float32 and r.shape == (rm.height, rm.width)
    exact = rm.model.distort_points(np.array([[0.0, 0.0], [rm.width - 1.0, rm.height - 1.0], [500.0, 300.0]]))
    for (x, y), (sx, sy) in zip([(0, 0), (rm.width - 1, rm.height - 1), (500, 300)], exact):
        assert r[y, x] == pytest.approx((sx + 0.5) / rm.width, abs=2e-6)
        assert g[y, x] == pytest.approx(1 - (sy + 0.5) / rm.height, abs=2e-6)


def test_every_export_reads_back_as_the_correction_it_states(real, exports):
    rm, _ = real
    for name, ex in exports.items():
        c = read_correction(ex.data, f"lens.{name}", rm.width, rm.height, lens_name="Canon EF 50mm f/1.8 II")
        assert c.kind.split(":")[0] in (name, "lensfun")
        g = _grid(rm)
        ours = rm.model.undistort_points(g)
        if name in ("maps", "stmap"):  # per-pixel maps hold the corrected image only
            inside = (
                (ours[:, 0] >= 0) & (ours[:, 0] <= rm.width - 1) & (ours[:, 1] >= 0) & (ours[:, 1] <= rm.height - 1)
            )
            g, ours = g[inside], ours[inside]
        rms, _ = mod_h(c.model.undistort_points(g), ours)
        assert rms <= ex.error.rms_mod_h_px * 1.3 + 1e-3, name
    assert set(FORMATS) >= {"opencv", "opencv-fisheye", "ros", "ros-equidistant", "lensfun", "mrcal", "maps", "stmap"}


def _grid(rm):
    xs, ys = np.linspace(0, rm.width - 1, 30), np.linspace(0, rm.height - 1, 20)
    return np.stack(np.meshgrid(xs, ys), axis=-1).reshape(-1, 2)
