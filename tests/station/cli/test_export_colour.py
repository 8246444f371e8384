"""A complete lensfun lens from the station (issue 24 item 4): distortion, TCA and vignetting measured
from the same camera RAW shots (``harp tca``, ``harp vignetting``), written by ``harp export --format
lensfun --tca --vignetting`` and applied by liblensfun itself (lensfunpy).

Truth: the shots are Bayer mosaics rendered through exact per-channel lens maps
(``tests/pipeline/colour_lenses.py``: the barrel lens of ``tests/pipeline/lenses.py`` for green, a
closed-form decentred TCA for red and blue) under a closed-form vignetting (cos^4) and an uneven
back-light that turns with the harp (``tests/pipeline/test_vignetting.py``), written as DNG files
(``tests/station/dng.py``) and read by the real LibRaw. Nothing of the truth is fitted.
"""

from __future__ import annotations

import re

import lensfunpy  # in the test extras: a missing lensfunpy fails, it is not skipped
import numpy as np
import pytest
import yaml

from pipeline.model_file import model_file_text
from pipeline.models.radial import RadialModel
from pipeline.models.tca_model import TcaField
from pipeline.render import HarpScene
from pipeline.render_colour import backlit_shading, render_mosaic
from station.cli import main
from tests.pipeline.colour_lenses import GAINS, colour_lens
from tests.pipeline.test_vignetting import ANGLES as ALL_ANGLES
from tests.pipeline.test_vignetting import LENS, H, W, cos4, uneven
from tests.station.dng import write_dng

PATTERN = "GRBG"
ANGLES = ALL_ANGLES[:3]  # three turns: the TCA sees three orientations, the back-light three angles
NAMES = ["--lens-maker", "Harp", "--lens-model", "Colour 35 test", "--mount", "Test", "--crop", "1"]
BODY = ["--camera-maker", "Harp", "--camera-model", "Body", "--focal-mm", "35"]


@pytest.fixture(scope="module")
def measured(tmp_path_factory):
    """Four DNG shots, the green lens's model file, and the files harp tca and harp vignetting wrote."""
    d = tmp_path_factory.mktemp("colour_export")
    lens = colour_lens(W, H)
    assert lens["lenses"]["G"] == LENS  # one green lens for the distortion, the TCA and the back-light
    paths = []
    for i, a in enumerate(ANGLES):
        scene = HarpScene(angle_deg=a, spacing_px=40.0, string_width_px=8.0, phase_px=7.0 * i, blur_px=1.0)
        shading = backlit_shading(W, H, cos4, uneven, a, LENS)
        r = render_mosaic(W, H, scene, lens["lenses"], PATTERN, gains=GAINS, shading=shading, seed=80 + i)
        paths.append(str(write_dng(d / f"shot{i}.dng", r.image, PATTERN, black=0, white=65535)))
    model = RadialModel(center=tuple(LENS.c), k=(1.0, 0.0) + (LENS.k[0], 0.0, LENS.k[1]), scale=LENS.r0)
    g = np.array([[0.0, 0.0], [W - 1.0, H - 1.0], [100.0, 300.0]])
    np.testing.assert_allclose(model.undistort_points(g), LENS.undistort_points(g), atol=1e-9)
    mpath = d / "lens.yaml"
    mpath.write_text(model_file_text(model, width=W, height=H))
    assert main(["tca", *paths, "--out", str(d / "tca.yaml")]) == 0
    angles = [f"{a:g}" for a in ANGLES]
    vig = ["vignetting", *paths, "--angles", *angles, "--model", str(mpath)]
    assert main([*vig, "--focal-mm", "35", "--aperture", "4", "-o", str(d / "vig.yaml")]) == 0
    return d, str(mpath), lens["tca"]


def _modifier(xml: str, flags):
    db = lensfunpy.Database(xml=xml, load_common=False, load_bundled=False)
    cam = db.find_cameras("Harp", "Body")[0]
    lens = db.find_lenses(cam, "Harp", "Colour 35 test")[0]
    mod = lensfunpy.Modifier(lens, cam.crop_factor, W, H)
    mod.initialize(35.0, 4.0, 1000.0, scale=1.0, pixel_format=np.float32, flags=flags)
    return mod


def _stated(text: str, pattern: str) -> float:
    m = re.search(pattern, text)
    assert m is not None, (pattern, text)
    return float(m[1])


