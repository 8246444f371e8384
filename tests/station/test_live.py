"""The live view's engine and checks on the simulated station (camera simulator, Zaber emulator
on a pty, real drivers): warnings against the session's limits, coverage accumulated at rest,
device errors as one line with recovery, ``harp live --once`` verdicts."""

from __future__ import annotations

import argparse
import json
import os

import numpy as np
import pytest

import drivers
from drivers.sim.camera import SimulatedCamera
from drivers.sim.pty_server import serve as serve_pty
from drivers.sim.world import SimWorld
from drivers.sim.zaber_emulator import start_zaber_emulator
from pipeline.assess import assess_frame
from station.config import CheckConfig
from station.live.checks import live_warnings
from station.live.runner import LiveStation
from tests.station.live_support import live_config, running_live, wait_for

FAST = dict(speed_deg_s=3600.0, accel_deg_s2=72000.0)


def test_exposure_warning_appears_exactly_when_the_frame_saturates():
    """Exposure swept through the simulator's clipping point (scale 255/200 = 1.275 at the centre
    of the lit sheet): the over-exposure warning is on exactly for the frames whose saturated
    fraction exceeds the session's limit, counted here on the frame itself."""
    checks = CheckConfig()
    cam = SimulatedCamera(width=320, height=240, seed=2)
    first = None
    with cam:
        for scale in np.arange(1.0, 1.40001, 0.0125):
            cam.set_exposure(10_000.0 * scale)
            img = cam.capture().image
            warned = any(w.startswith("over-exposed") for w in live_warnings(assess_frame(img), checks))
            saturated = float(np.mean(img == 255))
            assert warned == (saturated > checks.max_saturated_fraction), (scale, saturated)
            if scale <= 1.25:  # 200 x 1.25 = 250 grey levels: 3 sigma of noise below the top
                assert not warned
            if scale >= 1.30:
                assert warned
            if warned and first is None:
                first = scale
    assert first is not None and 1.2625 <= first <= 1.2875, first


def test_live_station_moves_on_next_and_accumulates_coverage_at_rest(tmp_path):
    with running_live(live_config(tmp_path)) as (st, cam, sim):
        wait_for(lambda: st.state().get("coverage_total"), what="a frame at rest")
        s = st.state()
        assert s["figures"]["strings_found"] >= 4 and s["warnings"] == [] and s["ok"]
        assert s["coverage_total"]["corners_covered"] == [False, False, False, False]
        assert s["coverage_total"]["covered_fraction"] == 0.0
        assert s["turntable"]["position_deg"] == pytest.approx(0.0, abs=1e-3)
        for k, target in enumerate((45.0, 90.0, 135.0), start=1):
            st.command("next").result(timeout=20)
            wait_for(
                lambda: st.state()["frame"]["stage_deg"] == pytest.approx(target, abs=1e-3), what="a frame at rest"
            )
            s = st.state()
            assert s["turntable"]["position_deg"] == pytest.approx(target, abs=1e-3)
            assert s["turntable"]["orientation_idx"] == k
            assert s["frame"]["expected_angle_deg"] == pytest.approx((target + 5.0) % 180)
        cov = s["coverage_total"]
        assert cov["orientations_seen_deg"] == [0.0, 45.0, 90.0, 135.0]  # nothing seen while moving
        assert cov["corners_covered"] == [True, True, True, True] and cov["covered_fraction"] == 1.0
        st.command("next").result(timeout=20)  # wraps around the plan
        assert st.state()["turntable"]["position_deg"] == pytest.approx(0.0, abs=1e-3)
        st.command("reset_coverage").result(timeout=1)
        assert st.state()["coverage_total"] is None


def test_focus_commands_and_the_through_focus_peak(tmp_path):
    with running_live(live_config(tmp_path, width=320, height=240)) as (st, cam, sim):
        st.command("reset_focus").result(timeout=1)
        for f in (0.29, 0.33, 0.37, 0.41, 0.45):
            assert st.command("focus", f).result(timeout=5)["focus"] == f
            n = st.frames_assessed
            wait_for(lambda: st.frames_assessed >= n + 2, what="frames at the new focus")
        peak = st.state()["focus_history"]["peak"]
        assert peak["bracketed"] and abs(peak["focus"] - 0.37) <= 0.02
        with pytest.raises(ValueError, match="outside the range"):
            st.command("focus", 1.5).result(timeout=5)
        with pytest.raises(ValueError, match="unknown action"):
            st.command("jump").result(timeout=1)


def test_camera_faults_are_one_line_and_the_view_carries_on(tmp_path):
    with running_live(live_config(tmp_path, width=320, height=240), reconnect_s=0.05) as (st, cam, sim):
        wait_for(lambda: st.frames_assessed >= 1, what="a first frame")
        cam.fail_next(1, "disconnect")
        err = wait_for(lambda: [e for e in st.state()["errors"] if e["device"] == "camera"], what="the camera error")
        assert err[0]["message"].startswith("sim camera SIM-0") and "\n" not in err[0]["message"]
        n = st.frames_assessed
        wait_for(lambda: st.frames_assessed >= n + 2, what="frames after the reconnect")
        (e,) = [e for e in st.state()["errors"] if e["device"] == "camera"]
        assert not e["active"] and e["recovered_at"]
        cam.fail_next(2, "timeout")
        wait_for(
            lambda: any(e["active"] and "no frame within" in e["message"] for e in st.state()["errors"]), 10, "timeout"
        )
        wait_for(lambda: not any(e["active"] for e in st.state()["errors"]), 10, "recovery")


