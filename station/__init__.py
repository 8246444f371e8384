"""harp station: sessions, profile store, QA and the ``harp`` command line.

Where things are (one idea, one room):

* :mod:`station.config` — the station configuration (YAML → frozen dataclasses);
* :mod:`station.profile` — a profile: the one :class:`~station.profile.Profile` record
  and its conversions to the model file and the store row;
* :mod:`station.calibration` — ``calibrate_shots``: measured shots → a profile's content
  (``harp calibrate`` and every session);
* :mod:`station.store` — the SQLite profile store;
* :mod:`station.export_source` — what an export of a profile is made from (lens and
  camera, holdout ``d``, the fitting shots' edges), for :mod:`pipeline.exports`;
* :mod:`station.files` (atomic writes, model files), :mod:`station.provenance`,
  :mod:`station.imageio` (reading photographs);
* :mod:`station.session` — a session: plan, executor, records, progress, the session
  directory and its layout, devices;
* :mod:`station.qa` — verdicts, a session's QA, the report, overlays;
* :mod:`station.cli` — the ``harp`` command, one module per command.

``__version__`` is the installed distribution's version (``importlib.metadata``), the
one source of the version every profile, model file and session records.
"""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("harp-station")
except PackageNotFoundError:  # pragma: no cover - running from a tree that was never installed
    __version__ = "0+unknown"

SOFTWARE = f"harp-station {__version__}"
"""How provenance records name this software."""
