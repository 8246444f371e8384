"""The Adobe lens profile (LCP) export read back and applied as RawTherapee's ``lcp.cc`` applies it.

No Adobe software here: the consumer is :mod:`tests.pipeline.lcp_equations`, RawTherapee's parsing,
normalisation (``fx = FocalLengthX * max(W, H)``, centre ``ImageXCenter * W``, ``ImageYCenter * H``)
and ``correctDistortion`` (corrected pixel -> the photo's pixel) written out independently of
``pipeline.exports.lcp``. Truth: the harp model, compared modulo homography as every export
(:func:`tests.pipeline.export_support.compare_points`), against the conversion error the file states.
"""

from dataclasses import replace

import numpy as np
import pytest

from pipeline.exports.lcp import LcpProfile, lcp_text, read_lcp_entries
from pipeline.exports.lens import LensInfo
from pipeline.exports.registry import read_correction, write_export
from pipeline.exports.source import ExportOptions, ExportSource
from pipeline.models.opencv_model import OpenCVModel
from tests.pipeline.export_support import compare_points, real_model, wide_radial
from tests.pipeline.lcp_equations import correct_distortion, mapper, read_profiles

REAL_LENS = LensInfo(
    lens_maker="Canon",
    lens_model="EF 50mm f/1.8 II",
    camera_maker="Canon",
    camera_model="EOS 40D",
    focal_mm=50.0,
    pixel_pitch_um=11.4,
    crop_factor=1.611,
)
WW, WH = 640, 480
WIDE93 = wide_radial(93.0, WW, WH)
# 93 degrees over the 640 x 480 diagonal: f = 400 px / (2 sin(93/4 degrees)) = 506.7 px, 1.52 mm at 3 um
WIDE_LENS = LensInfo(
    lens_maker="Sim", lens_model="Wide", camera_maker="Sim", camera_model="Cam", focal_mm=1.52, pixel_pitch_um=3.0
)


@pytest.fixture(scope="module")
def real(real_harp_dir):
    rm = real_model(1, str(real_harp_dir))
    src = ExportSource(rm.model, rm.width, rm.height, lens=REAL_LENS, holdout_d=rm.holdout_d)
    return rm.model, rm.width, rm.height, write_export("lcp", src, ExportOptions(focus_distance_m=1.2))


@pytest.fixture(scope="module")
def wide():
    src = ExportSource(WIDE93, WW, WH, lens=WIDE_LENS, wide_angle=True)
    return WIDE93, WW, WH, write_export("lcp", src)


