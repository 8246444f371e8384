"""Every turntable driver passes the shared Turntable conformance check,
talking through a real pty to its device emulator."""

import pytest

from drivers.grbl import GrblTurntable
from drivers.sim.grbl_emulator import start_grbl_emulator
from drivers.sim.world import SimWorld
from drivers.sim.zaber_emulator import start_zaber_emulator
from drivers.zaber import ZaberTurntable
from tests.drivers.conformance_turntable import DEFAULT_ANGLES, run_turntable_conformance

FAST = dict(speed_deg_s=3600.0, accel_deg_s2=72000.0)

TURNTABLES = {
    "zaber": (start_zaber_emulator, ZaberTurntable),
    "grbl": (start_grbl_emulator, GrblTurntable),
}


@pytest.mark.parametrize("kind", sorted(TURNTABLES))
def test_turntable_conformance(kind):
    start, cls = TURNTABLES[kind]
    world = SimWorld()
    with start(world=world, **FAST) as handle:
        tt = cls(handle.port_path, poll_interval=0.005, reply_timeout=0.5)
        readings = run_turntable_conformance(tt)
    assert [t for t, _ in readings] == list(DEFAULT_ANGLES)
    assert world.stage_deg == pytest.approx(DEFAULT_ANGLES[-1], abs=1e-3)


class _ReturnsBeforeArrival(ZaberTurntable):
    """Broken on purpose: move_to does not wait for the stage."""

    def move_to(self, degrees, timeout=None):
        self.start_move(degrees)
        return float(degrees)


class _IgnoresLimits(GrblTurntable):
    """Broken on purpose: limits advertised but not enforced."""

    @property
    def limits(self):
        return (0.0, 315.0)


@pytest.mark.parametrize("start, broken, speed, message", [
    (start_zaber_emulator, _ReturnsBeforeArrival, 360.0, "busy after move_to"),
    (start_grbl_emulator, _IgnoresLimits, 3600.0, "did not raise ValueError"),
])
def test_conformance_check_catches_broken_drivers(start, broken, speed, message):
    with start(speed_deg_s=speed, accel_deg_s2=10 * speed) as handle:
        tt = broken(handle.port_path, poll_interval=0.005, reply_timeout=0.5)
        with pytest.raises(AssertionError, match=message):
            run_turntable_conformance(tt)
