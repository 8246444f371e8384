"""``harp session run --live`` with board views placed by the operator (issue 23), the whole process: each
view is announced on the terminal and on the live page, answered by either (a line on standard input, a
button's POST), and the page shows the board coverage of the accepted views as it grows. The simulated
camera stands in for the camera and the person (it renders the board where the person was asked to hold it)."""

from __future__ import annotations

import contextlib
import json
import re
import subprocess
import urllib.error
import urllib.request

import pytest

from station.store import ProfileStore
from tests.station.cli.test_live import _finish, _harp
from tests.station.live.support import wait_for
from tests.station.session.test_operator_boards import operator_config


def _post(url: str, body: dict) -> tuple[int, dict]:
    req = urllib.request.Request(
        url + "api/command", data=json.dumps(body).encode(), headers={"content-type": "application/json"}
    )
    try:
        with urllib.request.urlopen(req, timeout=10) as r:
            return r.status, json.load(r)
    except urllib.error.HTTPError as exc:
        return exc.code, json.load(exc)


def test_views_announced_on_terminal_and_page_answered_by_either(tmp_path):
    cfg = operator_config(tmp_path, views=4)
    p = _harp("session", "run", cfg, "--live", "--live-port", "0", "--quiet", "--no-report", "--name", "s",
              stdin=subprocess.PIPE)  # fmt: skip
    said: list[str] = []
    try:
        line = p.stderr.readline()
        m = re.match(r"live page: (http://127\.0\.0\.1:\d+/)$", line.strip())
        assert m, line
        url = m.group(1)

        def board(pred):
            def get():
                s = json.load(urllib.request.urlopen(url + "api/state", timeout=10))
                b = (s.get("session") or {}).get("board")
                return b if b and pred(b) else None

            return get

        def wanted(v):
            return board(lambda b: b["wanted"] and b["wanted"]["view_idx"] == v)

        b = wait_for(wanted(0), 120, "the first board view asked for on the page")
        assert b["wanted"]["instruction"].startswith("board view 1 of 4: tilt the board 30° with its right edge ")
        assert b["wanted"]["why"].startswith("a tilt towards the right") and b["coverage"] is None
        # while the operator places the board, the page shows the camera's picture and the corners found in it

        def preview():
            s = json.load(urllib.request.urlopen(url + "api/state", timeout=10))
            return s if (s.get("board_preview") or {}).get("found") else None

        assert len(wait_for(preview, 60, "the camera's picture with the board")["board_preview"]["corners"]) >= 30
        assert urllib.request.urlopen(url + "api/frame.jpg", timeout=10).read()[:2] == b"\xff\xd8"
        # the terminal says the same, and how to answer there
        while not said or not said[-1].startswith("press Enter when the board is in place"):
            said.append(p.stderr.readline())
            assert said[-1], "".join(said)
        assert (
            said[-3].startswith(f"focus 0, {b['wanted']['instruction']}") and "or answer on the live page" in said[-1]
        )
        assert _post(url, {"action": "board", "value": "perhaps"})[0] == 400
        assert _post(url, {"action": "board", "value": "capture"}) == (200, {"ok": True, "board": "capture"})
        b = wait_for(wanted(1), 60, "the second view asked for")
        first = b["coverage"]["fraction"]
        assert b["accepted"] == 1 and b["last"]["accepted"] and b["last"]["corners"] >= 30 and 0 < first < 0.5
        p.stdin.write("\n")  # the second view: Enter on the terminal
        p.stdin.flush()
        b = wait_for(wanted(2), 60, "the third view asked for")
        assert b["accepted"] == 2 and b["coverage"]["fraction"] > first
        assert _post(url, {"action": "board", "value": "skip"})[0] == 200
        b = wait_for(wanted(3), 60, "the fourth view asked for")
        assert b["last"] == {"view_idx": 2, "accepted": False, "reasons": ["skipped by the operator"]}
        p.stdin.write("c\n")
        p.stdin.flush()
        b = wait_for(board(lambda b: b["accepted"] == 3), 60, "the fourth view accepted")
        cov = b["coverage"]
        assert cov["fraction"] > first and len(cov["covered"]) == 6 and len(cov["covered"][0]) == 8
        assert _post(url, {"action": "board", "value": "capture"}) == (400, {"error": "no board view is asked for"})

        def finished():
            s = json.load(urllib.request.urlopen(url + "api/state", timeout=10))
            return s if s["session"].get("state") == "finished" else None

        wait_for(finished, 120, "the session to finish")
        while not (said and "the live page shows the result until Ctrl-C" in said[-1]):
            said.append(p.stderr.readline())
            assert said[-1], "".join(said)
    finally:
        out, err = _finish(p, 60, interrupt=True)
    assert p.returncode in (0, 1), "".join(said) + err
    with ProfileStore(tmp_path / "profiles.sqlite", create=False) as st:
        (profile,) = st.profiles()
    k = profile.intrinsics
    assert k is not None and k.n_views == 3
    assert k.fx == pytest.approx(1200.0, abs=2 * k.sd[0])  # the simulator's focal length: 2.5 image widths
    manifest = [json.loads(x) for x in (tmp_path / "sessions" / "s" / "manifest.jsonl").read_text().splitlines()]
    assert [r["view_idx"] for r in manifest if r["kind"] == "board-ok"] == [0, 1, 3]


