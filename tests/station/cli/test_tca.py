"""``harp tca``: camera RAW files (DNG, read by the real LibRaw) and colour PNGs of rendered colour harps.

Truth: the exact per-channel maps the shots were rendered through
(``tests/pipeline/colour_lenses.py``); the RAW files are written from the mosaics by a
DNG writer that follows the specification (``tests/station/dng.py``).
"""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest
import yaml

from pipeline.models.tca_model import TcaField
from pipeline.render import HarpScene
from pipeline.render_colour import render_mosaic
from pipeline.tca import field_difference
from station.cli import main
from tests.pipeline.colour_lenses import COLOUR_ANGLES, GAINS, colour_lens
from tests.station.dng import write_dng

W, H = 640, 480


@pytest.fixture(scope="module")
def mosaics():
    lens = colour_lens(W, H)
    out = []
    for i, ang in enumerate(COLOUR_ANGLES):
        scene = HarpScene(angle_deg=ang, spacing_px=40.0, string_width_px=8.0, phase_px=7.0 * i, blur_px=1.0)
        out.append(render_mosaic(W, H, scene, lens["lenses"], "GBRG", gains=GAINS, seed=40 + i).image)
    return out


def test_raw_files_give_the_exact_field(tmp_path, mosaics, capsys):
    paths = [str(write_dng(tmp_path / f"shot{i}.dng", m, "GBRG")) for i, m in enumerate(mosaics)]
    out = tmp_path / "tca.yaml"
    assert main(["tca", *paths, "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "lensfun poly3" in text
    header, *planes = text.split("\n\n")[0].splitlines()  # off a terminal: the planes tab-separated
    assert header.split("\t")[:4] == ["image", "pattern", "plane", "edges"]
    assert {tuple(r.split("\t")[:2]) for r in planes} == {(p, "GBRG") for p in paths}
    doc = yaml.safe_load(out.read_text())
    truth = colour_lens(W, H)["tca"]
    for ch in "RB":
        fld = TcaField.from_dict(doc["channels"][ch]["field"])
        err = field_difference(fld.to_reference, truth[ch].to_reference, W, H)
        assert err.rms < 0.01 and err.max < 0.03, (ch, err)
    assert doc["lensfun"]["linear"]["red"][0] > 1.0 > doc["lensfun"]["linear"]["blue"][0]


def test_json_and_colour_png(tmp_path, mosaics, capsys):
    """A 16-bit colour PNG (a demosaiced image) is measured per channel; --json is one object."""
    paths = []
    for i, m in enumerate(mosaics[:2]):
        bgr = cv2.cvtColor(m, cv2.COLOR_BayerGR2BGR)  # OpenCV names GBRG from the second row
        p = tmp_path / f"shot{i}.png"
        cv2.imwrite(str(p), bgr)
        paths.append(str(p))
    assert main(["tca", *paths, "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["format"] == "harp-tca" and set(doc["channels"]) == {"R", "B"}
    assert [p["pattern"] for p in doc["per_image"]] == ["BGR"] * 2
    # a demosaiced image sees the TCA too (its size, within the interpolation's pull towards green)
    assert doc["channels"]["R"]["field_max_px"] > 0.3


def test_mono_image_and_bad_raw_are_one_line(tmp_path, mosaics, capsys):
    grey = tmp_path / "mono.png"
    cv2.imwrite(str(grey), mosaics[0])
    assert main(["tca", str(grey)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "mono.png" in err and "monochrome camera" in err
    bad = tmp_path / "broken.nef"
    bad.write_bytes(b"\x00not a raw file" * 64)
    assert main(["tca", str(bad)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "broken.nef" in err and "LibRaw" in err


def test_one_orientation_is_one_line(tmp_path, mosaics, capsys):
    p = write_dng(tmp_path / "one.dng", mosaics[0], "GBRG")
    assert main(["tca", str(p), str(p)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "one orientation" in err


def test_raw_reader_pattern_and_levels(tmp_path):
    from station.raw import read_raw

    m = (np.arange(64 * 48).reshape(48, 64) * 37 % 4000 + 100).astype(np.uint16)
    for pattern in ("RGGB", "BGGR", "GRBG", "GBRG"):
        r = read_raw(write_dng(tmp_path / f"{pattern}.dng", m, pattern, black=64, white=4095))
        assert r.pattern == pattern
        np.testing.assert_array_equal(r.mosaic, m)
        assert (r.black_level, r.white_level) == (64.0, 4095.0)


def test_rawpy_is_imported_only_for_raw_files():
    import subprocess
    import sys

    code = "import sys, station.cli.tca, station.colour; print('rawpy' in sys.modules)"
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert done.stdout.strip() == "False", done.stderr
