"""What a configuration asks of its devices, known without opening them; the turntable port."""

from __future__ import annotations

import math
import os
from pathlib import Path

from station.config.errors import ConfigError, shown
from station.config.schema import EMULATOR_PORT, Config, DeviceConfig, TurntableConfig

ROTARY_RANGE = (0.0, 360.0)
"""Orientations of a rotary stage without configured ``limits``: ``[0, 360)`` degrees."""


def check_what_the_devices_allow(
    path: Path,
    turntable: TurntableConfig,
    camera: DeviceConfig,
    orientations: tuple[float, ...],
    focus_settings: tuple[float, ...],
) -> None:
    """What can be known without the devices: orientations within the turntable's configured
    ``limits`` (inclusive) or, without them, ``[0, 360)`` for the rotary stages; focus settings
    within the simulated lens's range. The devices' own ranges are checked once they are open
    (:func:`station.session.devices.check_against_devices`)."""
    limits = turntable.settings.get("limits")
    if limits is not None:
        ok = (
            isinstance(limits, (list, tuple))
            and len(limits) == 2
            and all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in limits)
            and limits[0] < limits[1]
        )
        if not ok:
            raise ConfigError(path, "station.turntable.limits", f"expected [min, max] in degrees, got {shown(limits)}")
        lo, hi = float(limits[0]), float(limits[1])
        inside, allowed = (lambda d: lo <= d <= hi), f"[{lo:g}, {hi:g}] (station.turntable.limits)"
    else:
        lo, hi = ROTARY_RANGE
        inside, allowed = (lambda d: lo <= d < hi), f"[{lo:g}, {hi:g}) for a rotary stage"
    for i, deg in enumerate(orientations):
        if not inside(deg):
            raise ConfigError(path, f"capture.orientations_deg[{i}]", f"expected an angle in {allowed}, got {deg:g}")
    if camera.driver == "sim":
        from drivers.sim.lens import FOCUS_RANGE  # defers cv2

        for i, f in enumerate(focus_settings):
            if not FOCUS_RANGE[0] <= f <= FOCUS_RANGE[1]:
                raise ConfigError(
                    path,
                    f"focus.settings[{i}]",
                    f"expected a focus in [{FOCUS_RANGE[0]:g}, {FOCUS_RANGE[1]:g}] (the simulated lens), got {f:g}",
                )


def check_port(config: Config) -> None:
    """Fail early, naming the field, when the turntable port cannot be reached.

    A device path (``/dev/...`` or any absolute path) must exist; a URL
    (``socket://``, ``rfc2217://``, ``loop://``...) is left to the driver.
    """
    port = config.station.turntable.port
    if port == EMULATOR_PORT and config.simulation is not None:
        return
    if "://" in port:
        return
    if not os.path.exists(port):
        raise config.error("station.turntable.port", f"expected a reachable serial port, {port!r} does not exist")
