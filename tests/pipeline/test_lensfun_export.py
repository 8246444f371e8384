"""The lensfun export as lensfun needs it: the camera's crop factor (issue 20 item 3)."""

import math

import numpy as np
import pytest

from pipeline.exports.lens import LensInfo
from pipeline.exports.registry import ExportOptions, ExportSource, write_export
from pipeline.models import RadialModel
from tests.pipeline.export_support import compare_points, lensfun_in_consumer

W, H = 320, 240
BARREL = RadialModel.for_image(W, H, k=(1.0, 0.0, 0.04, 0.0, -0.01))
NAMES = {"lens_maker": "Harp", "lens_model": "Crop 6", "camera_maker": "Harp", "camera_model": "Crop body"}


@pytest.mark.parametrize(
    ("width", "height", "optics", "published"),
    [
        # a 1/3" sensor, 4.8 x 3.6 mm: crop factor 7.2 (every sensor-format table)
        (1280, 960, {"pixel_pitch_um": 3.75}, 7.2),
        # Canon APS-C, 22.3 x 14.9 mm: Canon's "1.6x"
        (6000, 4000, {"sensor_width_mm": 22.3}, 1.6),
        # 35 mm full frame, 36 x 24 mm
        (6000, 4000, {"pixel_pitch_um": 6.0}, 1.0),
    ],
)
def test_crop_factor_from_the_optics_is_the_published_one(width, height, optics, published):
    got = LensInfo(**optics).derived_crop_factor(width, height)
    assert got == pytest.approx(published, rel=0.01)


def test_no_optics_no_crop_factor():
    assert LensInfo(focal_mm=6.0).derived_crop_factor(W, H) is None


def _src(**optics) -> ExportSource:
    return ExportSource(BARREL, W, H, lens=LensInfo(focal_mm=6.0, mount="C", **NAMES, **optics))


def test_lensfun_export_writes_the_crop_factor_the_pixel_pitch_gives_and_lensfun_corrects_at_it():
    pitch = 15.0  # um: 320x240 at 15 um is 4.8 x 3.6 mm, a 1/3" sensor
    exp = write_export("lensfun", _src(pixel_pitch_um=pitch))
    xml = exp.data.decode()
    crop = math.hypot(36, 24) / math.hypot(4.8, 3.6)
    assert f"<cropfactor>{round(crop, 4)!r}</cropfactor>" in xml
    assert any("derived from the pixel pitch 15 um" in n for n in exp.notes)
    assert "derived from the pixel pitch" in xml  # the file says where it came from
    # lensfun, at the camera's own crop factor, corrects like the model
    cam, _, p, q = lensfun_in_consumer(xml, ("Harp", "Crop body"), ("Harp", "Crop 6"), 6.0, W, H)
    assert cam.crop_factor == pytest.approx(crop, rel=1e-4)
    rms, mx = compare_points(BARREL, p, q, W, H)
    assert mx < 0.05


def test_a_crop_factor_of_one_on_a_crop_camera_moves_lensfuns_correction():
    """Why the crop factor matters: the same lens filed at 1.0 and used on the crop-7.2 camera."""
    exp = write_export("lensfun", _src(), ExportOptions(crop_factor=1.0))
    xml = exp.data.decode()
    camera_crop = math.hypot(36, 24) / math.hypot(4.8, 3.6)
    # the camera entry as lensfun would have it for the real body
    body = xml.split("<camera>")[1].split("</camera>")[0]
    xml = xml.replace(body, body.replace("<cropfactor>1.0</cropfactor>", f"<cropfactor>{camera_crop!r}</cropfactor>"))
    _, _, p, q = lensfun_in_consumer(xml, ("Harp", "Crop body"), ("Harp", "Crop 6"), 6.0, W, H)
    _, mx = compare_points(BARREL, p, q, W, H)
    assert mx > 0.5


def test_lensfun_export_without_any_crop_information_refuses_and_names_what_to_give():
    with pytest.raises(ValueError, match=r"crop factor is not known.*--crop FACTOR.*pixel_pitch_um"):
        write_export("lensfun", _src())


def test_a_configured_crop_factor_that_the_pixel_pitch_contradicts_is_warned_of():
    exp = write_export("lensfun", _src(pixel_pitch_um=15.0), ExportOptions(crop_factor=1.6))
    assert "<cropfactor>1.6</cropfactor>" in exp.data.decode()
    (w,) = [w for w in exp.warnings if "crop factor" in w]
    assert "1.6 written" in w and "gives 7.21" in w
    agree = write_export("lensfun", _src(pixel_pitch_um=15.0), ExportOptions(crop_factor=7.2))
    assert not [w for w in agree.warnings if "crop factor" in w]
    assert np.isfinite(agree.error.max_px)
