"""A small simulated station for the live-view tests: the demo station at test size, with the
simulated camera's defocus switched on (best focus 0.37) and a fast Zaber emulator."""

from __future__ import annotations

import contextlib
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import yaml

REPO = Path(__file__).resolve().parents[3]
DEMO = REPO / "configs" / "demo.yaml"
BEST_FOCUS = 0.37


def live_config(dirpath: Path, width: int = 480, height: int = 360, frames: int = 1, **camera: Any) -> Path:
    d = yaml.safe_load(DEMO.read_text())
    d["station"]["camera"].update(
        width=width, height=height, spacing_px=40.0, best_focus=BEST_FOCUS, defocus_blur_px=8.0, **camera
    )
    d["focus"]["settings"] = [BEST_FOCUS]
    d["capture"]["orientations_deg"] = [0, 45, 90, 135]
    d["capture"]["frames_per_orientation"] = frames
    d["simulation"]["emulator"] = {"speed_deg_s": 720.0, "accel_deg_s2": 7200.0}
    d["store"] = {"path": "profiles.sqlite", "sessions_dir": "sessions"}
    dirpath.mkdir(parents=True, exist_ok=True)
    p = dirpath / "station.yaml"
    p.write_text(yaml.safe_dump(d))
    return p


def wait_for(cond: Callable[[], Any], timeout: float = 30.0, what: str = "condition") -> Any:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        v = cond()
        if v:
            return v
        time.sleep(0.02)
    raise AssertionError(f"timed out after {timeout:g} s waiting for {what}")


@contextlib.contextmanager
def running_live(config_path: Path, **kw: Any) -> Iterator[tuple[Any, Any, Any]]:
    """``(live_station, camera, simulated station)`` on the simulated devices, started."""
    from station.config import load_config
    from station.live.devices import apply_session_settings, live_station
    from station.session.simulated import simulated_devices

    config = load_config(config_path)
    with simulated_devices(config) as sim:
        sim.camera.open()
        sim.turntable.open()
        try:
            apply_session_settings(config, sim.camera)
            with live_station(config, sim.camera, sim.turntable, **kw) as st:
                yield st, sim.camera, sim
        finally:
            sim.turntable.close()
            sim.camera.close()
