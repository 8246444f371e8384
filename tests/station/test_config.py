"""Configuration: the shipped configs load; every bad field is one line naming it."""

import dataclasses
import os
from pathlib import Path

import pytest
import yaml

from station.config import ConfigError, check_port, load_config

REPO = Path(__file__).resolve().parents[2]
DEMO = REPO / "configs" / "demo.yaml"


def write(tmp_path, data, name="station.yaml"):
    p = tmp_path / name
    p.write_text(yaml.safe_dump(data) if not isinstance(data, str) else data)
    return p


def demo_data():
    return yaml.safe_load(DEMO.read_text())


def error_of(tmp_path, data) -> str:
    p = write(tmp_path, data)
    with pytest.raises(ConfigError) as ei:
        load_config(p)
    msg = str(ei.value)
    assert "\n" not in msg
    assert msg.startswith(str(p))
    return msg


@pytest.mark.parametrize("name", ["demo.yaml", "aravis-zaber.yaml", "v4l2-grbl.yaml"])
def test_shipped_configs_load(name):
    cfg = load_config(REPO / "configs" / name)
    assert len(cfg.focus_settings) == 3
    assert len(cfg.capture.orientations_deg) == 8
    assert cfg.capture.orientations_deg[1] == 22.5


def test_demo_values_and_relative_paths():
    cfg = load_config(DEMO)
    assert cfg.station.camera.driver == "sim"
    assert cfg.station.turntable.driver == "zaber"
    assert cfg.simulation is not None
    # no store.path: the per-user default store (XDG base directories), the same from every directory
    assert cfg.store_path == Path(os.environ["XDG_DATA_HOME"]) / "harp-station" / "harp-profiles.sqlite"
    assert cfg.station.turntable.as_driver_config(port="/dev/pts/9")["port"] == "/dev/pts/9"
    with pytest.raises(dataclasses.FrozenInstanceError):
        cfg.pipeline.t = 3  # frozen


def test_relative_store_path_is_relative_to_config_file(tmp_path):
    d = demo_data()
    d["store"] = {"path": "db/p.sqlite"}
    sub = tmp_path / "sub"
    sub.mkdir()
    cfg = load_config(write(sub, d))
    assert cfg.store_path == sub / "db" / "p.sqlite"
    assert cfg.sessions_dir == sub / "sessions"


def test_missing_field(tmp_path):
    d = demo_data()
    del d["lens"]["serial"]
    msg = error_of(tmp_path, d)
    assert "lens.serial: expected a string (one line, at most 200 characters), missing" in msg


def test_missing_section(tmp_path):
    d = demo_data()
    del d["capture"]
    assert "capture: expected a mapping, missing" in error_of(tmp_path, d)


def test_wrong_type(tmp_path):
    d = demo_data()
    d["capture"]["frames_per_orientation"] = "two"
    assert "capture.frames_per_orientation: expected an integer in [1, 1000], got 'two'" in error_of(tmp_path, d)


def test_wrong_list_item(tmp_path):
    d = demo_data()
    d["capture"]["orientations_deg"][2] = "45deg"
    assert "capture.orientations_deg[2]: expected a number in [-3600, 3600] deg, got '45deg'" in error_of(tmp_path, d)


def test_negative_number(tmp_path):
    d = demo_data()
    d["station"]["harp"]["string_spacing_mm"] = -1
    assert "station.harp.string_spacing_mm: expected a number in (0, 1000] mm, got -1" in error_of(tmp_path, d)


def test_unknown_camera_driver(tmp_path):
    d = demo_data()
    d["station"]["camera"]["driver"] = "webcam9000"
    msg = error_of(tmp_path, d)
    assert "station.camera.driver: expected a camera driver, one of aravis, sim, v4l2, got 'webcam9000'" in msg


def test_unknown_turntable_driver(tmp_path):
    d = demo_data()
    d["station"]["turntable"]["driver"] = "thorlabs"
    assert "station.turntable.driver: expected a turntable driver, one of grbl, zaber, got 'thorlabs'" in error_of(
        tmp_path, d
    )


def test_unknown_field_is_named(tmp_path):
    d = demo_data()
    d["capture"]["frame_per_orientation"] = 3  # typo
    assert "capture.frame_per_orientation: unknown field" in error_of(tmp_path, d)


def test_unknown_model(tmp_path):
    d = demo_data()
    d["pipeline"]["model"] = "fisheye9"
    assert "pipeline.model: expected a distortion model name" in error_of(tmp_path, d)


