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
    # off a terminal: two tab-separated tables (every edge; each image and all), a blank line between
    edges, images = out.rstrip("\n").split("\n\n")
    edge_rows = [l.split("\t") for l in edges.splitlines()]
    image_rows = [l.split("\t") for l in images.splitlines()]
    assert edge_rows[0][:4] == ["image", "string", "edge", "points"] and "d_max (px)" in image_rows[0]
    assert all(len(r) == len(edge_rows[0]) for r in edge_rows) and all(len(r) == len(image_rows[0]) for r in image_rows)
    _, doc, _ = _json(capsys, ["measure", "--json", str(files["pgm"]), str(files["png16"])])
    by = {r[0]: dict(zip(image_rows[0], r)) for r in image_rows[1:]}
    assert list(by) == [str(files["pgm"]), str(files["png16"]), "all"]
    assert by["all"]["d (px)"] == f"{doc['d']:.4f}" and by["all"]["edges"] == str(doc["n_lines"])
    assert len(edge_rows) - 1 == doc["n_lines"]


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
    assert code == 2 and len(err.strip().splitlines()) == 1 and "\nall\t" in out


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


@pytest.mark.parametrize("suffix", [".json", ".npz"])
def test_points_file_holds_every_edge_raw_and_smoothed(capsys, files, tmp_path, suffix):
    """Issue 8 item 5: per image and per edge the raw sub-pixel and the smoothed points, for other tools."""
    from pipeline.measure import measure_image
    from station.edge_points import read_edge_points
    from station.imageio import read_grey

    out = tmp_path / f"edges{suffix}"
    code, doc, _ = _json(capsys, ["measure", "--json", "--points", str(out), str(files["pgm"]), str(files["png16"])])
    assert code == 0 and out.is_file()
    pts = read_edge_points(out)
    assert pts["format"] == "harp-edge-points" and pts["version"] == 1
    assert [im["path"] for im in pts["images"]] == [str(files["pgm"]), str(files["png16"])]
    for im, jim, key in zip(pts["images"], doc["images"], ("pgm", "png16")):
        assert (im["width"], im["height"], im["t"], im["smoothing"]) == (W, H, 30, "local-quadratic")
        m = measure_image(read_grey(files[key]))  # the same measurement, independently of the CLI
        assert len(im["edges"]) == m.n_lines == jim["n_lines"]
        for e, ln, jl in zip(im["edges"], m.lines, jim["lines"]):
            assert (e["string"], e["polarity"]) == (ln.string_id, ln.polarity) == (jl["string"], jl["polarity"])
            assert np.array_equal(e["raw"], ln.raw_points) and np.array_equal(e["smoothed"], ln.points)
            assert e["raw"].shape == (jl["raw_points"], 2) and e["smoothed"].shape == (jl["points"], 2)
            # the pieces partition the points; the JSON ends are the first and last smoothed points
            assert e["smoothed_pieces"][0, 0] == 0 and e["smoothed_pieces"][-1, 1] == len(e["smoothed"])
            assert len(e["raw_pieces"]) == len(e["smoothed_pieces"]) == jl["pieces"]
            assert jl["start"] == e["smoothed"][0].tolist() and jl["end"] == e["smoothed"][-1].tolist()


def test_points_file_bad_name_or_place_is_one_line(capsys, files, tmp_path):
    code = main(["measure", "--points", str(tmp_path / "edges.txt"), str(files["pgm"])])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "edges.txt" in err[0] and ".json or .npz" in err[0]
    code = main(["measure", "--points", str(tmp_path / "no" / "such" / "dir" / "e.json"), str(files["pgm"])])
    captured = capsys.readouterr()
    err = captured.err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "cannot write the points file" in err[0]
    assert "harp.pgm" in captured.out  # the measurement itself is still printed


def test_plain_gaussian_option(capsys, files):
    code, doc, _ = _json(capsys, ["measure", "--json", "--smoothing", "gaussian", str(files["pgm"])])
    code2, doc2, _ = _json(capsys, ["measure", "--json", str(files["pgm"])])
    assert code == code2 == 0
    assert doc["images"][0]["smoothing"] == "gaussian" and doc2["images"][0]["smoothing"] == "local-quadratic"
    # the paper's Gaussian drops 3 sigma (72 px) at both ends of every edge: fewer points, a smaller d
    assert sum(ln["points"] for ln in doc["images"][0]["lines"]) < sum(
        ln["points"] for ln in doc2["images"][0]["lines"]
    )
    assert doc["d"] < doc2["d"]


