"""Manifest records: each kind's JSON is the manifest's layout, and reads back to the same record."""

import json

import pytest

from station.session import records as r

EXAMPLES = [
    r.Started("0.1.0"),
    r.Resumed("0.1.0"),
    r.FocusLocked(0, 0.5, 0.5),
    r.FrameSaved(0, 1, 0, 0, "frames/f0_o1_a0_i0.pgm", "ab" * 32, {"stage_deg": 22.5}),
    r.ShotRejected(0, 1, 0, ["over-exposed"]),
    r.ShotMeasured(0, 1, 1, 40, 1.9, 6.1, 27.5, "measurements/f0_o1_a1.npz", "cd" * 32),
    r.Fitted(
        0, {"model": "radial"}, {"model": "radial", "degree": 4}, 0.001, 0.004, 0.0012, 0.0045, [0.0011], None, None, {}
    ),
    r.Fitted(
        0, {"model": "radial"}, None, 0.001, 0.004, 0.0012, 0.0045, [], 0.0006, 0.003, {"n": 1}, "profiles/u.npz", "ef"
    ),
    r.FitFailed(2, "too few edges"),
    r.Stored(0, 7, "profiles/focus0.yaml"),
    r.Fault("move turntable to 90 deg", "DeviceFault", "stall", 1),
    r.QARecorded(0, "PASS", [], {"holdout_d_px": 0.0012}),
    r.InterpolationError(0.5, 0.0003, 0.003),
    r.SessionVerdict("PASS"),
    r.ReportWritten("report/report.md", "report/index.html"),
    r.ReportFailed("OSError: disk full"),
    r.Aborted("interrupted by the user"),
    r.Finished(),
]


@pytest.mark.parametrize("record", EXAMPLES, ids=lambda x: type(x).__name__)
def test_json_round_trip(record):
    line = json.loads(json.dumps({"t": 1.0, **record.to_json()}))
    assert r.from_json(line) == record


def test_the_manifest_layout_of_some_kinds():
    assert r.FrameSaved(0, 1, 2, 0, "frames/x.pgm", "ab", {}).to_json() == {
        "kind": "frame",
        "focus_idx": 0,
        "orientation_idx": 1,
        "frame_idx": 2,
        "attempt": 0,
        "file": "frames/x.pgm",
        "sha256": "ab",
        "meta": {},
    }
    fit = EXAMPLES[6].to_json()
    assert fit["kind"] == "fit" and "uncertainty_file" not in fit  # absent when not computed
    assert r.from_json({"kind": "fit", "focus_idx": 1, "failure": "x"}) == r.FitFailed(1, "x")
    assert r.from_json({"kind": "no-such-kind"}) is None


def test_lines_of_other_versions_read_for_what_they_hold():
    # a key this software does not know is left out; the time of the line is kept (not compared)
    newer = r.from_json({"t": 12.5, "kind": "stored", "focus_idx": 1, "profile_id": 3, "model_file": "p.yaml", "x": 1})
    assert newer == r.Stored(1, 3, "p.yaml") and newer.t == 12.5
    # an older line without sha256 (issue 14) or checks (issue 9): the defaults; without a field: None
    assert r.from_json({"kind": "stored", "focus_idx": 2}) == r.Stored(2, None, None)
    old_qa = r.from_json({"kind": "qa", "focus_idx": 0, "verdict": "PASS", "reasons": [], "metrics": {}})
    assert old_qa == r.QARecorded(0, "PASS", [], {}) and old_qa.checks == [] and old_qa.thresholds == {}
    # two records of one kind: the one whose fields the line holds
    assert isinstance(r.from_json(EXAMPLES[6].to_json()), r.Fitted)
    assert r.from_json({"kind": "report", "failure": "disk full", "x": 0}) == r.ReportFailed("disk full")
    assert r.from_json({"kind": "report", "file": "a.md", "html": "a.html"}) == r.ReportWritten("a.md", "a.html")
    # parse: in order, unknown kinds left out
    assert r.parse([{"kind": "finished"}, {"kind": "from-the-future"}, {"kind": "start", "software_version": "9"}]) == [
        r.Finished(),
        r.Started("9"),
    ]
    assert "t" not in r.Started("1").to_json()  # the directory stamps the line when it is written
