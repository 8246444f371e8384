"""A complete lensfun lens (distortion, TCA, vignetting) loaded and applied by liblensfun (lensfunpy).

Truth: lensfun's own library maps pixels and scales colours; the harp models say what it
must do (:class:`~pipeline.models.lensfun_model.LensfunModel`,
:class:`~pipeline.models.tca_model.LensfunTca`, :class:`~pipeline.vignetting.LensfunVignetting`).
"""

from __future__ import annotations

import lensfunpy  # in the test extras: a missing lensfunpy fails, it is not skipped
import numpy as np

from pipeline.exports.lens import LensInfo
from pipeline.exports.lensfun import LensfunEntry, lensfun_database_text
from pipeline.models.lensfun_model import LensfunModel
from pipeline.models.tca_model import LensfunTca
from pipeline.vignetting import LensfunVignetting, lensfun_radius

W, H = 600, 400
INFO = LensInfo(
    lens_maker="Harp", lens_model="Colour 35", mount="Test", crop_factor=1.0, focal_mm=35.0,
    camera_maker="Harp", camera_model="Body",
)  # fmt: skip


def _entry(tca_scale: float = 1.0, focal: float = 35.0) -> LensfunEntry:
    s = tca_scale
    return LensfunEntry(
        model=LensfunModel("poly5", (-0.04, 0.006), W, H),
        lens=LensInfo(**{**INFO.__dict__, "focal_mm": focal}),
        tca=LensfunTca("poly3", (1.0 + 6e-4 * s, 2e-4 * s, -1e-4 * s), (1.0 - 5e-4 * s, -1e-4 * s, 5e-5 * s), W, H),
        vignetting=LensfunVignetting((-0.5, 0.2, -0.04), 0.0, 0.0),
        aperture=4.0,
        distance=2.0,
    )


def _modifier(xml: str, flags, focal: float = 35.0):
    db = lensfunpy.Database(xml=xml, load_common=False, load_bundled=False)
    cam = db.find_cameras("Harp", "Body")[0]
    lens = db.find_lenses(cam, "Harp", "Colour 35")[0]
    mod = lensfunpy.Modifier(lens, cam.crop_factor, W, H)
    mod.initialize(focal, 4.0, 2.0, scale=1.0, pixel_format=np.float32, flags=flags)
    return mod


def test_complete_lens_applied_by_lensfun():
    entry = _entry()
    xml, done = lensfun_database_text([entry])
    assert "<tca " in xml and "<vignetting " in xml and "<distortion " in xml, xml
    mod = _modifier(xml, lensfunpy.ModifyFlags.DISTORTION | lensfunpy.ModifyFlags.TCA)
    sub = mod.apply_subpixel_geometry_distortion()  # (H, W, 3, 2): where each channel is read
    yy, xx = np.mgrid[0:H, 0:W].astype(float)
    ideal = np.column_stack([xx.ravel(), yy.ravel()])
    green = entry.model.distort_points(ideal)
    np.testing.assert_allclose(sub[:, :, 1].reshape(-1, 2), green, atol=2e-3)
    assert entry.tca is not None
    for c, ch in ((0, "R"), (2, "B")):
        want = entry.tca.from_reference(ch, green)
        assert np.abs(want - green).max() > 0.1  # the TCA is there
        np.testing.assert_allclose(sub[:, :, c].reshape(-1, 2), want, atol=2e-3, err_msg=ch)
    mod = _modifier(xml, lensfunpy.ModifyFlags.VIGNETTING)
    img = np.full((H, W, 3), 0.25, np.float32)
    assert mod.apply_color_modification(img)
    assert entry.vignetting is not None
    v = entry.vignetting.factor(lensfun_radius(ideal, W, H)).reshape(H, W)
    np.testing.assert_allclose(0.25 / img[..., 0], v, rtol=2e-4)


def test_adding_again_replaces_the_colour_elements_at_that_focal():
    first, _ = lensfun_database_text([_entry(1.0)])
    again, _ = lensfun_database_text([_entry(2.0)], existing=first)
    other, _ = lensfun_database_text([_entry(1.0, focal=50.0)], existing=again)
    assert again.count("<tca ") == 1 and again.count("<vignetting ") == 1
    assert other.count("<tca ") == 2 and other.count("<distortion ") == 2
    mod = _modifier(other, lensfunpy.ModifyFlags.TCA, focal=35.0)
    sub = mod.apply_subpixel_distortion()
    corner = sub[0, 0, 0]
    want = _entry(2.0).tca.from_reference("R", np.array([[0.0, 0.0]]))[0]  # type: ignore[union-attr]
    np.testing.assert_allclose(corner, want, atol=2e-3)


def test_tca_and_vignetting_are_applied_about_the_lens_centre():
    """liblensfun applies the TCA and the vignetting about the lens's <center>, as the distortion:
    what ``LensfunTca(center=...)`` and ``lensfun_radius(..., center)`` say (the exports fit them so)."""
    centre = (0.05, -0.03)
    base = _entry()
    assert base.tca is not None
    tca = LensfunTca("poly3", base.tca.red, base.tca.blue, W, H, center=centre)
    entry = LensfunEntry(
        model=LensfunModel("poly5", (-0.04, 0.006), W, H, center=centre),
        lens=INFO,
        tca=tca,
        vignetting=base.vignetting,
        aperture=4.0,
        distance=2.0,
    )
    xml, _ = lensfun_database_text([entry])
    assert "<center " in xml
    mod = _modifier(xml, lensfunpy.ModifyFlags.DISTORTION | lensfunpy.ModifyFlags.TCA)
    sub = mod.apply_subpixel_geometry_distortion().reshape(-1, 3, 2).astype(np.float64)
    green = sub[:, 1]
    about_image_centre = LensfunTca("poly3", tca.red, tca.blue, W, H)
    for c, ch in ((0, "R"), (2, "B")):
        np.testing.assert_allclose(sub[:, c], tca.from_reference(ch, green), atol=2e-3, err_msg=ch)
        assert np.abs(sub[:, c] - about_image_centre.from_reference(ch, green)).max() > 4e-3  # the centre matters
    mod = _modifier(xml, lensfunpy.ModifyFlags.VIGNETTING)
    img = np.full((H, W, 3), 0.25, np.float32)
    assert mod.apply_color_modification(img)
    yy, xx = np.mgrid[0:H, 0:W].astype(float)
    xy = np.column_stack([xx.ravel(), yy.ravel()])
    assert entry.vignetting is not None
    v = entry.vignetting.factor(lensfun_radius(xy, W, H, centre)).reshape(H, W)
    np.testing.assert_allclose(0.25 / img[..., 0], v, rtol=2e-4)
    off = entry.vignetting.factor(lensfun_radius(xy, W, H)).reshape(H, W)
    assert np.abs(0.25 / img[..., 0] / off - 1).max() > 0.01