def test_unplugged_turntable_is_one_line_and_reconnects_when_back(tmp_path):
    """The stage's cable is pulled and plugged back (a new tty behind the same by-id link)."""
    world = SimWorld(harp_offset_deg=5.0)
    first = start_zaber_emulator(world=world, **FAST)
    link = tmp_path / "usb-zaber"
    os.symlink(first.port_path, link)
    second = None
    cam = SimulatedCamera(world, width=320, height=240)
    tt = drivers.open_turntable({"driver": "zaber", "port": str(link), "poll_interval": 0.005, "reply_timeout": 0.5})
    try:
        cam.open()
        tt.open()
        with LiveStation(cam, tt, orientations=(0.0, 90.0), reconnect_s=0.05) as st:
            st.command("next").result(timeout=20)
            wait_for(lambda: st.frames_assessed > 0, what="a first frame")
            first.server.vanish()
            err = wait_for(
                lambda: [e for e in st.state()["errors"] if e["device"] == "turntable" and e["active"]], 10, "error"
            )
            assert err[0]["message"].startswith(tt.name) and "\n" not in err[0]["message"]
            n = st.frames_assessed
            wait_for(lambda: st.frames_assessed > n, what="frames while the turntable is away")  # the picture goes on
            os.unlink(link)
            second = serve_pty(first.emulator, name="zaber")
            os.symlink(second.port_path, link)
            wait_for(lambda: not any(e["active"] for e in st.state()["errors"]), 20, "the turntable back")
            assert st.command("next").result(timeout=20)["position_deg"] == pytest.approx(0.0, abs=1e-3)
    finally:
        tt.close()
        cam.close()
        first.stop()
        if second is not None:
            second.stop()


def test_session_mode_shows_records_and_refuses_device_commands():
    st = LiveStation(None)
    with st:
        st.begin_session({"session": "s1"})
        cam = SimulatedCamera(width=320, height=240)
        with cam:
            st.show_frame(cam.capture(), stage_deg=0.0, focus_idx=0, orientation_idx=0)
        st.session_record({"kind": "shot", "focus_idx": 0, "orientation_idx": 0, "problems": [], "n_lines": 14})
        st.session_record({"kind": "finished"})
        wait_for(lambda: st.frames_assessed >= 1, what="the session's frame")
        s = st.state()
        assert s["session"]["state"] == "finished" and s["session"]["shots"][0]["n_lines"] == 14
        assert s["frame"]["focus_idx"] == 0 and s["figures"]["strings_found"] >= 3
        with pytest.raises(ValueError, match="session is running"):
            st.command("next").result(timeout=1)


# ------------------------------------------------------------------ harp live --once
def _harp_live(argv):
    from station.live.command import register

    parser = argparse.ArgumentParser()
    register(parser.add_subparsers())
    args = parser.parse_args(["live", *map(str, argv)])
    return args.func(args)


def test_once_json_passes_a_good_shot(tmp_path, capsys):
    assert _harp_live([live_config(tmp_path, frames=2), "--once", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["pass"] is True and out["problems"] == [] and out["frames_averaged"] == 2
    a = out["assessment"]
    assert a["strings_found"] >= 4 and a["focus_score"] > 0.4 and a["exposure"]["saturated_fraction"] == 0
    assert out["session_measurement"]["string_edges"] >= 8
    assert out["expected_angle_deg"] == pytest.approx(5.0) and a["angle_deg"] == pytest.approx(5.0, abs=1.0)
    assert len(a["coverage"]["covered"]) == 6


@pytest.mark.parametrize(
    "change, problem",
    [
        ({"capture": {"exposure_us": 16000}}, "over-exposed"),
        ({"station": {"harp": {"offset_deg": 50.0}}}, "expected 50.0 deg"),
    ],
)
def test_once_fails_a_shot_the_session_would_recapture(tmp_path, capsys, change, problem):
    import yaml

    p = live_config(tmp_path)
    d = yaml.safe_load(p.read_text())
    for section, values in change.items():
        for k, v in values.items():
            if isinstance(v, dict):
                d[section][k].update(v)
            else:
                d[section][k] = v
    p.write_text(yaml.safe_dump(d))
    assert _harp_live([p, "--once", "--json"]) == 1
    out = json.loads(capsys.readouterr().out)
    assert out["pass"] is False and any(problem in x for x in out["problems"]), out["problems"]


def test_once_bad_config_is_one_line_exit_2(tmp_path, capsys):
    p = tmp_path / "bad.yaml"
    p.write_text("station: [1, 2]\n")
    assert _harp_live([p, "--once"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("harp live: ") and err.count("\n") == 1 and "bad.yaml" in err


def test_live_refuses_a_network_address_without_a_token(tmp_path, capsys):
    assert _harp_live([live_config(tmp_path), "--host", "0.0.0.0", "--token", ""]) == 2
    assert "token is empty" in capsys.readouterr().err
    os.environ.pop("HARP_WEB_TOKEN", None)
    assert _harp_live([live_config(tmp_path), "--host", "0.0.0.0"]) == 2
    assert "give a token" in capsys.readouterr().err
