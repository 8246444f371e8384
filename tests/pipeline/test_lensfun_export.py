"""The lensfun export as lensfun needs it: the camera's crop factor, no clash with an installed lens
(issue 20 item 3)."""

import math
from pathlib import Path

import lensfunpy
import numpy as np
import pytest

from pipeline.exports.lens import LensInfo
from pipeline.exports.lensfun import installed_lens, read_lensfun_text
from pipeline.exports.registry import write_export
from pipeline.exports.source import ExportOptions, ExportSource
from pipeline.models import RadialModel
from tests.pipeline.export_support import WIDE, WIDE_H, WIDE_W, compare_points, lensfun_in_consumer

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


# ----------------------------------------------- a lens lensfun already has
def _bundled() -> list[tuple[str, str]]:
    root = Path(lensfunpy.__file__).parent / "db_files"
    return [(str(p), p.read_text(encoding="utf-8")) for p in sorted(root.glob("*.xml"))]


def test_installed_lens_finds_a_lens_of_lensfuns_own_database_by_any_of_its_names():
    dbs = _bundled()
    for model in ("Canon EF 50mm f/1.8 MkII", "canon ef 50mm  F/1.8 II"):  # the plain and the lang="en" name
        assert Path(installed_lens(dbs, "Canon", model)).name == "slr-canon.xml"
    assert installed_lens(dbs, "Canon", "Canon EF 50mm f/1.8 MkII (harp SN 4711)") is None
    assert installed_lens(dbs, "Nikon", "Canon EF 50mm f/1.8 MkII") is None


def test_why_a_clash_is_refused_lensfun_drops_the_installed_entrys_tca():
    """Lensfun itself, loading its database and a file with a lens of the same name: the entry's TCA is gone."""
    lens = LensInfo(lens_maker="Canon", lens_model="Canon EF 50mm f/1.8 MkII", mount="Canon EF", focal_mm=50.0)
    xml = write_export("lensfun", ExportSource(BARREL, W, H, lens=lens), ExportOptions(crop_factor=1.0)).data.decode()

    def tca(db) -> object:
        (ln,) = [x for x in db.lenses if x.model == "Canon EF 50mm f/1.8 MkII" and x.crop_factor == 1.0]
        mod = lensfunpy.Modifier(ln, 1.0, W, H)
        mod.initialize(50.0, 2.8, 1000.0, flags=lensfunpy.ModifyFlags.TCA)
        return mod.apply_subpixel_distortion()

    assert tca(lensfunpy.Database(load_common=False)) is not None  # the installed entry has a TCA
    assert tca(lensfunpy.Database(xml=xml, load_common=False)) is None  # merged with ours: lost
    with pytest.raises(ValueError, match=r"is in the installed lensfun database .*slr-canon\.xml.*--lens-model"):
        write_export(
            "lensfun",
            ExportSource(BARREL, W, H, lens=lens),
            ExportOptions(crop_factor=1.0, installed_lensfun=tuple(_bundled())),
        )


def test_a_second_focus_setting_into_the_same_file_is_said_to_replace_the_first():
    """lensfun has no focus axis for distortion: one calibration per focal length survives, and the export says so."""
    lens = LensInfo(lens_maker="Harp", lens_model="Focus 6", mount="C", focal_mm=6.0, crop_factor=7.2, focus=0.0)
    first = write_export("lensfun", ExportSource(BARREL, W, H, lens=lens))
    other = RadialModel.for_image(W, H, k=(1.0, 0.0, 0.03))
    second = write_export(
        "lensfun",
        ExportSource(other, W, H, lens=LensInfo(**{**lens.__dict__, "focus": 1.0})),
        ExportOptions(existing=first.data, existing_name="mine.xml"),
    )
    (w,) = [w for w in second.warnings if "replaced" in w]
    assert "no focus axis" in w and "focus 1 calibration replaced the focus 0 one" in w
    xml = second.data.decode()
    assert xml.count("<distortion ") == 1 and "focus setting 1 (" in xml and "focus setting 0 (" not in xml
    # what is left is the second one
    kept = read_lensfun_text(xml, W, H, "mine.xml")
    pts = np.column_stack([np.linspace(0, W - 1, 50), np.linspace(0, H - 1, 50)])
    assert np.max(np.abs(kept.undistort_points(pts) - second.converted.undistort_points(pts))) < 1e-9
    assert np.max(np.abs(kept.undistort_points(pts) - first.converted.undistort_points(pts))) > 0.1