def test_emulator_port_needs_simulation(tmp_path):
    d = demo_data()
    del d["simulation"]
    assert "station.turntable.port:" in error_of(tmp_path, d)


def test_bad_yaml_names_line(tmp_path):
    p = write(tmp_path, "station:\n  id: [unclosed\n")
    with pytest.raises(ConfigError) as ei:
        load_config(p)
    assert "line" in str(ei.value) and "\n" not in str(ei.value)


def test_missing_file(tmp_path):
    with pytest.raises(ConfigError, match="no such file"):
        load_config(tmp_path / "nope.yaml")


def test_unreachable_port(tmp_path):
    d = yaml.safe_load((REPO / "configs" / "aravis-zaber.yaml").read_text())
    d["station"]["turntable"]["port"] = str(tmp_path / "ttyUSB77")
    cfg = load_config(write(tmp_path, d))
    with pytest.raises(ConfigError) as ei:
        check_port(cfg)
    msg = str(ei.value)
    assert "station.turntable.port: expected a reachable serial port" in msg and "ttyUSB77" in msg
    assert "\n" not in msg
    check_port(load_config(DEMO))  # the emulator is started by station.session.simulated


def test_boolean_field(tmp_path):
    d = demo_data()
    d["pipeline"]["tangential"] = "yes"
    assert "pipeline.tangential: expected true or false, got 'yes'" in error_of(tmp_path, d)


def test_pipeline_options():
    cfg = load_config(DEMO)
    assert cfg.pipeline.tangential is True and cfg.pipeline.bootstrap > 0 and cfg.pipeline.workers == 2


def test_the_keys_a_section_accepts_are_its_dataclass_fields(tmp_path):
    import dataclasses

    from station.config import PipelineConfig

    d = demo_data()
    d["pipeline"]["centre_prior"] = True  # a misspelling: the message lists the dataclass's fields
    msg = error_of(tmp_path, d)
    assert (
        f"pipeline.centre_prior: unknown field; expected one of {', '.join(f.name for f in dataclasses.fields(PipelineConfig))}"
        in msg
    )
    d["pipeline"].pop("centre_prior")
    d["pipeline"]["center_prior"] = True
    cfg = load_config(write(tmp_path, d))
    assert cfg.pipeline.spec.center_prior and cfg.pipeline.spec.label == "radial4+tangential+centre-prior"
    d["pipeline"]["degree"] = 11
    assert "pipeline.degree: expected a degree the model allows: radial degree must be within 1..10, got 11" in (
        error_of(tmp_path, d)
    )


def test_the_model_is_a_fit_label_or_auto(tmp_path):
    """Issue 22 item 2: ``pipeline.model`` is read by pipeline.fitspec.parse_choice; the older term keys
    beside it set the label's terms, and without it mean the radial model they meant (the default until
    2026-12-06); a configuration that names neither is chosen by cross-validation."""
    from pipeline.fitspec import FitSpec

    d = demo_data()
    for key in ("degree", "tangential", "prism", "center_prior"):
        d["pipeline"].pop(key, None)
    d["pipeline"]["model"] = "radial6+prism+division1"
    assert load_config(write(tmp_path, d)).pipeline.spec == FitSpec("radial", 6, prism=True, division=1)
    d["pipeline"]["tangential"] = True
    assert load_config(write(tmp_path, d)).pipeline.spec == FitSpec("radial", 6, True, True, division=1)
    d["pipeline"]["model"] = "auto"
    assert load_config(write(tmp_path, d)).pipeline.spec is None
    del d["pipeline"]["model"]  # a term without a model: an older configuration's radial model, as it meant
    assert load_config(write(tmp_path, d)).pipeline.spec == FitSpec("radial", 4, tangential=True)
    d["pipeline"].pop("tangential")  # named nowhere: chosen by cross-validation (the default since 2026-12-06)
    assert load_config(write(tmp_path, d)).pipeline.spec is None
    del d["pipeline"]
    assert load_config(write(tmp_path, d)).pipeline.spec is None
    d["pipeline"] = {"degree": 3}
    assert load_config(write(tmp_path, d)).pipeline.spec == FitSpec("radial", 3)
    d["pipeline"]["model"] = "radial4+fisheye"
    msg = error_of(tmp_path, d)
    assert "pipeline.model: expected a distortion model name (a fit label, or auto):" in msg and "'fisheye'" in msg


