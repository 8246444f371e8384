"""``harp export`` and ``harp profile export`` end to end: every format written through the CLI
and read by its real consumer (OpenCV, Debian's ROS parser + image_geometry and mrcal, lensfun,
numpy + cv2.remap, OpenEXR), the lens and camera from the model file / the session's
configuration, the fitting shots' residual d, warnings on stderr, exit codes; ``harp evaluate``
reads every format back.

Two sources, each exported once per format (module fixtures):

* ``harp export MODEL``: a model file holding an exact synthetic lens (decentred, with
  tangential and thin-prism terms that no OpenCV family holds exactly), its fitting shots
  rendered through that lens, its holdout d measured on a third shot;
* ``harp profile export``: a small simulated session (``harp session run``) whose
  configuration gives the lens' nominal focal length, mount, pixel pitch and crop factor.

The truth of each comparison is the lens (or the stored profile) itself, evaluated in the
consumer's own code; the figure it is held to is the one the export states.
"""

from __future__ import annotations

import contextlib
import io
import json
import math
import re
import subprocess
from dataclasses import dataclass, replace
from pathlib import Path

import cv2
import numpy as np
import pycolmap
import pytest
import yaml

from pipeline.edgeset import corrected_straightness
from pipeline.evaluate import corrected_points
from pipeline.exports.ros import ROS_EQUIDISTANT_READERS
from pipeline.fitspec import FitSpec
from pipeline.measure import measure_image
from pipeline.model_file import read_model_file
from pipeline.models import RadialModel
from pipeline.render import HarpScene, render_harp
from pipeline.straightness import straightness
from station.cli import main
from station.config import Identity, Optics
from station.files import write_model_file, write_profile
from station.profile import HOLDOUT_SHOTS, Holdout, Merit, Profile
from station.provenance import make_provenance
from tests.pipeline.basalt_equations import basalt_camera
from tests.pipeline.basalt_equations import normalised as basalt_normalised
from tests.pipeline.basalt_equations import unproject as basalt_unproject
from tests.pipeline.export_support import (
    compare_map,
    compare_points,
    fisheye_maps_of_ros,
    lensfun_in_consumer,
    mod_h,
    mrcal_in_consumer,
    opencv_maps,
    ros_in_consumer,
    wide_radial,
)
from tests.pipeline.kalibr_equations import kalibr_camera, unproject
from tests.pipeline.metashape_equations import metashape_camera
from tests.pipeline.metashape_equations import unproject as metashape_unproject

W, H = 400, 300
LENS = RadialModel.for_image(
    W, H, k=(1.0, 0.0, 0.06, 0.0, -0.012), center=(207.0, 146.0), tangential=(3e-3, -2e-3), prism=(2e-3, 0, -1.5e-3, 0)
)
ANGLES = (3.0, 93.0, 48.0)  # two fitting shots, one held out
FILES = {
    "opencv": "lens.yml",
    "opencv-fisheye": "fisheye.yml",
    "ros": "camera.yaml",
    "ros-equidistant": "camera-equidistant.yaml",
    "lensfun": "lensfun.xml",
    "mrcal": "lens.cameramodel",
    "colmap": "cameras.txt",
    "kalibr": "camchain.yaml",
    "basalt": "calib.json",
    "metashape": "calibration.xml",
    "maps": "maps.npz",
    "stmap": "stmap.exr",
    "json": "lens.json",
    "auto": "auto.yml",
}


@dataclass(frozen=True)
class Source:
    """What was exported, and what its exports must say about the lens and camera."""

    model: object
    width: int
    height: int
    model_file: Path
    lens: tuple[str, str]
    camera: tuple[str, str]
    focal_mm: float
    focal_px: float
    crop: float
    mount: str
    ros_name: str
    focus: float
    shots: tuple[Path, ...] = ()


@dataclass(frozen=True)
class Run:
    code: int
    out: str
    err: str
    path: Path

    @property
    def fig(self) -> dict:
        return json.loads(self.out)


def run_main(*argv) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main([str(a) for a in argv])
    return code, out.getvalue(), err.getvalue()


def export_all(command: list, directory: Path, formats=tuple(FILES)) -> dict[str, Run]:
    runs = {}
    for fmt in formats:
        name = FILES[fmt]
        path = directory / name
        code, out, err = run_main(*command, "--format", fmt, "-o", path, "--json")
        runs[fmt] = Run(code, out, err, path)
    return runs


# ------------------------------------------------------------------ sources
@pytest.fixture(scope="module")
def model_source(tmp_path_factory) -> Source:
    d = tmp_path_factory.mktemp("model")
    shots = []
    for i, angle in enumerate(ANGLES):
        img = render_harp(W, H, HarpScene(angle_deg=angle, spacing_px=28.0), lens=LENS, noise_sigma=1.0, seed=40 + i)
        p = d / f"shot{i}.pgm"
        assert cv2.imwrite(str(p), img.image)
        shots.append(p)
    held = [ln.points for ln in measure_image(cv2.imread(str(shots[2]), cv2.IMREAD_UNCHANGED), t=30).lines]
    holdout_d, holdout_d_max = corrected_straightness(LENS, held)
    profile = Profile(
        LENS,
        W,
        H,
        spec=FitSpec("radial", 4, tangential=True, prism=True),
        merit=Merit(holdout=Holdout(float(holdout_d), float(holdout_d_max), HOLDOUT_SHOTS)),
        lens=Identity("Canon", "EF-S 10-18mm f/4.5-5.6 IS STM", "4711"),
        camera=Identity("Canon", "EOS 40D", "C-1"),
        optics=Optics(focal_mm=10.0, mount="Canon EF-S", sensor_width_mm=22.2, crop_factor=1.611),
        focus=0.3,
        provenance=make_provenance(shots[:2], t=30, command="test"),
    )
    mf = write_profile(d / "lens.yaml", profile)
    return Source(
        LENS,
        W,
        H,
        mf,
        ("Canon", "EF-S 10-18mm f/4.5-5.6 IS STM"),
        ("Canon", "EOS 40D"),
        10.0,
        10.0 * W / 22.2,
        1.611,
        "Canon EF-S",
        "canon_eos_40d",
        0.3,
        tuple(shots[:2]),
    )


