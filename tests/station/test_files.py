"""Model files written by the station: atomic, readable YAML with provenance."""

import hashlib
import os

import yaml

from pipeline.model_file import FORMAT_NAME, read_model_file
from pipeline.models import RadialModel
from station.files import sha256_file, write_model_file, write_profile
from station.profile import Profile
from station.provenance import make_provenance

W, H = 640, 480
MODEL = RadialModel.for_image(
    W,
    H,
    k=(1.0, 0.0, 0.03, 0.0, -0.004),
    center=(322.3, 236.9),
    tangential=(1e-3, -2e-3),
    prism=(1e-4, 0.0, -2e-4, 0.0),
)


def test_file_is_readable_yaml_with_provenance(tmp_path):
    img = tmp_path / "shot.pgm"
    img.write_bytes(b"P5\n2 1\n255\n\x00\xff")
    prov = make_provenance([img], t=30, command=["harp", "calibrate", str(img)])
    path = write_profile(tmp_path / "m.yaml", Profile(MODEL, W, H, provenance=prov))
    doc = yaml.safe_load(path.read_text())
    assert doc["format"] == FORMAT_NAME and doc["format_version"] == 1
    assert doc["model"]["model"] == "radial" and doc["image"] == {"width": W, "height": H}
    p = doc["provenance"]
    assert p["software"].startswith("harp-station ") and p["created_utc"].endswith("Z")
    assert p["t"] == 30 and p["command"] == f"harp calibrate {img}"
    assert p["images"] == [{"path": str(img), "sha256": sha256_file(img)}]
    assert p["images"][0]["sha256"] == hashlib.sha256(b"P5\n2 1\n255\n\x00\xff").hexdigest()


def test_write_is_atomic_and_leaves_no_temporary(tmp_path):
    path = tmp_path / "m.yaml"
    path.write_text("old content")
    write_model_file(path, MODEL, width=W, height=H)
    assert os.listdir(tmp_path) == ["m.yaml"]
    assert read_model_file(path).width == W


# ------------------------------------------------ what is not a regular file (issue 14 item 7)
def _null_device(path):
    """A character device node equal to /dev/null (major 1, minor 3), made in the test's directory:
    the test never risks the machine's own /dev/null."""
    import stat

    os.mknod(path, stat.S_IFCHR | 0o666, os.makedev(1, 3))
    return path


def test_export_to_a_device_writes_it_and_does_not_replace_it(tmp_path, capsys):
    import stat

    from station.cli import main

    model = write_model_file(tmp_path / "lens.yaml", MODEL, width=W, height=H)
    null = _null_device(tmp_path / "null")
    before = os.stat(null)
    assert main(["export", str(model), "--format", "opencv", "-o", str(null)]) == 0
    capsys.readouterr()
    after = os.stat(null)
    assert stat.S_ISCHR(after.st_mode) and after.st_rdev == before.st_rdev and after.st_ino == before.st_ino
    assert sorted(os.listdir(tmp_path)) == ["lens.yaml", "null"]  # no temporary left either


def test_device_and_fifo_are_written_directly(tmp_path):
    import stat
    import threading

    from station.files import atomic_write_bytes

    null = _null_device(tmp_path / "null")
    atomic_write_bytes(null, b"data")
    assert stat.S_ISCHR(os.stat(null).st_mode)
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    got = []
    reader = threading.Thread(target=lambda: got.append(open(fifo, "rb").read()), daemon=True)
    reader.start()
    atomic_write_bytes(fifo, b"through the pipe")
    reader.join(10)
    assert got == [b"through the pipe"] and stat.S_ISFIFO(os.stat(fifo).st_mode)


def test_dash_is_standard_output(tmp_path, capfd):
    from station.files import atomic_write_bytes

    atomic_write_bytes("-", b"to stdout\n")
    assert capfd.readouterr().out == "to stdout\n"
    assert not (tmp_path / "-").exists() and not os.path.exists("-")


def test_symlink_is_followed(tmp_path):
    from station.files import atomic_write_bytes

    target = tmp_path / "real.yaml"
    target.write_text("old")
    link = tmp_path / "link.yaml"
    link.symlink_to(target)
    atomic_write_bytes(link, b"new")
    assert link.is_symlink() and os.readlink(link) == str(target)
    assert target.read_bytes() == b"new"
    assert sorted(os.listdir(tmp_path)) == ["link.yaml", "real.yaml"]


def test_mode_is_what_open_gives(tmp_path):
    import stat

    from station.files import atomic_write_bytes

    old = os.umask(0o027)
    try:
        atomic_write_bytes(tmp_path / "new.yaml", b"x")
        with open(tmp_path / "plain.yaml", "wb") as f:
            f.write(b"x")
    finally:
        os.umask(old)
    mode = stat.S_IMODE(os.stat(tmp_path / "new.yaml").st_mode)
    assert mode == stat.S_IMODE(os.stat(tmp_path / "plain.yaml").st_mode) == 0o640
    shared = tmp_path / "shared.yaml"
    shared.write_text("old")
    os.chmod(shared, 0o664)
    atomic_write_bytes(shared, b"new")  # replacing keeps the file's mode, as writing it in place would
    assert stat.S_IMODE(os.stat(shared).st_mode) == 0o664 and shared.read_bytes() == b"new"


def test_a_directory_is_an_error_and_nothing_is_left(tmp_path):
    import pytest

    from station.files import atomic_write_bytes

    (tmp_path / "d").mkdir()
    with pytest.raises(IsADirectoryError):
        atomic_write_bytes(tmp_path / "d", b"x")
    assert os.listdir(tmp_path / "d") == [] and sorted(os.listdir(tmp_path)) == ["d"]
