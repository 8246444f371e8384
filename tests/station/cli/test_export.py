"""``harp export``: files other software loads, with the conversion error stated."""

import json
import xml.etree.ElementTree as ET

import cv2
import pytest
import yaml

from pipeline.exports.opencv import read_opencv_text
from pipeline.models import RadialModel
from station.cli import main
from station.files import write_model_file

W, H = 400, 300
LENS = RadialModel.for_image(W, H, k=(1.0, 0.0, 0.05, 0.0, -0.01), center=(203.0, 147.0))


@pytest.fixture()
def model(tmp_path):
    p = tmp_path / "lens.yaml"
    write_model_file(p, LENS, width=W, height=H, merit={"fit": {"d": 0.01, "d_max": 0.04}})
    return p


def test_opencv_export_to_file_states_conversion_error(model, tmp_path, capsys):
    out = tmp_path / "calib.yml"
    assert main(["export", str(model), "--format", "opencv", "-o", str(out), "--focal", "500"]) == 0
    text = capsys.readouterr().out
    assert f"wrote {out}" in text and "conversion error (opencv): RMS" in text
    fs = cv2.FileStorage(str(out), cv2.FILE_STORAGE_READ)
    k = fs.getNode("camera_matrix").mat()
    assert k[0, 0] == 500.0 and k[1, 1] == 500.0 and fs.getNode("distortion_coefficients").mat().shape == (1, 5)
    rms = fs.getNode("conversion_rms_px").real()
    fs.release()
    assert 0 < rms < 0.05 and f"RMS {rms:.4f} px" in text
    m, size = read_opencv_text(out.read_text())
    assert size == (W, H) and abs(m.cx - 203.0) < 1.0 and abs(m.cy - 147.0) < 1.0


def test_stdout_exports_ros_lensfun_json(model, capsys):
    assert main(["export", str(model), "--format", "ros", "--coeffs", "8", "--camera-name", "cam0"]) == 0
    cap = capsys.readouterr()
    doc = yaml.safe_load(cap.out)
    assert doc["distortion_model"] == "rational_polynomial" and doc["camera_name"] == "cam0"
    assert "conversion error (ros)" in cap.err  # stdout stays a clean file
    assert main(["export", str(model), "--format", "lensfun", "--lensfun-model", "poly5", "--focal-mm", "24"]) == 0
    cap = capsys.readouterr()
    d = ET.fromstring(cap.out.split("\n", 1)[1]).find("lens/calibration/distortion")
    assert d.get("model") == "poly5" and d.get("focal") == "24.0" and set(d.attrib) == {"model", "focal", "k1", "k2"}
    assert main(["export", str(model), "--format", "json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["model"] == LENS.to_dict() and doc["image"] == {"width": W, "height": H}
    assert doc["merit"]["fit"]["d"] == 0.01


@pytest.mark.parametrize(
    "content, reason",
    [
        ("format: harp-distortion-model\nformat_version: 2\n", "unknown model file format version 2"),
        ("{{{{", "not a valid YAML"),
    ],
)
def test_bad_model_exit_2(tmp_path, capsys, content, reason):
    p = tmp_path / "m.yaml"
    p.write_text(content)
    assert main(["export", str(p), "--format", "opencv"]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"harp export: {p}: ") and reason in err and err.count("\n") == 1


@pytest.mark.parametrize("focal_mm", ["-3", "0", "nan"])
def test_lensfun_focal_must_be_positive(model, capsys, focal_mm):
    # lensfun files its calibration entries under a focal length: a negative one is no lens
    assert main(["export", str(model), "--format", "lensfun", "--focal-mm", focal_mm]) == 2
    out, err = capsys.readouterr()
    assert out == "" and err.startswith("harp export: --focal-mm must be a focal length > 0 mm")
    assert err.count("\n") == 1
