"""harp station: sessions, profile store, QA and the ``harp`` command line.

Where things are (one idea, one room):

* :mod:`station.config` — the station configuration (YAML → frozen dataclasses);
* :mod:`station.profile` — a profile: the one :class:`~station.profile.Profile` record
  and its conversions to the model file and the store row;
* :mod:`station.profile_choice` — which profile of a lens a command uses at a focus setting,
  and why (current, failed, interpolated);
* :mod:`station.calibration` — ``calibrate_shots``: measured shots → a profile's content
  (``harp calibrate`` and every session);
* :mod:`station.store` — the SQLite profile store;
* :mod:`station.export_source` — what an export of a profile is made from (lens and
  camera, holdout ``d``, the fitting shots' edges), for :mod:`pipeline.exports`;
* :mod:`station.files` (atomic writes, model files), :mod:`station.provenance`,
  :mod:`station.imageio` (reading photographs), :mod:`station.inputs` (bad input as one
  line, photographs read and measured), :mod:`station.evaluation` (the residual distortion
  of any correction, ``harp evaluate``);
* :mod:`station.session` — a session: plan, executor, records, progress, the session
  directory and its layout, devices;
* :mod:`station.qa` — verdicts, a session's QA, the report, overlays;
* :mod:`station.cli` — the ``harp`` command, one module per command: parsing, calling and
  printing only.

``__version__`` is the installed distribution's version (``importlib.metadata``), the
one source of the version every profile, model file and session records.
"""

from typing import Any


def __getattr__(name: str) -> Any:
    """``__version__`` and ``SOFTWARE`` (how provenance records name this software), read from the
    installed distribution on first use: a command that never asks (``harp measure``) does not pay
    for importing ``importlib.metadata``."""
    if name not in ("__version__", "SOFTWARE"):
        raise AttributeError(f"module 'station' has no attribute {name!r}")
    from importlib.metadata import PackageNotFoundError, version

    try:
        v = version("harp-station")
    except PackageNotFoundError:  # pragma: no cover - running from a tree that was never installed
        v = "0+unknown"
    globals().update(__version__=v, SOFTWARE=f"harp-station {v}")
    return globals()[name]
