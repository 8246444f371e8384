"""Test doubles of the driver Protocols for executor tests (tests only).

``FakeCamera`` renders a harp with :func:`pipeline.render.render_harp` at the
angle of the shared ``FakeStage`` through a fixed true lens; both accept a
script of faults to raise on given calls, so the executor's retry / abort
paths can be exercised deterministically.
"""

from __future__ import annotations

import time

from drivers.protocols import CameraIdentity, Frame
from pipeline.models.radial import RadialModel
from pipeline.render import HarpScene, render_harp

W, H = 320, 240
TRUE_LENS = RadialModel.for_image(W, H, k=(1.0, 0.0, 0.02))


class FakeStage:
    """A turntable double: ``move_to`` sets the shared angle at once."""

    def __init__(self, offset_deg=5.0, faults=None):
        self.deg = 0.0
        self.offset_deg = offset_deg
        self.faults = dict(faults or {})  # call number (from 1) -> exception, or callable(n)
        self.calls = 0
        self.opened = 0
        self.closed = 0

    def open(self):
        self.opened += 1

    def close(self):
        self.closed += 1

    def __enter__(self):
        self.open()
        return self

    def __exit__(self, *exc):
        self.close()

    def home(self, timeout=60.0):
        self.deg = 0.0

    def move_to(self, degrees, timeout=60.0):
        self.calls += 1
        fault = self.faults.get(self.calls) or self.faults.get("always")
        if callable(fault) and not isinstance(fault, BaseException):
            fault = fault(self.calls)
        if fault is not None:
            raise fault
        self.deg = float(degrees)
        return self.deg

    def position(self):
        return self.deg

    def stop(self):
        """A fake stage is always at rest."""

    @property
    def limits(self):
        return (0.0, 360.0)

    def status(self):
        return {"busy": False, "warnings": []}


class FakeCamera:
    """A camera double rendering the harp at the stage angle (8-bit, 320x240)."""

    def __init__(self, stage: FakeStage, faults=None, images=None, seed=0):
        self.stage = stage
        self.faults = dict(faults or {})  # capture number (from 1) -> exception
        self.images = dict(images or {})  # capture number -> replacement image
        self.calls = 0
        self.counter = 0
        self.focus = None
        self.exposure = 0.0
        self.seed = seed
        self.opened = 0

    def open(self):
        self.opened += 1

    def close(self):
        """Nothing to release."""

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        """Nothing to release."""

    @property
    def identity(self):
        return CameraIdentity("Fake", "Cam", "F1")

    @property
    def sensor_size(self):
        return (W, H)

    @property
    def pixel_format(self):
        return "Mono8"

    def set_exposure(self, us):
        self.exposure = us
        return us

    def get_exposure(self):
        return self.exposure

    def set_gain(self, db):
        return db

    def get_gain(self):
        return 0.0

    def lock_focus(self, position):
        self.focus = position
        return position

    def get_focus(self):
        return self.focus

    def capture(self, timeout=5.0):
        self.calls += 1
        fault = self.faults.get(self.calls) or self.faults.get("always")
        if fault is not None:
            raise fault
        if self.calls in self.images:
            img = self.images[self.calls]
        else:
            scene = HarpScene(
                angle_deg=(self.stage.deg + self.stage.offset_deg) % 180.0, spacing_px=40.0, vignetting=0.1
            )
            img = render_harp(
                W, H, scene, TRUE_LENS, noise_sigma=1.0, seed=self.seed + int(self.stage.deg * 10) + 1000 * self.counter
            ).image
        self.counter += 1
        return Frame(
            image=img,
            timestamp=time.time(),
            exposure_us=self.exposure,
            gain_db=0.0,
            focus=self.focus,
            camera=self.identity,
            counter=self.counter - 1,
        )
