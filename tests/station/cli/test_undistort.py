"""``harp undistort``: corrected images keep format, channels and bit depth; strings come out straight."""

import cv2
import numpy as np
import pytest

from pipeline.measure import measure_image
from pipeline.models import RadialModel
from pipeline.render import HarpScene, render_harp
from pipeline.straightness import straightness
from pipeline.undistort_maps import fast_undistortion_maps
from station.cli import main
from station.files import write_model_file

W, H = 480, 360
LENS = RadialModel.for_image(W, H, k=(1.0, 0.0, 0.06), tangential=(1e-3, -5e-4))


@pytest.fixture(scope="module")
def setup(tmp_path_factory):
    d = tmp_path_factory.mktemp("undist")
    model = d / "lens.yaml"
    write_model_file(model, LENS, width=W, height=H)
    r = render_harp(W, H, HarpScene(angle_deg=4.0, spacing_px=40.0), lens=LENS, noise_sigma=0.5, seed=3)
    grey = d / "shot.pgm"
    assert cv2.imwrite(str(grey), r.image)
    r16 = render_harp(W, H, HarpScene(angle_deg=91.0, spacing_px=40.0), lens=LENS, bit_depth=16, seed=4)
    png16 = d / "shot16.png"
    assert cv2.imwrite(str(png16), r16.image)
    colour = d / "colour.png"
    assert cv2.imwrite(str(colour), np.dstack([r.image, r.image // 2, 255 - r.image]))
    return d, model, grey, png16, colour, r.image


def test_corrected_images_keep_format_and_strings_are_straight(setup, tmp_path, capsys):
    d, model, grey, png16, colour, image = setup
    out = tmp_path / "out"
    assert main(["undistort", str(model), str(grey), str(png16), str(colour), "-o", str(out)]) == 0
    text = capsys.readouterr().out
    assert text.count("maps for 480x360") == 1  # computed once, reused for all three images
    g = cv2.imread(str(out / "shot.pgm"), cv2.IMREAD_UNCHANGED)
    assert g.dtype == np.uint8 and g.shape == (H, W)
    g16 = cv2.imread(str(out / "shot16.png"), cv2.IMREAD_UNCHANGED)
    assert g16.dtype == np.uint16 and g16.shape == (H, W) and g16.max() > 255 * 40
    c = cv2.imread(str(out / "colour.png"), cv2.IMREAD_UNCHANGED)
    assert c.shape == (H, W, 3) and c.dtype == np.uint8
    np.testing.assert_array_equal(c[:, :, 0], g)  # channels remapped identically
    before, after = measure_image(image), measure_image(g)
    assert before.d > 0.3 and after.n_lines >= before.n_lines - 2
    # straight up to noise and resampling (the same scene rendered without lens measures 0.0005 px)
    assert after.d < 0.003, (before.d, after.d)


def test_fast_maps_agree_with_exact_per_pixel_maps():
    fast = fast_undistortion_maps(LENS, W, H, step=16)
    assert fast.step == 16 and fast.interp_error_px < 1e-4
    ex, ey = LENS.undistortion_maps(W, H)
    assert np.max(np.abs(fast.map_x - ex)) < 1e-4 and np.max(np.abs(fast.map_y - ey)) < 1e-4


def test_bad_inputs_exit_2_with_one_line(setup, tmp_path, capsys):
    d, model, grey, png16, colour, image = setup
    bad = tmp_path / "bad.yaml"
    bad.write_text("format: harp-distortion-model\nformat_version: 3\n")
    assert main(["undistort", str(bad), str(grey), "-o", str(tmp_path / "o")]) == 2
    assert "unknown model file format version 3" in capsys.readouterr().err
    small = tmp_path / "small.pgm"
    cv2.imwrite(str(small), image[:100, :100])
    assert main(["undistort", str(model), str(small), "-o", str(tmp_path / "o")]) == 2
    assert "image is 100x100 but the model" in capsys.readouterr().err
    assert main(["undistort", str(model), str(tmp_path / "none.pgm"), "-o", str(tmp_path / "o")]) == 2
    assert "none.pgm: no such file" in capsys.readouterr().err
    assert main(["undistort", str(model), str(grey), "-o", str(d)]) == 2
    assert "would overwrite the input" in capsys.readouterr().err
    junk = tmp_path / "junk.png"
    junk.write_bytes(b"not an image at all")
    assert main(["undistort", str(model), str(junk), "-o", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("harp undistort: ") and "junk.png" in err and err.count("\n") == 1


def test_bad_images_are_named_and_the_others_still_corrected(setup, tmp_path, capsys):
    d, model, grey, png16, colour, image = setup
    small = tmp_path / "small.pgm"
    cv2.imwrite(str(small), image[:100, :100])
    missing = tmp_path / "none.pgm"
    out = tmp_path / "o"
    assert main(["undistort", str(model), str(missing), str(grey), str(small), str(png16), "-o", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 2 and "none.pgm: no such file" in err[0] and "small.pgm: image is 100x100" in err[1]
    assert sorted(p.name for p in out.iterdir()) == ["shot.pgm", "shot16.png"]


def test_output_dir_that_cannot_be_created_is_one_line(setup, tmp_path, capsys):
    d, model, grey, png16, colour, image = setup
    blocker = tmp_path / "a_file"
    blocker.write_text("x")
    assert main(["undistort", str(model), str(grey), "-o", str(blocker / "out")]) == 2
    err = capsys.readouterr().err
    assert err == f"harp undistort: {blocker / 'out'}: cannot create the output directory (Not a directory)\n"


def _colour_shot(angle: float, seed: int, tca) -> np.ndarray:
    """A BGR harp shot, each channel rendered through its own exact map (green: LENS; red and blue:
    LENS after the closed-form TCA of tests/pipeline/colour_lenses.py)."""
    from tests.pipeline.colour_lenses import ChannelLens

    scene = HarpScene(angle_deg=angle, spacing_px=40.0, string_width_px=8.0, blur_px=1.0)
    lenses = {"R": ChannelLens(LENS, tca["R"]), "G": LENS, "B": ChannelLens(LENS, tca["B"])}
    planes = {
        c: render_harp(W, H, scene, lens=m, noise_sigma=0.5, seed=seed + i).image
        for i, (c, m) in enumerate(lenses.items())
    }
    return np.dstack([planes["B"], planes["G"], planes["R"]])


def _channel_offset(img: np.ndarray, index: int) -> float:
    """Median |offset| (px) of channel ``index``'s edges from green's, along green's normals."""
    from pipeline.tca import edge_offsets

    ref = [ln.points for ln in measure_image(np.ascontiguousarray(img[..., 1])).lines]
    ch = [ln.points for ln in measure_image(np.ascontiguousarray(img[..., index])).lines]
    return float(np.median(np.abs(edge_offsets(ch, ref).offset)))


def test_tca_corrected_channels_coincide(tmp_path, capsys):
    """Issue 24 item 2: `harp undistort --tca` with the fields `harp tca` measured on four other
    shots: the corrected red and blue edges lie on green's (truth: the shots' exact per-channel maps)."""
    from tests.pipeline.colour_lenses import colour_lens

    tca = colour_lens(W, H, strength=3.0)["tca"]  # red ~1 px, blue ~0.8 px at the corners
    shots = []
    for i, ang in enumerate((5.0, 50.0, 95.0, 140.0)):
        p = tmp_path / f"fit{i}.png"
        assert cv2.imwrite(str(p), _colour_shot(ang, 10 * i, tca))
        shots.append(str(p))
    assert main(["tca", *shots, "--out", str(tmp_path / "tca.yaml")]) == 0
    model = tmp_path / "lens.yaml"
    write_model_file(model, LENS, width=W, height=H)
    test = tmp_path / "test.png"
    shot = _colour_shot(27.0, 99, tca)
    assert cv2.imwrite(str(test), shot)
    capsys.readouterr()
    assert main(["undistort", str(model), str(test), "-o", str(tmp_path / "plain")]) == 0
    assert (
        main(["undistort", str(model), str(test), "-o", str(tmp_path / "tca"), "--tca", str(tmp_path / "tca.yaml")])
        == 0
    )
    out = capsys.readouterr().out
    assert "maps for 480x360, R" in out and "maps for 480x360, B" in out
    plain = cv2.imread(str(tmp_path / "plain" / "test.png"), cv2.IMREAD_UNCHANGED)
    fixed = cv2.imread(str(tmp_path / "tca" / "test.png"), cv2.IMREAD_UNCHANGED)
    for index in (2, 0):  # red, blue
        before, after = _channel_offset(plain, index), _channel_offset(fixed, index)
        print(f"channel {index}: median offset from green {before:.4f} px without --tca, {after:.4f} px with")
        assert before > 0.1 and after < 0.02 and after < before / 8, (index, before, after)
    np.testing.assert_array_equal(fixed[..., 1], plain[..., 1])  # green: the model alone, as before


def test_tca_needs_colour_images_and_a_tca_file(setup, tmp_path, capsys):
    d, model, grey, png16, colour, image = setup
    bad = tmp_path / "bad.yaml"
    bad.write_text("format: something-else\n")
    assert main(["undistort", str(model), str(colour), "-o", str(tmp_path / "o"), "--tca", str(bad)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "bad.yaml: not a harp TCA file" in err
    from pipeline.models.tca_model import TcaField

    doc = {"format": "harp-tca", "channels": {c: {"field": TcaField.zero(W, H, 3).to_dict()} for c in "RB"}}
    ok = tmp_path / "zero.json"
    import json

    ok.write_text(json.dumps(doc))
    assert main(["undistort", str(model), str(grey), "-o", str(tmp_path / "o2"), "--tca", str(ok)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "a grey image has no colour channels" in err
    other = {"format": "harp-tca", "channels": {c: {"field": TcaField.zero(W + 2, H, 3).to_dict()} for c in "RB"}}
    ok.write_text(json.dumps(other))
    assert main(["undistort", str(model), str(colour), "-o", str(tmp_path / "o3"), "--tca", str(ok)]) == 2
    assert "the TCA is for 482x360 images, the model for 480x360" in capsys.readouterr().err


def test_alpha_one_keeps_every_pixel_of_the_photo_and_the_strings_straight(setup, tmp_path, capsys):
    d, model, grey, _, _, image = setup
    out = tmp_path / "alpha"
    assert main(["undistort", str(model), str(grey), "-o", str(out), "--alpha", "1", "--size", "600x450"]) == 0
    assert "corrected image 600x450" in capsys.readouterr().out
    g = cv2.imread(str(out / "shot.pgm"), cv2.IMREAD_UNCHANGED)
    assert g.shape == (450, 600)
    # every photo pixel is kept: the bright background reaches each side of the corrected image
    assert min(g[:, :3].max(), g[:, -3:].max(), g[:3, :].max(), g[-3:, :].max()) > 100
    # straight strings, as in the default image up to the magnification (1.18 here) and the strings' ends
    # at the empty border (the photo's own d is > 0.3 px); edges of 3-4 points where a string meets the empty border are not strings)
    lines = [ln.points for ln in measure_image(g).lines if len(ln.points) >= 10]
    assert len(lines) >= measure_image(image).n_lines - 2 and straightness(lines).d < 0.01


def test_bad_frame_options_exit_2_with_one_line(setup, tmp_path, capsys):
    _, model, grey, _, _, _ = setup
    for extra, said in (
        (["--size", "600"], "--size: expected WIDTHxHEIGHT"),
        (["--alpha", "1.5"], "--alpha: expected a number in [0, 1]"),
        (["--alpha", "1", "--scale", "2"], "--scale and --alpha are alternatives"),
        (["--overscan", "--size", "600x400"], "--overscan sets the size"),
    ):
        assert main(["undistort", str(model), str(grey), "-o", str(tmp_path / "x"), *extra]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and said in err[0], err
    assert not (tmp_path / "x").exists()