def test_another_centre_at_another_focal_is_refused_since_lensfun_holds_one_centre_per_lens():
    base = dict(lens_maker="Harp", lens_model="Zoom 6-12", mount="C", crop_factor=7.2)
    wide = RadialModel.for_image(W, H, k=(1.0, 0.0, 0.04), center=(166.0, 117.0))
    tele = RadialModel.for_image(W, H, k=(1.0, 0.0, -0.02), center=(152.0, 123.0))
    first = write_export("lensfun", ExportSource(wide, W, H, lens=LensInfo(focal_mm=6.0, **base)))
    again = ExportOptions(existing=first.data, existing_name="zoom.xml")
    with pytest.raises(
        ValueError, match=r"zoom\.xml: lens Harp Zoom 6-12 .* calibrations at 6 mm .*--lensfun-no-center"
    ):
        write_export("lensfun", ExportSource(tele, W, H, lens=LensInfo(focal_mm=12.0, **base)), again)
    # the same focal again: its centre goes with it (nothing else uses the old one)
    same = write_export("lensfun", ExportSource(tele, W, H, lens=LensInfo(focal_mm=6.0, **base)), again)
    xml = same.data.decode()
    assert xml.count("<lens>") == 1 and xml.count("<distortion ") == 1 and xml.count("<center ") == 1
    kept = read_lensfun_text(xml, W, H, "zoom.xml")
    pts = np.column_stack([np.linspace(0, W - 1, 50), np.linspace(0, H - 1, 50)])
    assert np.max(np.abs(kept.undistort_points(pts) - same.converted.undistort_points(pts))) < 1e-9
    # without fitted centres both focal lengths go into one lens
    plain = ExportOptions(lensfun_center=False)
    a = write_export("lensfun", ExportSource(wide, W, H, lens=LensInfo(focal_mm=6.0, **base)), plain)
    b = write_export(
        "lensfun",
        ExportSource(tele, W, H, lens=LensInfo(focal_mm=12.0, **base)),
        ExportOptions(lensfun_center=False, existing=a.data),
    )
    assert b.data.decode().count("<lens>") == 1 and b.data.decode().count("<distortion ") == 2


# ------------------------------------------------------------- fisheye lenses
LENSFUN_TYPE = {
    "rectilinear": "RECTILINEAR",
    "fisheye": "FISHEYE",
    "equisolid": "FISHEYE_EQUISOLID",
    "stereographic": "FISHEYE_STEREOGRAPHIC",
    "orthographic": "FISHEYE_ORTHOGRAPHIC",
    "fisheye_thoby": "FISHEYE_THOBY",
}


