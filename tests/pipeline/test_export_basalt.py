"""The Basalt export read back with the json module and evaluated with Basalt's kb4 equations.

No Basalt installed (a C++ library built from source, not on PyPI): the consumer here is the file parsed
as cereal parses it (the members of ``basalt::Calibration`` by name, ``value0`` first) and the equations of
basalt-headers' ``KannalaBrandtCamera4`` written out in ``tests/pipeline/basalt_equations.py``: the
closed-form ``project`` and ``unproject`` with Basalt's own 3 Newton steps, besides the same inverse
iterated to convergence. Truth: the harp model (``undistort_points``), independent of the writer,
compared modulo homography as every export. Lenses: a strong pin-hole lens with decentering and thin
prism (kb4 cannot hold those: stated, and warned against its holdout d), and the exact 149 degree
equisolid lens (kb4 holds it).
"""

import json
import re

import numpy as np
import pytest

from pipeline.compare import fit_homography
from pipeline.exports.basalt import read_basalt_text
from pipeline.exports.registry import read_correction, write_export
from pipeline.exports.source import ExportSource
from pipeline.models import RadialModel
from pipeline.models.homography import apply_homography
from tests.pipeline.basalt_equations import CALIBRATION_MEMBERS, basalt_camera, normalised, project, unproject
from tests.pipeline.export_support import WIDE, WIDE_H, WIDE_W, mod_h

STAMP = "FAILED QA: profile #7 at focus 0 was judged FAIL (test stamp)"
W, H = 400, 300
PINHOLE = RadialModel.for_image(
    W, H, k=(1.0, 0.0, 0.06, 0.0, -0.012), center=(207.0, 146.0), tangential=(3e-3, -2e-3), prism=(2e-3, 0, -1.5e-3, 0)
)


@pytest.fixture(scope="module")
def pinhole():
    return PINHOLE, W, H, write_export("basalt", ExportSource(PINHOLE, W, H, holdout_d=0.01))


@pytest.fixture(scope="module")
def wide():
    return WIDE, WIDE_W, WIDE_H, write_export("basalt", ExportSource(WIDE, WIDE_W, WIDE_H, stamp=(STAMP,)))


def grid(width, height, nx=64):
    ny = int(round(nx * height / width))
    xs, ys = np.linspace(0, width - 1, nx), np.linspace(0, height - 1, ny)
    return np.stack(np.meshgrid(xs, ys), axis=-1).reshape(-1, 2)


def check_with_basalt_equations(model, width, height, ex):
    p, res, value0 = basalt_camera(ex.data)
    assert res == [width, height]
    err = ex.error
    q = grid(width, height)
    ours = model.undistort_points(q)
    x = normalised(unproject(p, q, steps=50))  # converged: the model the file holds
    rms, mx = mod_h(x, ours)
    x3 = normalised(unproject(p, q))  # Basalt's own 3 Newton steps
    rms_b, mx_b = mod_h(x3, ours)
    short = float(np.max(np.hypot(*((x3 - x) * p[:2]).T)))
    # project (closed form): our ideal points into the file's camera by the homography, projected by kb4
    h, _ = fit_homography(x, ours)
    back = apply_homography(np.linalg.inv(h), ours)
    e = np.hypot(*(project(p, np.c_[back, np.ones(len(back))]) - q).T)
    print(
        f"\nbasalt kb4 (Basalt's equations, no Basalt installed): stated RMS {err.rms_mod_h_px:.3g} / max "
        f"{err.max_mod_h_px:.3g} px mod H; unproject converged RMS {rms:.3g} / max {mx:.3g} px; with Basalt's 3 "
        f"Newton steps RMS {rms_b:.3g} / max {mx_b:.3g} px (the steps leave {short:.2g} px); project RMS "
        f"{np.sqrt(np.mean(e**2)):.3g} / max {e.max():.3g} px"
    )
    assert rms <= 1.3 * err.rms_mod_h_px + 5e-4 and mx <= 1.3 * err.max_mod_h_px + 5e-4
    assert abs(rms - err.rms_mod_h_px) <= 0.3 * err.rms_mod_h_px + 5e-4
    assert np.sqrt(np.mean(e**2)) <= 1.3 * err.rms_mod_h_px + 5e-4 and e.max() <= 1.3 * err.max_mod_h_px + 5e-4
    # the file states what Basalt's 3 steps leave on this lens
    (stated,) = [float(m) for s in value0["harp_station"]["statement"] for m in re.findall(r"leave up to (\S+) px", s)]
    assert abs(stated - short) <= 0.05 * short + 1e-6
    return value0