def _export(capsys, d, model, out, *extra) -> tuple[str, str]:
    """``harp export --format lensfun`` with the TCA and vignetting files: (the XML, what was printed)."""
    capsys.readouterr()
    args = ["export", model, "--format", "lensfun", "-o", str(out), *NAMES, *BODY, "--no-shots", *extra]
    assert main([*args, "--tca", str(d / "tca.yaml"), "--vignetting", str(d / "vig.yaml")]) == 0
    return out.read_text(), capsys.readouterr().out


def _tca_figures(d, truth, xml: str, printed: str):
    """Per channel: lensfun against the harp TCA field, and the channels' mismatch against the truth."""
    tca_max = {c: _stated(printed, rf"TCA poly3 channel {c}: conversion error RMS \S+ px, max (\S+) px") for c in "RB"}
    assert f"max {tca_max['R']:.4f} px" in xml  # stated in the file's comment too
    mod = _modifier(xml, lensfunpy.ModifyFlags.DISTORTION | lensfunpy.ModifyFlags.TCA)
    sub = mod.apply_subpixel_geometry_distortion().reshape(-1, 3, 2).astype(np.float64)  # where each channel is read
    inside = np.all((sub[:, 1] >= 0) & (sub[:, 1] <= [W - 1, H - 1]), axis=1)
    assert inside.mean() > 0.9  # the corrected image reads (nearly) all inside the photo
    sub = sub[inside][::7]  # every 7th pixel (44 000 over the image): the fixed-point inverse costs
    green = sub[:, 1]
    doc = yaml.safe_load((d / "tca.yaml").read_text())
    out = {}
    for index, ch in ((0, "R"), (2, "B")):
        field = TcaField.from_dict(doc["channels"][ch]["field"])
        model_err = np.hypot(*(sub[:, index] - field.from_reference(green)).T).max()
        miss = np.hypot(*(truth[ch].to_reference(sub[:, index]) - green).T).max()  # red's image of what green sees
        before = np.hypot(*(truth[ch].to_reference(green) - green).T).max()
        print(
            f"\n{ch}: lensfun against the harp TCA field {model_err:.4f} px max (conversion stated {tca_max[ch]:.4f}); "
            f"channels' mismatch {before:.3f} px max without TCA correction, {miss:.4f} px with"
        )
        out[ch] = (tca_max[ch], model_err, miss, before)
    return out


def test_complete_lens_applied_by_lensfun(measured, tmp_path, capsys):
    """poly5 distortion: lensfun applies the TCA within its stated conversion error, the vignetting within 1 %."""
    d, model, truth = measured
    xml, printed = _export(capsys, d, model, tmp_path / "lens.xml", "--lensfun-model", "poly5")
    assert xml.count("<distortion ") == 1 and xml.count("<tca ") == 1, xml
    assert re.search(r'<vignetting model="pa" focal="35.0" aperture="4.0" distance="1000.0"', xml), xml
    for ch, (stated, model_err, miss, before) in _tca_figures(d, truth, xml, printed).items():
        assert model_err <= stated + 0.003, ch  # against the model: lensfun does what the file's terms say
        assert before > 0.4 and miss <= stated + 0.02, ch  # against the truth: the channels coincide

    vig_max = _stated(printed, r"vignetting pa: conversion error RMS \S+ %, max (\S+) %") / 100
    mod = _modifier(xml, lensfunpy.ModifyFlags.VIGNETTING)
    img = np.full((H, W, 3), 0.25, np.float32)
    assert mod.apply_color_modification(img)
    yy, xx = np.mgrid[0:H, 0:W].astype(np.float64)
    rel = 0.25 / img[..., 1].astype(np.float64).ravel() / cos4(np.column_stack([xx.ravel(), yy.ravel()])) - 1
    print(f"vignetting: lensfun against cos^4 {np.abs(rel).max():.4f} max (pa conversion stated {vig_max:.4f})")
    assert np.abs(rel).max() <= 0.01  # the target, through lensfun


def test_default_ptlens_lens(measured, tmp_path, capsys):
    """ptlens distortion (the default): liblensfun 0.3 applies the TCA beside it up to ~0.05 px off its own terms
    (measured here; with poly5 it does not), the channels still brought together 5-fold."""
    d, model, truth = measured
    xml, printed = _export(capsys, d, model, tmp_path / "lens.xml")
    assert '<distortion model="ptlens"' in xml
    for ch, (stated, model_err, miss, before) in _tca_figures(d, truth, xml, printed).items():
        assert model_err <= stated + 0.07 and miss <= stated + 0.07 and miss < before / 3, ch


