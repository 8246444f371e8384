"""The exit codes of every ``harp`` command, in one place (the README's table is this one).

=====  ==============================================================================
code   meaning
=====  ==============================================================================
0      success; for a command that judges (``harp qa``, ``harp session run`` /
       ``resume``), the verdict is PASS
1      the QA verdict is FAIL (``harp qa``, ``harp session run`` / ``resume``);
       ``harp profile export`` / ``show --focus`` refused a profile that failed QA;
       ``harp live CONFIG --once``: the shot would be refused
2      bad input or an error: one line on stderr naming the file, field or device;
       a session that stopped (its frames are kept; the line says how to go on)
130    interrupted (Ctrl-C); a session prints the resume command
143    stopped by SIGTERM (``systemctl stop``, ``docker stop``, ``kill``), 129 by SIGHUP (the
       terminal or SSH connection closed): answered as a Ctrl-C, the line says
       ``stopped by SIGTERM``; ignored signals (``nohup``) stay ignored
141    standard output closed early (e.g. piped into ``head``)
=====  ==============================================================================
"""

from __future__ import annotations

EXIT_OK = 0
EXIT_FAIL = 1
EXIT_ERROR = 2
EXIT_ABORTED = EXIT_ERROR
"""A session that stopped (its frames are kept): an error's code."""
EXIT_INTERRUPTED = 130
EXIT_BROKEN_PIPE = 141


def verdict_exit_code(verdict: str | None) -> int:
    """0 for PASS, 1 for FAIL (a judged result); 2 when there is no verdict (nothing judged)."""
    if verdict == "PASS":
        return EXIT_OK
    if verdict == "FAIL":
        return EXIT_FAIL
    return EXIT_ERROR