def test_the_file_is_a_basalt_calibration_with_every_member_cereal_reads(wide):
    _, w, h, ex = wide
    value0 = basalt_camera(ex.data)[2]
    assert [k for k in value0 if k in CALIBRATION_MEMBERS] == list(CALIBRATION_MEMBERS)
    assert set(value0) == {*CALIBRATION_MEMBERS, "harp_station"}
    (pose,) = value0["T_imu_cam"]
    assert pose == {"px": 0.0, "py": 0.0, "pz": 0.0, "qx": 0.0, "qy": 0.0, "qz": 0.0, "qw": 1.0}
    assert len(value0["calib_accel_bias"]) == 9 and len(value0["calib_gyro_bias"]) == 12
    assert all(len(value0[k]) == 3 for k in ("accel_noise_std", "gyro_noise_std", "accel_bias_std", "gyro_bias_std"))
    statement = value0["harp_station"]["statement"]
    assert statement[0] == STAMP and any("IMU members are placeholders" in s for s in statement)


def test_the_wide_lens_as_kb4_exactly(wide):
    model, w, h, ex = wide
    check_with_basalt_equations(model, w, h, ex)
    assert ex.error.max_mod_h_px < 1e-4 and ex.notes[0].startswith("basalt: kb4")


def test_a_pinhole_lens_as_kb4_within_the_stated_error_and_warned(pinhole):
    model, w, h, ex = pinhole
    check_with_basalt_equations(model, w, h, ex)
    # kb4 has no decentering or thin-prism terms: less exact than this lens' holdout d, said
    assert ex.error.rms_mod_h_px > 0.01 and any("less exact than the calibration" in s for s in ex.warnings)


@pytest.mark.parametrize("which", ["pinhole", "wide"])
def test_the_export_reads_back_as_the_model_it_holds(which, request):
    model, w, h, ex = request.getfixturevalue(which)
    c = read_correction(ex.data, "calib.json", w, h)
    assert c.kind == "basalt:kb4" and c.size == (w, h)
    q = grid(w, h, 30)
    assert np.allclose(c.model.undistort_points(q), ex.converted.undistort_points(q), atol=1e-9)


def test_bad_basalt_files_name_the_file_and_the_field(wide):
    _, w, h, ex = wide
    doc = json.loads(ex.data)
    v = doc["value0"]
    cam = v["intrinsics"][0]
    two = {"value0": {**v, "intrinsics": [cam, cam], "resolution": [[w, h], [100, 80]]}}
    assert read_basalt_text(json.dumps(two), "calib.json", (w, h))[1] == (w, h)  # the one of the shots' size
    for bad, why in (
        ("[1]", "not a Basalt calibration"),
        (json.dumps({"value0": {**v, "intrinsics": [{**cam, "camera_type": "ds"}]}}), "camera_type 'ds' not read"),
        (
            json.dumps({"value0": {**v, "intrinsics": [{**cam, "intrinsics": {"fx": 1.0}}]}}),
            r"intrinsics\[0\]: kb4 needs the numbers fx, fy",
        ),
        (json.dumps({"value0": {**v, "intrinsics": [cam, cam], "resolution": [[w, h], [w, h]]}}), "2 Basalt cameras"),
    ):
        with pytest.raises(ValueError, match=f"^calib.json: .*{why}"):
            read_basalt_text(bad, "calib.json", (w, h))