def test_bad_colour_options_are_one_line(measured, tmp_path, capsys):
    d, model, _ = measured
    cases = [
        (["--format", "kalibr", "--tca", str(d / "tca.yaml")], "the kalibr format holds no TCA"),
        (["--format", "lensfun", "--vignetting", str(d / "tca.yaml")], "not a harp vignetting file"),
        (["--format", "lensfun", "--tca", str(d / "vig.yaml")], "not a harp TCA file"),
        (["--format", "lensfun", "--tca", str(d / "none.yaml")], "none.yaml"),
        (["--format", "lensfun", "--vignetting", str(d / "vig.yaml"), "--aperture", "-2"], "--aperture: expected"),
    ]
    wrong = tmp_path / "wrong.yaml"
    doc = yaml.safe_load((d / "vig.yaml").read_text())
    del doc["lensfun"]["element"]
    wrong.write_text(yaml.safe_dump(doc))
    cases.append((["--format", "lensfun", "--vignetting", str(wrong)], "give --aperture F"))
    doc["fit"]["image_size"] = [W + 2, H]
    other = tmp_path / "other.yaml"
    other.write_text(yaml.safe_dump(doc))
    cases.append((["--format", "lensfun", "--vignetting", str(other), "--aperture", "4"], f"for {W + 2}x{H} images"))
    for extra, want in cases:
        out = tmp_path / "out.xml"
        assert main(["export", model, *extra, "-o", str(out), "--no-shots"]) == 2, extra
        err = capsys.readouterr().err.strip()
        assert err.count("\n") == 0 and want in err, (extra, err)
        assert not out.exists()


