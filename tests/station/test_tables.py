"""How every command prints a table (station/tables.py): tab-separated off a terminal, a rich table
on one (a real pty here), nothing cut short either way; lines around the tables never wrapped."""

from __future__ import annotations

import io
import os
import re

from station.tables import console, print_table

LONG = "radial6+tangential+prism+division2+centre-prior-" + "x" * 60  # longer than any terminal column


def test_off_a_terminal_a_table_is_tab_separated_text_with_nothing_cut():
    out = io.StringIO()
    rows = [(LONG, "14", None), ("two\tcells", "1\n2", "0.0047")]
    print_table(("candidate", "params", "CV d (px)"), rows, title="not printed", stream=out)
    assert out.getvalue() == (
        f"candidate\tparams\tCV d (px)\n{LONG}\t14\t\ntwo cells\t1 2\t0.0047\n"  # tabs, breaks: spaces
    )


def test_off_a_terminal_a_line_is_never_wrapped():
    out = io.StringIO()
    line = "QA focus 0: PASS " + "; ".join(f"check {i} 0.0047 px <= 0.05 px: PASS" for i in range(12))
    console(out).print(line)
    assert len(line) > 400 and out.getvalue() == line + "\n"


def test_on_a_terminal_a_long_cell_folds_and_is_kept_whole(monkeypatch):
    monkeypatch.setenv("COLUMNS", "80")
    master, slave = os.openpty()
    try:
        with os.fdopen(slave, "w", closefd=False) as tty:
            assert tty.isatty()
            print_table(("candidate", "params"), [(LONG, "14"), ("poly3", "12")], title="cross-validation", stream=tty)
            tty.flush()
        data = b""
        while b"\xe2\x94\x98" not in data:  # the table's last corner
            data += os.read(master, 65536)
    finally:
        os.close(master)
        os.close(slave)
    text = re.sub(r"\x1b\[[0-9;]*m", "", data.decode())
    lines = text.replace("\r", "").splitlines()
    assert max(map(len, lines)) <= 80 and "…" not in text
    body = [ln for ln in lines if ln.startswith("│")]
    first = "".join(ln.split("│")[1].strip() for ln in body[:-1])  # the first row's cell, folded
    assert first == LONG and body[-1].split("│")[1].strip() == "poly3"
