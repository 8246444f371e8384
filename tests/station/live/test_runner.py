"""The live view's engine on the simulated station (camera simulator, Zaber emulator on a pty,
real drivers): moves, coverage accumulated at rest, the through-focus peak, device errors as one
line with recovery, session mode."""

from __future__ import annotations

import os

import pytest

import drivers
from drivers.sim.camera import SimulatedCamera
from drivers.sim.pty_server import serve as serve_pty
from drivers.sim.world import SimWorld
from drivers.sim.zaber_emulator import start_zaber_emulator
from station.live.runner import LiveStation
from tests.station.live.support import live_config, running_live, wait_for

FAST = dict(speed_deg_s=3600.0, accel_deg_s2=72000.0)


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
        # the camera back: its error stays on the page, marked recovered (frames captured before the
        # fault may still be assessed meanwhile: they do not count as the camera being back)
        (e,) = wait_for(
            lambda: [e for e in st.state()["errors"] if e["device"] == "camera" and not e["active"]],
            what="the camera back",
        )
        assert e["recovered_at"] and e["message"] == err[0]["message"]
        n = st.frames_assessed
        wait_for(lambda: st.frames_assessed >= n + 2, what="frames after the reconnect")
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
