"""The simulated camera with the realistic simulator (``realism_seed``): configuration,
the harp turning through the full circle, exposure and gain on the sensor, exact truth."""

from __future__ import annotations

import numpy as np
import pytest

import drivers
from drivers.sim.camera import SimulatedCamera
from drivers.sim.world import SimWorld
from pipeline.measure import measure_image
from pipeline.realism import Shot
from pipeline.render import Rendered
from tests.pipeline import _harp_truth as truth

SMALL = {"driver": "sim", "width": 480, "height": 360, "spacing_px": 45.0, "string_width_px": 3.0}


def _camera(**cfg) -> SimulatedCamera:
    cam = drivers.open_camera({**SMALL, **cfg}, world=SimWorld())
    assert isinstance(cam, SimulatedCamera)
    return cam


def test_a_realistic_camera_renders_shots_whose_truth_the_measurement_finds():
    cam = _camera(realism_seed=3, seed=1)
    cam.world.set_stage(25.0)
    with cam:
        frame = cam.capture()
    shot = cam.last_rendered
    assert isinstance(shot, Shot) and np.array_equal(shot.image, frame.image)
    assert frame.image.dtype == np.uint8 and frame.extra["sim"]["realism_seed"] == 3
    assert shot.pose.turntable_deg == pytest.approx(25.0) and shot.pose.angle_deg == pytest.approx(25.0)
    assert shot.harp.spacing_px == 45.0 and shot.effects.sensor.cfa == "RGGB"
    assert frame.extra["sim"]["blur_px"] == shot.effects.blur.sigma_px
    m = measure_image(frame.image)
    c = truth.compare(shot, m)
    assert len(c.matches) >= 12
    assert m.d == pytest.approx(c.true.d, rel=0.03)


def test_the_harp_turns_through_the_whole_circle():
    """A clean harp looks the same at stage 10 and 190 degrees (its strings are straight); a real
    one is upside down: its strings' shapes, the back-light and the sag are not."""
    clean, real = _camera(seed=1), _camera(realism_seed=5, seed=1)
    out = {}
    for name, cam in (("clean", clean), ("real", real)):
        with cam:
            frames = []
            for stage in (10.0, 190.0):
                cam.world.set_stage(stage)
                cam.set_capture_index(0)
                frames.append(cam.capture())
        out[name] = frames
    assert np.array_equal(out["clean"][0].image, out["clean"][1].image)
    assert isinstance(clean.last_rendered, Rendered)
    a, b = out["real"]
    assert a.extra["sim"]["string_angle_deg"] == b.extra["sim"]["string_angle_deg"]
    assert np.abs(a.image.astype(int) - b.image.astype(int)).mean() > 1.0
    assert real.last_rendered.pose.angle_deg == pytest.approx(190.0)


def test_exposure_and_gain_reach_the_sensor():
    cam = _camera(realism_seed=2, bit_depth=16, seed=4)
    with cam:
        base = cam.render(angle_deg=30.0, index=0)
        cam.set_gain(12.0)
        gained = cam.render(angle_deg=30.0, index=0)
    s0, s1 = base.effects.sensor, gained.effects.sensor
    g = 10 ** (12.0 / 20)
    assert s1.exposure == pytest.approx(s0.exposure * g) and s1.full_well_e == pytest.approx(s0.full_well_e / g)
    # the same electrons over fewer per grey level: brighter, and the lit sheet clips (4x the codes)
    assert gained.image.mean() > base.image.mean()
    assert (gained.image == 65535).mean() > 0.5 > (base.image == 65535).mean()


def test_defocus_widens_the_drawn_psf():
    cam = _camera(realism_seed=2, best_focus=0.5, defocus_blur_px=2.0)
    sharp = cam.render(angle_deg=0.0, focus=0.5, index=0)
    blurred = cam.render(angle_deg=0.0, focus=1.0, index=0)
    assert blurred.effects.blur.sigma_px == pytest.approx(np.hypot(sharp.effects.blur.sigma_px, 1.0))


@pytest.mark.parametrize(
    ("cfg", "message"),
    [
        ({"realism_seed": -1}, "realism_seed"),
        ({"realism_seed": 1.5}, "realism_seed"),
        ({"realism_seed": True}, "realism_seed"),
        ({"jpeg_quality": 90}, "jpeg_quality needs realism_seed"),
        ({"realism_seed": 1, "jpeg_quality": 101}, "jpeg_quality"),
        ({"realism_seed": 1, "jpeg_quality": 90, "bit_depth": 16}, "bit_depth 8"),
    ],
)
def test_bad_realism_settings_are_one_line_naming_the_key(cfg, message):
    with pytest.raises(ValueError, match=message) as err:
        drivers.open_camera({**SMALL, **cfg}, world=SimWorld())
    assert "\n" not in str(err.value)


def test_jpeg_frames_and_null_keys():
    cam = _camera(realism_seed=1, jpeg_quality=90, seed=2)
    assert cam.render(angle_deg=10.0, index=0).effects.development.jpeg_quality == 90
    plain = _camera(realism_seed=None, jpeg_quality=None)
    assert plain.realism is None and isinstance(plain.render(angle_deg=10.0, index=0), Rendered)


def test_a_clean_camera_does_not_import_the_realistic_simulator():
    import subprocess
    import sys
    from pathlib import Path

    code = (
        "import sys, drivers\n"
        "from drivers.sim.world import SimWorld\n"
        "cam = drivers.open_camera({'driver': 'sim', 'width': 64, 'height': 48}, world=SimWorld())\n"
        "cam.open(); cam.capture()\n"
        "print(' '.join(m for m in sys.modules if m.startswith('pipeline.')))\n"
    )
    repo = Path(__file__).resolve().parents[2]
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=repo, timeout=120)
    assert done.returncode == 0, done.stderr
    mods = set(done.stdout.split())
    assert "pipeline.render" in mods
    assert not mods & {"pipeline.realism", "pipeline.harp_scene", "pipeline.sensor", "pipeline.optics"}
