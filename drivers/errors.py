"""Exceptions raised by every driver. Messages are one line and name the device."""


class DriverError(Exception):
    """Base class of all driver errors."""


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
