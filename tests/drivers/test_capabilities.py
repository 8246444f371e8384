"""The optional capabilities the station checks with isinstance (drivers/protocols.py)."""

from drivers.grbl import GrblTurntable
from drivers.protocols import IndexedCapture, Recoverable
from drivers.sim.camera import SimulatedCamera
from drivers.v4l2_camera import V4L2Camera
from drivers.zaber import ZaberTurntable
from tests.station.fakes import FakeCamera, FakeStage


def test_turntables_that_clear_faults_are_recoverable():
    assert issubclass(ZaberTurntable, Recoverable) and issubclass(GrblTurntable, Recoverable)
    assert not issubclass(FakeStage, Recoverable)


def test_only_the_simulator_takes_a_capture_index():
    assert issubclass(SimulatedCamera, IndexedCapture)
    assert not issubclass(V4L2Camera, IndexedCapture) and not issubclass(FakeCamera, IndexedCapture)