REPO = Path(__file__).resolve().parents[3]
SW, SH = 400, 300


@pytest.fixture(scope="module")
def session_source(tmp_path_factory) -> tuple[Source, Path]:
    """A small simulated session whose configuration gives the optics; (source, store)."""
    base = tmp_path_factory.mktemp("session")
    d = yaml.safe_load((REPO / "configs" / "demo.yaml").read_text())
    d["station"]["camera"].update(width=SW, height=SH, spacing_px=28.0)
    d["focus"]["settings"] = [0.0, 1.0]
    d["capture"]["orientations_deg"] = [0, 45, 90, 135]
    d["capture"]["frames_per_orientation"] = 1
    d["pipeline"].update(bootstrap=0, workers=1)
    d["lens"].update(focal_mm=6.0, mount="C")
    d["camera_body"].update(pixel_pitch_um=5.6, crop_factor=15.4)  # 400x300 at 5.6 um: 2.24 x 1.68 mm
    d["store"] = {"path": "profiles.sqlite", "sessions_dir": "sessions"}
    cfg = base / "station.yaml"
    cfg.write_text(yaml.safe_dump(d))
    code, _, err = run_main("session", "run", cfg, "--name", "s", "--quiet", "--no-report")
    assert code == 0, err
    mf = base / "sessions" / "s" / "profiles" / "focus0.yaml"
    src = Source(
        read_model_file(mf).model,
        SW,
        SH,
        mf,
        ("Simulated Optics", "SIM-12mm"),
        ("harp station", "SimulatedCamera"),
        6.0,
        6.0 / 5.6e-3,
        15.4,
        "C",
        "harp_station_simulatedcamera",
        0.0,
    )
    return src, base / "profiles.sqlite"


@pytest.fixture(scope="module")
def exported(model_source, tmp_path_factory) -> dict[str, Run]:
    return export_all(["export", model_source.model_file], tmp_path_factory.mktemp("export"))


@pytest.fixture(scope="module")
def profile_exported(session_source, tmp_path_factory) -> dict[str, Run]:
    _, store = session_source
    cmd = ["profile", "export", "DEMO-0001", "--focus", "0", "--store", store]
    formats = [f for f in FILES if f != "auto"]  # auto writes one of the formats: tested with harp export
    return export_all(cmd, tmp_path_factory.mktemp("profile-export"), formats)


@pytest.fixture(params=["harp export", "harp profile export"])
def both(request, model_source, session_source):
    """(source, runs) of each command."""
    if request.param == "harp export":
        return model_source, request.getfixturevalue("exported")
    return session_source[0], request.getfixturevalue("profile_exported")


def _ok(run: Run) -> dict:
    assert run.code == 0, run.err
    fig = run.fig
    assert fig["output"] == str(run.path) and run.path.is_file()
    return fig


def _agrees(rms, mx, conv, rel=0.3, abs_px=5e-4):
    """The consumer finds the stated conversion error (different grids: within ``rel``)."""
    assert abs(rms - conv["rms_mod_h_px"]) <= rel * conv["rms_mod_h_px"] + abs_px, (rms, conv)
    assert mx <= conv["max_mod_h_px"] * (1 + rel) + abs_px, (mx, conv)


# ----------------------------------------------------------- each format
def test_opencv_in_opencv(both):
    src, runs = both
    for fmt in ("opencv", "auto") if "auto" in runs else ("opencv",):
        fig = _ok(runs[fmt])
        assert fig["format"] == "opencv"  # auto: the pin-hole model is exact enough for this lens
        mx, my, kind, k = opencv_maps(runs[fmt].path, src.width, src.height)
        assert kind == "pinhole" and k[0, 0] == pytest.approx(src.focal_px)  # nominal, from the optics
        rms, mxe, _ = compare_map(src.model, mx, my, step=4)
        _agrees(rms, mxe, fig["conversion"])
        text = runs[fmt].path.read_text()
        assert "camera matrix: nominal" in text and f"lens {src.lens[0]} {src.lens[1]}" in text
    if "auto" in runs:
        assert any(n.startswith("auto: opencv (pin-hole, 12 coefficients)") for n in runs["auto"].fig["notes"])
    assert cv2.FileStorage(str(runs["opencv"].path), cv2.FILE_STORAGE_READ).getNode(
        "distortion_coefficients"
    ).mat().shape == (1, 12)


def test_opencv_fisheye_in_cv2_fisheye(both):
    src, runs = both
    fig = _ok(runs["opencv-fisheye"])
    mx, my, kind, k = opencv_maps(runs["opencv-fisheye"].path, src.width, src.height)
    assert kind == "fisheye" and k[0, 0] == pytest.approx(src.focal_px)
    rms, mxe, _ = compare_map(src.model, mx, my, step=4)
    _agrees(rms, mxe, fig["conversion"])


