"""harp station: sessions, profile store, QA and the ``harp`` command line.

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
