"""harp station: sessions, profile store, QA and the ``harp`` command line."""

__version__ = "0.1.0"
