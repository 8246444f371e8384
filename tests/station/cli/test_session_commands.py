"""The operational commands (issue 9 item 5): ``harp config check``, ``harp session plan``,
``harp session list`` and ``harp devices`` — their tables (tab-separated when stdout is not a
terminal, units in the headers) and their ``--json``."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import yaml

from station.cli import main
from station.config import load_config
from station.session.directory import SessionDir
from station.session.records import Aborted, Finished, SessionVerdict, Started

REPO = Path(__file__).resolve().parents[3]
DEMO = REPO / "configs" / "demo.yaml"


def run(capsys, *args):
    code = main([str(a) for a in args])
    out, err = capsys.readouterr()
    return code, out, err


def tsv(out: str) -> list[list[str]]:
    """Rows of tab-separated output, every row as wide as the header."""
    rows = [line.split("\t") for line in out.splitlines()]
    assert rows and all(len(r) == len(rows[0]) for r in rows), out
    return rows


def demo_copy(tmp_path: Path, **changes) -> Path:
    d = yaml.safe_load(DEMO.read_text())
    d["store"] = {"path": "p.sqlite", "sessions_dir": "sessions"}
    for k, v in changes.items():
        d[k] = v
    p = tmp_path / "demo.yaml"
    p.write_text(yaml.safe_dump(d))
    return p


def test_config_check(tmp_path, capsys):
    code, out, err = run(capsys, "config", "check", DEMO)
    assert code == 0 and err == "" and out.startswith(f"{DEMO}: OK (3 focus settings x 8 orientations x 2 frames")
    code, out, _ = run(capsys, "config", "check", DEMO, "--json")
    doc = json.loads(out)
    assert code == 0 and doc["ok"] is True and doc["error"] is None and doc["warnings"] == []
    bad = tmp_path / "bad.yaml"
    bad.write_text(DEMO.read_text().replace("frames_per_orientation: 2", "frames_per_orientation: two"))
    code, out, err = run(capsys, "config", "check", bad, "--json")
    assert code == 2 and err.count("\n") == 1 and "capture.frames_per_orientation" in err
    assert json.loads(out)["ok"] is False
    assert not (tmp_path / "sessions").exists() and not (tmp_path / "p.sqlite").exists()


def test_config_check_warns_of_a_plan_that_puts_the_strings_along_the_pixel_grid(tmp_path, capsys):
    """The demo's harp set at 0.5 deg instead of 5: at turntable 0 and 90 deg its strings lie at 0.5 and 90.5 deg
    (the plan's angles plus the offset, by hand), within 2 deg of the rows and columns; one warning naming both, the
    configuration still usable, and ``harp session plan`` says the same. At 5 deg (the demo as shipped) none."""
    d = yaml.safe_load(DEMO.read_text())
    d["station"]["harp"]["offset_deg"] = 0.5
    p = demo_copy(tmp_path, station=d["station"])
    code, out, err = run(capsys, "config", "check", p, "--json")
    doc = json.loads(out)
    assert code == 0 and doc["ok"] is True and len(doc["warnings"]) == 1, doc
    w = doc["warnings"][0]
    assert "turntable 0 deg (strings at 0.5 deg), 90 deg (strings at 90.5 deg)" in w and "22.5 deg" not in w
    assert "station.harp.offset_deg 0.5" in w and err.count("\n") == 1 and "Traceback" not in err
    code, out, err = run(capsys, "session", "plan", p)  # the plan's preview says it too
    assert code == 0 and err.count("pixel rows or columns") == 1 and w in err and not (tmp_path / "sessions").exists()


def warned_before_the_session(capsys, tmp_path, warning, changes, quiet=()) -> str:
    """The demo configuration with ``changes``: ``harp config check`` usable with exactly ``warning`` (``{p}``: the
    file), ``harp session plan`` saying it and creating nothing; with each of ``quiet`` applied over ``changes``, no
    warning. Returns what both commands printed."""
    p = demo_copy(tmp_path, **changes)
    code, out, err = run(capsys, "config", "check", p, "--json")
    doc = json.loads(out)
    assert code == 0 and doc["ok"] is True, doc
    assert doc["warnings"] == [warning.format(p=p)]
    code, plan_out, plan_err = run(capsys, "session", "plan", p)
    assert code == 0 and doc["warnings"][0] in plan_err and not (tmp_path / "sessions").exists()
    for q in quiet:
        code, q_out, _ = run(capsys, "config", "check", demo_copy(tmp_path, **{**changes, **q}), "--json")
        assert code == 0 and json.loads(q_out)["warnings"] == [], q_out
    return out + err + plan_out + plan_err


def test_config_check_warns_of_a_named_model_the_plan_cannot_support(tmp_path, capsys):
    """poly5 named with three turntable angles (0, 60, 120: three string directions): a free polynomial needs four,
    so the session's profile would be "not well supported"; one warning naming pipeline.model, the configuration
    still usable, and ``harp session plan`` says it before anything runs. With four angles, or model auto, none."""
    d = yaml.safe_load(DEMO.read_text())
    pipeline = {**d["pipeline"], "model": "poly5", "degree": 5}
    capture = {**d["capture"], "orientations_deg": [0, 60, 120]}
    warned_before_the_session(
        capsys,
        tmp_path,
        "{p}: pipeline.model: poly5 needs >= 4 distinct string orientations (>= 10 deg apart) and the fitted shots "
        "of capture.orientations_deg give 3: its fit would not be well supported (the profile and the QA report "
        "would say so); add turntable angles, or name a model with fewer terms (or auto)",
        {"pipeline": pipeline, "capture": capture},
        quiet=(
            {"capture": {**capture, "orientations_deg": [0, 45, 90, 135]}},
            {"pipeline": {**pipeline, "model": "auto"}},
        ),
    )


def test_config_check_warns_when_field_auto_cannot_add_a_field_with_the_plan(tmp_path, capsys):
    """pipeline.field: auto (the default) with three turntable angles (0, 60, 120: three string directions): a
    residual field needs four, so the session would never add one and said so only in the profile's reason. One
    warning naming pipeline.field, repeated by ``harp session plan``; none with four directions, or field none;
    still one with 0 and 5 deg among four angles (one direction)."""
    d = yaml.safe_load(DEMO.read_text())
    pipeline = {**d["pipeline"], "field": "auto"}
    capture = {**d["capture"], "orientations_deg": [0, 60, 120]}
    warning = (
        "{p}: pipeline.field: auto adds a residual field only with >= 4 distinct string orientations (>= 10 deg "
        "apart) and the fitted shots of capture.orientations_deg give 3: the session would fit no field; add "
        "turntable angles, or set pipeline.field: none"
    )
    quiet = (
        {"capture": {**capture, "orientations_deg": [0, 45, 90, 135]}},
        {"pipeline": {**pipeline, "field": "none"}},
    )
    warned_before_the_session(capsys, tmp_path, warning, {"pipeline": pipeline, "capture": capture}, quiet)
    close = {**capture, "orientations_deg": [0, 5, 60, 120]}
    warned_before_the_session(capsys, tmp_path, warning, {"pipeline": pipeline, "capture": close})


def test_config_check_warns_of_a_store_url_password_the_session_copies_would_keep(tmp_path, capsys):
    """store.url with a password: every session directory keeps a verbatim copy of the configuration, so the
    password would be copied into each; one warning naming store.url, the store named without the password (the
    password printed nowhere), repeated by ``harp session plan``. None without a password (~/.pgpass)."""
    said = warned_before_the_session(
        capsys,
        tmp_path,
        "{p}: store.url: postgresql://harp:***@db.example:5432/harp holds a password, and every session directory "
        "keeps a copy of this configuration (config.yaml) with it: take it out of the URL and put it in ~/.pgpass "
        "(or $PGPASSWORD), which the store's driver reads when the URL has none",
        {"store": {"url": "postgresql://harp:s3cret-pw@db.example:5432/harp"}},
        quiet=(
            {"store": {"url": "postgresql://harp@db.example:5432/harp"}},
            {"store": {"url": f"sqlite:///{tmp_path / 'store.sqlite'}"}},
        ),
    )
    assert "s3cret" not in said


def test_config_check_warns_of_a_missing_port_that_session_run_refuses_also_with_a_simulation(tmp_path, capsys):
    # a simulated station whose turntable is a real port (simulation section kept, port no longer "emulator"):
    # harp config check said OK without a warning, harp session run refused it
    d = yaml.safe_load(DEMO.read_text())
    d["station"]["turntable"]["port"] = str(tmp_path / "ttyUSB9")
    p = demo_copy(tmp_path, station=d["station"])
    code, out, err = run(capsys, "config", "check", p, "--json")
    doc = json.loads(out)
    assert code == 0 and doc["ok"] is True and err.count("\n") == 1, err
    assert doc["warnings"] == [
        f"{p}: station.turntable.port: '{tmp_path / 'ttyUSB9'}' does not exist on this machine "
        "(plug the turntable in, or see `harp devices` for the ports found)"
    ]
    code, out, err = run(capsys, "session", "run", p)
    assert code == 2 and err.count("\n") == 1 and "station.turntable.port: expected a reachable serial port" in err
    assert not (tmp_path / "sessions").exists()
    code, out, err = run(capsys, "config", "check", demo_copy(tmp_path))  # the emulator's port: no warning
    assert code == 0 and err == ""


@pytest.mark.parametrize(
    "capture, without",
    [
        ({"orientations_deg": [0, 90]}, 0),  # two orientations: each fold keeps one
        ({"orientations_deg": [0, 90, 180]}, 90),  # 0 and 180: the same string direction
        ({"orientations_deg": [0, 5, 90]}, 90),
        ({"orientations_deg": [0, 90], "twin_deg": 90}, 0),  # the twin is not fitted
    ],
)
def test_a_plan_no_session_can_fit_is_refused_before_anything_is_captured(tmp_path, capsys, capture, without):
    # such a plan passed harp config check; harp session run captured every shot, then stopped at the first fit
    # ("cross-validation without orientation 0: all 22 edges lie within 0.4 deg of one orientation"), and again at
    # every resume: a session that could never finish
    d = yaml.safe_load(DEMO.read_text())
    d["capture"].update(capture)
    p = demo_copy(tmp_path, capture=d["capture"])
    for argv in (("config", "check", p), ("session", "plan", p), ("session", "run", p)):
        code, out, err = run(capsys, *argv)
        assert code == 2 and err.count("\n") == 1, (argv, err)
        assert f"{p}: capture.orientations_deg: expected turntable angles" in err, err
        assert (
            f"without the shot at {without:g} deg the others keep no two string directions more than 20 deg apart"
            in err
        )
    assert not (tmp_path / "sessions").exists() and not (tmp_path / "p.sqlite").exists()


@pytest.mark.parametrize("value", ["some", "yes", "[all]"])
def test_config_check_refuses_a_bad_overlay_retention(tmp_path, capsys, value):
    bad = tmp_path / "bad.yaml"
    bad.write_text(DEMO.read_text() + f"report:\n  overlays: {value}\n")
    code, out, err = run(capsys, "config", "check", bad)
    assert code == 2 and err.count("\n") == 1 and "Traceback" not in err
    assert f"{bad}: report.overlays: " in err and ("expected " in err or "quote it" in err)


@pytest.mark.parametrize("value", ["all", "failed", "none"])
def test_config_check_accepts_each_overlay_retention(tmp_path, capsys, value):
    good = tmp_path / "good.yaml"
    good.write_text(DEMO.read_text() + f"report:\n  overlays: {value}\n")
    code, out, err = run(capsys, "config", "check", good)
    assert code == 0 and "OK" in out
    assert load_config(good).report.overlays == value


def test_config_check_refuses_an_unknown_camera_key(tmp_path, capsys):
    # issue 25: keys elsewhere were refused, those under camera passed "OK" (the driver saw them only
    # when a session opened it); the driver's own key list, read without opening anything
    d = yaml.safe_load(DEMO.read_text())
    d["station"]["camera"]["exposure_typo_us"] = 5000
    bad = tmp_path / "bad.yaml"
    bad.write_text(yaml.safe_dump(d))
    code, out, err = run(capsys, "config", "check", bad)
    assert code == 2 and err.count("\n") == 1
    assert "station.camera.exposure_typo_us: unknown key for the sim camera (known: " in err


def test_config_check_refuses_sessions_dir_naming_a_file(tmp_path, capsys):
    # issue 25: a sessions_dir that is a regular file passed with a warning, then every session failed
    d = yaml.safe_load(DEMO.read_text())
    (tmp_path / "afile").write_text("not a directory")
    d["store"]["sessions_dir"] = str(tmp_path / "afile")
    bad = tmp_path / "bad.yaml"
    bad.write_text(yaml.safe_dump(d))
    code, out, err = run(capsys, "config", "check", bad)
    assert code == 2 and err.count("\n") == 1
    assert f"store.sessions_dir: expected a directory for the sessions, {tmp_path / 'afile'} is a file" in err


def test_session_plan_touches_nothing_and_counts_the_plan(tmp_path, capsys):
    cfg = demo_copy(tmp_path)
    code, out, err = run(capsys, "session", "plan", cfg, "--json")
    assert code == 0, err
    doc = json.loads(out)
    # truth from the configuration: 3 focus settings x 8 orientations x 2 frames
    assert (doc["frames"], doc["moves"], doc["focus_locks"], doc["fits"]) == (48, 24, 3, 3)
    captures = [s for s in doc["steps"] if s["what"] == "capture + measure"]
    assert [s["orientation_deg"] for s in captures[:8]] == [0, 22.5, 45, 67.5, 90, 112.5, 135, 157.5]
    assert all(s["frames"] == 2 for s in captures) and len(captures) == 24
    assert 5 < doc["estimated_seconds"] < 120
    assert doc["estimated_seconds"] == pytest.approx(sum(s["estimated_seconds"] for s in doc["steps"]), abs=0.5)
    code, out, err = run(capsys, "session", "plan", cfg)
    rows = tsv(out)
    assert rows[0] == ["focus", "step", "orientation (deg)", "frames", "estimated (s)"]
    assert len(rows) == 1 + 24 + 3 + 1
    assert "48 frames, 24 moves, 3 fits; estimated duration" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["demo.yaml"]  # no session, no store


def test_session_plan_lists_each_rows_linear_stage_position(tmp_path, capsys):
    # two-axis capture: every angle at each position of the stage in turn (truth from the configuration)
    d = yaml.safe_load(DEMO.read_text())
    d["station"]["turntable"]["shift_axis"] = 3
    d["station"]["harp"]["shift_direction_deg"] = 0.0
    d["focus"]["settings"] = [0.0]
    d["capture"].update(orientations_deg=[0, 45, 90, 135, 157.5], shift_positions_mm=[10, 50])
    cfg = tmp_path / "two.yaml"
    cfg.write_text(yaml.safe_dump(d))
    code, out, err = run(capsys, "session", "plan", cfg, "--json")
    assert code == 0, err
    doc = json.loads(out)
    assert doc["shift_positions_mm"] == [10, 50]
    captures = [s for s in doc["steps"] if s["what"].startswith("capture + measure")]
    assert [(s["shift_mm"], s["orientation_deg"]) for s in captures] == [
        (mm, a) for mm in (10, 50) for a in (0, 45, 90, 135, 157.5)
    ]
    assert all(s["shift_mm"] is None for s in doc["steps"] if not s["what"].startswith("capture"))
    code, out, err = run(capsys, "session", "plan", demo_copy(tmp_path), "--json")  # no stage: no positions
    doc = json.loads(out)
    assert doc["shift_positions_mm"] == [] and all(s["shift_mm"] is None for s in doc["steps"])


def test_session_plan_json_flags_the_twins_steps(tmp_path, capsys):
    # capture.twin_deg: a script tells the twin's step by its flag, not by the text (truth from the configuration)
    d = yaml.safe_load(DEMO.read_text())
    d["focus"]["settings"] = [0.0, 1.0]
    d["capture"].update(orientations_deg=[0, 45, 90, 135], twin_deg=45)
    cfg = tmp_path / "twin.yaml"
    cfg.write_text(yaml.safe_dump(d))
    code, out, err = run(capsys, "session", "plan", cfg, "--json")
    assert code == 0, err
    doc = json.loads(out)
    twins = [(s["focus"], s["orientation_deg"]) for s in doc["steps"] if s["twin"]]
    assert twins == [(0.0, 45), (1.0, 45)] and doc["twin_deg"] == 45
    assert sum(1 for s in doc["steps"] if s["what"].startswith("capture + measure") and not s["twin"]) == 8


def session_with(root: Path, config, name: str, records) -> Path:
    with SessionDir.create(root, config, name=name) as s:
        for r in records:
            s.append(r)
    return root / name


def test_session_list_states_and_verdicts(tmp_path, capsys):
    config = load_config(demo_copy(tmp_path))
    root = tmp_path / "sessions"
    session_with(root, config, "a-complete", [Started("0"), SessionVerdict("FAIL"), Finished()])
    session_with(root, config, "b-failed", [Started("0"), Aborted("move turntable to 45 deg failed 3 times")])
    session_with(root, config, "c-interrupted", [Started("0"), Aborted("interrupted by the user")])
    session_with(root, config, "d-killed", [Started("0")])
    # a fault, then a resume that was killed: interrupted (the last run's stop counts)
    session_with(root, config, "e-resumed", [Started("0"), Aborted("camera timeout"), {"kind": "resume"}])
    (root / "not-a-session").mkdir()
    running = SessionDir.open(session_with(root, config, "f-running", [Started("0")]))
    try:
        code, out, err = run(capsys, "session", "list", "--config", tmp_path / "demo.yaml", "--json")
        assert code == 0, err
        listed = {s["name"]: s for s in json.loads(out)["sessions"]}
        code, tsv_out, _ = run(capsys, "session", "list", root)
    finally:
        running.close()
    assert {n: (s["state"], s["verdict"]) for n, s in listed.items()} == {
        "a-complete": ("complete", "FAIL"),
        "b-failed": ("failed", None),
        "c-interrupted": ("interrupted", None),
        "d-killed": ("interrupted", None),
        "e-resumed": ("interrupted", None),
        "f-running": ("running", None),
    }
    assert listed["b-failed"]["stop_reason"] == "move turntable to 45 deg failed 3 times"
    assert listed["a-complete"]["lens"] == "Simulated Optics SIM-12mm DEMO-0001"
    rows = tsv(tsv_out)
    assert rows[0][:3] == ["session", "state", "verdict"] and len(rows) == 7
    assert run(capsys, "session", "list", tmp_path / "absent")[0] == 2
    # one session's own directory lists it (before: "no sessions in DIR")
    code, out, err = run(capsys, "session", "list", root / "b-failed", "--json")
    assert code == 0 and [(s["name"], s["state"]) for s in json.loads(out)["sessions"]] == [("b-failed", "failed")]
    # a session of a format this version does not read is named with it, not listed as if it were its own
    meta = json.loads((root / "a-complete" / "session.json").read_text())
    (root / "a-complete" / "session.json").write_text(json.dumps({**meta, "format": 2}))
    code, out, err = run(capsys, "session", "list", root, "--json")
    assert code == 0 and "a-complete" not in {s["name"] for s in json.loads(out)["sessions"]}
    assert f"harp session: warning: {root / 'a-complete' / 'session.json'}: session format 2, but harp station" in err


def test_devices_lists_the_fakes_with_snippets(tmp_path, capsys):
    from drivers.sim.zaber_emulator import start_zaber_emulator
    from tests.drivers.fake_v4l2 import FakeV4L2Camera

    emu = start_zaber_emulator()
    try:
        with FakeV4L2Camera(tmp_path / "video0", formats=("GREY",), width=80, height=60):
            pattern = str(tmp_path / "video*")
            code, out, err = run(capsys, "devices", "--v4l2", pattern, "--port", emu.port_path, "--probe", "--json")
            assert code == 0, err
            doc = json.loads(out)
            code, table, _ = run(capsys, "devices", "--v4l2", pattern, "--port", emu.port_path)
    finally:
        emu.stop()
    by_device = {d["device"]: d for d in doc["devices"]}
    cam = by_device[str(tmp_path / "video0")]
    assert cam["kind"] == "camera" and cam["driver"] == "v4l2" and cam["config"]["device"] == str(tmp_path / "video0")
    port = by_device[emu.port_path]
    assert port["driver"] == "zaber" and port["config"]["port"] == emu.port_path and doc["probed"] is True
    rows = tsv(table)
    assert rows[0] == ["kind", "driver", "device", "description", "problem", "config snippet"]
    unprobed = [r for r in rows[1:] if r[2] == emu.port_path]
    assert unprobed and unprobed[0][1] == ""  # not probed: the driver is unknown, nothing was written to it
