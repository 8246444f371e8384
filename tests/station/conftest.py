import pytest


@pytest.fixture(scope="session")
def factory_archive(tmp_path_factory):
    """One real session of the small demo station and its SQLite store, shared by the harp serve and
    harp reprocess tests (tests/station/archive.py). Read it; copy it to change it."""
    from tests.station.archive import build_archive

    return build_archive(tmp_path_factory.mktemp("factory"))
