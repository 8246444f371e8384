"""Several stations at once (separate ``harp session run`` processes, each its own lens) into one
store, on both backends: every exit 0, no "database is locked" reaching the user, every profile and
QA result stored exactly once. The issue's full load (8 into PostgreSQL, 3 into SQLite) with its
latency table is ``benchmarks/store_load.py``."""

from tests.station.store.stations import check_exactly_once, run_stations


def test_stations_at_once_store_everything_exactly_once(store_url, tmp_path):
    n = 2
    run = run_stations(tmp_path / "load", store_url, n, timeout=300)
    assert run.returncodes == [0] * n, run.stderr
    assert not any("locked" in e.lower() or "traceback" in e.lower() for e in run.stderr), run.stderr
    counts = check_exactly_once(store_url, n, 1)
    assert counts["profiles"] == n and counts["lenses"] == n
    assert {w["op"] for w in run.writes} >= {"storing the profile", "recording the verdict"}
