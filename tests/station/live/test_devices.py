"""The live view on a configuration's devices (:mod:`station.live.devices`), on the simulated
station: the session's settings applied as the configuration says, one shot checked."""

from __future__ import annotations

import pytest

from tests.station.live.support import live_config


def test_check_once_captures_with_the_session_settings_at_the_stage_angle(tmp_path):
    import yaml

    from station.config import load_config
    from station.live.devices import check_once
    from station.session.simulated import simulated_devices

    p = live_config(tmp_path, width=320, height=240, frames=2)
    d = yaml.safe_load(p.read_text())
    d["capture"].update(exposure_us=7000.0, gain_db=1.5)
    p.write_text(yaml.safe_dump(d))
    config = load_config(p)
    with simulated_devices(config) as sim:
        sim.camera.open()
        sim.turntable.open()
        sim.turntable.move_to(45.0)
        out = check_once(config, sim.camera, sim.turntable)
    assert (out["exposure_us"], out["gain_db"], out["focus"]) == (7000.0, 1.5, config.focus_settings[0])
    assert out["frames_averaged"] == 2 and out["stage_deg"] == pytest.approx(45.0)
    assert out["expected_angle_deg"] == pytest.approx(config.station.harp.expected_angle(45.0))
    assert out["pass"] is (out["problems"] == []) and out["session_measurement"]["string_edges"] >= 8
