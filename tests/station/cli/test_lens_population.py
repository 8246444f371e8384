"""``simulation.lens_spread`` as a user meets it (issue 21 item 2): ``harp session run`` of two lens
serials on the simulated station calibrates two different lenses, each its own unit of the demo
lens (``drivers.sim.lens.lens_unit``), reproducibly; ``harp config check`` refuses a spread out of
its range with one line naming the field.

Truth: the exact lens of each unit (the simulator's definition), compared with the stored profiles
modulo homography (``pipeline.compare.compare_models``); the calibration is what is tested.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from drivers.sim.lens import lens_for_focus, lens_unit
from pipeline.compare import compare_models
from station.store import ProfileStore
from tests.station.cli.test_session import REPO, H, W, small_config

SERIALS = ("LINE-0002", "LINE-0003")
SPREAD = 2.0


def run_harp(*args: object, timeout: float = 600) -> subprocess.CompletedProcess:
    """``harp ARGS`` in its own process group, killed with its group on every way out."""
    proc = subprocess.Popen(
        [sys.executable, "-m", "station.cli", *map(str, args)],
        cwd=REPO,
        stdin=subprocess.DEVNULL,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
    )
    try:
        out, err = proc.communicate(timeout=timeout)
        return subprocess.CompletedProcess(proc.args, proc.returncode, out, err)
    finally:
        try:
            os.killpg(proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        proc.wait()


def config_of(base: Path, serial: str, spread: object = SPREAD) -> Path:
    path = small_config(base / serial, frames=1)
    d = yaml.safe_load(path.read_text())
    d["lens"]["serial"] = serial
    d["simulation"]["lens_spread"] = spread
    path.write_text(yaml.safe_dump(d))
    return path


@pytest.fixture(scope="module")
def population(tmp_path_factory):
    base = tmp_path_factory.mktemp("population")
    out = {}
    for serial in SERIALS:
        cfg = config_of(base, serial)
        r = run_harp("session", "run", cfg, "--name", "s", "--quiet", "--no-report")
        assert r.returncode == 0, r.stderr
        with ProfileStore(cfg.parent / "profiles.sqlite", create=False) as st:
            out[serial] = {p.focus: p for p in st.profiles()}
    return out


def test_each_serial_is_calibrated_as_its_own_lens(population):
    assert sorted(population) == sorted(SERIALS)
    for serial, profiles in population.items():
        (other,) = [s for s in SERIALS if s != serial]
        assert sorted(profiles) == [0.0, 1.0]
        for focus, p in profiles.items():
            assert p.lens.serial == serial
            own = compare_models(p.model, lens_for_focus(focus, W, H, lens_unit(serial, SPREAD)), W, H)
            theirs = compare_models(p.model, lens_for_focus(focus, W, H, lens_unit(other, SPREAD)), W, H)
            nominal = compare_models(p.model, lens_for_focus(focus, W, H), W, H)
            assert own.rms < 0.02, (serial, focus, own.rms)
            assert theirs.rms > 10 * own.rms and nominal.rms > 10 * own.rms, (theirs.rms, nominal.rms, own.rms)
    # the distortion magnitudes of the two lenses differ (the control chart has a spread to show)
    d = {s: population[s][0.0].qa.metrics["distortion_max_px"] for s in SERIALS}
    assert abs(d[SERIALS[0]] - d[SERIALS[1]]) > 0.05, d


@pytest.mark.parametrize(
    ("value", "expected"),
    [
        (6, "simulation.lens_spread: expected a number in [0, 5] (times the population's spread), got 6.0"),
        (-1, "simulation.lens_spread: expected a number >= 0, got -1"),
        ("wide", "simulation.lens_spread: expected a number >= 0, got 'wide'"),
    ],
)
def test_config_check_refuses_a_spread_out_of_range(tmp_path, value, expected):
    cfg = config_of(tmp_path, "LINE-0001", value)
    r = run_harp("config", "check", cfg, timeout=120)
    assert r.returncode == 2
    assert r.stderr.splitlines() == [f"harp config: {cfg}: {expected}"], r.stderr
