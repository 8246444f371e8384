"""Hardware drivers behind two small protocols, created from configuration.

``open_camera(cfg)`` and ``open_turntable(cfg)`` take a mapping whose
``driver`` key names the driver (see ``CAMERA_DRIVERS`` /
``TURNTABLE_DRIVERS``); the other keys are that driver's settings, passed to
its ``from_config(cfg, **context)`` class method. The returned object is not
yet opened: use it as a context manager.
"""

from __future__ import annotations

import importlib
from collections.abc import Mapping
from typing import Any, cast

from drivers.errors import (  # noqa: F401  (re-exported)
    CaptureError,
    DeviceDisconnected,
    DeviceFault,
    DeviceRejected,
    DeviceTimeout,
    DriverError,
    OutOfRange,
    ProtocolError,
)
from drivers.protocols import (  # noqa: F401  (re-exported)
    Camera,
    CameraIdentity,
    CameraRanges,
    Frame,
    Range,
    Turntable,
    TurntableRanges,
)
from drivers.settings import Setting

CAMERA_DRIVERS = {
    "v4l2": "drivers.v4l2_camera:V4L2Camera",
    "aravis": "drivers.aravis_camera:AravisCamera",
    "sim": "drivers.sim.camera:SimulatedCamera",
}
TURNTABLE_DRIVERS = {
    "zaber": "drivers.zaber:ZaberTurntable",
    "grbl": "drivers.grbl:GrblTurntable",
}


def _driver_class(table: Mapping[str, str], kind: str, cfg: Mapping[str, Any]) -> Any:
    name = cfg.get("driver") if isinstance(cfg, Mapping) else None
    if not isinstance(name, str) or name not in table:
        raise ValueError(f"unknown {kind} driver {name!r}; expected one of {', '.join(sorted(table))}")
    module, cls = table[name].split(":")
    return getattr(importlib.import_module(module), cls)


def driver_settings(table: Mapping[str, str], name: str) -> Mapping[str, Setting]:
    """The configuration keys the driver ``name`` of ``table`` accepts besides ``driver``, each with its
    type, unit and range (its class's ``SETTINGS``, :mod:`drivers.settings`), without creating or
    opening anything."""
    module, cls = table[name].split(":")
    settings: Mapping[str, Setting] = getattr(importlib.import_module(module), cls).SETTINGS
    return settings


def open_camera(cfg: Mapping[str, Any], **context: Any) -> Camera:
    """Create (not open) the camera driver named by ``cfg["driver"]``."""
    return cast(Camera, _driver_class(CAMERA_DRIVERS, "camera", cfg).from_config(dict(cfg), **context))


def open_turntable(cfg: Mapping[str, Any], **context: Any) -> Turntable:
    """Create (not open) the turntable driver named by ``cfg["driver"]``."""
    return cast(Turntable, _driver_class(TURNTABLE_DRIVERS, "turntable", cfg).from_config(dict(cfg), **context))