def test_vignetting_of_raw_files(measured, tmp_path, capsys):
    """``harp vignetting`` on the DNG files (their green plane): within 1 % of cos^4 at the landmarks;
    a file LibRaw cannot read is one line, exit 2."""
    d, _, _ = measured
    doc = yaml.safe_load((d / "vig.yaml").read_text())
    pts = doc["relative_illumination"]["points"]
    truth = cos4(np.array([[p["x"], p["y"]] for p in pts]))
    np.testing.assert_allclose([p["fit"] for p in pts], truth, rtol=0.01)
    assert doc["images"][0]["edges"] > 10
    bad = tmp_path / "broken.nef"
    bad.write_bytes(b"\x00not a raw file" * 64)
    assert main(["vignetting", str(bad), str(bad), "--angles", "0", "90"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "broken.nef" in err and "LibRaw" in err
    clipped = write_dng(tmp_path / "clipped.dng", np.full((64, 96), 4095, np.uint16), PATTERN, white=4095)
    assert main(["vignetting", str(clipped), str(clipped), "--angles", "0", "90"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "clipped.dng" in err and "at the white level 4095 (saturated)" in err


def opencv_channel_figures(model, tca_path, truth, out, printed: str) -> dict:
    """Per channel, of an OpenCV per-channel file ``out`` (``printed``: what the export said): OpenCV's own maps
    (``initUndistortRectifyMap`` with the file's R and newK) against ``harp undistort --tca``'s maps of the
    model file ``model`` and the TCA file ``tca_path``, and the channels' mismatch against the exact ``truth``:
    ``{ch: (agree, green conversion stated, channel conversion stated, mismatch with, mismatch without)}``."""
    import cv2

    from pipeline.corrected_frame import FrameChoice, corrected_frame
    from pipeline.model_file import read_model_file
    from pipeline.models.tca_model import ChannelModel
    from pipeline.undistort_maps import DEFAULT_STEP_PX, fast_undistortion_maps
    from station.colour import read_tca_file

    stated = {
        c: _stated(printed, rf"{n}: camera_matrix_{n} .* RMS \S+ px, max (\S+) px")
        for c, n in (("R", "red"), ("B", "blue"))
    }
    green_max = _stated(printed, r"4-corner normalised: RMS \S+ px, max (\S+) px")
    fs = cv2.FileStorage(str(out), cv2.FILE_STORAGE_READ)
    k, r, new_k = (fs.getNode(n).mat() for n in ("camera_matrix", "rectification_matrix", "new_camera_matrix"))
    size = (int(fs.getNode("new_image_width").real()), int(fs.getNode("new_image_height").real()))
    nodes = {"G": "", "R": "_red", "B": "_blue"}
    cv_maps = {}
    for ch, suffix in nodes.items():
        k_c, d_c = (fs.getNode(n + suffix).mat() for n in ("camera_matrix", "distortion_coefficients"))
        assert k_c[0, 0] == k[0, 0] and k_c[1, 1] == k[1, 1]  # green's focal lengths, the channel's own centre
        mx, my = cv2.initUndistortRectifyMap(k_c, d_c, r, new_k, size, cv2.CV_32FC1)
        cv_maps[ch] = np.column_stack([mx.ravel(), my.ravel()]).astype(np.float64)
    assert fs.getNode("channel_conversion_max_px_red").real() == pytest.approx(stated["R"], abs=1e-4)
    mf = read_model_file(model)
    frame = corrected_frame(mf.model, W, H, FrameChoice())
    fields = read_tca_file(tca_path, W, H)
    inside = np.all((cv_maps["G"] >= 0) & (cv_maps["G"] <= [W - 1, H - 1]), axis=1)
    assert inside.mean() > 0.9
    out_figures = {}
    for ch in "RB":
        hm = fast_undistortion_maps(ChannelModel(mf.model, fields[ch]), W, H, step=DEFAULT_STEP_PX, frame=frame)
        harp = np.column_stack([hm.map_x.ravel(), hm.map_y.ravel()]).astype(np.float64)
        agree = np.hypot(*(cv_maps[ch] - harp)[inside].T).max()
        miss = np.hypot(*(truth[ch].to_reference(cv_maps[ch]) - cv_maps["G"])[inside].T).max()
        before = np.hypot(*(truth[ch].to_reference(cv_maps["G"]) - cv_maps["G"])[inside].T).max()
        print(
            f"\n{ch}: OpenCV against harp undistort --tca {agree:.4f} px max (green conversion {green_max:.4f}, "
            f"channel {stated[ch]:.4f} stated); channels' mismatch {before:.3f} px without, {miss:.4f} px with"
        )
        out_figures[ch] = (agree, green_max, stated[ch], miss, before)
    return out_figures


def test_opencv_channel_files_agree_with_harp_undistort(measured, tmp_path, capsys):
    """``--format opencv --tca``: red's and blue's coefficients with green's camera matrix; OpenCV's own
    per-channel maps (``initUndistortRectifyMap`` with the file's R and newK) against ``harp undistort
    --tca``'s maps, and the channels brought together (truth: the exact TCA)."""
    d, model, truth = measured
    out = tmp_path / "lens_opencv.yaml"
    capsys.readouterr()
    assert (
        main(["export", model, "--format", "opencv", "-o", str(out), "--tca", str(d / "tca.yaml"), "--no-shots"]) == 0
    )
    printed = capsys.readouterr().out
    for ch, (agree, green_max, stated, miss, before) in opencv_channel_figures(
        model, d / "tca.yaml", truth, out, printed
    ).items():
        assert agree <= green_max + stated + 0.01, ch
        assert before > 0.4 and miss <= stated + 0.02, ch


def test_profile_export_carries_the_colour_too(measured, tmp_path, capsys):
    """``harp profile export`` takes the same options: a stored profile (640x480) exported as a complete
    lensfun lens, liblensfun reads red where the measured field puts it (within the stated conversion)."""
    from station.qa.verdicts import qa_verdict
    from station.store import ProfileStore
    from tests.station.cli.test_profile import PASSING
    from tests.station.store.test_database import profile

    d, _, _ = measured
    p = profile(session="colour", focus=0.5, lens=("Harp", "Colour 35 test", "S1"))
    with ProfileStore(tmp_path / "p.sqlite") as st:
        pid = st.put_profile(p.with_(qa=qa_verdict(p, PASSING)))
    out = tmp_path / "profile.xml"
    capsys.readouterr()
    argv = ["profile", "export", "--id", str(pid), "--store", str(tmp_path / "p.sqlite"), "--format", "lensfun"]
    argv += ["-o", str(out), *NAMES, *BODY, "--no-shots", "--tca", str(d / "tca.yaml")]
    assert main([*argv, "--vignetting", str(d / "vig.yaml")]) == 0, capsys.readouterr().err
    xml = out.read_text()
    assert xml.count("<tca ") == 1 and xml.count('<vignetting model="pa"') == 1, xml
    stated = _stated(capsys.readouterr().out, r"TCA poly3 channel R: conversion error RMS \S+ px, max (\S+) px")
    mod = _modifier(xml, lensfunpy.ModifyFlags.TCA)
    sub = mod.apply_subpixel_distortion().reshape(-1, 3, 2).astype(np.float64)[::7]
    field = TcaField.from_dict(yaml.safe_load((d / "tca.yaml").read_text())["channels"]["R"]["field"])
    assert np.hypot(*(sub[:, 0] - field.from_reference(sub[:, 1])).T).max() <= stated + 0.003
