"""Every ``harp`` table into a pipe or a file (issue 21 item 3), run as a user runs them: the real
command in its own process (``python -m station.cli``), its stdout a pipe or a file.

Off a terminal a table is tab-separated text (:mod:`station.tables`): a header line, one line per
row, every row as many fields as the header, no box drawing, nothing cut short (whole candidate
names and paths) and no line wrapped, however long. What each table must hold is read here from
the command's own ``--json`` output, the session's manifest or the store, not from the printing
code.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import cv2
import pytest

from pipeline.models import RadialModel
from pipeline.render import HarpScene, render_harp

REPO = Path(__file__).resolve().parents[3]
W, H = 640, 480
LENS = RadialModel.for_image(W, H, k=(1.0, 0.0, 0.03, 0.0, 0.005), center=(330, 230), tangential=(0.001, 0.0))
LONG = "shots-in-a-directory-whose-name-alone-is-longer-than-a-table-cell-would-have-kept-of-it"
BOX = set("│┃─━┏┓┗┛┡┩└┘├┤┼╇╈")


def harp(*argv, stdout=subprocess.PIPE, timeout=600) -> tuple[int, str, str]:
    """``harp ARGV`` in its own process group, stdout a pipe (or the file given); the group is
    killed on every way out."""
    proc = subprocess.Popen(
        [sys.executable, "-m", "station.cli", *map(str, argv)],
        cwd=REPO,
        env=dict(os.environ, PYTHONPATH=str(REPO), COLUMNS="80"),
        stdin=subprocess.DEVNULL,
        stdout=stdout,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
    )
    try:
        out, err = proc.communicate(timeout=timeout)
    finally:
        if proc.poll() is None:
            try:
                os.killpg(proc.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
            proc.wait()
    return proc.returncode, out or "", err


def tsv(block: str) -> tuple[list[str], list[dict[str, str]]]:
    """A tab-separated table: its header and its rows as dicts (every row as long as the header)."""
    header, *lines = block.strip("\n").split("\n")
    cols = header.split("\t")
    rows = [line.split("\t") for line in lines]
    assert len(cols) > 1 and all(len(r) == len(cols) for r in rows), block
    return cols, [dict(zip(cols, r)) for r in rows]


def plain(out: str) -> None:
    assert not BOX & set(out), out  # no box drawing
    assert "\x1b[" not in out  # no colour


@pytest.fixture(scope="module")
def shots(tmp_path_factory):
    d = tmp_path_factory.mktemp("pipes") / LONG
    d.mkdir()
    paths = []
    for i, ang in enumerate((3.0, 63.0, 123.0, 93.0)):
        img = render_harp(
            W, H, HarpScene(angle_deg=ang, spacing_px=40.0, phase_px=7.0 * i), lens=LENS, noise_sigma=1.5, seed=i
        ).image
        paths.append(d / f"shot{i}.pgm")
        assert cv2.imwrite(str(paths[-1]), img)
    return paths


@pytest.fixture(scope="module")
def calibrated(shots, tmp_path_factory):
    """``harp calibrate`` (model chosen by cross-validation) into a pipe, and its --json report."""
    d = tmp_path_factory.mktemp("calibrated")
    code, out, err = harp("calibrate", *shots[:3], "--holdout", shots[3], "--out", d / "lens.yaml")
    assert code == 0, err
    code, js, err = harp("calibrate", *shots[:3], "--holdout", shots[3], "--out", d / "again.yaml", "--json")
    assert code == 0, err
    return d / "lens.yaml", out, json.loads(js)


def test_measure_prints_tab_separated_tables_into_a_pipe(shots):
    code, out, err = harp("measure", *shots[:2])
    code_js, js, _ = harp("measure", "--json", *shots[:2])
    assert code == code_js == 0, err
    plain(out)
    doc = json.loads(js)
    edges, images = out.rstrip("\n").split("\n\n")
    cols, rows = tsv(edges)
    assert cols[:4] == ["image", "string", "edge", "points"] and "rms (px)" in cols
    assert [r["image"] for r in rows] == [str(p) for p, im in zip(shots, doc["images"]) for _ in im["lines"]]
    assert [r["points"] for r in rows] == [str(ln["points"]) for im in doc["images"] for ln in im["lines"]]
    cols, rows = tsv(images)
    assert [r["image"] for r in rows] == [*map(str, shots[:2]), "all"]  # whole paths, nothing cut
    assert rows[-1]["d (px)"] == f"{doc['d']:.4f}" and rows[-1]["d_max (px)"] == f"{doc['d_max']:.4f}"


def test_calibrate_prints_every_candidate_name_whole_into_a_pipe(calibrated, shots):
    _model, out, rep = calibrated
    plain(out)
    head, cv, straightness, tail = out.rstrip("\n").split("\n\n")
    assert head == f"model: {rep['choice']['label']} ({rep['choice']['reason']})"  # one line, however long
    cols, rows = tsv(cv)
    assert cols == ["candidate", "params", "CV d (px)", "per fold (px)"]
    labels = [r["label"] for r in rep["choice"]["table"]]
    assert [r["candidate"] for r in rows] == labels and max(map(len, labels)) > 20
    assert [r["params"] for r in rows] == [str(r["n_params"]) for r in rep["choice"]["table"]]
    cols, rows = tsv(straightness)
    assert [r["shot"] for r in rows] == ["shot0.pgm", "shot1.pgm", "shot2.pgm", "fit (all)", "holdout shot3.pgm"] + [
        "holdout (all)"
    ]
    assert rows[3]["d after (px)"] == f"{rep['fit']['d']:.4f}"
    assert tail.splitlines()[-1].startswith("wrote ")


def test_evaluate_prints_a_tab_separated_table_into_a_pipe(calibrated, shots):
    model, _out, _rep = calibrated
    code, out, err = harp("evaluate", model, *shots)
    code_js, js, _ = harp("evaluate", model, *shots, "--json")
    assert code == code_js == 0, err
    plain(out)
    rep = json.loads(js)
    first, table = out.split("\n", 1)
    assert first.startswith("correction: ")
    cols, rows = tsv(table)
    assert cols == [
        "image",
        "lines",
        "d before (px)",
        "d_max before (px)",
        "d after (px)",
        "d_max after (px)",
        "shared after (px)",
        "own after (px)",
    ]
    assert [r["image"] for r in rows] == [*map(str, shots), "all"]  # the whole paths, not 40 characters
    assert rows[0]["shared after (px)"] == f"{rep['images'][0]['after_shared']['shared_px']:.4f}"
    assert rows[-1]["d after (px)"] == f"{rep['after']['d']:.4f}" and rows[-1]["lines"] == str(rep["n_lines"])


def test_reprocess_prints_a_tab_separated_table_into_a_pipe(factory_archive, tmp_path):
    from station.store import ProfileStore

    store = tmp_path / "profiles.sqlite"
    shutil.copy(factory_archive.store, store)
    with ProfileStore(store, create=False) as st:
        old = {p.focus: p for p in st.profiles()}
    code, out, err = harp("reprocess", factory_archive.session, "--workers", "1", "--store", store)
    assert code == 0, err
    plain(out)
    table, summary = out.rstrip("\n").split("\n\n")
    cols, rows = tsv(table)
    assert cols[:4] == ["session", "focus", "profile old", "profile new"] and "holdout d new (px)" in cols
    with ProfileStore(store, create=False) as st:
        new = {p.id: p for p in st.profiles()}
    assert [r["session"] for r in rows] == [str(factory_archive.session.resolve())] * len(old)
    for r in rows:
        p = old[float(r["focus"])]
        assert r["profile old"] == f"#{p.id}" and r["holdout d old (px)"] == f"{p.merit.holdout.d:.4f}"
        q = new[int(r["profile new"].lstrip("#"))]
        assert q.focus == p.focus and r["holdout d new (px)"] == f"{q.merit.holdout.d:.4f}"
        assert (r["verdict old"], r["verdict new"]) == (p.qa.verdict, q.qa.verdict)
    assert summary.startswith("1 session(s) re-processed, 0 failed") and summary.endswith("new profiles stored")


def test_profile_show_by_id_prints_the_profile_on_stdout(factory_archive):
    from pipeline.plain import plain as plain_json
    from station.store import ProfileStore

    with ProfileStore(factory_archive.store, create=False) as st:
        p = next(iter(st.profiles()))
    code, out, err = harp("profile", "show", "--id", p.id, "--store", factory_archive.store)
    assert code == 0 and err == "", err  # a passing profile: nothing to warn about
    plain(out)
    table, rest = out.split("\n\n", 1)  # the table, a blank line, the profile itself
    cols, rows = tsv(table)
    assert [r["id"] for r in rows] == [f"#{p.id}"]
    lines = rest.splitlines()
    assert lines[0].startswith(f"image {p.width}x{p.height}, session {p.provenance.session_dir}")
    assert lines[1:-1] == [f"check: {c.text}" for c in p.qa.checks]
    assert json.loads(lines[-1]) == json.loads(json.dumps(plain_json(p.model.to_dict())))


def test_session_qa_lines_are_not_wrapped_in_a_file(tmp_path):
    from tests.station.archive import FOCUS, small_station

    config = small_station(tmp_path / "station")
    log = tmp_path / "session.log"
    with open(log, "w") as f:
        code, _out, err = harp("session", "run", config, "--name", "s", "--no-report", stdout=f)
    assert code == 0, err
    text = log.read_text()
    plain(text)
    manifest = [json.loads(line) for line in (config.parent / "sessions" / "s" / "manifest.jsonl").open()]
    qa = [r for r in manifest if r["kind"] == "qa"]
    assert len(qa) == len(FOCUS)
    lines = text.splitlines()
    for r in qa:  # each focus setting's QA line, whole on one line
        passed = r["verdict"] == "PASS"
        want = f"QA focus {FOCUS[r['focus_idx']]:g}: {r['verdict']} " + "; ".join(
            c["text"] for c in r["checks"] if c["passed"] is passed
        )
        assert want in lines and len(want) > 120, text
    summary = next(i for i, line in enumerate(lines) if line.startswith("focus\tshots\t"))
    cols, rows = tsv("\n".join(lines[summary : summary + 1 + len(FOCUS)]))
    assert [r["focus"] for r in rows] == [f"{f:g}" for f in FOCUS]
