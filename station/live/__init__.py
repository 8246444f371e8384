"""The set-up assistant (issue 13): a live view of the camera that tells the operator when the
harp, the focus and the exposure are right, before and during a session.

* :mod:`station.live.checks` -- the live figures against the session's acceptance checks, and
  the one-shot check of ``harp live --once`` (the executor's own checks on an averaged shot).
* :mod:`station.live.runner` -- :class:`~station.live.runner.LiveStation`: the camera and
  turntable threads, reconnects, the accumulated coverage and the through-focus history.
* :mod:`station.live.devices` -- the live view on a configuration's devices: the session's
  settings applied, the configuration's :class:`~station.live.runner.LiveStation`, and
  ``harp live --once`` (one shot captured, checked and assessed).
* :mod:`station.live.view` -- what the page receives (JSON figures, the downscaled frame).
* :mod:`station.live.web` -- the page, built on :mod:`station.web` (imported only to serve).
* :mod:`station.live.session_tap` -- the page during a session (``harp session run --live``):
  a subscriber to the session's records and frames.

The command is :mod:`station.cli.live` (``harp live``: it parses, calls these and prints).

The assessment itself is pure and lives in :mod:`pipeline.assess`.
"""
