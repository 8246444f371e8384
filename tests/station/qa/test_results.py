"""``results.json`` and the report's context (issue 9 items 2, 3): the devices as they reported
themselves beside the configuration, a warning when they differ, the configuration's SHA-256."""

from __future__ import annotations

import hashlib
from pathlib import Path

import yaml

from station.config import load_config
from station.qa.report import session_context
from station.qa.results import device_identities, identity_warnings, session_results
from station.session.directory import SessionDir

REPO = Path(__file__).resolve().parents[3]
REPORTED = ["harp station", "SimulatedCamera", "SIM-0001"]  # what the simulated camera says of itself


def session_configured_as(tmp_path: Path, serial: str) -> SessionDir:
    d = yaml.safe_load((REPO / "configs" / "demo.yaml").read_text())
    d["camera_body"]["serial"] = serial
    d["store"] = {"path": "p.sqlite", "sessions_dir": "sessions"}
    cfg = tmp_path / f"station-{serial}.yaml"
    cfg.write_text(yaml.safe_dump(d))
    s = SessionDir.create(tmp_path / "sessions", load_config(cfg), name=serial)
    # a frame record as the executor writes it: the camera's identity read from the device
    s.append({"kind": "frame", "focus_idx": 0, "orientation_idx": 0, "meta": {"camera": REPORTED}})
    return s


def test_a_camera_that_is_not_the_configured_one_is_warned_about(tmp_path):
    with session_configured_as(tmp_path, "SIM-0001") as s:
        devices = device_identities(s)
        assert devices["camera"]["matches"] is True and identity_warnings(devices) == []
    with session_configured_as(tmp_path, "CAM-4711") as s:
        devices = device_identities(s)
        cam = devices["camera"]
        assert cam["reported"] == [dict(zip(("maker", "model", "serial"), REPORTED))]
        assert cam["configured"]["serial"] == "CAM-4711" and cam["matches"] is False
        (warning,) = identity_warnings(devices)
        assert "serial SIM-0001" in warning and "serial CAM-4711" in warning and "\n" not in warning
        rows, warnings = session_context(s)
        assert warnings == [warning]
        assert "(**does not match**)" in dict(rows)["camera"]
        results = session_results(s)
        assert results["devices"]["camera"]["matches"] is False
        copy = s.path / "config.yaml"
        assert results["config"]["sha256"] == hashlib.sha256(copy.read_bytes()).hexdigest()
        assert results["state"] == "interrupted" and results["verdict"] is None and results["exit_code"] == 130


def test_a_finished_session_killed_before_its_results_gets_them_gathered_once(tmp_path):
    import json

    from station.qa.results import finished_results, read_results
    from station.session.records import Finished, SessionVerdict

    with session_configured_as(tmp_path, "SIM-0001") as s:
        s.append(SessionVerdict("PASS"))
        s.append(Finished())
        assert read_results(s.path) is None  # killed after "finished", before results.json
        got = finished_results(s)
        assert got["state"] == "complete" and got["verdict"] == "PASS" and read_results(s.path) == got
        written = json.loads((s.path / "results.json").read_text())
        (s.path / "results.json").write_text(json.dumps({**written, "station": "as written"}))
        assert finished_results(s)["station"] == "as written"  # a complete results.json is what it says
