"""Alembic migrations of the profile store (run by :mod:`station.store.migrate`, never by hand).

``env.py`` runs the revisions in ``versions/`` on the connection it is given (already inside
the transaction that holds the store's write lock); ``script.py.mako`` is the template for a new
revision (``alembic -c station/store/migrations/alembic.ini revision -m "..."``, then add the
revision to :data:`station.store.schema.REVISIONS`).
"""
