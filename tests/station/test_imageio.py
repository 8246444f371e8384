import cv2
import numpy as np
import pytest

from station.imageio import ImageReadError, read_grey


@pytest.fixture()
def grey():
    rng = np.random.default_rng(0)
    return (rng.random((40, 50)) * 255).astype(np.uint8)


@pytest.mark.parametrize("suffix", [".pgm", ".png", ".tif"])
@pytest.mark.parametrize("depth", [8, 16])
def test_grey_lossless_round_trip(tmp_path, grey, suffix, depth):
    img = grey if depth == 8 else grey.astype(np.uint16) * 257
    p = tmp_path / f"g{suffix}"
    cv2.imwrite(str(p), img)
    out = read_grey(p)
    assert out.dtype == img.dtype and out.shape == img.shape
    np.testing.assert_array_equal(out, img)


@pytest.mark.parametrize(
    "dtype,suffix", [(np.uint8, ".png"), (np.uint16, ".png"), (np.uint8, ".tif"), (np.uint16, ".tiff")]
)
def test_colour_to_grey_bt601(tmp_path, dtype, suffix):
    rng = np.random.default_rng(1)
    top = np.iinfo(dtype).max
    bgr = (rng.random((30, 40, 3)) * top).astype(dtype)
    p = tmp_path / f"c{suffix}"
    cv2.imwrite(str(p), bgr)
    out = read_grey(p)
    expect = np.rint(0.114 * bgr[..., 0] + 0.587 * bgr[..., 1] + 0.299 * bgr[..., 2].astype(float))
    assert out.dtype == dtype and out.ndim == 2
    np.testing.assert_array_equal(out, expect.astype(dtype))


def test_alpha_is_dropped(tmp_path):
    bgra = np.zeros((20, 30, 4), np.uint8)
    bgra[..., 1] = 200
    bgra[..., 3] = 7
    p = tmp_path / "a.png"
    cv2.imwrite(str(p), bgra)
    assert np.all(read_grey(p) == round(0.587 * 200))


def test_jpeg_colour(tmp_path):
    bgr = np.full((32, 32, 3), (10, 200, 60), np.uint8)
    p = tmp_path / "c.jpg"
    cv2.imwrite(str(p), bgr, [cv2.IMWRITE_JPEG_QUALITY, 100])
    out = read_grey(p)
    assert out.dtype == np.uint8 and abs(float(out.mean()) - (0.114 * 10 + 0.587 * 200 + 0.299 * 60)) < 2


def test_errors_name_the_file_and_reason(tmp_path, grey):
    cases = {}
    cases["missing"] = (tmp_path / "nope.png", "no such file")
    cases["dir"] = (tmp_path, "is a directory")
    e = tmp_path / "e.pgm"
    e.write_bytes(b"")
    cases["empty"] = (e, "empty file")
    p = tmp_path / "g.pgm"
    cv2.imwrite(str(p), grey)
    t = tmp_path / "t.pgm"
    t.write_bytes(p.read_bytes()[:-100])
    cases["truncated pgm"] = (t, "truncated: 1900 of 2000 bytes")
    h = tmp_path / "h.pgm"
    h.write_bytes(b"P5\n50 ")
    cases["truncated header"] = (h, "truncated PNM header")
    png = tmp_path / "g.png"
    cv2.imwrite(str(png), grey)
    tp = tmp_path / "tp.png"
    tp.write_bytes(png.read_bytes()[:-20])
    cases["png without end"] = (tp, "truncated")
    j = tmp_path / "j.jpg"
    cv2.imwrite(str(j), cv2.merge([grey] * 3))
    tj = tmp_path / "tj.jpg"
    tj.write_bytes(j.read_bytes()[:-10])
    cases["jpeg without end"] = (tj, "truncated")
    n = tmp_path / "n.tif"
    n.write_text("hello")
    cases["not an image"] = (n, "not a readable image")
    for name, (path, reason) in cases.items():
        with pytest.raises(ImageReadError) as exc:
            read_grey(path)
        msg = str(exc.value)
        assert msg.startswith(str(path)) and reason in msg and "\n" not in msg, (name, msg)
