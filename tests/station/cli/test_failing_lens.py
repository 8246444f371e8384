"""A lens that fails QA can never pass (issue 9 item 1), end to end through ``harp``.

The issue's reproduction: a copy of configs/demo.yaml with ``qa.max_holdout_d_px: 0.0001``
printed "QA verdict: FAIL" but exited 0, its profile became the current one, was exported
without a word, and ``harp qa LENS`` then said PASS. Here the same session (at test size) must
exit 1, say FAIL truthfully in its results, report and JSON, and every later command must keep
saying FAIL. Also issue 14's tampered profile (k1 = 5.0 written into the store) fails
``harp qa LENS``.
"""

from __future__ import annotations

import json
import sqlite3
from pathlib import Path

import pytest
import yaml

from station.cli import main

REPO = Path(__file__).resolve().parents[3]
LIMIT = 0.0001


def run(capsys, *args):
    code = main([str(a) for a in args])
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture(scope="module")
def failed(tmp_path_factory):
    """``harp session run --json`` of the demo at test size with ``qa.max_holdout_d_px: 0.0001``."""
    base = tmp_path_factory.mktemp("failing")
    d = yaml.safe_load((REPO / "configs" / "demo.yaml").read_text())
    d["station"]["camera"].update(width=640, height=480, spacing_px=40.0)
    d["focus"]["settings"] = [0.0, 1.0]
    d["capture"].update(orientations_deg=[0, 45, 90, 135], frames_per_orientation=1)
    d["pipeline"]["bootstrap"] = 0
    d["qa"]["max_holdout_d_px"] = LIMIT
    d["store"] = {"path": "profiles.sqlite", "sessions_dir": "sessions"}
    cfg = base / "station.yaml"
    cfg.write_text(yaml.safe_dump(d))
    import io
    from contextlib import redirect_stderr, redirect_stdout

    out, err = io.StringIO(), io.StringIO()
    with redirect_stdout(out), redirect_stderr(err):
        code = main(["session", "run", str(cfg), "--name", "f", "--quiet", "--json"])
    return code, json.loads(out.getvalue()), err.getvalue(), base


def test_the_session_exits_1_and_says_fail_truthfully(failed):
    code, results, err, base = failed
    session = base / "sessions" / "f"
    assert code == 1, err
    assert err.rstrip().endswith(f"session finished, QA verdict FAIL: {session}")
    assert results == json.loads((session / "results.json").read_text())
    assert results["state"] == "complete" and results["verdict"] == "FAIL" and results["exit_code"] == 1
    assert results["thresholds"]["max_holdout_d_px"] == LIMIT
    assert [f["focus"] for f in results["focus"]] == [0.0, 1.0]
    for f in results["focus"]:
        assert f["verdict"] == "FAIL" and f["profile_id"] is not None
        hold = next(c for c in f["checks"] if c["name"] == "holdout_d")
        # truth: the session's own holdout figure, against the configured limit
        assert hold["value"] == pytest.approx(f["holdout"]["d"]) and hold["value"] > LIMIT
        assert (hold["comparison"], hold["limit"], hold["passed"]) == ("<=", LIMIT, False)
        assert hold["text"] == f"holdout d {hold['value']:.4f} px > {LIMIT:g} px: FAIL"
        # the stored model on its own shots is judged against the same limit: it fails too, the rest holds
        failing = {c["name"] for c in f["checks"] if c["passed"] is False}
        assert failing == {"holdout_d", "corrected_d"}, f["checks"]
    report = (session / "report" / "report.md").read_text()
    assert "**Verdict: FAIL**" in report and f"<= {LIMIT:g} px" not in report
    for f in results["focus"]:
        for c in f["checks"]:
            assert c["text"] in report  # every check, as the JSON says it
        assert f"holdout d {f['holdout']['d']:.4f} px > {LIMIT:g} px: the correction does not straighten" in report
    html = (session / "report" / "index.html").read_text()
    assert '<strong class="verdict fail">Verdict: FAIL</strong>' in html


def test_resume_and_list_keep_saying_fail(failed, capsys):
    _, _, _, base = failed
    session = base / "sessions" / "f"
    code, out, err = run(capsys, "session", "resume", session, "--json")
    assert code == 1 and "already finished (QA verdict FAIL)" in err
    assert json.loads(out)["verdict"] == "FAIL"
    code, out, _ = run(capsys, "session", "list", base / "sessions", "--json")
    (listed,) = json.loads(out)["sessions"]
    assert code == 0 and (listed["state"], listed["verdict"]) == ("complete", "FAIL")


def test_the_failed_profiles_are_not_current_and_not_exported(failed, capsys):
    _, results, _, base = failed
    store = base / "profiles.sqlite"
    ids = [f["profile_id"] for f in results["focus"]]
    code, out, err = run(capsys, "profile", "show", "DEMO-0001", "--store", store, "--json")
    doc = json.loads(out)
    assert code == 0 and doc["profiles"] == [] and [p["id"] for p in doc["left_out"]] == ids
    assert all(p["verdict"] == "FAIL" for p in doc["left_out"]) and err.count("not current") == 2
    code, out, err = run(capsys, "profile", "export", "DEMO-0001", "--focus", "0", "--format", "json", "--store", store)
    assert code == 1 and out == "" and err.count("\n") == 1
    assert err.startswith(f"harp profile: lens Simulated Optics SIM-12mm serial DEMO-0001, focus 0: profile #{ids[0]}")
    assert f"holdout d {results['focus'][0]['holdout']['d']:.4f} px > {LIMIT:g} px" in err and "not exported" in err
    code, out, err = run(
        capsys, "profile", "export", "DEMO-0001", "--focus", "0", "--format", "json", "--store", store, "--allow-failed"
    )
    assert code == 0 and json.loads(out)["model"] and "warning" in err and "--allow-failed" in err
    # between the two failed settings: nothing to interpolate from but failed profiles
    code, out, err = run(
        capsys, "profile", "export", "DEMO-0001", "--focus", "0.5", "--format", "json", "--store", store
    )
    assert code == 1 and out == "" and "failed QA" in err