def test_optics_fields_of_lens_and_camera_body(tmp_path):
    from station.config import Optics

    assert load_config(DEMO).optics == Optics(focal_mm=12.0, pixel_pitch_um=3.75)
    d = demo_data()
    d["lens"].update(focal_mm=50, mount="Canon EF")
    del d["camera_body"]["pixel_pitch_um"]
    d["camera_body"].update(sensor_width_mm=22.2, crop_factor=1.611)
    cfg = load_config(write(tmp_path, d))
    assert cfg.optics == Optics(focal_mm=50.0, mount="Canon EF", sensor_width_mm=22.2, crop_factor=1.611)
    assert cfg.lens.serial == "DEMO-0001"  # the identity is unchanged


@pytest.mark.parametrize(
    "section, values, message",
    [
        # a pitch written in millimetres is outside the micrometre range
        ("camera_body", {"pixel_pitch_um": 0.0057}, "camera_body.pixel_pitch_um: expected a number in [0.2, 100] µm, "
         "got 0.0057"),
        ("lens", {"focal_mm": 0}, "lens.focal_mm: expected a number in [0.1, 10000] mm, got 0"),
        ("lens", {"focal_mm": "50mm"}, "lens.focal_mm: expected a number in [0.1, 10000] mm, got '50mm'"),
        ("lens", {"mount": ""}, "lens.mount: expected a string (one line, at most 200 characters), got ''"),
        ("camera_body", {"crop_factor": True}, "camera_body.crop_factor: expected a number in [0.1, 20], got True"),
        ("camera_body", {"pixel_pitch_um": 3.45, "sensor_width_mm": 5.0}, "expected pixel_pitch_um or sensor_width_mm"),
        ("lens", {"pixel_pitch_um": 3.45}, "lens.pixel_pitch_um: unknown field"),
    ],
)  # fmt: skip
def test_bad_optics_are_one_line_naming_the_field(tmp_path, section, values, message):
    d = demo_data()
    d[section].update(values)
    assert message in error_of(tmp_path, d)


# -------------------------------------------- what the hardware can do, known without it (issue 14 item 3)
@pytest.mark.parametrize(
    "orientations,bad,expected",
    [
        ([0, 90, 400], 2, "expected an angle in [0, 360) for a rotary stage, got 400"),
        ([-30, 0, 90], 0, "expected an angle in [0, 360) for a rotary stage, got -30"),
        ([0, 180, 360], 2, "expected an angle in [0, 360) for a rotary stage, got 360"),
    ],
)
def test_orientations_outside_a_rotary_stage(tmp_path, orientations, bad, expected):
    d = demo_data()
    d["capture"]["orientations_deg"] = orientations
    assert error_of(tmp_path, d).endswith(f"capture.orientations_deg[{bad}]: {expected}")


def test_orientations_within_configured_limits(tmp_path):
    d = demo_data()
    d["station"]["turntable"]["limits"] = [-90, 90]
    d["capture"]["orientations_deg"] = [-90, -30, 30, 90]
    assert load_config(write(tmp_path, d)).capture.orientations_deg == (-90.0, -30.0, 30.0, 90.0)
    d["capture"]["orientations_deg"] = [-30, 30, 120]
    assert error_of(tmp_path, d).endswith(
        "capture.orientations_deg[2]: expected an angle in [-90, 90] (station.turntable.limits), got 120"
    )
    d["station"]["turntable"]["limits"] = [90, -90]
    assert error_of(tmp_path, d).endswith("station.turntable.limits: expected [min, max] in degrees, got [90, -90]")


def test_focus_outside_the_simulated_lens(tmp_path):
    # focus 7.0 was clamped to 1.0 by the simulated camera, stored as 7.0 and spoilt the interpolation
    d = demo_data()
    d["focus"]["settings"] = [0, 0.5, 7.0]
    assert error_of(tmp_path, d).endswith("focus.settings[2]: expected a focus in [0, 1] (the simulated lens), got 7")


