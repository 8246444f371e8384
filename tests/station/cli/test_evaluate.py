"""``harp evaluate``: residual distortion of any correction; the OpenCV export round trip."""

import json
import os
import re
import signal
import subprocess
import sys

import cv2
import numpy as np
import pytest

from pipeline.evaluate import corrected_points
from pipeline.exports.fit import fit_opencv
from pipeline.exports.lensfun import lensfun_text
from pipeline.exports.opencv import opencv_text
from pipeline.exports.ros import ros_text
from pipeline.exports.statement import Statement
from pipeline.models import LensfunModel, RadialModel
from pipeline.render import HarpScene, render_harp
from pipeline.resample import DEFAULT_T
from pipeline.straightness import straightness
from station.cli import main
from station.files import write_model_file
from station.inputs import measure_grey, read_image
from tests.pipeline.export_support import wide_radial

W, H = 640, 480
# barrel lens with an odd radial term: OpenCV's even polynomial cannot represent it exactly
LENS = RadialModel.for_image(W, H, k=(1.0, 0.03, 0.05))


@pytest.fixture(scope="module")
def shots(tmp_path_factory):
    d = tmp_path_factory.mktemp("shots")
    paths = []
    for i, angle in enumerate((3.0, 93.0)):
        r = render_harp(W, H, HarpScene(angle_deg=angle, spacing_px=40.0), lens=LENS, noise_sigma=1.5, seed=10 + i)
        p = d / f"shot{i}.pgm"
        assert cv2.imwrite(str(p), r.image)
        paths.append(str(p))
    return paths


def run_json(capsys, *argv):
    code = main(["evaluate", *map(str, argv), "--json"])
    out = capsys.readouterr()
    assert code == 0, out.err
    return json.loads(out.out)


def test_opencv_round_trip_residual_matches_stated_conversion_error(tmp_path, shots, capsys):
    """Export the true lens to OpenCV YAML; evaluating that file on the shots leaves the stated error.

    Noise floor: the same shots corrected by the true lens (``d_floor``). The
    export's stated residual on a noise-free harp is ``err.d_px``; residual
    and measurement noise add in quadrature, so the measured ``after`` must be
    ``sqrt(d_floor^2 + d_px^2)`` to within half the 0.01 px bar.
    """
    true_file = tmp_path / "true.yaml"
    write_model_file(true_file, LENS, width=W, height=H)
    cv_model, err = fit_opencv(LENS, W, H, n_coeffs=5)
    cv_file = tmp_path / "opencv.yaml"
    cv_file.write_text(opencv_text(cv_model, W, H, Statement(err)))
    assert err.d_px > 0.015  # the export really cannot represent this lens: the test can tell

    floor = run_json(capsys, true_file, *shots)
    rep = run_json(capsys, cv_file, *shots)
    assert rep["kind"] == "opencv" and floor["kind"] == "harp:radial"
    assert rep["before"] == floor["before"] and rep["before"]["d"] > 0.5  # uncorrected lens
    d_floor, d_after = floor["after"]["d"], rep["after"]["d"]
    assert d_floor < 0.012
    expected = float(np.hypot(d_floor, err.d_px))
    assert abs(d_after - expected) < 0.005, (d_after, expected, d_floor, err.d_px)
    assert d_after > d_floor + 0.01
    assert [im["n_lines"] for im in rep["images"]] == [im["n_lines"] for im in floor["images"]]

    # OpenCV's own code path: its maps from the exported file correct the images; measured as they are
    fs = cv2.FileStorage(str(cv_file), cv2.FILE_STORAGE_READ)
    k, dist = fs.getNode("camera_matrix").mat(), fs.getNode("distortion_coefficients").mat()
    fs.release()
    mx, my = cv2.initUndistortRectifyMap(k, dist, None, k, (W, H), cv2.CV_32FC1)
    corrected = []
    for p in shots:
        q = tmp_path / ("cv_" + p.rsplit("/", 1)[-1])
        cv2.imwrite(str(q), cv2.remap(cv2.imread(p, cv2.IMREAD_UNCHANGED), mx, my, cv2.INTER_LANCZOS4))
        corrected.append(q)
    by_opencv = run_json(capsys, "none", *corrected, "--already-corrected")
    assert abs(by_opencv["after"]["d"] - expected) < 0.005, (by_opencv["after"]["d"], expected)

    # with 8 coefficients the conversion is ~exact: the residual is the noise floor
    cv8, err8 = fit_opencv(LENS, W, H, n_coeffs=8)
    assert err8.d_px < 0.002
    ros_file = tmp_path / "camera_info.yaml"
    ros_file.write_text(ros_text(cv8, W, H, Statement(err8)))
    rep8 = run_json(capsys, ros_file, *shots)
    assert rep8["kind"] == "ros"
    assert abs(rep8["after"]["d"] - d_floor) < 0.002


