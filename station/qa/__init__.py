"""Factory QA around a finished session or a stored lens.

* :mod:`station.qa.verdicts` — PASS / FAIL of a profile against thresholds, typed checks;
* :mod:`station.qa.judge` — judging every profile of a session (recorded in the
  manifest and the store) and the focus-interpolation error, after the executor;
* :mod:`station.qa.targets` — what ``harp qa`` judges (a session's profiles or a stored lens's
  newest ones), the measurements, thresholds and reference each is judged with, the report of it;
* :mod:`station.qa.report` — the Markdown report of a session or a judgement, with
  :mod:`station.qa.plots` (its PNG plots, drawn here or in worker processes) and
  :mod:`station.qa.report_doc` (the report as one document, written as Markdown and as an HTML
  page by its Jinja templates);
* :mod:`station.qa.overlay` — overlay PNGs of a measurement.
"""