def in_rawtherapee(data: bytes, width: int, height: int, n: int = 60):
    """Ideal pixels ``p`` of a grid and where RawTherapee reads the photo for them, ``q``."""
    prof = read_profiles(data)
    (m,) = prof["models"]
    mc = mapper(m, width, height, m["focal"], prof["sensor_format_factor"])
    xs, ys = np.linspace(0, width - 1, n), np.linspace(0, height - 1, max(2, n * height // width))
    p = np.stack(np.meshgrid(xs, ys), axis=-1).reshape(-1, 2)
    return prof, m, p, correct_distortion(mc, p, prof["fisheye"])


def check(model, w, h, ex, fisheye):
    prof, m, p, q = in_rawtherapee(ex.data, w, h)
    assert prof["fisheye"] is fisheye
    rms, mx = compare_points(model, p, q, w, h)
    e = ex.error
    print(
        f"\nlcp {'FisheyeModel' if fisheye else 'PerspectiveModel'} in RawTherapee's equations: RMS {rms:.4f} / max "
        f"{mx:.4f} px; stated RMS {e.rms_mod_h_px:.4f} / max {e.max_mod_h_px:.4f} px modulo homography"
    )
    assert rms <= 1.3 * e.rms_mod_h_px + 5e-4 and mx <= 1.3 * e.max_mod_h_px + 5e-4
    return prof, m


def test_the_real_lens_as_a_perspective_model_within_the_stated_error(real):
    model, w, h, ex = real
    prof, m = check(model, w, h, ex, fisheye=False)
    assert prof["sensor_format_factor"] == pytest.approx(1.611) and prof["lens"] == "EF 50mm f/1.8 II"
    assert (m["focal"], m["focus"]) == (50.0, 1.2)
    # the camera is the nominal one, normalised by the long side: 50 mm / 11.4 um over 1761 px
    assert m["foc_len_x"] * max(w, h) == pytest.approx(50 / 11.4e-3, rel=1e-8)
    # OpenCV's 5 coefficients, p1 p2 as the tangential terms
    d = ex.converted.dist
    assert m["param"] == pytest.approx([d[0], d[1], d[4], d[2], d[3]], rel=1e-8)


def test_the_wide_lens_as_a_fisheye_model_within_the_stated_error(wide):
    model, w, h, ex = wide
    check(model, w, h, ex, fisheye=True)
    assert ex.notes[0].startswith("lcp: FisheyeModel (k1 k2), the closer in max")
    assert ex.error.max_mod_h_px < 0.05


@pytest.mark.parametrize("which", ["real", "wide"])
def test_the_profile_reads_back_as_the_model_it_holds(which, request):
    model, w, h, ex = request.getfixturevalue(which)
    c = read_correction(ex.data, "lens.lcp", w, h, focal=50.0)
    assert c.kind == "lcp:" + ("PerspectiveModel" if which == "real" else "FisheyeModel") and c.size is None
    g = np.stack(np.meshgrid(np.linspace(0, w - 1, 20), np.linspace(0, h - 1, 15)), -1).reshape(-1, 2)
    assert np.allclose(c.model.undistort_points(g), ex.converted.undistort_points(g), atol=1e-6)


def test_settings_add_up_in_one_profile_and_a_setting_again_replaces_it(wide):
    """A zoom lens's (focal, focus distance) settings, each exported into the same file (as ``harp profile
    export LENS --focus F --format lcp -o FILE`` does per focal length)."""
    model, w, h, ex = wide
    text = ex.data.decode()
    for focal, dist in ((1.52, 0.5), (1.52, 2.0), (2.5, 0.5)):
        profile = LcpProfile(ex.converted, w, h, focal, dist)
        text, done = lcp_text(profile, replace(WIDE_LENS, focal_mm=focal), existing=text, existing_name="zoom.lcp")
        assert not any(d.startswith("replaced") for d in done)
    text, done = lcp_text(LcpProfile(ex.converted, w, h, 1.52, 2.0), WIDE_LENS, existing=text, existing_name="zoom.lcp")
    assert done[0] == "replaced the profile at focal 1.52 mm, focus distance 2 m in zoom.lcp"
    # RawTherapee sees every (focal, focus) entry, in order
    settings = [(m["focal"], m["focus"]) for m in read_profiles(text.encode())["models"]]
    assert settings == [(1.52, 0.0), (1.52, 0.5), (1.52, 2.0), (2.5, 0.5)]
    assert len(read_lcp_entries(text, "zoom.lcp")) == 4
    # the reader takes the nearest focal, then the farthest focus distance
    assert read_correction(text.encode(), "zoom.lcp", w, h, focal=2.3).kind == "lcp:FisheyeModel"
    with pytest.raises(ValueError, match=r"^zoom.lcp: the profile holds 2 focal lengths \(1.52, 2.5 mm\): give the"):
        read_correction(text.encode(), "zoom.lcp", w, h)
    # one model kind per profile (RawTherapee reads a profile with any FisheyeModel entry as a fisheye)
    pin = LcpProfile(OpenCVModel(fx=500.0, fy=500.0, cx=320.0, cy=240.0, dist=(0.01, 0, 0, 0, 0)), w, h, 9.0, 1.0)
    with pytest.raises(ValueError, match=r"^zoom.lcp: the profile's entries are FisheyeModel, not PerspectiveModel"):
        lcp_text(pin, WIDE_LENS, existing=text, existing_name="zoom.lcp")
    other = ExportSource(model, w, h, lens=LensInfo(lens_model="Other", focal_mm=3.0), wide_angle=True)
    with pytest.raises(ValueError, match=r"^zoom.lcp: a profile of lens 'Wide', not 'Other'; an LCP file holds"):
        write_export("lcp", other, ExportOptions(existing=text.encode(), existing_name="zoom.lcp"))


@pytest.mark.parametrize(
    "mutate, reason",
    [
        (lambda t: t[: len(t) // 2], "not a well-formed LCP file"),
        (lambda t: t.replace("PerspectiveModel", "VignetteModel"), "holds no PerspectiveModel or FisheyeModel"),
        (lambda t: t.replace('stCamera:RadialDistortParam1="', 'stCamera:RadialDistortParam1="x'), "is not a number"),
        (lambda t: t.replace('ImageLength="1174"', 'ImageLength="600"'), "profile for 1761x600 images"),
        (lambda t: t.replace("photoshop:CameraProfiles", "photoshop:Other"), "not a recognised correction"),
    ],
)
def test_a_defective_profile_is_one_line_naming_the_file(real, mutate, reason):
    _, w, h, ex = real
    with pytest.raises(ValueError) as exc:
        read_correction(mutate(ex.data.decode()).encode(), "bad.lcp", w, h)
    assert str(exc.value).startswith("bad.lcp: ") and reason in str(exc.value) and "\n" not in str(exc.value)