def test_points_file_lies_on_the_exact_edges_to_their_ends(capsys, tmp_path):
    """Issue 8 item 5 against the exact geometry: on a shot rendered through a barrel lens (8 px strings),
    every edge of the points file lies on a true edge curve (tests/pipeline/_harp_truth.py: the exact
    image of the ideal string edge through the lens, never passed through the measurement), the
    smoothed points to 0.03 px, and the ``--json`` end points are the ends of the visible true edge."""
    from station.edge_points import read_edge_points
    from tests.pipeline._harp_truth import _arclength_positions, curve_distance, whole_edges

    lens = RadialModel.for_image(W, H, k=(1.0, 0.0, 0.02))
    r = render_harp(
        W, H, HarpScene(angle_deg=80.0, spacing_px=50.0, string_width_px=8.0), lens=lens, noise_sigma=1.5, seed=1
    )
    img = tmp_path / "barrel.png"
    cv2.imwrite(str(img), r.image)
    out = tmp_path / "edges.npz"
    code, doc, _ = _json(capsys, ["measure", "--json", "--points", str(out), str(img)])
    assert code == 0
    (im,) = read_edge_points(out)["images"]
    lines = doc["images"][0]["lines"]
    truths = whole_edges(r, t=30)
    assert len(im["edges"]) == len(lines) >= 20
    used = set()
    for e, jl in zip(im["edges"], lines):
        k = int(np.argmin([np.median(curve_distance(te, e["raw"][::25])) for te in truths]))
        te = truths[k]
        assert k not in used
        used.add(k)
        raw, sm = curve_distance(te, e["raw"]), curve_distance(te, e["smoothed"])
        assert np.median(raw) < 0.03 and raw.max() < 0.15, (k, np.median(raw), raw.max())
        assert np.sqrt(np.mean(sm**2)) < 0.01 and sm.max() < 0.03, (k, sm.max())
        # the end points: first and last smoothed points, on the curve, at the ends of the visible edge
        assert jl["start"] == e["smoothed"][0].tolist() and jl["end"] == e["smoothed"][-1].tolist()
        assert len(te.dense) == 1 and len(e["smoothed_pieces"]) == 1
        piece, s = _arclength_positions(te, np.array([jl["start"], jl["end"]]))
        length = float(np.sum(np.hypot(*np.diff(te.dense[0], axis=0).T)))
        assert min(s) < 1.5 and max(s) > length - 1.5, (k, s, length)
        assert e["raw_pieces"][-1, 1] == len(e["raw"]) and e["smoothed_pieces"][-1, 1] == len(e["smoothed"])


def test_measure_imports_only_what_it_uses(files):
    """Issue 8 item 6: ``harp measure`` (a whole process) imports no scipy module, no other command and
    nothing of fitting, plotting or the station's storage; ``--points`` adds only its own format module."""
    code = (
        "import sys, io, contextlib\n"
        "from station.cli import main\n"
        "with contextlib.redirect_stdout(io.StringIO()): rc = main(sys.argv[1:])\n"
        "print(rc, ' '.join(sorted(sys.modules)))\n"
    )
    for extra in ([], ["--points", str(files["pgm"].with_suffix(".npz"))]):
        argv = ["measure", "--json", *extra, str(files["pgm"])]
        done = subprocess.run(
            [sys.executable, "-c", code, *argv], capture_output=True, text=True, cwd=REPO, timeout=120
        )
        rc, mods = done.stdout.strip().splitlines()[-1].split(" ", 1)
        mods = set(mods.split())
        assert rc == "0", done.stderr
        assert "pipeline.measure" in mods and "cv2" in mods  # it did measure
        unused = {
            m for m in mods if m == "scipy" or m.startswith(("scipy.", "matplotlib", "sqlalchemy", "yaml", "rich"))
        }
        unused |= mods & {"pipeline.fit", "pipeline.select", "station.calibration", "station.cli.calibrate"}
        assert not unused, sorted(unused)
        assert ("station.edge_points" in mods) == bool(extra)


def test_huge_header_device_and_fifo_are_refused_and_the_others_measured(files, tmp_path):
    # issue 14 item 8: a PNG header claiming 100000x100000 (a cv2.error traceback, the good files'
    # results lost), /dev/zero (memory exhausted) and a FIFO (hung): one line each, whole process
    import struct
    import zlib

    def chunk(kind, body):
        return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body) & 0xFFFFFFFF)

    huge = tmp_path / "huge.png"
    huge.write_bytes(
        b"\x89PNG\r\n\x1a\n"
        + chunk(b"IHDR", struct.pack(">IIBBBBB", 100_000, 100_000, 8, 0, 0, 0, 0))
        + chunk(b"IDAT", zlib.compress(b"\0" * 64))
        + chunk(b"IEND", b"")
    )
    fifo = tmp_path / "pipe.pgm"
    os.mkfifo(fifo)
    good = [str(files["pgm"]), str(files["png16"])]
    p = subprocess.run(
        [sys.executable, "-m", "station.cli", "measure", "--json", good[0], str(huge), "/dev/zero", str(fifo), good[1]],
        capture_output=True,
        text=True,
        cwd=REPO,
        timeout=120,
    )
    assert p.returncode == 2 and "Traceback" not in p.stderr, p.stderr
    doc = json.loads(p.stdout)
    assert [im["path"] for im in doc["images"]] == good and all(im["n_lines"] >= 10 for im in doc["images"])
    err = p.stderr.strip().splitlines()
    assert len(err) == 3, err
    assert err[0].startswith(f"harp measure: {huge}: image too large: 100000x100000")
    assert err[1] == "harp measure: /dev/zero: not a regular file (a character device); give an image file"
    assert err[2] == f"harp measure: {fifo}: not a regular file (a FIFO); give an image file"
