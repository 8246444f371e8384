"""Which xdist worker runs a test: the tests that share a module-scoped fixture run on one worker.

Imported by ``tests/conftest.py`` (its hook) and loaded by ``tests/test_support_grouping.py`` as a plugin, which
checks that the installed pytest and pytest-xdist really honour it (pytest 9.2 with pytest-xdist 3.8 silently do
not: pytest-dev/pytest-xdist#1386; every worker then built every module fixture: the whole run took 782 s
against 711 s with the groups).
"""

from __future__ import annotations

import pytest


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(config, items):
    """Under ``--dist loadgroup`` (pyproject's addopts), a test that uses a module-scoped fixture runs on the same
    xdist worker as the module's other such tests, so that the fixture (a rendered or simulated session, an export
    of every format, a server) is built once per run rather than once per worker; every other test is distributed
    one by one as ``--dist load`` does. Which worker runs a test changes nothing it asserts."""
    for item in items:
        info = getattr(item, "_fixtureinfo", None)
        if info is None or item.get_closest_marker("xdist_group") is not None:
            continue
        scopes = {d.scope for name in info.names_closure for d in info.name2fixturedefs.get(name, ())}
        if scopes & {"module", "package", "class"}:
            item.add_marker(pytest.mark.xdist_group(item.nodeid.split("::")[0]))
