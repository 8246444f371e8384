"""Shared conformance check of the :class:`drivers.protocols.Camera` protocol.

Every camera driver runs :func:`run_camera_conformance` against a device (the
Aravis fakes, linuxpy over a faked ioctl layer, the simulated camera; see
``tests/drivers/test_camera_conformance.py``). It checks the protocol's
promises, not one device's features::

    from tests.drivers.conformance_camera import run_camera_conformance
    run_camera_conformance(camera, focus=100.0)   # camera created, not opened
"""

from __future__ import annotations

import math
import time

import numpy as np
import pytest

from drivers.errors import DriverError, OutOfRange
from drivers.protocols import Camera, CameraIdentity, CameraRanges, Frame, Range

#: pixel format names a driver may report, and the image dtype they produce
PIXEL_DTYPES = {
    "Mono8": np.uint8,
    "GREY": np.uint8,
    "YUYV": np.uint8,
    "MJPG": np.uint8,
    "Mono16": np.uint16,
    "Y16": np.uint16,
    "Mono10": np.uint16,
    "Mono12": np.uint16,
}


def _check_ranges(cam, exposure_us: float, gain_db: float, focus: float) -> None:
    for getter, setter, value in (
        (cam.exposure_range, cam.set_exposure, exposure_us),
        (cam.gain_range, cam.set_gain, gain_db),
        (cam.focus_range, cam.lock_focus, focus),
    ):
        rng = getter()
        if rng is None:
            continue
        assert isinstance(rng, Range) and rng.minimum < rng.maximum, rng
        assert value in rng, f"{value} set above, but outside {rng}"
        span = max(rng.maximum - rng.minimum, 1.0)
        below = rng.minimum / 2 if rng.minimum > 0 else rng.minimum - span  # an exposure stays positive
        for bad in (rng.maximum + span, below):
            with pytest.raises(OutOfRange):
                setter(bad)


def _close(a: float, b: float, tol: float) -> bool:
    return math.isfinite(a) and abs(a - b) <= tol


def run_camera_conformance(
    cam,
    *,
    exposure_us: float = 20_000.0,
    gain_db: float = 2.0,
    focus: float = 0.5,
    exposure_tol_us: float = 1e-6,
    gain_tol_db: float = 1e-6,
    focus_tol: float = 1e-6,
    n_frames: int = 3,
    timeout: float = 5.0,
) -> list[Frame]:
    """Exercise ``cam`` (created, not opened) through the whole Camera protocol.

    Checks: structural ``isinstance``; ``__enter__`` returns the camera;
    ``identity`` is a :class:`CameraIdentity` of strings with a model name;
    ``sensor_size`` is a pair of positive ints; ``pixel_format`` is a known
    name; ``set_exposure`` / ``set_gain`` / ``lock_focus`` return the read-back,
    equal to the getters and within the tolerance of the request; ``capture``
    returns ``n_frames`` :class:`Frame` objects with a 2-D C-contiguous image
    of the sensor size and the dtype of the pixel format, a wall-clock
    timestamp taken during the call, the settings read back above, the
    camera identity, counters 0, 1, 2, ... and a dict ``extra``; after
    ``close`` a capture raises :class:`DriverError`; reopening restarts the
    counter at 0. With :class:`CameraRanges` (every driver here): each range
    is a :class:`Range` (or None) containing the values set above, and a
    value beyond either end raises :class:`OutOfRange` and changes nothing.
    Returns the frames of the first session.
    """
    assert isinstance(cam, Camera), f"{type(cam).__name__} does not satisfy the Camera protocol"
    frames: list[Frame] = []
    with cam as entered:
        assert entered is cam, "__enter__ must return the camera itself"
        ident = cam.identity
        assert isinstance(ident, CameraIdentity), f"identity is {type(ident).__name__}"
        assert all(isinstance(v, str) for v in (ident.vendor, ident.model, ident.serial)), ident
        assert ident.model, f"identity has no model name: {ident!r}"
        w, h = cam.sensor_size
        assert isinstance(w, int) and isinstance(h, int) and w > 0 and h > 0, cam.sensor_size
        fmt = cam.pixel_format
        assert fmt in PIXEL_DTYPES, f"unknown pixel format {fmt!r}"

        got_exp = cam.set_exposure(exposure_us)
        assert isinstance(got_exp, float), f"set_exposure returned {got_exp!r}"
        assert _close(got_exp, exposure_us, exposure_tol_us), (got_exp, exposure_us)
        assert cam.get_exposure() == got_exp
        got_gain = cam.set_gain(gain_db)
        assert isinstance(got_gain, float), f"set_gain returned {got_gain!r}"
        assert _close(got_gain, gain_db, gain_tol_db), (got_gain, gain_db)
        assert cam.get_gain() == got_gain
        got_focus = cam.lock_focus(focus)
        assert isinstance(got_focus, float), f"lock_focus returned {got_focus!r}"
        assert _close(got_focus, focus, focus_tol), (got_focus, focus)
        assert cam.get_focus() == got_focus
        if isinstance(cam, CameraRanges):
            _check_ranges(cam, exposure_us, gain_db, focus)
            assert (cam.get_exposure(), cam.get_gain(), cam.get_focus()) == (got_exp, got_gain, got_focus)

        last_stamp = -math.inf
        for i in range(n_frames):
            t0 = time.time()
            f = cam.capture(timeout=timeout)
            t1 = time.time()
            assert isinstance(f, Frame), f"capture returned {type(f).__name__}"
            assert isinstance(f.image, np.ndarray) and f.image.ndim == 2, getattr(f.image, "shape", f.image)
            assert f.image.shape == (h, w), f"image {f.image.shape} != sensor (h, w) = {(h, w)}"
            assert f.image.dtype == PIXEL_DTYPES[fmt], f"{fmt} frame has dtype {f.image.dtype}"
            assert f.image.flags.c_contiguous
            assert t0 - 1.0 <= f.timestamp <= t1 + 1e-3, (t0, f.timestamp, t1)
            assert f.timestamp >= last_stamp
            last_stamp = f.timestamp
            assert f.exposure_us == got_exp and f.gain_db == got_gain and f.focus == got_focus
            assert f.camera == ident
            assert f.counter == i, f"frame {i} has counter {f.counter}"
            assert isinstance(f.extra, dict)
            frames.append(f)
    with pytest.raises(DriverError):
        cam.capture(timeout=0.5)
    with cam:
        assert cam.capture(timeout=timeout).counter == 0, "counter must restart at 0 after reopening"
    with pytest.raises(DriverError):
        cam.capture(timeout=0.5)
    return frames