def test_qa_of_the_lens_uses_the_thresholds_it_was_calibrated_under(failed, capsys):
    _, results, _, base = failed
    store = base / "profiles.sqlite"
    code, out, err = run(capsys, "qa", "DEMO-0001", "--store", store, "--json", "--no-record")
    assert code == 1, err
    doc = json.loads(out)
    assert doc["verdict"] == "FAIL" and doc["thresholds"]["max_holdout_d_px"] == LIMIT
    for p in doc["profiles"]:
        assert p["thresholds_from"] == "calibration" and p["verdict"] == "FAIL"
        assert p["measurements"] is not None  # the session directory is at hand: its edges are used
        names = {c["name"]: c for c in p["checks"]}
        assert {"holdout_d", "holdout_d_stored", "corrected_d", "defined", "distortion_max"} <= set(names)
        assert names["holdout_d"]["passed"] is False and "recomputed" in names["holdout_d"]["text"]
    # the command line's thresholds, when given, are the ones judged
    code, out, _ = run(capsys, "qa", "DEMO-0001", "--store", store, "--max-holdout-d", "0.05", "--json", "--no-record")
    doc = json.loads(out)
    assert code == 0 and doc["verdict"] == "PASS"
    assert all(p["thresholds_from"] == "calibration and the command line" for p in doc["profiles"])


def test_a_tampered_stored_profile_fails_qa(failed, capsys, tmp_path):
    # issue 14: k1 = 5.0 written into a stored profile (258 px of distortion) passed `harp qa LENS`
    _, results, _, base = failed
    store = tmp_path / "tampered.sqlite"
    store.write_bytes((base / "profiles.sqlite").read_bytes())
    pid = results["focus"][1]["profile_id"]
    with sqlite3.connect(store) as db:
        (model_json,) = db.execute("SELECT model_json FROM profiles WHERE id = ?", (pid,)).fetchone()
        model = json.loads(model_json)
        model["k"][1] = 5.0
        db.execute("UPDATE profiles SET model_json = ? WHERE id = ?", (json.dumps(model), pid))
    code, out, err = run(
        capsys, "qa", "DEMO-0001", "--store", store, "--max-holdout-d", "0.05", "--json", "--no-record"
    )
    assert code == 1, err
    doc = json.loads(out)
    intact, tampered = doc["profiles"]
    assert intact["verdict"] == "PASS" and tampered["verdict"] == "FAIL"
    failed_checks = {c["name"] for c in tampered["checks"] if c["passed"] is False}
    # the model itself is judged: on its measurements and against what was recorded (it is defined over
    # the image: k1 = 5 is monotonic, its inverse exact since the shared safeguarded inverse, issue 20 item 9)
    assert {"corrected_d", "distortion_recorded"} <= failed_checks, tampered["checks"]
    assert "defined" not in failed_checks
    assert "holdout_d" not in failed_checks  # the recomputed holdout refits the measurements: not the tampered model
    # without the session's measurements (another machine), the model still fails on its own
    code, out, _ = run(
        capsys,
        "qa",
        "DEMO-0001",
        "--store",
        store,
        "--max-holdout-d",
        "0.05",
        "--no-recompute",
        "--json",
        "--no-record",
    )
    quick = json.loads(out)["profiles"][1]
    assert code == 1 and "holdout_d_stored" not in {c["name"] for c in quick["checks"]}  # not recomputed
    assert {"corrected_d", "distortion_recorded"} <= {c["name"] for c in quick["checks"] if c["passed"] is False}
    (session_dir := base / "sessions" / "f").rename(base / "moved")
    try:
        code, out, _ = run(
            capsys, "qa", "DEMO-0001", "--store", store, "--max-holdout-d", "0.05", "--json", "--no-record"
        )
    finally:
        (base / "moved").rename(session_dir)
    doc = json.loads(out)
    tampered = doc["profiles"][1]
    assert code == 1 and tampered["measurements"] is None and "not at hand" in tampered["notes"][0]
    assert "distortion_recorded" in {c["name"] for c in tampered["checks"] if c["passed"] is False}


def test_kept_measurements_are_read_once_and_again_when_damaged(failed, tmp_path):
    import shutil

    from station.qa.evidence import stored_measurement
    from station.session.directory import SessionDir
    from station.session.records import ShotMeasured

    _, _, _, base = failed
    copy = tmp_path / "copy"
    shutil.copytree(base / "sessions" / "f", copy)
    with SessionDir.open(copy) as s:
        first = stored_measurement(s, 0, 0)
        assert first is not None and stored_measurement(s, 0, 0) is first  # store step, QA, report: one read
        rec = s.last(ShotMeasured, focus_idx=0, orientation_idx=0)
        f = copy / rec.file
        data = bytearray(f.read_bytes())
        data[len(data) // 2] ^= 0xFF
        f.write_bytes(bytes(data))
        assert stored_measurement(s, 0, 0) is None  # damaged since: read again, its checksum fails
