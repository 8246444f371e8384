"""Damaged session files (issue 14 item 5): found before resuming, repaired from frames and manifest."""

import hashlib
import json
import shutil

import pytest
import yaml

from drivers.errors import DeviceDisconnected
from station.cli import main
from station.session.directory import SessionDir
from station.session.executor import EXIT_ABORTED, EXIT_OK
from tests.station.fakes import FakeCamera, FakeStage
from tests.station.session.test_executor import make_config, run


@pytest.fixture(scope="module")
def made(tmp_path_factory):
    """A finished session (2 focus settings x 4 orientations, one frame each) and one stopped after
    its first focus setting was stored (the stage unplugged)."""
    base = tmp_path_factory.mktemp("made")
    cfg = make_config(base, focus=(0.0, 0.5))
    stage = FakeStage()
    with SessionDir.create(base, cfg, name="done") as s:
        result, _ = run(s, FakeCamera(stage), stage)
    assert result.exit_code == EXIT_OK
    stage = FakeStage(faults={n: DeviceDisconnected("port vanished") for n in range(6, 40)})
    with SessionDir.create(base, cfg, name="stopped") as s:
        result, _ = run(s, FakeCamera(stage), stage)
    assert result.exit_code == EXIT_ABORTED
    return base


def copy(made, tmp_path, name):
    shutil.copytree(made / name, tmp_path / name)
    return tmp_path / name


def records(path):
    return [json.loads(line) for line in (path / "manifest.jsonl").read_text().splitlines()]


def one_line(capsys) -> str:
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    return err.strip()


def test_garbled_session_json_says_repair_which_rederives_it(made, tmp_path, capsys):
    s = copy(made, tmp_path, "done")
    (s / "session.json").write_text('{"format": 1, "created": "2026-')
    assert main(["session", "resume", str(s)]) == 2  # was a JSONDecodeError traceback
    line = one_line(capsys)
    assert line.startswith(f"harp session: {s}/session.json: damaged (") and line.endswith(
        f"run: harp session repair {s}"
    )
    assert main(["session", "repair", str(s), "--base-dir", str(made)]) == 0
    err = capsys.readouterr().err
    assert f"re-derived: session.json: re-derived from config.yaml and the manifest; base_dir {made}" in err
    meta = json.loads((s / "session.json").read_text())
    assert meta["base_dir"] == str(made)
    assert main(["session", "resume", str(s)]) == 0  # already finished, nothing to do
    assert "already finished" in capsys.readouterr().err


def test_a_session_of_another_format_is_refused_by_resume_repair_and_qa_and_left_as_it_is(made, tmp_path, capsys):
    """A ``session.json`` whose format this version does not read (a newer version's session): before, resume, QA
    and repair read it as their own format, and a repair of it re-derived nothing it could not read. Now each says
    which format and what to do, exit 2, and the directory is left byte for byte."""
    from station import __version__

    s = copy(made, tmp_path, "stopped")
    meta = json.loads((s / "session.json").read_text())
    assert meta["format"] == 1
    (s / "session.json").write_text(json.dumps({**meta, "format": 2}))
    before = {p: p.read_bytes() for p in sorted(s.rglob("*")) if p.is_file() and p.name != ".lock"}
    want = (
        f"{s}/session.json: session format 2, but harp station {__version__} reads format 1 (written by a newer "
        "version): open it with the version that wrote it (its software_version); nothing was changed"
    )
    for argv, prog in (
        (["session", "resume", str(s)], "harp session"),
        (["session", "repair", str(s)], "harp session"),
        (["qa", str(s), "--no-record"], "harp qa"),
    ):
        assert main(argv) == 2
        assert one_line(capsys) == f"{prog}: {want}"
    assert {p: p.read_bytes() for p in sorted(s.rglob("*")) if p.is_file() and p.name != ".lock"} == before


