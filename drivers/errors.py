"""Exceptions raised by every driver. Messages are one line and name the device."""


class DriverError(Exception):
    """Base class of all driver errors.

    The message is always one line: line breaks in a device's or library's
    own text (a GLib error, a garbled reply) are folded into spaces.

    Not a HarpError: ``drivers`` stands below ``station`` and imports nothing of it
    (``tests/test_architecture.py``). Where a driver error can reach a command, ``station`` turns it
    into one: a :class:`station.config.ConfigError` naming the device's field when the devices are
    opened or their ranges read (:mod:`station.session.devices`, :mod:`station.config.devices`), a
    :class:`station.errors.HarpError` in ``harp live`` and ``harp intrinsics``, a row's problem in
    ``harp devices``; during a session the executor recovers from it or records it as the abort.
    """

    config_key: str | None = None
    """The key of the device's configuration section the error is about (a tilt or shift axis the device
    lacks: ``"shift_axis"``), so that a station names that field; None: the device as a whole."""

    def __init__(self, *args: object) -> None:
        if len(args) == 1 and isinstance(args[0], str) and ("\n" in args[0] or "\r" in args[0]):
            args = (" ".join(args[0].split()),)
        super().__init__(*args)


class ConfigKeyError(ValueError):
    """A driver's configuration value it cannot use, whatever the device: ``config_key`` names the key
    (``"shift_axis"``) so that a station names that field.

    Not a HarpError: drivers import nothing of station; the station turns it into a
    :class:`station.config.ConfigError` naming ``station.turntable.KEY``
    (:func:`station.config.devices.device_field`).
    """

    def __init__(self, config_key: str, message: str) -> None:
        super().__init__(message)
        self.config_key = config_key


class DeviceTimeout(DriverError):
    """The device did not answer (or did not finish) within the timeout."""


class DeviceRejected(DriverError):
    """The device refused a command (e.g. Zaber ``RJ``, GRBL ``error:N``)."""


class DeviceFault(DriverError):
    """The device reports a fault (stall, limit, driver fault, alarm)."""


class ProtocolError(DriverError):
    """A reply that does not parse: garbage bytes, wrong address, truncated line."""


class DeviceDisconnected(DriverError):
    """The device vanished (port closed, cable unplugged, EOF)."""


class CaptureError(DriverError):
    """A frame could not be captured or is corrupt."""


def _number(value: float) -> str:
    return f"{value:.10g}"


def with_unit(unit: str) -> str:
    """What follows a number in ``unit`` in a message: ``"°"`` directly (``45°``), any other unit after a
    space (``12.5 mm``), nothing for ``""`` (a device's own units)."""
    return unit if unit in ("", "°") else f" {unit}"


class OutOfRange(DeviceRejected, ValueError):
    """A commanded value outside the range the device accepts; nothing was sent.

    The range is the one read from the device when it was opened (intersected
    with the configured limits for a turntable), so the device never clamps
    the value silently. Also a ``ValueError``, as the drivers raised for
    out-of-limits moves before ranges were read from the devices.

    Attributes: ``device`` (the driver's name), ``what`` (``"move to"``,
    ``"focus"``, ``"exposure"``, ``"gain"``), ``value``, ``minimum``,
    ``maximum``, ``unit``, ``source`` (where the range came from).
    """

    def __init__(
        self, device: str, what: str, value: float, minimum: float, maximum: float, unit: str = "", source: str = ""
    ):
        self.device, self.what, self.value = device, what, float(value)
        self.minimum, self.maximum, self.unit, self.source = float(minimum), float(maximum), unit, source
        u = with_unit(unit)
        where = f" ({source})" if source else ""
        super().__init__(
            f"{device}: {what} {_number(value)}{u} is outside the range"
            f" [{_number(minimum)}, {_number(maximum)}]{u}{where}; nothing was sent"
        )