def test_ros_in_the_ros_parser_and_image_geometry(both):
    src, runs = both
    fig = _ok(runs["ros"])
    got = ros_in_consumer(runs["ros"].path, rectify=True)
    assert got["camera_name"] == src.ros_name and got["model"] == "rational_polynomial" and len(got["D"]) == 8
    assert got["K"][0] == pytest.approx(src.focal_px)
    rms, mxe, _ = compare_map(src.model, got["mapx"], got["mapy"], step=4)
    _agrees(rms, mxe, fig["conversion"])
    fig = _ok(runs["ros-equidistant"])
    got = ros_in_consumer(runs["ros-equidistant"].path)
    assert got["model"] == "equidistant" and got["camera_name"] == src.ros_name
    rms, mxe, _ = compare_map(src.model, *fisheye_maps_of_ros(got, src.width, src.height), step=4)
    _agrees(rms, mxe, fig["conversion"])


def test_mrcal_in_mrcal(both):
    src, runs = both
    fig = _ok(runs["mrcal"])
    lensmodel, size, q, p = mrcal_in_consumer(runs["mrcal"].path, src.width, src.height)
    assert lensmodel == "LENSMODEL_OPENCV12" and size == [src.width, src.height]
    rms, mxe = mod_h(p, src.model.undistort_points(q))
    _agrees(rms, mxe, fig["conversion"])


def test_colmap_in_pycolmap(both, tmp_path):
    src, runs = both
    fig = _ok(runs["colmap"])
    # COLMAP's own reader of a text model (cameras.txt, empty images.txt and points3D.txt)
    d = tmp_path / "sparse"
    d.mkdir()
    (d / "cameras.txt").write_bytes(runs["colmap"].path.read_bytes())
    (d / "images.txt").write_text("")
    (d / "points3D.txt").write_text("")
    rec = pycolmap.Reconstruction()
    rec.read_text(str(d))
    (cam,) = rec.cameras.values()
    assert cam.model_name == "FULL_OPENCV" and (cam.width, cam.height) == (src.width, src.height)
    assert cam.focal_length_x == pytest.approx(src.focal_px)  # nominal, from the optics
    xs, ys = np.linspace(0, src.width - 1, 40), np.linspace(0, src.height - 1, 30)
    q = np.stack(np.meshgrid(xs, ys), axis=-1).reshape(-1, 2)
    x = cam.cam_from_img(q + 0.5)  # COLMAP's pixel convention: the top-left pixel's centre at (0.5, 0.5)
    rms, mxe = mod_h(x, src.model.undistort_points(q))
    _agrees(rms, mxe, fig["conversion"])
    assert "camera matrix: nominal" in runs["colmap"].path.read_text()


def test_kalibr_by_its_documented_equations(both):
    # no Kalibr installed: the file parsed by PyYAML, the camera evaluated with Kalibr's equations
    src, runs = both
    fig = _ok(runs["kalibr"])
    p, dm, k, cam = kalibr_camera(runs["kalibr"].path.read_bytes())
    assert dm in ("radtan", "equidistant") and cam["resolution"] == [src.width, src.height]
    name = {"radtan": "radtan", "equidistant": "equi"}[dm]
    assert any(n.startswith(f"kalibr: pinhole-{name}") for n in fig["notes"])  # the closer of the two
    assert p[0] == pytest.approx(src.focal_px)  # nominal, from the optics
    xs, ys = np.linspace(0, src.width - 1, 40), np.linspace(0, src.height - 1, 30)
    q = np.stack(np.meshgrid(xs, ys), axis=-1).reshape(-1, 2)
    # the model the file holds (its inverse converged); Kalibr's own keypoint undistortion stops after 5
    # Gauss-Newton / 20 fixed-point steps, which on this strong lens's equidistant file stops pixels short
    # (printed; the file says so)
    rms, mxe = mod_h(unproject(p, dm, k, q, converged=True), src.model.undistort_points(q))
    _agrees(rms, mxe, fig["conversion"])
    rms_k, mxe_k = mod_h(unproject(p, dm, k, q), src.model.undistort_points(q))
    print(
        f"\nkalibr pinhole-{name}: converged RMS {rms:.4f} / max {mxe:.4f} px; Kalibr's step count RMS {rms_k:.4f} / max {mxe_k:.4f} px"
    )
    assert "Kalibr's keypoint undistortion" in runs["kalibr"].path.read_text()


def test_basalt_by_its_documented_equations(both):
    # no Basalt installed: the file parsed by the json module, the camera evaluated with Basalt's kb4 equations
    src, runs = both
    fig = _ok(runs["basalt"])
    p, res, value0 = basalt_camera(runs["basalt"].path.read_bytes())
    assert res == [src.width, src.height] and value0["harp_station"]["statement"][0].startswith("conversion error")
    xs, ys = np.linspace(0, src.width - 1, 40), np.linspace(0, src.height - 1, 30)
    q = np.stack(np.meshgrid(xs, ys), axis=-1).reshape(-1, 2)
    rms, mxe = mod_h(basalt_normalised(basalt_unproject(p, q, steps=50)), src.model.undistort_points(q))
    _agrees(rms, mxe, fig["conversion"])


def test_metashape_by_its_documented_equations(both):
    # no Metashape installed: the XML parsed by ElementTree, the camera evaluated with the manual's equations
    src, runs = both
    fig = _ok(runs["metashape"])
    proj, w, h, p = metashape_camera(runs["metashape"].path.read_bytes())
    assert (w, h) == (src.width, src.height) and any(n.startswith(f"metashape: {proj}") for n in fig["notes"])
    xs, ys = np.linspace(0, src.width - 1, 40), np.linspace(0, src.height - 1, 30)
    q = np.stack(np.meshgrid(xs, ys), axis=-1).reshape(-1, 2)
    rms, mxe = mod_h(metashape_unproject(proj, w, h, p, q + 0.5), src.model.undistort_points(q))
    _agrees(rms, mxe, fig["conversion"])
    assert "camera matrix: nominal" in runs["metashape"].path.read_text()