def test_garbled_profile_is_reported_then_fitted_again_the_same(made, tmp_path, capsys):
    # a garbled profiles/focus0.yaml made every resume fail at QA: the session could never finish
    s = copy(made, tmp_path, "done")
    good = yaml.safe_load((s / "profiles" / "focus0.yaml").read_text())
    (s / "profiles" / "focus0.yaml").write_text("format: harp-distortion-model\nmodel: [\n")
    assert main(["session", "resume", str(s)]) == 2
    line = one_line(capsys)
    assert line == (
        f"harp session: {s}: damaged: profiles/focus0.yaml: checksum does not match the manifest; "
        f"run: harp session repair {s}"
    )
    assert main(["session", "repair", str(s)]) == 0
    err = capsys.readouterr().err
    assert "repaired: profiles/focus0.yaml: checksum does not match the manifest: re-derived from the frames" in err
    again = yaml.safe_load((s / "profiles" / "focus0.yaml").read_text())
    assert again["model"] == good["model"] and again["merit"]["holdout"] == good["merit"]["holdout"]
    recs = records(s)
    assert [r["kind"] for r in recs].count("reopened") == 1 and recs[-1]["kind"] == "finished"
    assert main(["session", "repair", str(s)]) == 0
    assert "nothing to repair" in capsys.readouterr().err


def test_deleted_frame_of_a_stored_focus_is_reported_not_finished(made, tmp_path, capsys):
    # resume said "session finished", exit 0, and wrote no report
    s = copy(made, tmp_path, "done")
    frame = next(r["file"] for r in records(s) if r["kind"] == "frame" and r["focus_idx"] == 1)
    (s / frame).unlink()
    assert main(["session", "resume", str(s)]) == 2
    line = one_line(capsys)
    assert line == (
        f"harp session: {s}: damaged: {frame}: missing; run: harp session repair {s} "
        "(it says what cannot be re-derived)"
    )
    assert main(["session", "repair", str(s)]) == 2
    err = capsys.readouterr().err
    assert f"cannot re-derive: {frame}: missing: cannot be re-derived; the profile of focus setting 1" in err
    assert f"harp session repair {s} --recapture 1" in err
    assert main(["session", "repair", str(s), "--recapture", "1"]) == 0
    assert f"then: harp session resume {s}" in capsys.readouterr().err
    stage = FakeStage()
    with SessionDir.open(s) as sd:
        result, _ = run(sd, FakeCamera(stage), stage)
        assert result.exit_code == EXIT_OK and result.frames_saved == 4  # focus 1 captured again whole
    assert records(s)[-1]["kind"] == "finished"


def test_frame_checksum_mismatch_says_what_to_do_and_repair_recaptures(made, tmp_path, capsys):
    s = copy(made, tmp_path, "stopped")
    frame = next(r for r in records(s) if r["kind"] == "frame" and r["focus_idx"] == 1)
    data = bytearray((s / frame["file"]).read_bytes())
    data[-1] ^= 0xFF
    (s / frame["file"]).write_bytes(bytes(data))
    assert main(["session", "resume", str(s)]) == 2
    line = one_line(capsys)
    assert line == (
        f"harp session: {s}: damaged: {frame['file']}: checksum does not match the manifest; "
        f"run: harp session repair {s}"
    )
    assert main(["session", "repair", str(s)]) == 0
    err = capsys.readouterr().err
    assert f"repaired: {frame['file']}: checksum does not match the manifest: its shot will be captured again" in err
    stage = FakeStage()
    with SessionDir.open(s) as sd:
        result, _ = run(sd, FakeCamera(stage), stage)
    assert result.exit_code == EXIT_OK
    recs = records(s)
    shot = [
        r
        for r in recs
        if r["kind"] == "frame" and (r["focus_idx"], r["orientation_idx"]) == (1, frame["orientation_idx"])
    ]
    assert [r["attempt"] for r in shot] == [0, 1] and recs[-1]["kind"] == "finished"


