"""Model file: round trip of every model type, provenance, atomic write, clear errors."""

import numpy as np
import pytest

import pipeline
from pipeline.model_file import model_file_text, read_model_file
from pipeline.models import LensfunModel, OpenCVModel, RadialModel
from pipeline.models.base import IdentityModel
from pipeline.normalise import normalise_by_corners

W, H = 640, 480
PTS = np.array([[0.0, 0.0], [639.0, 479.0], [100.5, 300.25], [320.0, 10.0]])

MODELS = [
    RadialModel.for_image(
        W,
        H,
        k=(1.0, 0.0, 0.03, 0.0, -0.004),
        center=(322.3, 236.9),
        tangential=(1e-3, -2e-3),
        prism=(1e-4, 0.0, -2e-4, 0.0),
    ),
    IdentityModel(),
    OpenCVModel(fx=700.0, fy=702.0, cx=319.0, cy=241.0, dist=(-0.2, 0.05, 1e-3, -1e-3, 0.01)),
    LensfunModel(kind="ptlens", terms=(0.01, -0.02, 0.005), width=W, height=H),
]
MODELS.append(normalise_by_corners(MODELS[0], W, H))  # a homography-composed model nests another


@pytest.mark.parametrize("model", MODELS, ids=lambda m: m.name)
def test_round_trip_preserves_the_correction_exactly(tmp_path, model):
    path = tmp_path / "lens.yaml"
    merit = {"fit": {"d": 0.0123, "d_max": 0.05}, "holdout": {"d": np.float64(0.02), "d_max": 0.07}}
    path.write_text(model_file_text(model, width=W, height=H, merit=merit, provenance={"t": 30}))
    mf = read_model_file(path)
    assert type(mf.model) is type(model)
    assert (mf.width, mf.height) == (W, H)
    assert mf.merit["holdout"]["d"] == 0.02 and mf.merit["fit"]["d_max"] == 0.05
    np.testing.assert_array_equal(mf.model.undistort_points(PTS), model.undistort_points(PTS))
    # pipeline.load_model gives the model itself
    np.testing.assert_array_equal(pipeline.load_model(path).undistort_points(PTS), model.undistort_points(PTS))


@pytest.mark.parametrize(
    "text, reason",
    [
        ("format: harp-distortion-model\nformat_version: 1\nmodel: {model: radial\n", "not a valid YAML"),
        ("just a string", "not a harp model file"),
        (
            "format: harp-distortion-model\nformat_version: 7\nmodel: {model: radial}\nimage: {width: 2, height: 2}\n",
            "unknown model file format version 7",
        ),
        (
            "format: harp-distortion-model\nformat_version: 1\nmodel: {model: warp9}\nimage: {width: 2, height: 2}\n",
            "unknown distortion model 'warp9'",
        ),
        (
            "format: harp-distortion-model\nformat_version: 1\nmodel: {model: radial}\nimage: {width: 2, height: 2}\n",
            "invalid parameters for model 'radial'",
        ),
        ("format: harp-distortion-model\nformat_version: 1\nmodel: {model: identity}\n", "image size"),
    ],
)
def test_defective_files_raise_one_line_value_error_naming_file(tmp_path, text, reason):
    path = tmp_path / "bad.yaml"
    path.write_text(text)
    with pytest.raises(ValueError) as exc:
        read_model_file(path)
    msg = str(exc.value)
    assert msg.startswith(f"{path}: ") and reason in msg and "\n" not in msg


def test_missing_and_binary_files(tmp_path):
    with pytest.raises(ValueError, match="model file not found"):
        pipeline.load_model(tmp_path / "nope.yaml")
    p = tmp_path / "bin.yaml"
    p.write_bytes(b"\xff\xfe\x00garbage")
    with pytest.raises(ValueError, match=f"^{p}: "):
        read_model_file(p)


@pytest.mark.parametrize(
    "text, reason",
    [
        (
            "%YAML:1.0\n---\ncamera_matrix: !!opencv-matrix\n   rows: 3\n   cols: 3\n   dt: d\n   data: [1,0,0,0,1,0,0,0,1]\n",
            "an OpenCV FileStorage calibration file",
        ),
        (
            '<?xml version="1.0"?>\n<opencv_storage>\n<camera_matrix type_id="opencv-matrix"></camera_matrix>\n'
            "</opencv_storage>\n",
            "an OpenCV FileStorage calibration file",
        ),
        ("<lensdatabase><lens><model>x</model></lens></lensdatabase>\n", "a lensfun XML profile"),
        (
            "image_width: 2\ncamera_matrix: {rows: 3, cols: 3, data: [1,0,0,0,1,0,0,0,1]}\ndistortion_model: plumb_bob\n",
            "a ROS camera_info file",
        ),
        (
            "format: harp-distortion-model\nformat_version: 1\nimage: {width: 2, height: 2}\n"
            "model: {model: radial, center: [1, 1], k: oops, scale: 1}\n",
            "invalid parameters for model 'radial'",
        ),
    ],
)
def test_other_software_files_and_bad_values_are_named(tmp_path, text, reason):
    path = tmp_path / "other.yaml"
    path.write_text(text)
    with pytest.raises(ValueError) as exc:
        read_model_file(path)
    msg = str(exc.value)
    assert msg.startswith(f"{path}: ") and reason in msg and "\n" not in msg, msg


def test_directory_is_named_as_such(tmp_path):
    with pytest.raises(ValueError, match=f"^{tmp_path}: is a directory, not a model file$"):
        read_model_file(tmp_path)
