"""``harp measure``: formats, JSON schema, tables, overlays and every kind of bad input."""

import json
import os
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from pipeline.models.radial import RadialModel
from pipeline.render import HarpScene, render_harp
from station.cli import main

REPO = Path(__file__).resolve().parents[3]
W, H = 640, 480


@pytest.fixture(scope="module")
def harp8():
    lens = RadialModel.for_image(W, H, k=(1.0, 0.0, 0.02))
    return render_harp(W, H, HarpScene(angle_deg=80.0, spacing_px=50.0), lens=lens, noise_sigma=1.5, seed=1).image


@pytest.fixture(scope="module")
def harp16():
    return render_harp(W, H, HarpScene(angle_deg=10.0, spacing_px=50.0), noise_sigma=1.5, bit_depth=16, seed=2).image


@pytest.fixture()
def files(tmp_path, harp8, harp16):
    f = {}
    f["pgm"] = tmp_path / "harp.pgm"
    cv2.imwrite(str(f["pgm"]), harp8)
    f["png16"] = tmp_path / "harp16.png"
    cv2.imwrite(str(f["png16"]), harp16)
    f["tif16"] = tmp_path / "harp16.tif"
    cv2.imwrite(str(f["tif16"]), harp16)
    colour = cv2.merge([harp8, harp8, harp8])
    f["jpg"] = tmp_path / "colour.jpg"
    cv2.imwrite(str(f["jpg"]), colour, [cv2.IMWRITE_JPEG_QUALITY, 97])
    # bad inputs
    data = f["pgm"].read_bytes()
    f["truncated_pgm"] = tmp_path / "truncated.pgm"
    f["truncated_pgm"].write_bytes(data[: len(data) // 2])
    png = tmp_path / "harp8.png"
    cv2.imwrite(str(png), harp8)
    f["truncated_png"] = tmp_path / "truncated.png"
    f["truncated_png"].write_bytes(png.read_bytes()[:-2000])
    f["junk"] = tmp_path / "notes.png"
    f["junk"].write_text("this is not an image\n")
    f["empty"] = tmp_path / "empty.tif"
    f["empty"].write_bytes(b"")
    rng = np.random.default_rng(3)
    f["blank"] = tmp_path / "blank.png"
    cv2.imwrite(str(f["blank"]), np.clip(180 + rng.normal(0, 1.5, (H, W)), 0, 255).astype(np.uint8))
    f["dir"] = tmp_path / "a_directory"
    f["dir"].mkdir()
    f["missing"] = tmp_path / "missing.pgm"
    return f


def _json(capsys, argv):
    code = main(argv)
    out, err = capsys.readouterr()
    return code, json.loads(out), err


def test_json_schema_and_values(capsys, files):
    code, doc, err = _json(capsys, ["measure", "--json", str(files["pgm"]), str(files["png16"])])
    assert code == 0 and err == ""
    assert set(doc) >= {"d", "d_max", "n_lines", "images"}
    assert [im["path"] for im in doc["images"]] == [str(files["pgm"]), str(files["png16"])]
    for im in doc["images"]:
        assert im["width"] == W and im["height"] == H
        assert isinstance(im["n_lines"], int) and im["n_lines"] == len(im["lines"]) >= 10
        for ln in im["lines"]:
            assert isinstance(ln["points"], int) and ln["points"] >= 3
            for k in ("rms", "p2p", "angle_deg", "length_px", "hf_rms"):
                assert isinstance(ln[k], float)
    distorted, straight = doc["images"]
    assert straight["d"] < 0.01 < 0.1 < distorted["d"]
    assert doc["n_lines"] == distorted["n_lines"] + straight["n_lines"]
    # overall d pools all edges: between the two images' values
    assert straight["d"] < doc["d"] < distorted["d"]


def test_formats_and_colour_give_the_same_measure(capsys, files):
    code, doc, _ = _json(
        capsys, ["measure", "--json", str(files["png16"]), str(files["tif16"]), str(files["pgm"]), str(files["jpg"])]
    )
    assert code == 0
    png16, tif16, pgm, jpg = doc["images"]
    assert png16["d"] == tif16["d"]  # lossless 16-bit in two containers
    assert jpg["n_lines"] == pgm["n_lines"]
    assert jpg["d"] == pytest.approx(pgm["d"], rel=0.05)  # grey from colour JPEG (lossy)


def test_t_option(capsys, files):
    _, d30, _ = _json(capsys, ["measure", "--json", str(files["pgm"])])
    _, d10, _ = _json(capsys, ["measure", "--json", "--t", "10", str(files["pgm"])])
    assert d10["t"] == 10 and d30["t"] == 30
    n30 = sum(ln["points"] for ln in d30["images"][0]["lines"])
    n10 = sum(ln["points"] for ln in d10["images"][0]["lines"])
    assert n10 > 2.5 * n30
    with pytest.raises(SystemExit) as exc:
        main(["measure", "--t", "0", str(files["pgm"])])
    assert exc.value.code == 2


def test_tables(capsys, files):
    code = main(["measure", str(files["pgm"]), str(files["png16"])])
    out, err = capsys.readouterr()
    assert code == 0 and err == ""
    assert "overall" in out and "harp16.png" in out and "d_max" in out
    _, doc, _ = _json(capsys, ["measure", "--json", str(files["pgm"]), str(files["png16"])])
    assert f"{doc['d']:.4f}" in out


def test_overlay(capsys, files, tmp_path):
    odir = tmp_path / "overlays" / "new"
    code = main(["measure", "--json", "--overlay", str(odir), str(files["pgm"]), str(files["png16"])])
    capsys.readouterr()
    assert code == 0
    for name in ("harp.pgm.overlay.png", "harp16.png.overlay.png"):
        img = cv2.imread(str(odir / name), cv2.IMREAD_COLOR)
        assert img is not None and img.shape[1] == W and img.shape[0] > H
        # the measured edges are drawn in colour on the grey photo
        top = img[:H].astype(int)
        colourful = (np.abs(top[..., 0] - top[..., 1]) + np.abs(top[..., 1] - top[..., 2])) > 60
        assert colourful.sum() > 1000


BAD = {
    "missing": "no such file",
    "dir": "is a directory",
    "truncated_pgm": "truncated",
    "truncated_png": "truncated",
    "junk": "not a readable image",
    "empty": "empty file",
    "blank": "no strings found",
}


@pytest.mark.parametrize("bad", sorted(BAD))
def test_bad_input_is_reported_and_others_still_measured(capsys, files, bad):
    good = str(files["pgm"])
    code, doc, err = _json(capsys, ["measure", "--json", good, str(files[bad]), str(files["png16"])])
    assert code == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert str(files[bad]) in lines[0] and BAD[bad] in lines[0]
    assert [im["path"] for im in doc["images"]] == [good, str(files["png16"])]
    assert doc["errors"][0]["path"] == str(files[bad])
    # and without --json: same one line, tables for the good ones
    code = main(["measure", good, str(files[bad])])
    out, err = capsys.readouterr()
    assert code == 2 and len(err.strip().splitlines()) == 1 and "overall" in out


def test_only_bad_input(capsys, files):
    code, doc, err = _json(capsys, ["measure", "--json", str(files["blank"])])
    assert code == 2 and doc["images"] == [] and doc["d"] is None and doc["n_lines"] == 0
    assert "no strings found" in err


def test_subprocess_exit_code_stdout_and_stderr(files):
    env = dict(os.environ, PYTHONPATH=str(REPO))
    p = subprocess.run(
        [
            sys.executable,
            "-m",
            "station.cli",
            "measure",
            "--json",
            str(files["pgm"]),
            str(files["truncated_pgm"]),
            str(files["dir"]),
        ],
        capture_output=True,
        text=True,
        cwd=REPO,
        env=env,
        timeout=120,
    )
    assert p.returncode == 2
    doc = json.loads(p.stdout)  # exactly one JSON object on stdout
    assert len(doc["images"]) == 1 and doc["images"][0]["n_lines"] >= 10
    err = p.stderr.strip().splitlines()
    assert len(err) == 2
    assert str(files["truncated_pgm"]) in err[0] and "truncated" in err[0]
    assert str(files["dir"]) in err[1] and "directory" in err[1]


def test_png_cut_in_the_middle_gives_one_line_and_no_libpng_noise(capfd, files):
    # libpng writes "libpng error: ..." to the C-level stderr when it decodes a short
    # PNG; the file must be rejected before decoding so stderr holds our one line only
    png = files["truncated_png"].with_name("half.png")
    cv2.imwrite(str(png), cv2.imread(str(files["pgm"]), cv2.IMREAD_UNCHANGED))
    data = png.read_bytes()
    png.write_bytes(data[: len(data) // 2])
    code = main(["measure", str(png)])
    out, err = capfd.readouterr()
    assert code == 2
    assert err.strip().splitlines() == [f"harp measure: {png}: truncated image data"]


def test_stdout_closed_early_gives_no_traceback(files):
    # ``harp measure --json ... | head -c 10``: the reader goes away mid-output
    env = dict(os.environ, PYTHONPATH=str(REPO))
    p = subprocess.Popen(
        [sys.executable, "-m", "station.cli", "measure", "--json", "--t", "1", str(files["pgm"])],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        cwd=REPO,
        env=env,
    )
    # close before the child has written anything (it is still importing), so its
    # first write fails for certain: reading some bytes first would race with a child
    # that fits its whole output into the pipe buffer and exits 0
    p.stdout.close()
    err = p.stderr.read().decode()
    code = p.wait(timeout=120)
    assert "Traceback" not in err and "BrokenPipeError" not in err, err
    assert code == 141


def test_overlay_dir_that_is_a_file(capsys, files, tmp_path):
    blocker = tmp_path / "overlays.png"
    blocker.write_bytes(b"x")
    code = main(["measure", "--overlay", str(blocker), str(files["pgm"])])
    out, err = capsys.readouterr()
    assert code == 2
    assert err == f"harp measure: {blocker}: cannot create overlay directory: exists and is not a directory\n"
    code = main(["measure", "--overlay", str(blocker / "sub"), str(files["pgm"])])
    err = capsys.readouterr().err
    assert code == 2 and err == f"harp measure: {blocker / 'sub'}: cannot create overlay directory: Not a directory\n"


def test_too_large_t_is_told_apart_from_no_strings(capsys, files):
    # the strings are there; t = 1000 on a 480 px image leaves no edge enough points
    code = main(["measure", "--t", "1000", str(files["pgm"]), str(files["blank"])])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 2
    assert str(files["pgm"]) in err[0] and "string edges found, but each keeps < 3 points" in err[0]
    assert "t=1000: use a smaller --t" in err[0]
    assert str(files["blank"]) in err[1] and "no strings found" in err[1]


def test_stdout_closed_before_the_rich_table_is_not_a_qa_fail(files):
    # ``harp measure IMG | head``: rich turns the broken pipe into SystemExit(1), which
    # a production-line script would read as a QA FAIL; harp reports 141 instead
    env = dict(os.environ, PYTHONPATH=str(REPO))
    p = subprocess.Popen(
        [sys.executable, "-m", "station.cli", "measure", str(files["pgm"])],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        cwd=REPO,
        env=env,
    )
    p.stdout.close()  # before the child has written anything: its first write fails
    err = p.stderr.read().decode()
    code = p.wait(timeout=120)
    assert "Traceback" not in err, err
    assert code == 141
