"""``harp vignetting``: rendered 16-bit harp shots with a known vignetting and an uneven back-light
that turns with the harp, written as PNG files and read back by the command.

Truth: the closed-form relative illumination (cos^4 of a thin lens) and back-light the shots were
rendered with (``tests/pipeline/test_vignetting.py``, ``pipeline.render_colour.backlit_shading``),
through the exact barrel map of ``tests/pipeline/lenses.py``; lensfun's ``pa`` formula written out
here (1 + k1 r^2 + k2 r^4 + k3 r^6, r over the half-diagonal).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml

from pipeline.model_file import model_file_text
from pipeline.models.radial import RadialModel
from pipeline.render import HarpScene
from pipeline.render_colour import backlit_shading, render_shaded
from station.cli import main
from tests.pipeline.test_vignetting import ANGLES, LENS, H, W, cos4, uneven

REPO = Path(__file__).resolve().parents[3]
ARGS_ANGLES = [f"{a:g}" for a in ANGLES]


@pytest.fixture(scope="module")
def shots(tmp_path_factory):
    """Four 16-bit PNG shots at ANGLES, and a model file of the lens they were rendered through."""
    d = tmp_path_factory.mktemp("vignetting")
    paths = []
    for i, a in enumerate(ANGLES):
        scene = HarpScene(angle_deg=a, spacing_px=40.0, string_width_px=8.0, phase_px=7.0 * i, blur_px=1.0)
        shading = backlit_shading(W, H, cos4, uneven, a, LENS)
        r = render_shaded(W, H, scene, LENS, shading, seed=60 + i, shot_noise=True)
        assert r.image.dtype == np.uint16
        p = d / f"shot{i}.png"
        assert cv2.imwrite(str(p), r.image)
        paths.append(str(p))
    # the same map as LENS, as a model file (RadialModel: f = k0 + k2 rho^2 + k4 rho^4, scale R0)
    model = RadialModel(center=tuple(LENS.c), k=(1.0, 0.0) + (LENS.k[0], 0.0, LENS.k[1]), scale=LENS.r0)
    g = np.array([[0.0, 0.0], [W - 1.0, H - 1.0], [100.0, 300.0]])
    np.testing.assert_allclose(model.undistort_points(g), LENS.undistort_points(g), atol=1e-9)
    mpath = d / "lens.yaml"
    mpath.write_text(model_file_text(model, width=W, height=H))
    return paths, str(mpath)


def _pixels():
    yy, xx = np.mgrid[0:H, 0:W].astype(np.float64)
    return np.column_stack([xx.ravel(), yy.ravel()])


def _pa(k, xy):
    c = np.array([(W - 1) / 2.0, (H - 1) / 2.0])
    r2 = np.sum((xy - c) ** 2, axis=1) / np.sum(c**2)
    return 1 + k[0] * r2 + k[1] * r2**2 + k[2] * r2**3


def test_flat_field_within_one_percent(shots, tmp_path, capsys):
    """Issue 24: <= 1 % error in relative illumination over the image, as the flat-field file holds it."""
    paths, model = shots
    flat, out = tmp_path / "flat.tiff", tmp_path / "vignetting.yaml"
    args = ["vignetting", *paths, "--angles", *ARGS_ANGLES, "--model", model, "--flat-field", str(flat)]
    assert main([*args, "-o", str(out), "--focal-mm", "35", "--aperture", "2.8"]) == 0
    text = capsys.readouterr().out
    ff = cv2.imread(str(flat), cv2.IMREAD_UNCHANGED)
    assert ff.dtype == np.float32 and ff.shape == (H, W)
    rel = ff.astype(np.float64).ravel() / cos4(_pixels()) - 1
    print(f"\nflat field against cos^4: error RMS {np.sqrt(np.mean(rel**2)):.4f}, max {np.abs(rel).max():.4f}")
    assert np.abs(rel).max() <= 0.01
    doc = yaml.safe_load(out.read_text())
    assert doc["format"] == "harp-vignetting" and doc["image_size"] == [W, H]
    assert doc["flat_field"]["depth"] == 32 and doc["distortion_model"] == model
    # the printed and written figures: the corners' illumination, the back-light's unevenness, lensfun pa
    corners = [p for p in doc["relative_illumination"]["points"] if "corner" in p["where"]]
    truth = cos4(np.array([[p["x"], p["y"]] for p in corners]))
    np.testing.assert_allclose([p["fit"] for p in corners], truth, atol=0.005)
    assert f"{corners[0]['fit']:.4f}" in text
    g = np.column_stack([np.linspace(0, W - 1, 50), np.linspace(0, H - 1, 50)]) - [(W - 1) / 2.0, (H - 1) / 2.0]
    u = uneven(g)
    assert 0.5 * (u.max() / u.min() - 1) < doc["backlight_unevenness"] < 0.5  # ~23 % over the image
    lf = doc["lensfun"]
    k = (lf["k1"], lf["k2"], lf["k3"])
    assert np.abs(_pa(k, _pixels()[::97]) / cos4(_pixels()[::97]) - 1).max() < 0.012
    assert lf["conversion_error"]["max"] < 0.005
    assert f"lensfun pa: k1 {lf['k1']:.6g}" in text
    assert lf["element"]["model"] == "pa" and float(lf["element"]["k1"]) == pytest.approx(lf["k1"])
    assert '<vignetting model="pa" focal="35.0" aperture="2.8"' in text
    header = text.split("\n\n")[0].splitlines()[0]  # off a terminal: tab-separated tables
    assert header.split("\t") == ["image", "angle (deg)", "edges", "samples", "exposure"]


def test_json_and_16_bit_flat_field(shots, tmp_path, capsys):
    """--json is one object; the 16-bit flat field is 65535 V / max V."""
    paths, model = shots
    flat = tmp_path / "flat16.tif"
    args = ["vignetting", *paths, "--angles", *ARGS_ANGLES, "--model", model, "--json"]
    assert main([*args, "--flat-field", str(flat), "--flat-field-depth", "16"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert [i["angle_deg"] for i in doc["images"]] == list(ANGLES)
    assert all(i["samples"] > 2000 for i in doc["images"])
    ff = cv2.imread(str(flat), cv2.IMREAD_UNCHANGED)
    assert ff.dtype == np.uint16 and ff.shape == (H, W) and ff.max() == 65535
    v = cos4(_pixels())
    rel = (ff.astype(np.float64).ravel() / doc["flat_field"]["scale"]) / v - 1
    print(f"\n16-bit flat field against cos^4: error RMS {np.sqrt(np.mean(rel**2)):.4f}, max {np.abs(rel).max():.4f}")
    assert np.abs(rel).max() <= 0.01


def test_a_clipped_shot_is_refused(shots, tmp_path, capsys):
    """A shot whose sheet is saturated (here: 16-bit values doubled and clipped) hides the fall-off."""
    paths, _ = shots
    img = cv2.imread(paths[0], cv2.IMREAD_UNCHANGED).astype(np.float64)
    clipped = tmp_path / "clipped.png"
    cv2.imwrite(str(clipped), np.clip(img * 2.0, 0, 65535).astype(np.uint16))
    assert main(["vignetting", str(clipped), *paths[1:], "--angles", *ARGS_ANGLES]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "clipped.png" in err and "saturated" in err and "lower the exposure" in err


@pytest.mark.parametrize(
    "case",
    ["count", "missing", "equal", "one"],
)
def test_bad_input_is_one_line_and_writes_nothing(shots, tmp_path, capsys, case):
    paths, model = shots
    flat, out = tmp_path / "flat.tiff", tmp_path / "v.json"
    images, angles = list(paths), list(ARGS_ANGLES)
    want = {"count": "4 images", "missing": "nothere.png", "equal": "turn the harp", "one": "two or more"}[case]
    if case == "count":
        angles = angles[:3]
    elif case == "missing":
        images[1] = str(tmp_path / "nothere.png")
    elif case == "equal":
        angles = ["30"] * 4
    else:
        images, angles = images[:1], angles[:1]
    code = main(["vignetting", *images, "--angles", *angles, "--flat-field", str(flat), "-o", str(out)])
    err = capsys.readouterr().err.strip()
    assert code == 2 and err.count("\n") == 0 and err.startswith("harp vignetting: ") and want in err, err
    assert not flat.exists() and not out.exists()


def test_angles_that_do_not_separate_are_refused(shots, tmp_path, capsys):
    """Two shots half a turn apart: the back-light's 2-fold harmonics look the same in both."""
    paths, _ = shots
    assert main(["vignetting", *paths[:2], "--angles", "10", "190", "-o", str(tmp_path / "v.yaml")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "do not separate" in err and not (tmp_path / "v.yaml").exists()


def test_a_real_process(shots, tmp_path):
    """``python -m station.cli vignetting`` as the user runs it: the JSON on stdout, nothing on stderr."""
    paths, model = shots
    cmd = [sys.executable, "-m", "station.cli", "vignetting", *paths, "--angles", *ARGS_ANGLES, "--json"]
    env = dict(os.environ, PYTHONPATH=str(REPO))
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=300, cwd=REPO, env=env)
    assert done.returncode == 0 and done.stderr == "", done.stderr
    doc = json.loads(done.stdout)
    assert doc["format"] == "harp-vignetting" and doc["distortion_model"] is None
    # without the model the back-light is placed through the identity: a few tenths of a % more
    corners = [p for p in doc["relative_illumination"]["points"] if "corner" in p["where"]]
    truth = cos4(np.array([[p["x"], p["y"]] for p in corners]))
    err = np.abs(np.array([p["fit"] for p in corners]) / truth - 1).max()
    print(f"\nwithout the model: corners' relative illumination error max {err:.4f}")
    assert err < 0.02
