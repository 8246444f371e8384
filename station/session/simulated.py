"""The demo's simulated station: one SimWorld, a Zaber emulator (or, for a ``grbl`` turntable, a GRBL
emulator) on a real pty and the simulated camera, built from a configuration with a ``simulation``
section.

Only the *devices* are simulated: the station talks to them through the real
drivers (``drivers.zaber.ZaberTurntable`` over pyserial on the pty, the
simulated camera through the Camera protocol), exactly as it would to
hardware. The turntable emulator writes the stage angle into the shared
world; the camera renders the harp at that angle, through the simulated lens
at the locked focus: the unit of the demo lens that the configuration's
``lens.serial`` names, with the manufacturing spread ``simulation.lens_spread``
(:func:`drivers.sim.lens.lens_unit`).
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

from drivers import open_camera, open_turntable
from drivers.errors import DriverError
from drivers.grbl import GrblTurntable
from drivers.ranges import UNIT_WORDS
from drivers.sim.grbl_emulator import start_grbl_emulator
from drivers.sim.world import SimWorld
from drivers.sim.zaber_emulator import start_zaber_emulator
from station.config import EMULATOR_PORT, Config
from station.config.devices import device_field, zaber_emulator_options


@dataclass
class SimulatedStation:
    camera: Any  # drivers.sim.camera.SimulatedCamera (not yet opened)
    turntable: Any  # drivers.zaber.ZaberTurntable (drivers.grbl.GrblTurntable) on the emulator's pty, not opened
    world: SimWorld
    emulator: Any  # EmulatorHandle of the Zaber (GRBL) emulator: .port_path, .emulator (.inject faults), .stop()


def _one_line(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    return text[0] if text else type(exc).__name__


GRBL_EMULATOR_KEYS = ("speed_deg_s", "accel_deg_s2", "position_deg", "seed", "shift_speed_mm_s", "shift_accel_mm_s2")
"""The ``simulation.emulator`` options a GRBL turntable's emulator takes too (the others are the Zaber's)."""


def _start_stage_emulator(config: Config, world: SimWorld, overrides: dict[str, Any]) -> Any:
    """The emulator of the configured turntable's controller on a new pty: the GRBL emulator for a ``grbl``
    turntable (its axis, units per degree, tilt and shift axes the turntable's), the Zaber emulator
    otherwise (with the tilt and shift axes the turntable names)."""
    assert config.simulation is not None
    tt = config.station.turntable
    try:  # the driver's own reading of its section (axes, units), not opened
        probe = open_turntable(tt.as_driver_config(port=EMULATOR_PORT))
    except (ValueError, TypeError, DriverError) as exc:
        raise config.error(
            device_field("station.turntable", exc), f"cannot use this turntable: {_one_line(exc)}"
        ) from None
    opts = {**config.simulation.emulator, **overrides}
    if tt.driver == "grbl":
        other = sorted(set(opts) - set(GRBL_EMULATOR_KEYS))
        if other:
            raise config.error(
                "simulation.emulator",
                f"{other[0]!r} is a Zaber emulator option; a GRBL turntable's emulator takes "
                + ", ".join(GRBL_EMULATOR_KEYS),
            )
        assert isinstance(probe, GrblTurntable)
        opts.update(units_per_degree=probe.units_per_degree, axis=probe.axis)
        # the simulated stage has the tilt and shift axes the turntable names, counting degrees and mm
        for role, axis, unit in (("tilt", probe.tilt, "degrees"), ("shift", probe.shift, "mm")):
            if axis is None:
                continue
            if axis.units_per_unit != 1.0:
                raise config.error(
                    f"station.turntable.{axis.config_prefix}units_per_{UNIT_WORDS[axis.unit]}",
                    f"the GRBL emulator's {role} axis counts {unit}: leave it out (1) for a simulated station",
                )
            opts[f"{role}_axis"] = axis.axis
        start, name = start_grbl_emulator, "GRBL"
    else:
        opts = {**zaber_emulator_options(config, probe), **overrides}
        start, name = start_zaber_emulator, "Zaber"
    try:
        return start(world=world, **opts)
    except (ValueError, TypeError, OSError) as exc:
        raise config.error("simulation.emulator", f"cannot start the {name} emulator: {_one_line(exc)}") from None


@contextlib.contextmanager
def simulated_devices(config: Config, **emulator_overrides) -> Iterator[SimulatedStation]:
    """Start the simulated world and devices; yield a :class:`SimulatedStation`.

    The devices are created but not opened. The emulator is stopped on exit (and the VISCA emulator a
    camera's ``zoom_controller`` with ``port: emulator`` is given, driving the simulated zoom lens).
    ``emulator_overrides`` reach ``start_zaber_emulator``.
    """
    if config.simulation is None:
        raise ValueError(f"{config.path}: simulation: expected a mapping for a simulated station, missing")
    from drivers.sim.lens import lens_field, lens_unit  # defers cv2

    # the lens on the camera: the unit of the demo lens that carries this serial (simulation.lens_spread), with
    # its residual field (simulation.lens_field_px), its centre moving between poses (simulation.lens_centre_sd_px)
    world = SimWorld(
        harp_offset_deg=config.simulation.harp_offset_deg,
        lens_unit=lens_unit(config.lens.serial, config.simulation.lens_spread),
        shift_direction_deg=config.simulation.shift_direction_deg,
        lens_field=lens_field(config.lens.serial, config.simulation.lens_field_px),
        lens_centre_sd_px=config.simulation.lens_centre_sd_px,
    )
    handle = _start_stage_emulator(config, world, emulator_overrides)
    tt = config.station.turntable
    stack = contextlib.ExitStack()  # the lens controller's emulator, if any
    try:
        port = handle.port_path if tt.port == EMULATOR_PORT else tt.port
        # a setting the simulator refuses is a configuration error naming the section, not a traceback
        cam_cfg = config.station.camera.as_driver_config()
        controller = cam_cfg.get("zoom_controller")
        if isinstance(controller, dict) and controller.get("port") == EMULATOR_PORT:
            from drivers.sim.visca_emulator import start_visca_emulator  # defers cv2

            visca = start_visca_emulator(world=world)
            stack.callback(visca.stop)
            cam_cfg["zoom_controller"] = {**controller, "port": visca.port_path}
        try:
            camera = open_camera(cam_cfg, world=world)
        except (ValueError, TypeError, DriverError, OSError) as exc:
            raise config.error("station.camera", f"cannot use this camera: {_one_line(exc)}") from None
        # a shift of the turntable moves the harp in the image by the camera's pixels per mm at the harp: its
        # string pitch in pixels over the harp's in mm
        scene = getattr(camera, "scene", None)
        if scene is not None:
            world.shift_px_per_mm = scene.spacing_px / config.station.harp.string_spacing_mm
        try:
            turntable = open_turntable(tt.as_driver_config(port=port))
        except (ValueError, TypeError, DriverError, OSError) as exc:
            raise config.error(
                device_field("station.turntable", exc), f"cannot use this turntable: {_one_line(exc)}"
            ) from None
        yield SimulatedStation(camera, turntable, world, handle)
    finally:
        stack.close()
        handle.stop()
