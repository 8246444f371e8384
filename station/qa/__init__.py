"""Factory QA around a finished session or a stored lens.

* :mod:`station.qa.verdicts` — PASS / FAIL of a profile against thresholds, typed checks;
* :mod:`station.qa.judge` — judging every profile of a session (recorded in the
  manifest and the store) and the focus-interpolation error, after the executor;
* :mod:`station.qa.report` — the Markdown / HTML report with its plots;
* :mod:`station.qa.overlay` — overlay PNGs of a measurement.
"""