def _lensfun_corrects(xml: str, width: int, height: int, focal: float, crop: float, n: int = 30):
    """lensfun's own correction to rectilinear (distortion, then geometry), at pixels of a grid: ``(p, q, lens)``."""
    db = lensfunpy.Database(xml=xml, load_common=False, load_bundled=False)
    (lens,) = db.lenses
    mod = lensfunpy.Modifier(lens, crop, width, height)
    flags = lensfunpy.ModifyFlags.DISTORTION | lensfunpy.ModifyFlags.GEOMETRY
    mod.initialize(focal, 2.8, 1000.0, scale=1.0, targeom=lensfunpy.LensType.RECTILINEAR, flags=flags)
    xs, ys = np.linspace(0, width - 1, n), np.linspace(0, height - 1, max(2, n * height // width))
    p = np.stack(np.meshgrid(xs, ys), axis=-1).reshape(-1, 2)
    q = np.array([mod.apply_geometry_distortion(float(x), float(y), 1, 1)[0, 0] for x, y in p], dtype=np.float64)
    return p, q, lens


@pytest.mark.parametrize("lens_type", list(LENSFUN_TYPE))
def test_lensfun_model_of_every_lens_type_is_lensfuns_own_correction(lens_type):
    w, h, crop, focal = 1501, 1001, 1.5, 8.0
    terms, centre = (0.01, -0.03, 0.02), (0.02, -0.01)
    xml = f"""<lensdatabase version="1"><lens><maker>M</maker><model>L</model><mount>X</mount>
    <cropfactor>{crop}</cropfactor><aspect-ratio>{(w - 1) / (h - 1)!r}</aspect-ratio><type>{lens_type}</type>
    <center x="{centre[0]}" y="{centre[1]}"/><calibration>
    <distortion model="ptlens" focal="{focal}" a="{terms[0]}" b="{terms[1]}" c="{terms[2]}"/>
    </calibration></lens></lensdatabase>"""
    p, q, lens = _lensfun_corrects(xml, w, h, focal, crop)
    assert lens.type == getattr(lensfunpy.LensType, LENSFUN_TYPE[lens_type])
    ours = read_lensfun_text(xml, w, h, "one.xml")
    assert ours.lens_type == lens_type
    ok = np.all(np.isfinite(q), axis=1)
    assert ok.mean() > 0.9
    np.testing.assert_allclose(ours.distort_points(p[ok]), q[ok], atol=5e-4)  # lensfun computes in float32
    back = ours.undistort_points(q[ok])
    np.testing.assert_allclose(back, p[ok], atol=5e-4)


def test_a_fisheye_lens_is_written_as_its_lensfun_type_and_lensfun_straightens_it():
    """The exact equisolid lens WIDE (149 deg diagonal): as rectilinear ptlens it cannot be held; as
    lensfun's equisolid type it is, checked by lensfun's own correction against the lens' closed form."""
    pitch, focal = 3.0, WIDE.f * 3.0e-3  # the lens' focal length in mm at that pitch
    lens = LensInfo(lens_maker="Harp", lens_model="Fish", mount="C", focal_mm=focal, pixel_pitch_um=pitch)
    exp = write_export("lensfun", ExportSource(WIDE, WIDE_W, WIDE_H, lens=lens))
    xml = exp.data.decode()
    assert "<type>equisolid</type>" in xml
    assert any("lens type equisolid" in n for n in exp.notes) and any("geometry conversion" in n for n in exp.notes)
    crop = lens.derived_crop_factor(WIDE_W, WIDE_H)
    p, q, _ = _lensfun_corrects(xml, WIDE_W, WIDE_H, focal, crop)
    _, mx = compare_points(WIDE, p, q, WIDE_W, WIDE_H)
    assert mx < 0.05
    assert exp.error.max_mod_h_px < 0.05
    # the rectilinear file the export wrote before: far off
    rect = write_export(
        "lensfun", ExportSource(WIDE, WIDE_W, WIDE_H, lens=lens), ExportOptions(lensfun_type="rectilinear")
    )
    assert "<type>" not in rect.data.decode() and rect.error.max_mod_h_px > 5.0
    # a fisheye type needs the focal length lensfun converts the geometry with
    with pytest.raises(ValueError, match="needs the nominal focal length"):
        write_export(
            "lensfun",
            ExportSource(WIDE, WIDE_W, WIDE_H, lens=LensInfo(pixel_pitch_um=pitch)),
            ExportOptions(lensfun_type="equisolid"),
        )


def test_a_rectilinear_lens_stays_rectilinear():
    exp = write_export("lensfun", _src(pixel_pitch_um=15.0))
    assert "<type>" not in exp.data.decode() and not any("lens type" in n for n in exp.notes)