def test_lensfun_finds_the_lens_by_its_names_at_the_crop_factor(both):
    src, runs = both
    fig = _ok(runs["lensfun"])
    text = runs["lensfun"].path.read_text()
    cam, lens, p, q = lensfun_in_consumer(text, src.camera, src.lens, src.focal_mm, src.width, src.height)
    assert cam.crop_factor == pytest.approx(src.crop) and cam.mount == src.mount and lens.mounts == [src.mount]
    rms, mxe = compare_points(src.model, p, q, src.width, src.height)
    _agrees(rms, mxe, fig["conversion"])
    assert f"focus setting {src.focus:g}" in text


def test_maps_give_harp_undistorts_image(both, tmp_path):
    src, runs = both
    fig = _ok(runs["maps"])
    assert fig["conversion"]["max_mod_h_px"] < 0.01
    shot = next(iter(src.shots), None) or next((src.model_file.parents[1] / "frames").glob("*.png"))
    assert run_main("undistort", src.model_file, shot, "-o", tmp_path)[0] == 0
    theirs = cv2.imread(str(tmp_path / shot.name), cv2.IMREAD_UNCHANGED)
    with np.load(runs["maps"].path) as z:
        map_x, map_y = z["map_x"], z["map_y"]
    img = cv2.imread(str(shot), cv2.IMREAD_UNCHANGED)
    ours = cv2.remap(img, map_x, map_y, cv2.INTER_LANCZOS4, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    assert np.array_equal(ours, theirs)


def test_stmap_in_openexr_holds_the_exact_projection(both):
    import OpenEXR

    src, runs = both
    _ok(runs["stmap"])
    head = subprocess.run(["exrheader", str(runs["stmap"].path)], capture_output=True, text=True, check=True).stdout
    assert "R, 32-bit floating-point" in head and "Nuke" in head
    with OpenEXR.File(str(runs["stmap"].path), separate_channels=True) as f:
        r, g = f.channels()["R"].pixels, f.channels()["G"].pixels
    px = np.array([[0, 0], [src.width - 1, src.height - 1], [120, 77], [src.width - 1, 0]])
    exact = src.model.distort_points(px.astype(np.float64))
    for (x, y), (sx, sy) in zip(px, exact):
        assert r[y, x] == pytest.approx((sx + 0.5) / src.width, abs=3e-5)
        assert g[y, x] == pytest.approx(1 - (sy + 0.5) / src.height, abs=3e-5)


def test_json_is_the_whole_record_with_the_optics(both):
    src, runs = both
    _ok(runs["json"])
    doc = json.loads(runs["json"].path.read_text())
    assert doc["model"] == src.model.to_dict() and doc["image"] == {"width": src.width, "height": src.height}
    assert doc["provenance"]["optics"]["focal_mm"] == src.focal_mm
    assert doc["provenance"]["optics"]["crop_factor"] == src.crop


def test_every_export_states_its_residual_on_the_fitting_shots(both):
    src, runs = both
    for fmt, run in runs.items():
        if fmt == "json":
            continue
        fig = _ok(run)
        c = fig["conversion"]
        assert fig["fitting_shots"]["used"] and fig["fitting_shots"]["n_shots"] == (len(src.shots) or 4), fmt
        assert c["shots_d_px"] is not None and c["model_shots_d_px"] is not None, fmt
        # an export is never straighter than the harp correction by more than noise, nor much worse
        # than its conversion error allows
        assert c["shots_d_px"] <= np.hypot(c["model_shots_d_px"], 2 * c["d_px"]) + 1e-3, (fmt, c)
    text = runs["opencv"].path.read_text()
    assert "residual on the fitting shots" in text


def test_the_fitting_shots_are_what_the_session_fitted(session_source, profile_exported):
    src, _ = session_source
    fig = _ok(profile_exported["opencv"])
    assert fig["fitting_shots"]["source"] == "the session's stored measurements (4 shots at focus 0)"
    # the harp correction on the edges found is the fit d the session recorded
    fit_d = yaml.safe_load(src.model_file.read_text())["merit"]["fit"]["d"]
    # (within 5 %: the fit's figure leaves out the edges it rejected as outliers)
    assert fig["conversion"]["model_shots_d_px"] == pytest.approx(fit_d, rel=0.05)
    assert fig["holdout_d"] == yaml.safe_load(src.model_file.read_text())["merit"]["holdout"]["d"]


def test_a_warning_exactly_when_the_export_is_less_exact_than_the_calibration(both):
    src, runs = both
    warned = set()
    for fmt, run in runs.items():
        fig = _ok(run)
        lines = run.err.splitlines()
        assert len(lines) == len(fig["warnings"]) and all(ln.startswith("harp ") for ln in lines), fmt
        if fig["conversion"] is None:
            assert not lines
            continue
        c = fig["conversion"]
        worse = max(c["rms_mod_h_px"], c["d_px"]) > fig["holdout_d"]
        readers = fmt == "ros-equidistant"  # and one warning naming the ROS consumers that read the file
        assert (fig["warnings"][-1:] == [ROS_EQUIDISTANT_READERS]) == readers, fmt
        assert (len(fig["warnings"]) > readers) == worse, (fmt, c, fig["holdout_d"])
        if worse:
            assert "exceeds the model's own holdout d" in lines[0]
            warned.add(fmt)
    if src.shots:  # lensfun and the fisheye model have no decentering or thin-prism terms
        assert {"lensfun", "opencv-fisheye", "ros-equidistant"} <= warned
        assert "opencv" not in warned and "mrcal" not in warned


# ---------------------------------------------------------- harp evaluate
def _lens_on_its_corrected_image(shots) -> float:
    """d of LENS (4-corner normalised) on the edge points of ``shots`` it corrects to inside the
    image: those a maps file holds."""
    kept = []
    for p in shots:
        for ln in measure_image(cv2.imread(str(p), cv2.IMREAD_UNCHANGED), t=30).lines:
            u = LENS.undistort_points(ln.points)
            ok = (u[:, 0] >= 0) & (u[:, 0] <= W - 1) & (u[:, 1] >= 0) & (u[:, 1] <= H - 1)
            if ok.sum() >= 3:
                kept.append(ln.points[ok])
    return float(straightness(corrected_points(kept, LENS, W, H)).d)


def test_harp_evaluate_reads_every_format(model_source, exported):
    def evaluate(path, *extra):
        code, out, err = run_main("evaluate", path, *model_source.shots, "--json", *extra)
        assert code == 0, err
        return json.loads(out)

    floor = evaluate(model_source.model_file)
    assert floor["kind"] == "harp:radial" and floor["before"]["d"] > 0.5
    kinds = {
        "opencv": "opencv",
        "opencv-fisheye": "opencv-fisheye",
        "ros": "ros",
        "ros-equidistant": "ros-equidistant",
        "lensfun": "lensfun:ptlens",
        "mrcal": "mrcal",
        "colmap": "colmap:FULL_OPENCV",
        "kalibr": "kalibr:pinhole-equi",  # 4 radial-tangential coefficients hold this lens less well
        "basalt": "basalt:kb4",
        "metashape": "metashape:frame",
        "maps": "maps",
        "stmap": "stmap",
        "json": "harp:radial",
        "auto": "opencv",
    }
    for fmt, run in exported.items():
        rep = evaluate(run.path)
        assert rep["kind"] == kinds[fmt] and rep["before"] == floor["before"], fmt
        after = rep["after"]["d"]
        if fmt in ("json",):
            assert after == floor["after"]["d"]
        elif fmt in ("maps", "stmap"):  # the correction itself on the points the maps hold
            assert rep["n_excluded"] > 0 and rep["n_points"] == floor["n_points"], fmt
            assert abs(after - _lens_on_its_corrected_image(model_source.shots)) < 1e-3, (fmt, after)
        else:  # the file holds what the export stated for these very shots
            assert after == pytest.approx(run.fig["conversion"]["shots_d_px"], abs=2e-5), fmt


# ------------------------------------------------------ warnings, lenses
def test_text_output_and_the_warning_when_less_exact_than_the_calibration(model_source, tmp_path):
    out = tmp_path / "lf.xml"
    code, stdout, stderr = run_main("export", model_source.model_file, "--format", "lensfun", "-o", out, "--no-shots")
    assert code == 0 and out.is_file()
    lines = stdout.splitlines()
    assert lines[0] == f"wrote {out} (lensfun)" and lines[1].startswith("conversion error (lensfun): RMS ")
    assert "not stated on the fitting shots (not measured (--no-shots))" in lines[2]
    # lensfun has no decentering or thin-prism terms: less exact than this lens' holdout d
    (warning,) = stderr.splitlines()
    assert lines[3].startswith("added lens Canon EF-S 10-18mm")
    assert warning.startswith("harp export: warning: lensfun: the conversion error") and "holdout d" in warning


def test_the_pinhole_export_to_stdout_keeps_stdout_the_file(model_source):
    code, stdout, stderr = run_main(
        "export", model_source.model_file, "--format", "ros", "--coeffs", "5", "--no-shots", "--camera-name", "cam0"
    )
    assert code == 0
    doc = yaml.safe_load(stdout)
    assert doc["distortion_model"] == "plumb_bob" and doc["camera_name"] == "cam0"
    assert "conversion error (ros): RMS" in stderr


def test_lensfun_database_holds_several_lenses(model_source, exported, tmp_path):
    db = tmp_path / "db.xml"
    db.write_bytes(exported["lensfun"].path.read_bytes())
    code, stdout, _ = run_main(
        "export", model_source.model_file, "--format", "lensfun", "-o", db, "--no-shots",
        "--lens-model", "EF-S 18-55mm f/3.5-5.6", "--focal-mm", "18",
    )  # fmt: skip
    assert code == 0 and "added lens Canon EF-S 18-55mm" in stdout
    text = db.read_text()
    for model, focal in ((model_source.lens[1], 10.0), ("EF-S 18-55mm f/3.5-5.6", 18.0)):
        lensfun_in_consumer(text, model_source.camera, (model_source.lens[0], model), focal, W, H, n=4)
    # harp evaluate picks one lens of the database by its name
    code, out, err = run_main("evaluate", db, model_source.shots[0], "--json")
    assert code == 2 and "several lenses" in err
    code, out, err = run_main("evaluate", db, model_source.shots[0], "--lens", "Canon EF-S 18-55mm f/3.5-5.6", "--json")
    assert code == 0 and json.loads(out)["kind"] == "lensfun:ptlens"


# ------------------------------------------------------------- bad input
@pytest.mark.parametrize(
    "args, message",
    [
        (
            ["--format", "opencv", "--coeffs", "3", "-o", "OUT"],
            "--coeffs 3: the opencv export takes 5, 8, 12, 14 coeff",
        ),
        (["--format", "ros", "--coeffs", "12", "-o", "OUT"], "--coeffs 12: the ros export takes 5, 8 coefficients"),
        (["--format", "lensfun", "--coeffs", "5", "-o", "OUT"], "--coeffs 5: the lensfun export has no choice of"),
        (["--format", "maps"], "--format maps writes a binary file: give -o FILE.npz"),
        (["--format", "opencv", "--json"], "--json needs -o FILE"),
        (
            ["--format", "opencv", "--pixel-pitch-um", "0.0057", "-o", "OUT"],
            "--pixel-pitch-um: expected the pixel pitch",
        ),
        (["--format", "lensfun", "--focal-mm", "-3", "-o", "OUT"], "--focal-mm: expected the nominal focal length"),
        (["--format", "lensfun", "--crop", "x", "-o", "OUT"], "--crop: expected a number, got 'x'"),
        (["--format", "opencv", "--focal-px", "0", "-o", "OUT"], "--focal-px: expected a focal length > 0 px"),
        (["--format", "opencv", "--pixel-pitch-um", "5", "--sensor-width-mm", "20", "-o", "OUT"], "alternatives"),
        (["--format", "opencv", "--shots", "missing.pgm", "-o", "OUT"], "missing.pgm: no such file"),
    ],
)
def test_bad_options_exit_2_with_one_line_and_nothing_written(model_source, tmp_path, args, message):
    out = tmp_path / "out"
    args = [str(out) if a == "OUT" else a for a in args]
    code, stdout, stderr = run_main("export", model_source.model_file, *args)
    assert code == 2 and stdout == "" and not out.exists()
    assert stderr.startswith("harp export: ") and message in stderr and stderr.count("\n") == 1, stderr


def test_shots_of_another_size_than_the_model_exit_2_nothing_written(model_source, tmp_path):
    # a shot of another camera (or a crop) was measured and its residual d stated as the fitting shots'
    small = tmp_path / "small.png"
    cv2.imwrite(str(small), cv2.imread(str(model_source.model_file.parent / "shot0.pgm"), cv2.IMREAD_UNCHANGED)[:200])
    out = tmp_path / "out.yml"
    code, stdout, stderr = run_main(
        "export", model_source.model_file, "--format", "opencv", "--shots", small, "-o", out
    )
    assert code == 2 and stdout == "" and not out.exists() and stderr.count("\n") == 1, stderr
    assert stderr == (
        f"harp export: {small}: image is {W}x200 but the model {model_source.model_file} is for {W}x{H} images: "
        "give the shots the model was fitted on\n"
    )


def test_coeffs_5_on_a_wide_lens_names_the_export_family_exit_2_nothing_written(tmp_path):
    model = tmp_path / "wide.yaml"
    write_model_file(model, wide_radial(150.0, 1200, 900), width=1200, height=900)
    out = tmp_path / "out.yaml"
    code, stdout, stderr = run_main("export", model, "--format", "opencv", "--coeffs", "5", "-o", out)
    assert code == 2 and stdout == "" and not out.exists() and stderr.count("\n") == 1, stderr
    assert stderr.startswith("harp export: the OpenCV 5-coefficient pin-hole model cannot represent this lens")
    assert "--coeffs 8, 12 or 14" in stderr and "--format auto" in stderr


def test_lensfun_without_a_crop_factor_exit_2_names_what_to_give_nothing_written(tmp_path):
    """A bare model file has no optics: lensfun's crop factor cannot be derived, so nothing is guessed."""
    model = tmp_path / "bare.yaml"
    write_model_file(model, wide_radial(60.0, 400, 300), width=400, height=300)
    out = tmp_path / "lens.xml"
    code, stdout, stderr = run_main("export", model, "--format", "lensfun", "-o", out)
    assert code == 2 and stdout == "" and not out.exists() and stderr.count("\n") == 1, stderr
    assert "crop factor is not known" in stderr and "--crop FACTOR" in stderr
    # the pixel pitch is enough: 400 x 300 at 12 um is 4.8 x 3.6 mm, a 1/3" sensor (crop factor 7.2)
    code, stdout, stderr = run_main(
        "export", model, "--format", "lensfun", "--pixel-pitch-um", "12", "--focal-mm", "4", "-o", out
    )
    assert code == 0, stderr
    assert "crop factor 7.211 derived from the pixel pitch 12 um over 400x300 images" in stdout + stderr
    assert "<cropfactor>7.2111</cropfactor>" in out.read_text()


def test_lensfun_under_the_name_of_an_installed_lens_exit_2_nothing_written(tmp_path, monkeypatch):
    """lensfunpy's own database has the Canon EF 50mm f/1.8 MkII: a file under that name would replace it."""
    monkeypatch.delenv("HARP_LENSFUN_DIRS", raising=False)
    model = tmp_path / "lens.yaml"
    write_model_file(model, wide_radial(60.0, 400, 300), width=400, height=300)
    out = tmp_path / "mine.xml"
    name = ["--lens-maker", "Canon", "--lens-model", "Canon EF 50mm f/1.8 MkII", "--crop", "1", "--focal-mm", "50"]
    code, stdout, stderr = run_main("export", model, "--format", "lensfun", *name, "-o", out)
    assert code == 2 and stdout == "" and not out.exists() and stderr.count("\n") == 1, stderr
    assert "is in the installed lensfun database" in stderr and "slr-canon.xml" in stderr
    assert "--lens-model" in stderr
    # under its own name it is written; and adding to one's own database in a lensfun directory is no clash
    own = ["--lens-maker", "Canon", "--lens-model", "Canon EF 50mm f/1.8 MkII (harp SN 4711)", "--crop", "1"]
    monkeypatch.setenv("HARP_LENSFUN_DIRS", str(tmp_path))
    for _ in range(2):
        code, stdout, stderr = run_main("export", model, "--format", "lensfun", *own, "--focal-mm", "50", "-o", out)
        assert code == 0, stderr
    assert "replaced the calibration" in stderr
    other = tmp_path / "other.xml"
    code, _, stderr = run_main("export", model, "--format", "lensfun", *own, "-o", other)
    assert code == 2 and "mine.xml" in stderr and not other.exists()


def test_unwritable_output_exit_2(model_source, tmp_path):
    code, _, stderr = run_main(
        "export", model_source.model_file, "--format", "json", "-o", tmp_path / "no" / "such" / "dir.json"
    )
    assert code == 2 and stderr.startswith("harp export: cannot write ") and stderr.count("\n") == 1


@pytest.mark.parametrize(
    "content, reason",
    [
        ("format: harp-distortion-model\nformat_version: 2\n", "unknown model file format version 2"),
        ("{{{{", "not a valid YAML"),
    ],
)
def test_bad_model_exit_2(tmp_path, content, reason):
    p = tmp_path / "m.yaml"
    p.write_text(content)
    code, _, err = run_main("export", p, "--format", "opencv")
    assert code == 2 and err.startswith(f"harp export: {p}: ") and reason in err and err.count("\n") == 1


@pytest.mark.parametrize(
    "field, value, reason",
    [
        ("center", [600.0], "invalid parameters for model 'radial' (RadialModel center needs (x, y), got 1 values)"),
        ("tangential", [1e-4, 2e-4, 3e-4], "RadialModel tangential needs (p1, p2), got 3 values"),
        ("prism", [1e-4], "RadialModel prism needs (s1, s2, s3, s4), got 1 values"),
        ("k", [1.0, float("nan")], "model.k[1] is nan; every parameter of the model must be a finite number"),
        ("center", [float("inf"), 300.0], "model.center[0] is inf; every parameter of the model must be a finite"),
    ],
)
def test_a_model_parameter_damaged_by_hand_is_one_line_naming_the_file(tmp_path, field, value, reason):
    # a centre of one value was "internal error: IndexError: tuple index out of range"; three tangential
    # terms "zip() argument 2 is shorter than argument 1" (no file named); a NaN "our correction is
    # undefined over much of the image" (export) or "the correction is not defined at the image corners"
    model = tmp_path / "lens.yaml"
    lens = RadialModel(center=(599.5, 449.5), k=(1.0, 0.02), scale=750.0, tangential=(1e-4, 2e-4), prism=(0,) * 4)
    write_model_file(model, lens, width=1200, height=900)
    doc = yaml.safe_load(model.read_text())
    doc["model"][field] = value
    model.write_text(yaml.safe_dump(doc))
    image = tmp_path / "shot.png"
    cv2.imwrite(str(image), np.full((900, 1200), 128, np.uint8))
    out = tmp_path / "out"
    for argv in (
        ["export", model, "--format", "opencv", "-o", out / "lens.yml"],
        ["undistort", model, image, "-o", out],
        ["evaluate", model, image],
    ):
        code, stdout, stderr = run_main(*argv)
        assert code == 2 and stdout == "" and stderr.count("\n") == 1, (argv, stderr)
        assert stderr.startswith(f"harp {argv[0]}: {model}: ") and reason in stderr, (argv, stderr)
    assert not out.exists()


def test_profile_export_errors_are_one_line(session_source):
    _, store = session_source
    code, _, err = run_main("profile", "export", "DEMO-0001", "--focus", "1.5", "--format", "ros", "--store", store)
    assert code == 2 and err.count("\n") == 1 and "not between two calibrated focus settings" in err
    code, _, err = run_main(
        "profile", "export", "DEMO-0001", "--focus", "0", "--format", "ros", "--coeffs", "14", "--store", store
    )
    assert code == 2 and err.startswith("harp profile: ") and "--coeffs 14" in err and err.count("\n") == 1


def test_profile_export_between_focus_settings_has_the_optics_but_no_fitting_shots(session_source, tmp_path):
    src, store = session_source
    out = tmp_path / "mid.yaml"
    code, stdout, err = run_main(
        "profile", "export", "DEMO-0001", "--focus", "0.5", "--format", "ros", "-o", out, "--store", store, "--json"
    )
    assert code == 0, err
    fig = json.loads(stdout)
    assert not fig["fitting_shots"]["used"] and "interpolated" in fig["fitting_shots"]["source"]
    got = ros_in_consumer(out)
    assert got["camera_name"] == src.ros_name and got["K"][0] == pytest.approx(src.focal_px)


def test_opencv_xml_from_the_option_or_the_file_name():
    from station.cli import build_parser
    from station.cli.export import export_options

    parser = build_parser()
    for argv, xml in ((["-o", "lens.xml"], True), (["--xml"], True), (["-o", "lens.yml"], False)):
        args = parser.parse_args(["export", "m.yaml", "--format", "opencv", *argv])
        assert export_options(args).xml is xml


# ------------------------------------------------- where the fitting shots come from
def test_fitting_shots_from_the_model_files_images_only_when_unchanged(model_source, tmp_path):
    import shutil

    from station.export_source import fitting_edges

    profile = Profile.from_model_file(read_model_file(model_source.model_file))
    got = fitting_edges(profile)
    assert got.n_shots == 2 and len(got.edges) > 10 and "shot0.pgm, shot1.pgm" in got.source
    # moved with the model file: found beside it
    moved = tmp_path / "moved"
    moved.mkdir()
    for p in (model_source.model_file, *model_source.shots):
        shutil.copy(p, moved / p.name)
    far = profile.with_(
        provenance=replace(
            profile.provenance, images=tuple((f"elsewhere/{Path(p).name}", sha) for p, sha in profile.provenance.images)
        )
    )
    assert fitting_edges(far, moved).n_shots == 2
    assert fitting_edges(far).source == "fitting shot elsewhere/shot0.pgm is no longer there"
    (moved / "shot1.pgm").write_bytes((moved / "shot0.pgm").read_bytes())
    got = fitting_edges(far, moved)
    assert got.edges is None and got.source.endswith("shot1.pgm changed since the calibration (SHA-256 differs)")


def test_fitting_shots_from_a_session_only_with_the_manifests_checksums(session_source, tmp_path):
    import shutil

    from station.export_source import session_edges

    src, _ = session_source
    session = src.model_file.parents[1]
    assert session_edges(session, 0.0).n_shots == 4
    assert "no focus setting 0.5" in session_edges(session, 0.5).source
    copy = tmp_path / "s"
    shutil.copytree(session, copy)
    victim = sorted((copy / "measurements").glob("f0_*.npz"))[0]
    victim.write_bytes(victim.read_bytes()[:-10] + b"0123456789")
    got = session_edges(copy, 0.0)
    assert got.edges is None and got.source == f"{victim}: checksum does not match the session manifest"


def test_a_sessions_twin_is_not_among_its_fitting_shots(tmp_path):
    """A session's twin (``capture.twin_deg``) is compared, not fitted: the residual an export states on the
    fitting shots is on the four shots the fit took. Before, the twin's edges were among them ("the session's stored
    measurements (5 shots at focus 0)"), a shot the correction never saw (on a lens that moves between poses the
    stated figure was then up to 12 % off the fit's). Truth: the manifest's ``measure`` records, one per shot with
    its edge count, and the plan's orientations (the twin is the fifth)."""
    from station.export_source import session_edges

    d = yaml.safe_load((REPO / "configs" / "demo.yaml").read_text())
    d["station"]["camera"].update(width=SW, height=SH, spacing_px=28.0)
    d["focus"]["settings"] = [0.0]
    d["capture"].update(orientations_deg=[0, 45, 90, 135], frames_per_orientation=1, twin_deg=45)
    d["pipeline"].update(bootstrap=0, workers=1)
    d["store"] = {"path": "profiles.sqlite", "sessions_dir": "sessions"}
    cfg = tmp_path / "station.yaml"
    cfg.write_text(yaml.safe_dump(d))
    code, _, err = run_main("session", "run", cfg, "--name", "s", "--quiet", "--no-report")
    assert code == 0, err
    session = tmp_path / "sessions" / "s"
    records = [json.loads(ln) for ln in (session / "manifest.jsonl").read_text().splitlines()]
    lines = {r["orientation_idx"]: r["n_lines"] for r in records if r["kind"] == "measure"}
    assert sorted(lines) == [0, 1, 2, 3, 4]  # orientation 4: the twin, measured too
    got = session_edges(session, 0.0)
    assert got.n_shots == 4 and got.source == "the session's stored measurements (4 shots at focus 0)"
    assert got.edges is not None and len(got.edges) == sum(lines[o] for o in range(4))
    out = tmp_path / "lens.yml"
    code, stdout, err = run_main(
        "export", session / "profiles" / "focus0.yaml", "--format", "opencv", "-o", out, "--json"
    )
    assert code == 0, err
    fitting = json.loads(stdout)["fitting_shots"]
    assert fitting["n_shots"] == 4 and fitting["source"] == got.source


def test_ros_equidistant_file_and_export_state_which_ros_consumers_read_it(model_source, tmp_path):
    """ROS 1's Python image_geometry ignores distortion_model (checked below in Debian's own package):
    the file says so in its header and the export warns on stderr."""
    out = tmp_path / "eq.yaml"
    code, _stdout, stderr = run_main("export", model_source.model_file, "--format", "ros-equidistant", "-o", out)
    assert code == 0, stderr
    head = [ln for ln in out.read_text().splitlines() if ln.startswith("#")]
    assert any("'equidistant' is read by the C++ image_geometry" in ln and "plumb_bob" in ln for ln in head)
    assert "harp export: warning: distortion_model 'equidistant'" in stderr
    src = Path("/usr/lib/python3/dist-packages/image_geometry/cameramodels.py")  # Debian python3-image-geometry
    assert src.exists() and "equidistant" not in src.read_text()  # the statement about ROS 1 Python holds
    plain = tmp_path / "pin.yaml"
    code, _o, stderr = run_main("export", model_source.model_file, "--format", "ros", "-o", plain)
    assert code == 0 and "equidistant" not in plain.read_text() and "'equidistant' is read" not in stderr


def test_lensfun_type_choices_are_the_models_types_and_a_wide_lens_is_exported_as_fisheye(tmp_path):
    from pipeline.models.lensfun_model import LENSFUN_TYPES
    from station.cli.export import LENSFUN_TYPE_CHOICES

    assert LENSFUN_TYPE_CHOICES == ("auto", *LENSFUN_TYPES)
    model = tmp_path / "wide.yaml"
    write_model_file(model, wide_radial(115.0, 640, 480), width=640, height=480)
    out = tmp_path / "fish.xml"
    focal = 0.5 * math.hypot(639, 479) / (2 * math.sin(math.radians(115 / 2) / 2)) * 3e-3  # wide_radial's f at 3 um
    args = ["--pixel-pitch-um", "3", "--focal-mm", f"{focal:.6f}", "-o", out]
    code, stdout, stderr = run_main("export", model, "--format", "lensfun", *args)
    assert code == 0, stderr
    # a fisheye type (which one fits a degree-6 approximation of an equisolid lens best is the fit's to say)
    written = re.search(r"<type>(\w+)</type>", out.read_text())
    assert written is not None and written[1] != "rectilinear" and f"lens type {written[1]}" in stdout + stderr
    code, _, stderr = run_main("export", model, "--format", "lensfun", "--lensfun-type", "rectilinear", *args)
    assert code == 0 and "<type>" not in out.read_text()
