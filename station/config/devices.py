"""What a configuration asks of its devices, known without opening them; the turntable port.

:func:`check_the_devices` (the validator's last pass, :mod:`station.config.validate`):

* the drivers are created, not opened, from their sections (a driver's checks across its own keys:
  a simulated camera's ``pixel_format`` against its ``bit_depth``, ``jpeg_quality`` without
  ``realism_seed``, strings as wide as their spacing; an Aravis ``autofocus_feature`` without a
  ``focus_feature``...), and a simulated station's Zaber emulator;
* orientations (and the board views' angles, ``intrinsics.angles_deg``) within the turntable's configured
  ``limits`` (inclusive) or, without them,
  :data:`ROTARY_RANGE` for the rotary stages; focus settings within the simulated lens's range;
* ``capture.checks.min_lines`` no more than the string edges the simulated camera's harp can show at
  every orientation (the image's extent across the strings over their spacing, two edges a string);
* a session with the camera-matrix stage (``intrinsics``) on the turntable has a camera that can be shown the board
  (:class:`drivers.protocols.BoardScene`: the simulator);
* a two-axis capture (``capture.shift_positions_mm``) has a turntable with a linear stage, its positions within
  the stage's configured travel, and the image direction of a stage move when it has fewer than four angles.

The devices' own ranges are checked once they are open (:func:`station.session.devices.check_against_devices`).
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from typing import Any

from drivers import open_camera, open_turntable
from drivers.errors import DriverError
from drivers.protocols import BoardScene
from drivers.settings import shown
from drivers.sim.zaber_emulator import ZaberEmulator, axes_options
from station.config.schema import EMULATOR_PORT, Config

ROTARY_RANGE = (0.0, 360.0)
"""Orientations of a rotary stage without configured ``limits``: ``[0, 360)`` degrees."""


def _one_line(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    return text[0] if text else type(exc).__name__


def device_field(section: str, exc: BaseException, default: str | None = None) -> str:
    """The configuration field a driver's error is about: ``section.KEY`` when the driver names the key
    (``config_key`` of :class:`drivers.errors.ConfigKeyError`, :class:`drivers.errors.DriverError`: a
    shift axis on the turntable's own axis, one the device lacks), else ``default`` (the section)."""
    key = getattr(exc, "config_key", None)
    return f"{section}.{key}" if key else (default or section)


def created_devices(config: Config) -> tuple[Any, Any]:
    """The camera and turntable drivers of ``config`` created (``from_config``), not opened; a driver
    that refuses its settings is a :class:`ConfigError` naming its section."""
    devices = []
    for key, section, make in (
        ("camera", config.station.camera, open_camera),
        ("turntable", config.station.turntable, open_turntable),
    ):
        try:
            devices.append(make(section.as_driver_config()))
        except (ValueError, TypeError, DriverError, OSError) as exc:
            raise config.error(device_field(f"station.{key}", exc), f"expected settings the {section.driver} {key} "
                               f"accepts: {_one_line(exc)}") from None  # fmt: skip
    return devices[0], devices[1]


def zaber_emulator_options(config: Config, turntable: Any) -> dict[str, Any]:
    """The Zaber emulator's options for a simulated station: ``simulation.emulator``, and what it leaves out
    from the turntable (``turntable``, its driver created from its section, not opened): its microsteps per
    degree, and for a Zaber turntable the axes it names (the tilt, the shift axis:
    :func:`drivers.sim.zaber_emulator.axes_options`) with the shift axis's microsteps per mm."""
    assert config.simulation is not None
    opts = dict(config.simulation.emulator)
    if config.station.turntable.steps_per_degree is not None:
        opts.setdefault("microsteps_per_degree", config.station.turntable.steps_per_degree)
    if config.station.turntable.driver == "zaber":  # the simulated stage has the axes the turntable names
        tilt, shift = getattr(turntable, "tilt", None), getattr(turntable, "shift", None)
        numbers = (None if a is None else a.axis_number for a in (tilt, shift))
        for k, v in axes_options(*numbers, opts.get("axes")).items():
            opts.setdefault(k, v)
        if shift is not None:
            opts.setdefault("shift_microsteps_per_mm", shift.microsteps_per_unit)
    return opts


def check_the_devices(config: Config) -> None:
    """The checks of the module docstring; :class:`ConfigError` naming the field."""
    _orientations(config)
    camera, turntable = created_devices(config)
    _shift_positions(config, turntable)
    if config.simulation is not None:
        opts = zaber_emulator_options(config, turntable)
        try:
            ZaberEmulator(None, **opts)
        except (ValueError, TypeError) as exc:
            raise config.error("simulation.emulator", f"cannot start the Zaber emulator: {_one_line(exc)}") from None
    if config.station.camera.driver == "sim":
        _simulated_lens_and_harp(config, camera)
    k = config.intrinsics
    if k is not None and k.placement == "stage":
        tilt = getattr(turntable, "tilt", None)
        if tilt is None:
            raise config.error(
                "intrinsics.placement", "stage: expected a turntable with a tilt axis (station.turntable.tilt_axis, "
                f"zaber), the {config.station.turntable.driver} turntable has none",
            )  # fmt: skip
        _in_limits(config, "intrinsics.tilts_deg", k.tilts_deg, tilt.travel_range(), "a tilt", "tilt_limits")
    if k is not None and k.placement == "turntable" and not isinstance(camera, BoardScene):
        raise config.error(
            "intrinsics", f"expected a camera the station can show the board (the simulated one), not the "
            f"{config.station.camera.driver} camera: on this station the operator places the board "
            "(intrinsics.placement: operator)",
        )  # fmt: skip


def _shift_positions(config: Config, turntable: Any) -> None:
    """Two-axis capture (``capture.shift_positions_mm``): the turntable has a linear stage (``turntable.shift``,
    its driver's ``shift_axis``) and every position is within its configured travel; without the image direction
    of a stage move (``station.harp.shift_direction_deg``) each place's axis is searched on its own shots, which
    takes four turntable angles or more (:func:`pipeline.harp_frame.group_frames`)."""
    cap = config.capture
    if not cap.shift_positions_mm:
        return
    from pipeline.harp_frame import MIN_GROUP_ANGLES  # defers cv2

    shift = getattr(turntable, "shift", None)
    if shift is None:
        raise config.error(
            "capture.shift_positions_mm", "expected a turntable with a linear stage under it "
            f"(station.turntable.shift_axis), the {config.station.turntable.driver} turntable has none",
        )  # fmt: skip
    travel = getattr(shift, "travel_range", None)
    try:
        r = None if travel is None else travel()
    except (DriverError, OSError, ValueError):  # a range known only once open: checked then
        r = None
    if r is not None:
        _in_limits(config, "capture.shift_positions_mm", cap.shift_positions_mm, r, "a position", "shift_limits", " mm")
    if config.station.harp.shift_direction_deg is None and len(cap.orientations_deg) < MIN_GROUP_ANGLES:
        raise config.error(
            "station.harp.shift_direction_deg", "expected the image direction of a positive linear-stage move: "
            f"with fewer than {MIN_GROUP_ANGLES} turntable angles (capture.orientations_deg) a place's turntable "
            "axis cannot be found without it",
        )  # fmt: skip


def _in_limits(
    config: Config, field: str, values: Sequence[float], r: Any, what: str, limits: str, unit: str = ""
) -> None:
    """Raise :class:`~station.config.ConfigError` naming ``field[i]`` for the first of ``values`` outside an
    axis's configured travel ``r`` (``minimum``, ``maximum``; ``station.turntable.<limits>``), inclusive."""
    for i, v in enumerate(values):
        if not r.minimum <= v <= r.maximum:
            raise config.error(
                f"{field}[{i}]", f"expected {what} in [{r.minimum:g}, {r.maximum:g}]{unit} "
                f"(station.turntable.{limits}), got {v:g}",
            )  # fmt: skip


def _orientations(config: Config) -> None:
    limits = config.station.turntable.settings.get("limits")
    if limits is not None:
        if not limits[0] < limits[1]:
            raise config.error("station.turntable.limits", f"expected [min, max] in degrees, got {shown(limits)}")
        lo, hi = float(limits[0]), float(limits[1])
        inside, allowed = (lambda d: lo <= d <= hi), f"[{lo:g}, {hi:g}] (station.turntable.limits)"
    else:
        lo, hi = ROTARY_RANGE
        inside, allowed = (lambda d: lo <= d < hi), f"[{lo:g}, {hi:g}) for a rotary stage"
    angles = [("capture.orientations_deg", config.capture.orientations_deg)]
    if config.intrinsics is not None and config.intrinsics.placement != "operator":
        angles.append(("intrinsics.angles_deg", config.intrinsics.angles_deg))
    for key, values in angles:
        for i, deg in enumerate(values):
            if not inside(deg):
                raise config.error(f"{key}[{i}]", f"expected an angle in {allowed}, got {deg:g}")


def harp_edges(width: int, height: int, spacing_px: float, angle_deg: float) -> int:
    """The most string edges a harp of pitch ``spacing_px`` at image angle ``angle_deg`` can show in a
    ``width`` x ``height`` image: the image's extent along the strings' normal ``(-sin, cos)``,
    ``width |sin| + height |cos|``, holds at most ``floor(extent / spacing) + 1`` strings, two edges each."""
    a = math.radians(angle_deg)
    extent = width * abs(math.sin(a)) + height * abs(math.cos(a))
    return 2 * (math.floor(extent / spacing_px) + 1)


def _simulated_lens_and_harp(config: Config, camera: Any) -> None:
    from drivers.sim.lens import FOCUS_RANGE  # defers cv2

    for i, f in enumerate(config.focus_settings):
        if not FOCUS_RANGE[0] <= f <= FOCUS_RANGE[1]:
            raise config.error(
                f"focus.settings[{i}]",
                f"expected a focus in [{FOCUS_RANGE[0]:g}, {FOCUS_RANGE[1]:g}] (the simulated lens), got {f:g}",
            )
    width, height = camera.sensor_size
    spacing = camera.scene.spacing_px
    offset = config.simulation.harp_offset_deg if config.simulation is not None else config.station.harp.offset_deg
    offset = config.station.camera.settings.get("harp_offset_deg", offset)
    need = config.capture.checks.min_lines
    for deg in config.capture.orientations_deg:
        most = harp_edges(width, height, spacing, offset + deg)
        if need > most:
            raise config.error(
                "capture.checks.min_lines",
                f"expected at most {most}, the string edges the simulated harp can show at orientation {deg:g} deg "
                f"({width}x{height} px, strings {spacing:g} px apart), got {need}",
            )


def port_missing(config: Config) -> bool:
    """Whether the turntable port is a device path that does not exist on this machine: a device path
    (``/dev/...`` or any absolute path) must exist; a URL (``socket://``, ``rfc2217://``, ``loop://``...) is left
    to the driver, and the simulator's emulated port (``EMULATOR_PORT`` with a ``simulation`` section) is made."""
    port = config.station.turntable.port
    emulated = port == EMULATOR_PORT and config.simulation is not None
    return not emulated and "://" not in port and not os.path.exists(port)


def check_port(config: Config) -> None:
    """Fail early, naming the field, when the turntable port cannot be reached (:func:`port_missing`)."""
    if port_missing(config):
        port = config.station.turntable.port
        raise config.error("station.turntable.port", f"expected a reachable serial port, {port!r} does not exist")
