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


# ------------------------------------------------------- bounded reading (issue 14 item 8)
def _png_header(w, h):
    import struct
    import zlib

    def chunk(kind, body):
        return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body) & 0xFFFFFFFF)

    ihdr = struct.pack(">IIBBBBB", w, h, 8, 0, 0, 0, 0)
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", zlib.compress(b"\0" * 64)) + chunk(b"IEND", b"")


def _tiff_header(w, h, order="<"):
    import struct

    # one IFD: width, height (LONG), bits per sample 8, one strip of a few bytes
    entries = [(256, 4, 1, w), (257, 4, 1, h), (258, 3, 1, 8), (273, 4, 1, 8 + 2 + 12 * 5 + 4), (279, 4, 1, 16)]
    body = struct.pack(order + "H", len(entries))
    for tag, typ, count, value in entries:
        v = struct.pack(order + ("HH" if typ == 3 else "I"), *((value, 0) if typ == 3 else (value,)))
        body += struct.pack(order + "HHI", tag, typ, count) + v
    body += struct.pack(order + "I", 0)
    head = (b"II*\x00" if order == "<" else b"MM\x00*") + struct.pack(order + "I", 8)
    return head + body + b"\0" * 16


@pytest.mark.parametrize(
    "name,data",
    [
        ("huge.png", _png_header(100_000, 100_000)),
        ("huge.tif", _tiff_header(100_000, 100_000)),
        ("huge-be.tiff", _tiff_header(100_000, 100_000, ">")),
        ("huge.pgm", b"P5\n100000 100000\n255\n" + b"\0" * 100),
    ],
    ids=["png", "tiff", "tiff-big-endian", "pgm"],
)
def test_header_claiming_a_huge_image_is_refused_before_decoding(tmp_path, monkeypatch, name, data):
    from station import imageio

    def no_decode(*a, **k):
        raise AssertionError("decoded")

    monkeypatch.setattr(imageio.cv2, "imdecode", no_decode)
    p = tmp_path / name
    p.write_bytes(data)
    with pytest.raises(ImageReadError) as exc:
        read_grey(p)
    msg = str(exc.value)
    assert msg.startswith(str(p)) and "image too large: 100000x100000" in msg and "HARP_MAX_IMAGE_PIXELS" in msg
    assert "\n" not in msg


def test_pixel_limit_is_configurable(tmp_path, grey, monkeypatch):
    p = tmp_path / "g.png"
    cv2.imwrite(str(p), grey)  # 50x40 = 2000 pixels
    assert read_grey(p, max_pixels=2000).shape == (40, 50)
    with pytest.raises(ImageReadError, match="2000 pixels, the limit is 1999"):
        read_grey(p, max_pixels=1999)
    monkeypatch.setenv("HARP_MAX_IMAGE_PIXELS", "1000")
    with pytest.raises(ImageReadError, match="the limit is 1000"):
        read_grey(p)


def test_only_regular_files_are_read(tmp_path):
    import os
    import threading

    fifo = tmp_path / "pipe.pgm"
    os.mkfifo(fifo)
    out = []

    def read(path):
        try:
            read_grey(path)
        except ImageReadError as exc:
            out.append(str(exc))

    for path in ("/dev/zero", fifo):  # endless, and one that would block forever
        t = threading.Thread(target=read, args=(path,), daemon=True)
        t.start()
        t.join(10)
        assert not t.is_alive(), f"{path}: still reading"
    assert out[0] == "/dev/zero: not a regular file (a character device); give an image file"
    assert out[1] == f"{fifo}: not a regular file (a FIFO); give an image file"
