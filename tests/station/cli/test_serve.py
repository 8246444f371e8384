"""``harp serve``: the whole process on a real store (served until Ctrl-C), the token off localhost, and
the errors that are one line and exit 2."""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import time
import urllib.error
import urllib.request

import pytest

from station.cli import main

REPO_ENV = {**os.environ, "PYTHONUNBUFFERED": "1"}


def _get(url, token=None):
    req = urllib.request.Request(url)
    if token:
        req.add_header("Authorization", f"Bearer {token}")
    try:
        with urllib.request.urlopen(req, timeout=30) as r:
            return r.status, r.read()
    except urllib.error.HTTPError as e:
        return e.code, e.read()


@pytest.mark.parametrize("sig", ["SIGINT", "SIGTERM"])
def test_serve_off_localhost_needs_the_token_and_stops_on_ctrl_c(factory_archive, sig):
    """Stopped by Ctrl-C (exit 130) or by ``systemctl stop`` (SIGTERM, exit 143): the same line, after uvicorn's
    own shutdown (before, SIGTERM ended the process by the signal once uvicorn had shut down)."""
    cmd = [sys.executable, "-m", "station.cli", "serve", "--config", str(factory_archive.config)]
    cmd += ["--host", "0.0.0.0", "--port", "0", "--token", "t0ken-for-the-test"]
    proc = subprocess.Popen(cmd, stderr=subprocess.PIPE, text=True, env=REPO_ENV)
    try:
        line = proc.stderr.readline()
        m = re.match(r"serving on http://0\.0\.0\.0:(\d+)/\?token=t0ken-for-the-test \(Ctrl-C to stop\)$", line.strip())
        assert m, line
        base = f"http://127.0.0.1:{m.group(1)}"
        status, body = _get(base + "/api/lenses")
        assert status == 401 and b"needs its token" in body
        status, body = _get(base + "/api/lenses", token="t0ken-for-the-test")
        assert status == 200
        assert [l["serial"] for l in json.loads(body)["lenses"]] == [factory_archive.serial]
    finally:
        proc.send_signal(getattr(signal, sig))
        try:
            code = proc.wait(timeout=30)
        finally:
            if proc.poll() is None:
                proc.kill()
    rest = proc.stderr.read()
    proc.stderr.close()
    assert code == (130 if sig == "SIGINT" else 143) and rest.strip() == "harp serve: stopped"


def test_any_other_address_without_a_token_is_refused(factory_archive, capsys):
    code = main(["serve", "--store", str(factory_archive.store), "--host", "0.0.0.0"])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1
    assert err.startswith("harp serve: host '0.0.0.0' makes the page reachable from other machines: give a token")


def test_a_store_that_is_not_there_is_one_line_and_is_not_created(tmp_path, capsys):
    code = main(["serve", "--store", str(tmp_path / "none.sqlite")])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and str(tmp_path / "none.sqlite") in err
    assert not (tmp_path / "none.sqlite").exists()
    started = time.time()
    code = main(["serve", "--store", "postgresql://harp@127.0.0.1:9/nowhere"])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "127.0.0.1" in err and "Traceback" not in err
    assert time.time() - started < 30


def test_a_port_out_of_range_is_one_line_naming_the_option(tmp_path, capsys):
    # was "internal error: OverflowError: bind(): port must be 0-65535." (harp serve, harp live, session --live)
    for argv, option in (
        (["serve", "--store", str(tmp_path / "none.sqlite"), "--port", "99999"], "--port"),
        (["live", str(tmp_path / "station.yaml"), "--port", "-1"], "--port"),
        (["session", "run", str(tmp_path / "station.yaml"), "--live", "--live-port", "70000"], "--live-port"),
    ):
        with pytest.raises(SystemExit) as exc:
            main(argv)
        err = capsys.readouterr().err
        assert exc.value.code == 2 and err.count("\n") == 1, err
        assert f"argument {option}: expected a port number in 0..65535 (0: any free port), got {argv[-1]}" in err
    assert list(tmp_path.iterdir()) == []  # nothing created