def test_table_output_lensfun_and_already_corrected(tmp_path, shots, capsys):
    lf = tmp_path / "lens.xml"
    lf.write_text(lensfun_text(LensfunModel(kind="poly5", terms=(0.0, 0.0), width=W, height=H)))
    # an identity lensfun correction leaves the distortion: after == before (up to the corner homography)
    code = main(["evaluate", str(lf), shots[0]])
    out = capsys.readouterr().out
    assert code == 0 and "lensfun:poly5" in out and "shot0.pgm" in out and out.splitlines()[-1].startswith("all")
    rep = run_json(capsys, lf, shots[0])
    assert rep["after"]["d"] == pytest.approx(rep["before"]["d"], rel=1e-6)
    # images measured as they are; no correction known
    measured = rep["before"]
    rep = run_json(capsys, "none", shots[0], "--already-corrected")
    assert rep["kind"] == "none" and rep["before"] is None
    assert rep["after"] == measured


@pytest.mark.parametrize(
    "content, message",
    [
        ("format: harp-distortion-model\nformat_version: 99\n", "unknown model file format version 99"),
        ("format: harp-distortion-model\nformat_version: 1\nmodel: [\n", "not a valid YAML"),
        ("hello: world\n", "not a recognised correction"),
        ("<lensdatabase><lens><model>x</model></lens></lensdatabase>", "no <calibration><distortion>"),
        ('{"value0": {"intrinsics": [{"camera_type": "eucm"}]}}', "Basalt camera_type 'eucm' not read"),
        ("<calibration><projection>frame</projection><width>8</width></calibration>", "without <height>"),
    ],
)
def test_bad_correction_files_exit_2_with_one_line(tmp_path, shots, capsys, content, message):
    p = tmp_path / "bad.yaml"
    p.write_text(content)
    assert main(["evaluate", str(p), shots[0]]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("harp evaluate: ") and message in err and "\n" not in err


def _first_number_replaced(text: str, after: str, by: str) -> str:
    """``text`` with the first number after the first ``after`` replaced by ``by``."""
    at = text.index(after) + len(after)
    head, tail = text[:at], text[at:]
    return head + re.sub(r"-?\d+\.\d+(?:e[-+]?\d+)?", by, tail, count=1)


@pytest.mark.parametrize(
    "fmt, name, damage, message",
    [
        # was "internal error: error: OpenCV(5.1.0) .../persistence.cpp:2884: error: (-2:Unspecified error) readRawData ..."
        (
            "opencv",
            "lens.yml",
            lambda t: _first_number_replaced(t, "camera_matrix", "abc").encode(),
            "not a readable OpenCV FileStorage file (readRawData can only be used to read plain sequences of numbers)",
        ),
        # were numpy's RuntimeWarnings (four lines with the source) before the one line
        (
            "kalibr",
            "camchain.yaml",
            lambda t: _first_number_replaced(t, "distortion_coeffs", "inf").encode(),
            "model's distortion_coefficients[0] as read from this kalibr file); every parameter must be a finite number",
        ),
        # was "harp evaluate: lensfun coord_scale must be > 0, got nan" (no file)
        (
            "lensfun",
            "lens.xml",
            lambda t: _first_number_replaced(t, "<aspect-ratio>", "nan").encode(),
            "lensfun coord_scale must be > 0, got nan",
        ),
        # was OpenEXR's own line on the C stderr, then "harp evaluate: Invalid part index '0': file has 0 parts."
        ("stmap", "lens.exr", None, "not a readable OpenEXR file (Invalid part index '0': file has 0 parts.)"),
    ],
)
def test_a_damaged_export_is_one_line_naming_the_file(tmp_path, shots, capfd, fmt, name, damage, message):
    model = tmp_path / "lens.yaml"
    write_model_file(model, LENS, width=W, height=H)
    exported = tmp_path / name
    assert main(["export", str(model), "--format", fmt, "--crop", "1", "--focal-mm", "8", "-o", str(exported)]) == 0
    data = exported.read_bytes()
    exported.write_bytes(damage(data.decode()) if damage else data[: len(data) // 2])
    capfd.readouterr()
    assert main(["evaluate", str(exported), shots[0]]) == 2
    out, err = capfd.readouterr()  # the file descriptors: what a codec prints there too
    assert out == "" and err.count("\n") == 1, err
    assert err.startswith(f"harp evaluate: {exported}: ") and message in err, err


def test_size_mismatch_and_missing_image_exit_2(tmp_path, shots, capsys):
    m = tmp_path / "m.yaml"
    write_model_file(m, LENS, width=W + 2, height=H)
    assert main(["evaluate", str(m), shots[0]]) == 2
    assert f"model is for {W + 2}x{H} images, the shots are {W}x{H}" in capsys.readouterr().err
    assert main(["evaluate", str(m), str(tmp_path / "missing.pgm")]) == 2
    assert "missing.pgm: no such file" in capsys.readouterr().err


def test_bad_shots_are_named_and_the_others_still_evaluated(tmp_path, shots, capsys):
    m = tmp_path / "m.yaml"
    write_model_file(m, LENS, width=W, height=H)
    blank = tmp_path / "blank.png"
    cv2.imwrite(str(blank), np.full((H, W), 200, np.uint8))
    small = tmp_path / "small.png"
    cv2.imwrite(str(small), np.full((H // 2, W // 2), 200, np.uint8))
    missing = tmp_path / "missing.pgm"
    code = main(["evaluate", str(m), shots[0], str(missing), str(blank), str(small), shots[1], "--json"])
    out, err = capsys.readouterr()
    assert code == 2
    rep = json.loads(out)
    measured = [e["path"] for e in rep["images"] if e["after"] is not None]
    assert measured == [shots[0], shots[1]] and rep["after"]["d"] < 0.01
    lines = err.strip().splitlines()
    assert len(lines) == 3 and all(ln.startswith("harp evaluate: ") for ln in lines)
    for path, reason in ((missing, "no such file"), (blank, "no strings found"), (small, "same size")):
        assert sum(str(path) in ln and reason in ln for ln in lines) == 1, (path, lines)
    assert {e["path"] for e in rep["errors"]} == {str(missing), str(blank), str(small)}


def test_none_without_already_corrected_says_what_is_missing(shots, capsys):
    assert main(["evaluate", "none", shots[0]]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "--already-corrected" in err


# ------------------------------------------------ maps and STMap of a wide lens (issue 20 item 5)
def harp_subprocess(*args, timeout=300):
    """``harp ARGS`` as a user runs it (its own process group, killed with it on every exit path)."""
    proc = subprocess.Popen(
        [sys.executable, "-m", "station.cli", *map(str, args)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
    )
    try:
        out, err = proc.communicate(timeout=timeout)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    return proc.returncode, out, err


@pytest.mark.parametrize("fov", [115.0, 93.0])
def test_maps_and_stmap_of_a_wide_lens_are_not_extrapolated(tmp_path, fov):
    """The maps of a wide lens hold the corrected image only: the edge points near the shots'
    borders have no ideal position in them. harp evaluate leaves those out and says how many (the
    truth: the points the lens itself corrects to outside [0, W-1] x [0, H-1]), and the figure of
    the maps / STMap is the lens's own on the points kept, in the same 4-corner frame (before the
    fix it extrapolated the maps: 0.63 px for 0.023)."""
    lens = wide_radial(fov, W, H)
    paths = []
    for i, angle in enumerate((3.0, 93.0)):
        r = render_harp(W, H, HarpScene(angle_deg=angle, spacing_px=40.0), lens=lens, noise_sigma=1.5, seed=20 + i)
        p = tmp_path / f"wide{i}.pgm"
        assert cv2.imwrite(str(p), r.image)
        paths.append(p)
    model_file = tmp_path / "lens.yaml"
    write_model_file(model_file, lens, width=W, height=H)
    reports = {}
    for fmt, name in (("maps", "m.npz"), ("stmap", "m.exr")):
        code, _out, err = harp_subprocess("export", model_file, "--format", fmt, "-o", tmp_path / name)
        assert code == 0, err
        code, out, err = harp_subprocess("evaluate", tmp_path / name, *paths, "--json")
        assert code == 0, err
        reports[fmt] = json.loads(out)
    code, out, err = harp_subprocess("evaluate", tmp_path / name, *paths)
    assert code == 0 and "edge points left out: outside the area the correction defines" in out, out
    code, out, err = harp_subprocess("evaluate", model_file, *paths, "--json")
    assert code == 0, err
    whole = json.loads(out)
    assert whole["n_excluded"] == 0 and whole["n_points"] > 0

    # truth: the lens's own evaluation on the edge points its corrected image holds
    edges = [ln.points for p in paths for ln in measure_grey(str(p), read_image(str(p)), DEFAULT_T).lines]
    kept, n_out = [], 0
    for e in edges:
        u = lens.undistort_points(e)
        ok = (u[:, 0] >= 0) & (u[:, 0] <= W - 1) & (u[:, 1] >= 0) & (u[:, 1] <= H - 1)
        if ok.sum() >= 3:
            kept.append(e[ok])
            n_out += int((~ok).sum())
        else:
            n_out += len(e)
    truth = straightness(corrected_points(kept, lens, W, H))
    assert n_out > 0.2 * whole["n_points"]  # a wide lens: the maps miss much of the shots
    for fmt, rep in reports.items():
        assert rep["kind"] == fmt and rep["n_points"] == whole["n_points"]
        assert rep["normalisation"] == "4 corrected image corners"
        assert abs(rep["n_excluded"] - n_out) <= 0.002 * rep["n_points"], (fmt, rep["n_excluded"], n_out)
        assert rep["n_lines"] == len(kept)
        assert rep["after"]["d"] == pytest.approx(truth.d, rel=0.01), (fmt, rep["after"], truth)
        assert rep["after"]["d_max"] == pytest.approx(truth.d_max, rel=0.02), (fmt, rep["after"], truth)
        assert rep["before"] == whole["before"]


def test_the_residual_is_split_into_what_every_string_shares_and_each_edges_own(tmp_path, shots, capsys):
    """Corrected by the true lens, what is left is the measurement's noise: each edge's own, not shared;
    the two parts add up to the shot's d, and the table shows them."""
    true_file = tmp_path / "true.yaml"
    write_model_file(true_file, LENS, width=W, height=H)
    rep = run_json(capsys, true_file, shots[0])
    sb = rep["images"][0]["after_shared"]
    assert sb["n_edges"] >= 4 and sb["shared_px"] < 0.5 * sb["own_px"]
    assert np.hypot(sb["shared_px"], sb["own_px"]) == pytest.approx(rep["images"][0]["after"]["d"], rel=0.25)
    assert main(["evaluate", str(true_file), shots[0]]) == 0
    header, row = capsys.readouterr().out.splitlines()[1:3]
    cols = dict(zip(header.split("\t"), row.split("\t")))
    assert cols["shared after (px)"] == f"{sb['shared_px']:.4f}" and cols["own after (px)"] == f"{sb['own_px']:.4f}"