def test_two_axis_capture_needs_a_turntable_with_a_linear_stage(tmp_path, capsys):
    from station.cli import main

    d = demo_data()
    d["store"] = {"path": "p.sqlite", "sessions_dir": "sessions"}
    assert load_config(write(tmp_path, d)).capture.shift_positions_mm == ()  # none: one axis place
    d["capture"]["shift_positions_mm"] = [0, 40]
    assert error_of(tmp_path, d).endswith(
        "capture.shift_positions_mm: expected a turntable with a linear stage under it (station.turntable.shift_axis),"
        " the zaber turntable has none"
    )
    assert main(["session", "run", str(tmp_path / "station.yaml")]) == 2  # before anything is created
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "capture.shift_positions_mm: expected a turntable with a linear stage" in err
    assert not (tmp_path / "sessions").exists()
    d["capture"]["shift_positions_mm"] = [10]
    assert "capture.shift_positions_mm: expected a list of at least 2 numbers" in error_of(tmp_path, d)
    d["capture"]["shift_positions_mm"] = [10, 10]
    assert "without repeats" in error_of(tmp_path, d)


def test_two_axis_positions_within_the_stage_and_a_direction_for_few_angles(tmp_path):
    d = demo_data()
    d["station"]["turntable"]["shift_axis"] = 3
    d["station"]["harp"]["shift_direction_deg"] = 30
    d["capture"]["shift_positions_mm"] = [0, 40]
    cfg = load_config(write(tmp_path, d))
    assert cfg.capture.orientations[:2] == ((0.0, 0.0), (0.0, 22.5)) and cfg.capture.shifts_mm[8] == 40.0
    d["capture"]["shift_positions_mm"] = [0, 150]
    assert error_of(tmp_path, d).endswith(
        "capture.shift_positions_mm[1]: expected a position in [0, 100] mm (station.turntable.shift_limits), got 150"
    )
    d["capture"]["shift_positions_mm"] = [0, 40]
    d["station"]["harp"]["shift_direction_deg"] = None
    assert load_config(write(tmp_path, d)).station.harp.shift_direction_deg is None  # 8 angles: each place searched
    d["capture"]["orientations_deg"] = [0, 60, 120]
    assert error_of(tmp_path, d).endswith(
        "station.harp.shift_direction_deg: expected the image direction of a positive linear-stage move: with fewer "
        "than 4 turntable angles (capture.orientations_deg) a place's turntable axis cannot be found without it"
    )


def test_a_twin_returns_to_one_of_the_plans_angles_after_the_others(tmp_path, capsys):
    """``capture.twin_deg`` (issue 19 item 5): one more orientation at the end of the plan, at one of its angles
    (on a two-axis capture at the first place), taken on a second visit and not fitted; an angle the plan does not
    take is one line naming the field, before anything is created."""
    from station.cli import main

    d = demo_data()
    d["store"] = {"path": "p.sqlite", "sessions_dir": "sessions"}
    cap = load_config(write(tmp_path, d)).capture
    assert cap.twin is None and cap.fitted == tuple(range(8)) and cap.visits == (0,) * 8
    d["capture"]["twin_deg"] = 45
    cap = load_config(write(tmp_path, d)).capture
    assert len(cap.orientations) == 9 and cap.orientations[8] == (None, 45.0) and cap.angles_deg[2] == 45.0
    assert cap.twin == (2, 8) and cap.fitted == tuple(range(8)) and cap.visits == (0,) * 8 + (1,)
    assert cap.orientation_name(2) == "orientation 2 (45 deg)"
    assert cap.orientation_name(8) == "orientation 8 (45 deg, the twin)"
    d["station"]["turntable"]["shift_axis"] = 3
    d["station"]["harp"]["shift_direction_deg"] = 30
    d["capture"]["shift_positions_mm"] = [10, 40]
    cap = load_config(write(tmp_path, d)).capture
    assert len(cap.orientations) == 17 and cap.orientations[16] == (10.0, 45.0) and cap.twin == (2, 16)
    assert cap.fitted == tuple(range(16)) and cap.visits[16] == 1 and sum(cap.visits) == 1
    assert cap.orientation_name(9) == "orientation 9 (22.5 deg at 40 mm)"
    assert cap.orientation_name(16) == "orientation 16 (45 deg at 10 mm, the twin)"
    del d["capture"]["shift_positions_mm"]
    d["capture"]["twin_deg"] = 30
    assert error_of(tmp_path, d).endswith(
        "capture.twin_deg: expected one of capture.orientations_deg (0, 22.5, 45, 67.5, 90, 112.5, 135, 157.5), got 30"
    )
    assert main(["session", "run", str(tmp_path / "station.yaml")]) == 2  # before anything is created
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "capture.twin_deg: expected one of" in err and "Traceback" not in err
    assert not (tmp_path / "sessions").exists()
