"""The one rule that combines a turntable's configured limits with the travel its device reports, and the
units of its axes."""

from __future__ import annotations

from drivers.errors import DeviceRejected
from drivers.protocols import Range

SHIFT_LIMITS_MM = (0.0, 100.0)
"""A shift axis's positions by default, in mm (a 100 mm linear stage; narrowed to the device's travel at open)."""

UNIT_WORDS = {"°": "degree", "mm": "mm"}
"""A turntable axis's unit -> the word its configuration keys use (``microsteps_per_degree``,
``shift_microsteps_per_mm``, ``shift_units_per_mm``)."""


def effective_travel(name: str, configured: Range, device: Range | None) -> Range:
    """The angles a turntable may be commanded to: ``configured`` within ``device``.

    The configuration may narrow what the device allows, never widen it. When
    the two do not overlap (or overlap in a single point) no move is possible:
    :class:`~drivers.errors.DeviceRejected` naming ``name`` and both ranges.
    """
    if device is None:
        return configured
    lo, hi = max(configured.minimum, device.minimum), min(configured.maximum, device.maximum)
    if not lo < hi:
        raise DeviceRejected(
            f"{name}: configured limits {configured} lie outside the device's travel {device} ({device.source});"
            f" set 'limits' inside it"
        )
    if (lo, hi) == (configured.minimum, configured.maximum):
        return configured
    return Range(lo, hi, configured.unit, f"{configured.source} within {device.source}")
