"""Shared conformance check of the :class:`drivers.protocols.Turntable` protocol.

Every turntable driver runs :func:`run_turntable_conformance` against a device
(an emulator on a real pty in the tests). It checks the protocol's promises,
not a particular device's bytes::

    from tests.drivers.conformance_turntable import run_turntable_conformance
    run_turntable_conformance(driver)   # driver created, not opened
"""

from __future__ import annotations

import math

from drivers.errors import OutOfRange
from drivers.protocols import Turntable, TurntableRanges

DEFAULT_ANGLES = (0.0, 45.0, 90.0, 135.0, 180.0, 225.0, 270.0, 315.0)


def run_turntable_conformance(
    tt, angles=DEFAULT_ANGLES, tolerance_deg: float = 1e-3, timeout: float = 10.0
) -> list[tuple[float, float]]:
    """Exercise ``tt`` (not yet opened) through the whole Turntable protocol.

    Checks: structural ``isinstance``; context manager returning the driver;
    ``limits`` a (min, max) pair of floats; ``home`` leaves the stage idle;
    ``move_to`` returns only when idle at the target, for every angle in
    ``angles`` (within ``tolerance_deg``), and ``position()`` agrees; a
    target outside the limits raises ``ValueError`` and does not move;
    ``status()`` is a dict with ``busy`` (bool) and ``warnings`` (list of
    str); ``stop()`` on an idle stage is harmless; the driver can be closed
    and opened again. With :class:`TurntableRanges` (every driver here):
    ``travel_range()`` is ``limits`` and the refusal is an :class:`OutOfRange`.
    Returns ``[(target, read back), ...]``.
    """
    assert isinstance(tt, Turntable), f"{type(tt).__name__} does not satisfy the Turntable protocol"
    lo, hi = tt.limits
    assert isinstance(lo, float) and isinstance(hi, float) and lo < hi, f"bad limits {tt.limits!r}"
    readings = []
    with tt as entered:
        assert entered is tt, "__enter__ must return the driver itself"
        assert tt.home(timeout=timeout) is None
        st = tt.status()
        assert isinstance(st, dict), f"status() must return a dict, got {type(st).__name__}"
        assert st["busy"] is False, f"stage busy after home: {st}"
        assert isinstance(st["warnings"], list) and all(isinstance(w, str) for w in st["warnings"])
        assert math.isfinite(tt.position())
        for target in angles:
            assert lo <= target <= hi, f"test angle {target} outside the driver's limits {tt.limits}"
            got = tt.move_to(target, timeout=timeout)
            assert isinstance(got, float), f"move_to must return a float, got {got!r}"
            assert abs(got - target) <= tolerance_deg, f"move_to({target}) read back {got}"
            assert tt.status()["busy"] is False, f"stage busy after move_to({target}) returned"
            now = tt.position()
            assert abs(now - target) <= tolerance_deg, f"position() {now} after move_to({target})"
            readings.append((target, got))
        before = tt.position()
        if isinstance(tt, TurntableRanges):
            travel = tt.travel_range()
            assert (travel.minimum, travel.maximum) == tt.limits, (
                f"travel_range() {travel} differs from limits {tt.limits}"
            )
            for bad in (hi + 1.0, lo - 1.0):
                try:
                    tt.move_to(bad, timeout=timeout)
                except OutOfRange as exc:
                    assert (exc.minimum, exc.maximum) == tt.limits
                else:
                    raise AssertionError(f"move_to({bad}) outside {travel} did not raise OutOfRange")
        for bad in (hi + 1.0, lo - 1.0):
            try:
                tt.move_to(bad, timeout=timeout)
            except ValueError as exc:
                assert str(bad) in str(exc) or "limit" in str(exc), f"unclear limit error: {exc}"
            else:
                raise AssertionError(f"move_to({bad}) outside limits {tt.limits} did not raise ValueError")
        assert abs(tt.position() - before) <= tolerance_deg, "a refused move moved the stage"
        tt.stop()
        assert tt.status()["busy"] is False
    tt.open()
    try:
        assert abs(tt.position() - before) <= tolerance_deg, "position changed across close/open"
    finally:
        tt.close()
    return readings
