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
