"""Open a configured station's camera and turntable (real or simulated).

Problems opening a device become a :class:`station.config.ConfigError`
naming the configuration field to look at (one line), e.g. an unreachable
turntable port names ``station.turntable.port``.

Once the devices are open, :func:`check_against_devices` holds the configuration
against what they report they can do — the turntable's travel
(:class:`drivers.protocols.TurntableRanges`: the configured limits within the
device's own, read at open) for every orientation, the camera's focus, exposure and
gain ranges (:class:`drivers.protocols.CameraRanges`) for the focus settings and the
capture settings — so that ``harp session run`` refuses, naming the field, before the
session directory is created, instead of failing at the first move.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterator, Sequence

from drivers import open_camera, open_turntable
from drivers.errors import DriverError
from drivers.protocols import CameraRanges, Range, TurntableRanges
from station.config import Config, check_port
from station.config.devices import device_field
from station.session.simulated import simulated_devices


@contextlib.contextmanager
def _created(config: Config) -> Iterator[tuple]:
    if config.simulation is not None:
        with simulated_devices(config) as sim:
            yield sim.camera, sim.turntable
        return
    check_port(config)
    try:
        camera = open_camera(config.station.camera.as_driver_config())
    except (ValueError, TypeError, DriverError, OSError, ImportError) as exc:
        raise config.error("station.camera", f"cannot use this camera: {_one_line(exc)}") from None
    try:
        turntable = open_turntable(config.station.turntable.as_driver_config())
    except (ValueError, TypeError, DriverError, OSError, ImportError) as exc:
        raise config.error("station.turntable", f"cannot use this turntable: {_one_line(exc)}") from None
    yield camera, turntable


@contextlib.contextmanager
def open_station(config: Config, *, check: bool = True) -> Iterator[tuple]:
    """Create and open the configured devices; yield ``(camera, turntable)``; close on exit.

    ``check``: hold the configuration against the devices' ranges first
    (:func:`check_against_devices`, a :class:`~station.config.ConfigError` naming the field)."""
    with _created(config) as (camera, turntable):
        try:
            camera.open()
        except (DriverError, OSError) as exc:
            raise config.error("station.camera", f"cannot open the camera: {_one_line(exc)}") from None
        try:
            try:
                turntable.open()
            except (DriverError, OSError) as exc:
                raise config.error(  # the port, or the tilt or shift axis the device lacks
                    device_field("station.turntable", exc, "station.turntable.port"),
                    f"cannot open the turntable at {config.station.turntable.port!r}: {_one_line(exc)}",
                ) from None
            try:
                if check:
                    check_against_devices(config, camera, turntable)
                yield camera, turntable
            finally:
                _quiet_close(turntable)
        finally:
            _quiet_close(camera)


def check_against_devices(config: Config, camera: object, turntable: object) -> None:
    """Raise :class:`~station.config.ConfigError` naming the field when the configuration asks
    for what the open devices report they cannot do (see the module docstring)."""
    cap = config.capture
    if isinstance(turntable, TurntableRanges):
        travel = _range(config, turntable.travel_range, "station.turntable")
        _each_within(config, "capture.orientations_deg", cap.orientations_deg, travel, lambda deg, r: (
            f"expected an angle the turntable can reach, {deg:g}° is outside {r} ({r.source}); change the "
            "orientation or the turntable's limits"
        ))  # fmt: skip
    shift = getattr(turntable, "shift", None)
    if cap.shift_positions_mm and isinstance(shift, TurntableRanges):  # the linear stage's travel, read at open
        travel = _range(config, shift.travel_range, "station.turntable")
        _each_within(config, "capture.shift_positions_mm", cap.shift_positions_mm, travel, lambda mm, r: (
            f"expected a position the linear stage can reach, {mm:g} mm is outside {r} ({r.source}); change the "
            "position or station.turntable.shift_limits"
        ))  # fmt: skip
    if isinstance(camera, CameraRanges):
        focus = _range(config, camera.focus_range, "station.camera")
        _each_within(config, "focus.settings", config.focus_settings, focus, lambda f, r: (
            f"expected a focus setting the camera has, {f:g} is outside {r} ({r.source})"
        ))  # fmt: skip
        for key, value, get in (
            ("exposure_us", cap.exposure_us, camera.exposure_range),
            ("gain_db", cap.gain_db, camera.gain_range),
        ):
            r = _range(config, get, "station.camera")
            if r is not None and value not in r:
                raise config.error(
                    f"capture.{key}", f"expected a value the camera accepts, {value:g} is outside {r} ({r.source})"
                )


def _each_within(
    config: Config, field: str, values: Sequence[float], r: Range | None, said: Callable[[float, Range], str]
) -> None:
    """Raise :class:`~station.config.ConfigError` naming ``field[i]`` for the first of ``values`` outside the
    open device's range ``r`` (None: the device does not say), with the message ``said(value, r)``."""
    if r is None:
        return
    for i, v in enumerate(values):
        if v not in r:
            raise config.error(f"{field}[{i}]", said(v, r))


def _range(config: Config, get, section: str) -> Range | None:
    try:
        return get()
    except (DriverError, OSError) as exc:
        raise config.error(section, f"cannot read the device's ranges: {_one_line(exc)}") from None


def _quiet_close(device) -> None:
    with contextlib.suppress(Exception):
        device.close()


def _one_line(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    return text[0] if text else type(exc).__name__