def _records(session) -> list[dict]:
    return [json.loads(x) for x in (session / "manifest.jsonl").read_text().splitlines()]


def test_killed_between_a_views_save_and_its_check_then_resumed(tmp_path):
    """``harp session run`` killed (SIGKILL, its whole process group) while the operator places the second
    view; the manifest is then cut back to right after the first view's ``board`` record, where a kill a
    moment earlier leaves it (between the save and the check: a SIGKILL stops between two appends).
    ``harp session resume`` checks that view first, without asking for it again, then asks for the rest."""
    import os
    import signal

    cfg = operator_config(tmp_path, views=3)
    session = tmp_path / "sessions" / "s"
    p = _harp("session", "run", cfg, "--quiet", "--no-report", "--name", "s", stdin=subprocess.PIPE)
    try:
        p.stdin.write("\n")  # the first view: the board is in place
        p.stdin.flush()

        def asked_second():
            recs = _records(session) if (session / "manifest.jsonl").is_file() else []
            return any(r["kind"] == "board-ask" and r["view_idx"] == 1 for r in recs) or None

        wait_for(asked_second, 120, "the second view asked for")
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(p.pid, signal.SIGKILL)
        p.communicate(timeout=30)
    assert p.returncode == -signal.SIGKILL
    lines = (session / "manifest.jsonl").read_text().splitlines(keepends=True)
    kinds = [json.loads(line)["kind"] for line in lines]
    cut = kinds.index("board") + 1
    assert kinds[cut:] == ["board-ok", "board-ask"]  # the check and the next question, as if never written
    (session / "manifest.jsonl").write_text("".join(lines[:cut]))

    r = _harp("session", "resume", session, "--quiet", "--no-report", stdin=subprocess.PIPE)
    try:
        out, err = r.communicate("\n\n", timeout=180)  # the second and third views
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(r.pid, signal.SIGKILL)
        if r.poll() is None:
            r.communicate(timeout=30)
    assert r.returncode in (0, 1), err
    resumed = _records(session)[cut:]
    board = [(x["kind"], x["view_idx"]) for x in resumed if x["kind"].startswith("board")]
    assert board[0] == ("board-ok", 0)  # checked first, not asked for again
    assert board[1:] == [("board-ask", 1), ("board", 1), ("board-ok", 1), ("board-ask", 2), ("board", 2),
                         ("board-ok", 2)]  # fmt: skip
    with ProfileStore(tmp_path / "profiles.sqlite", create=False) as st:
        (profile,) = st.profiles()
    assert profile.intrinsics is not None and profile.intrinsics.n_views == 3
