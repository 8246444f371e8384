"""Turntable drivers and their emulators as the turntable tests use them.

``TURNTABLES``: driver name -> (emulator starter, driver class); ``FAST``:
emulator motion fast enough for quick tests; :func:`make_driver`: a driver
with the tests' short poll interval and reply timeout.
"""

from __future__ import annotations

from drivers.grbl import GrblTurntable
from drivers.sim.grbl_emulator import start_grbl_emulator
from drivers.sim.zaber_emulator import start_zaber_emulator
from drivers.zaber import ZaberTurntable

FAST = dict(speed_deg_s=3600.0, accel_deg_s2=72000.0)

TURNTABLES = {
    "zaber": (start_zaber_emulator, ZaberTurntable),
    "grbl": (start_grbl_emulator, GrblTurntable),
}


def make_driver(cls, port, **kw):
    """``cls(port, ...)`` polling every 5 ms, waiting 2 s for a reply (unless given: the drivers' default is 1 s;
    a loaded machine running the emulator beside the tests has delayed a reply past 0.3 s)."""
    kw.setdefault("poll_interval", 0.005)
    kw.setdefault("reply_timeout", 2.0)
    return cls(port, **kw)