def test_corrupt_manifest_line_and_damaged_measurement(made, tmp_path, capsys):
    s = copy(made, tmp_path, "done")
    lines = (s / "manifest.jsonl").read_bytes().split(b"\n")
    k = next(i for i, line in enumerate(lines) if b'"kind":"fault"' in line or b'"kind":"focus"' in line)
    lines[k] = b'{"kind":"focus","focus_idx":0,"foc\x00\x00'
    (s / "manifest.jsonl").write_bytes(b"\n".join(lines))
    measure = next(r for r in records_lenient(s) if r["kind"] == "measure")
    (s / measure["file"]).write_bytes(b"PK\x03\x04 damaged")
    assert main(["session", "resume", str(s)]) == 2
    line = one_line(capsys)
    assert "corrupt manifest record; run: harp session repair" in line
    assert main(["session", "repair", str(s)]) == 0
    err = capsys.readouterr().err
    assert "re-derived: manifest.jsonl: dropped 1 damaged line (the original is kept as manifest.jsonl.damaged)" in err
    assert f"repaired: {measure['file']}: checksum does not match the manifest: re-derived from the frames" in err
    new = [r for r in records(s) if r["kind"] == "measure" and r["file"] == measure["file"]][-1]
    assert hashlib.sha256((s / measure["file"]).read_bytes()).hexdigest() == new["sha256"]
    assert main(["session", "resume", str(s)]) == 0


def records_lenient(path):
    out = []
    for line in (path / "manifest.jsonl").read_bytes().splitlines():
        try:
            out.append(json.loads(line))
        except ValueError:
            continue
    return out


def test_garbled_profile_of_an_unfinished_session_is_found_before_capture(made, tmp_path, capsys):
    # issue 14: a garbled profiles/focus0.yaml in an unfinished session: resume captured and fitted
    # the rest, then failed at QA every time, so the session could never finish
    s = copy(made, tmp_path, "stopped")
    before = records(s)
    (s / "profiles" / "focus0.yaml").write_text("format: harp-distortion-model\nmodel: [\n")
    assert main(["session", "resume", str(s)]) == 2
    assert one_line(capsys) == (
        f"harp session: {s}: damaged: profiles/focus0.yaml: checksum does not match the manifest; "
        f"run: harp session repair {s}"
    )
    assert records(s) == before  # found before anything was captured, fitted or judged
    assert main(["session", "repair", str(s)]) == 0
    assert f"then: harp session resume {s}" in capsys.readouterr().err
    stage = FakeStage()
    with SessionDir.open(s) as sd:
        result, _ = run(sd, FakeCamera(stage), stage)
    assert result.exit_code == EXIT_OK
    recs = records(s)
    assert recs[-1]["kind"] == "finished"
    assert sorted(r["focus_idx"] for r in recs if r["kind"] == "qa") == [0, 1]
    assert yaml.safe_load((s / "profiles" / "focus0.yaml").read_text())["format"] == "harp-distortion-model"


@pytest.mark.parametrize("name", ["done", "stopped"])
@pytest.mark.parametrize("damage", ["deleted", "emptied"])
def test_lost_manifest_is_refused_by_resume_repair_and_qa_nothing_captured_over(made, tmp_path, capsys, name, damage):
    # resume of a session whose manifest.jsonl was deleted or emptied captured the whole plan again over
    # the frames of the same names (and said "session finished"); repair said "nothing to repair"
    s = copy(made, tmp_path, name)
    manifest = s / "manifest.jsonl"
    if damage == "deleted":
        manifest.unlink()
    else:
        manifest.write_bytes(b"")
    before = {p: p.read_bytes() for p in s.rglob("*") if p.is_file() and p.name != ".lock"}
    frames = len(list((s / "frames").iterdir()))
    state = "missing" if damage == "deleted" else "empty"
    expected = f"{manifest}: {state}, but the session holds what it recorded (frames/ {frames} files, measurements/ "
    for argv in (["session", "resume", str(s)], ["session", "repair", str(s)], ["qa", str(s), "--no-record"]):
        assert main(argv) == 2, argv
        line = one_line(capsys)
        assert line.startswith(f"harp {argv[0]}: {expected}"), line
        assert line.endswith(
            "restore manifest.jsonl from a backup (nothing was changed), or start a new session with harp session run"
        )
    after = {p: p.read_bytes() for p in s.rglob("*") if p.is_file() and p.name != ".lock"}
    assert after == before and manifest.exists() == (damage == "emptied")  # nothing captured over, nothing made
    # harp session list listed it "interrupted", 0 frames: now the same line, as a warning, and not listed
    assert main(["session", "list", str(tmp_path)]) == 0
    out, err = capsys.readouterr()
    warning, listed = err.splitlines()
    assert (
        warning.startswith(f"harp session: warning: {expected}")
        and listed == f"harp session: no sessions in {tmp_path}"
    )
