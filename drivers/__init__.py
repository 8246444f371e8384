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
from drivers.zoom_controller import SETTING as ZOOM_CONTROLLER
from drivers.zoom_controller import ControlledZoom

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
    if table is CAMERA_DRIVERS:  # every camera's zoom may be a lens controller's (drivers.zoom_controller)
        settings = {**settings, "zoom_controller": ZOOM_CONTROLLER}
    return settings


def open_camera(cfg: Mapping[str, Any], **context: Any) -> Camera:
    """Create (not open) the camera driver named by ``cfg["driver"]``; with ``zoom_controller``, the
    camera whose zoom a lens controller drives (:class:`drivers.zoom_controller.ControlledZoom`)."""
    cfg = dict(cfg)
    controller = cfg.pop("zoom_controller", None)
    if controller is None:
        return cast(Camera, _driver_class(CAMERA_DRIVERS, "camera", cfg).from_config(cfg, **context))
    from drivers.visca import ViscaLens  # defers serial

    if not isinstance(controller, Mapping):
        raise ValueError(f"zoom_controller: expected a mapping (port, address, ...), got {controller!r}")
    controller = dict(controller)
    zoom = controller.pop("zoom", None)  # the controller's position, set before the camera opens
    camera = _driver_class(CAMERA_DRIVERS, "camera", cfg).from_config(cfg, **context)
    return cast(Camera, ControlledZoom(camera, ViscaLens.from_config(controller), zoom))


def open_turntable(cfg: Mapping[str, Any], **context: Any) -> Turntable:
    """Create (not open) the turntable driver named by ``cfg["driver"]``."""
    return cast(Turntable, _driver_class(TURNTABLE_DRIVERS, "turntable", cfg).from_config(dict(cfg), **context))
