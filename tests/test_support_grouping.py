"""The test run's own distribution: tests sharing a module-scoped fixture run on one xdist worker
(``tests/grouping.py``), so the fixture is built once per run. A real pytest with two workers in its own process
group, on a throw-away test module; fails when the installed pytest / pytest-xdist ignore the groups (pytest 9.2
with pytest-xdist 3.8: pytest-dev/pytest-xdist#1386)."""

from __future__ import annotations

import os
import sys
import textwrap

from tests.conftest import REPO
from tests.station.processes import run_process

MODULE = textwrap.dedent(
    """
    import os
    from pathlib import Path

    import pytest

    LOG = Path(__file__).with_name("log")


    def note(what):
        with LOG.open("a") as f:
            f.write(f"{what} {os.environ['PYTEST_XDIST_WORKER']}\\n")


    @pytest.fixture(scope="module")
    def shared():
        note("built")


    @pytest.mark.parametrize("i", range(4))
    def test_with_the_fixture(shared, i):
        note("with")


    @pytest.mark.parametrize("i", range(4))
    def test_alone(i):
        note("alone")
    """
)


def test_tests_sharing_a_module_fixture_run_on_one_worker_and_build_it_once(tmp_path):
    (tmp_path / "test_shared.py").write_text(MODULE)
    done = run_process(
        [
            sys.executable, "-m", "pytest", "-q", "-n", "2", "--dist", "loadgroup", "-p", "tests.grouping",
            "-p", "no:cacheprovider", "-c", os.devnull, "--rootdir", str(tmp_path), str(tmp_path),
        ],
        timeout=120,
        cwd=REPO,
    )  # fmt: skip
    assert done.returncode == 0, done.stdout + done.stderr
    lines = [line.split() for line in (tmp_path / "log").read_text().splitlines()]
    built = [w for what, w in lines if what == "built"]
    with_it = {w for what, w in lines if what == "with"}
    assert len(built) == 1 and with_it == set(built), lines
    assert len([1 for what, _ in lines if what in ("with", "alone")]) == 8
