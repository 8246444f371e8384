"""Board views tilted by the stage's second axis (``intrinsics.placement: stage``, issue 23): the turntable
turns the board and its tilt axis (a Zaber axis 2, emulated on the same connection) tilts it, one view per
angle and tilt, with nobody at the station. The simulated camera renders the board at the tilt the
emulated axis is at when the frame is exposed; its own camera matrix is the truth."""

from __future__ import annotations

import json
import time

import pytest
import yaml

from station.cli import main
from station.config import load_config
from station.session.directory import SessionDir
from station.session.executor import Executor
from station.session.simulated import simulated_devices
from station.store import ProfileStore
from tests.station.session.test_operator_boards import k_sigmas, operator_config


def stage_config(dirpath, **intrinsics):
    p = operator_config(dirpath)
    d = yaml.safe_load(p.read_text())
    d["station"]["turntable"]["tilt_axis"] = 2
    d["intrinsics"] = {"board": "charuco:9x7:24:17", "placement": "stage", "angles_deg": [0, 120, 240],
                       "tilts_deg": [20, 40], "min_views": 4, **intrinsics}  # fmt: skip
    p.write_text(yaml.safe_dump(d))
    return p


def test_the_stage_tilts_and_turns_the_board_for_each_view(tmp_path):
    cfg = load_config(stage_config(tmp_path))
    with simulated_devices(cfg) as sim, SessionDir.create(cfg.sessions_dir, cfg, name="s") as s:
        sim.camera.open()
        sim.turntable.open()
        with ProfileStore(tmp_path / "profiles.sqlite") as store:
            result = Executor(s, sim.camera, sim.turntable, store=store, sleep=lambda _s: None).run()
            (profile,) = store.profiles()
        truth = sim.camera.camera_matrix()
        tilt_now = sim.world.tilt_at()
    assert result.exit_code == 0, result.message
    recs = [json.loads(x) for x in (cfg.sessions_dir / "s" / "manifest.jsonl").read_text().splitlines()]
    boards = [r for r in recs if r["kind"] == "board"]
    assert [r["commanded_deg"] for r in boards] == [0.0, 120.0, 240.0] * 2
    assert [r["tilt_deg"] for r in boards] == pytest.approx([20] * 3 + [40] * 3, abs=1e-3)  # read back: 1 microstep
    assert all(abs(r["stage_deg"] - r["commanded_deg"]) < 0.05 for r in boards) and tilt_now == boards[-1]["tilt_deg"]
    (k_rec,) = [r for r in recs if r["kind"] == "intrinsics"]
    assert k_rec["rejected"] == []
    k = profile.intrinsics
    assert k is not None and k.n_views == 6
    z = k_sigmas(k, truth)
    print(f"K - truth in sigmas {[f'{v:+.2f}' for v in z]}, sigma {[f'{v:.2f}' for v in k.sd[:4]]}")
    assert all(abs(v) <= 2 for v in z)


def test_a_stage_without_a_tilt_axis_or_a_tilt_beyond_it_is_refused(tmp_path, capsys):
    p = stage_config(tmp_path)
    d = yaml.safe_load(p.read_text())
    del d["station"]["turntable"]["tilt_axis"]
    p.write_text(yaml.safe_dump(d))
    assert main(["config", "check", str(p)]) == 2
    err = capsys.readouterr().err.strip()
    assert f"{p}: intrinsics.placement: stage: expected a turntable with a tilt axis" in err and "\n" not in err
    p = stage_config(tmp_path / "far", tilts_deg=[20, 75])
    assert main(["config", "check", str(p)]) == 2
    err = capsys.readouterr().err.strip()
    assert f"{p}: intrinsics.tilts_deg[1]: expected a tilt in [0, 60] (station.turntable.tilt_limits), got 75" in err


def test_a_grbl_stage_turns_and_tilts_the_board(tmp_path):
    """The simulated station with a GRBL turntable (``driver: grbl``, ``port: emulator``): the GRBL emulator
    on a pty, the turntable on its X axis and the board's tilt on its Y axis (``tilt_axis: Y``), driven by
    the real GRBL driver in G-code. The views' read-back angles and tilts are the commanded ones, the tilt
    axis ends where the last view put it, and the camera matrix holds the simulator's within 2 sigma."""
    from drivers.grbl import GrblTurntable
    from drivers.sim.grbl_emulator import GrblEmulator

    p = stage_config(tmp_path, angles_deg=[0, 120, 240], tilts_deg=[20, 40])
    d = yaml.safe_load(p.read_text())
    d["station"]["turntable"] = {"driver": "grbl", "port": "emulator", "tilt_axis": "Y", "poll_interval": 0.01}
    p.write_text(yaml.safe_dump(d))
    cfg = load_config(p)
    with simulated_devices(cfg) as sim, SessionDir.create(cfg.sessions_dir, cfg, name="s") as s:
        assert isinstance(sim.turntable, GrblTurntable) and isinstance(sim.emulator.emulator, GrblEmulator)
        sim.camera.open()
        sim.turntable.open()
        with ProfileStore(tmp_path / "profiles.sqlite") as store:
            result = Executor(s, sim.camera, sim.turntable, store=store, sleep=lambda _s: None).run()
            (profile,) = store.profiles()
        truth = sim.camera.camera_matrix()
        emu = sim.emulator.emulator
        assert emu.tilt is not None
        tilt_now, tilt_axis_now = sim.world.tilt_at(), emu.tilt.position(time.monotonic())
    assert result.exit_code == 0, result.message
    recs = [json.loads(x) for x in (cfg.sessions_dir / "s" / "manifest.jsonl").read_text().splitlines()]
    boards = [r for r in recs if r["kind"] == "board"]
    assert [(r["commanded_deg"], r["tilt_deg"]) for r in boards] == [
        (a, t) for t in (20.0, 40.0) for a in (0.0, 120.0, 240.0)
    ]  # GRBL reports 3 decimals: the read-back is the commanded angle
    assert all(abs(r["stage_deg"] - r["commanded_deg"]) < 0.05 for r in boards)
    assert tilt_now == tilt_axis_now == 40.0
    k = profile.intrinsics
    assert k is not None and k.n_views == 6
    z = k_sigmas(k, truth)
    print(f"GRBL stage: K - truth in sigmas {[f'{v:+.2f}' for v in z]}, sigma {[f'{v:.2f}' for v in k.sd[:4]]}")
    assert all(abs(v) <= 2 for v in z)


def test_a_grbl_stage_refuses_zaber_emulator_options(tmp_path, capsys):
    p = stage_config(tmp_path)
    d = yaml.safe_load(p.read_text())
    d["station"]["turntable"] = {"driver": "grbl", "port": "emulator", "tilt_axis": "Y"}
    d["simulation"]["emulator"]["axes"] = 2
    p.write_text(yaml.safe_dump(d))
    assert main(["session", "run", str(p), "--quiet", "--name", "s"]) == 2
    err = capsys.readouterr().err.strip()
    assert "simulation.emulator: 'axes' is a Zaber emulator option; a GRBL turntable's emulator takes " in err
    assert "\n" not in err
