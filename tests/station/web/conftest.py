import pytest


@pytest.fixture(scope="session")
def dashboard(factory_archive, tmp_path_factory):
    """The QA dashboard served on 127.0.0.1 over the SQLite store of tests/station/web/dashboard_store.py,
    shared by the HTTP and the browser tests (plots and exports it renders are cached by the app):
    ``(server, store, {serial: stored profiles}, store path)``."""
    from station.store import ProfileStore
    from station.web import start
    from station.web.dashboard import dashboard_app
    from tests.station.web.dashboard_store import build_store

    path, stored = build_store(factory_archive, tmp_path_factory.mktemp("dashboard"))
    store = ProfileStore(path, create=False)
    with start(dashboard_app(store)) as srv:
        yield srv, store, stored, path
    store.close()
