"""Open a configured station's camera and turntable (real or simulated).

Problems opening a device become a :class:`station.config.ConfigError`
naming the configuration field to look at (one line), e.g. an unreachable
turntable port names ``station.turntable.port``.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator

from drivers import open_camera, open_turntable
from drivers.errors import DriverError
from station.config import Config, check_port


@contextlib.contextmanager
def _created(config: Config) -> Iterator[tuple]:
    if config.simulation is not None:
        from station.session.simulated import simulated_devices

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
def open_station(config: Config) -> Iterator[tuple]:
    """Create and open the configured devices; yield ``(camera, turntable)``; close on exit."""
    with _created(config) as (camera, turntable):
        try:
            camera.open()
        except (DriverError, OSError) as exc:
            raise config.error("station.camera", f"cannot open the camera: {_one_line(exc)}") from None
        try:
            try:
                turntable.open()
            except (DriverError, OSError) as exc:
                raise config.error(
                    "station.turntable.port",
                    f"cannot open the turntable at {config.station.turntable.port!r}: {_one_line(exc)}",
                ) from None
            try:
                yield camera, turntable
            finally:
                _quiet_close(turntable)
        finally:
            _quiet_close(camera)


def _quiet_close(device) -> None:
    with contextlib.suppress(Exception):
        device.close()


def _one_line(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    return text[0] if text else type(exc).__name__
