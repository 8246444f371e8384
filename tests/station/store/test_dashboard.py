"""The factory dashboard's read queries, on both backends; expected counts from the rows put in."""

import math

import pytest

from station.store import ProfileStore
from station.store.dashboard import control_limits
from tests.station.store.test_database import profile, verdict

# (serial, session, station, holdout d per focus 0 / 1 (None: not judged), distortion max) — lens model Acme 12mm
CALIBRATIONS = [
    ("A-1", "s1", "line-1", (0.010, 0.012), 20.0),
    ("A-2", "s2", "line-1", (0.011, 0.300), 21.0),  # fails at focus 1
    ("A-3", "s3", "line-2", (0.013, 0.009), 22.0),
    ("A-4", "s4", "line-2", (None, None), None),  # stored, not judged yet
    ("A-1", "s5", "line-2", (0.012, 0.011), 20.5),  # A-1 again, later: its newest
]


@pytest.fixture
def store(store_url):
    with ProfileStore(store_url) as st:
        for serial, session, station, holdouts, dist in CALIBRATIONS:
            for focus, hd in zip((0.0, 1.0), holdouts):
                qa = verdict(hd, distortion=dist) if hd is not None else None
                st.put_profile(
                    profile(
                        session=session,
                        focus=focus,
                        lens=("Acme", "12mm", serial),
                        holdout_d=hd or 0.02,
                        qa=qa,
                        station=station,
                    )
                )
        st.put_profile(profile(session="z1", lens=("Zeta", "8mm", "Z-1"), qa=verdict(0.01)))
        yield st


def test_lens_models(store):
    acme, zeta = store.lens_models()
    assert (acme.maker, acme.model, acme.lenses, acme.calibrations) == ("Acme", "12mm", 4, 5)
    assert (acme.passed, acme.failed, acme.unjudged) == (3, 1, 1)
    assert (zeta.lenses, zeta.passed, zeta.failed) == (1, 1, 0)


def test_verdict_counts_per_station_and_day(store):
    rows = store.verdict_counts("Acme", "12mm")
    by_station: dict[str, list[int]] = {}
    for r in rows:  # summed over days: a fixture that straddles midnight has two
        acc = by_station.setdefault(r.station, [0, 0, 0])
        for i, v in enumerate((r.passed, r.failed, r.unjudged)):
            acc[i] += v
    assert by_station == {"line-1": [1, 1, 0], "line-2": [2, 0, 1]}
    stored_days = {p.stored_at[:10] for p in store.profiles()}
    assert {r.day for r in rows} <= stored_days and all(len(r.day) == 10 for r in rows)  # YYYY-MM-DD
    assert {(r.maker, r.model) for r in store.verdict_counts()} == {("Acme", "12mm"), ("Zeta", "8mm")}


def test_lens_summaries(store):
    rows = store.lens_summaries()
    assert [(r.maker, r.serial) for r in rows] == [
        ("Acme", "A-1"),
        ("Acme", "A-2"),
        ("Acme", "A-3"),
        ("Acme", "A-4"),
        ("Zeta", "Z-1"),
    ]
    a1, a2, a3, a4, z1 = rows
    assert (a1.profiles, a1.calibrations, a1.last_station, a1.last_verdict) == (4, 2, "line-2", "PASS")  # s5, newest
    assert (a2.calibrations, a2.last_verdict) == (1, "FAIL") and a3.last_verdict == "PASS"
    assert (a4.profiles, a4.last_verdict) == (2, None)  # stored, not judged
    assert (z1.profiles, z1.last_station) == (1, "st") and len(a1.last_at) >= 19
    assert [r.serial for r in store.lens_summaries("Zeta", "8mm")] == ["Z-1"]


def test_lens_history_per_focus_with_verdicts(store):
    lens = store.find_lens("A-1")[0]
    hist = store.lens_history(lens)
    assert sorted(hist) == [0.0, 1.0]
    assert [p.provenance.session_dir for p in hist[0.0]] == ["s5", "s1"]  # newest first
    assert all(p.qa.checks for ps in hist.values() for p in ps)


def test_model_trend_and_control_limits(store):
    points = store.model_trend("Acme", "12mm", focus=1.0)
    assert [(t.serial, t.session_dir) for t in points] == [("A-2", "s2"), ("A-3", "s3"), ("A-4", "s4"), ("A-1", "s5")]
    assert [t.verdict for t in points] == ["FAIL", "PASS", None, "PASS"]
    assert [t.distortion_max for t in points] == [21.0, 22.0, None, 20.5]
    lim = control_limits(points, "holdout_d")  # over the passed lenses only: 0.009 and 0.011
    assert lim.n == 2 and lim.mean == pytest.approx(0.010)
    assert lim.sigma == pytest.approx(math.sqrt(2e-6)) and lim.upper == pytest.approx(0.010 + 3 * math.sqrt(2e-6))
    assert control_limits(points[:1]) is None
    assert len(store.model_trend("Acme", "12mm")) == 8  # 4 lenses x 2 focus settings, newest each
