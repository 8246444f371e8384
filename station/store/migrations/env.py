"""Alembic environment: migrate the connection :mod:`station.store.migrate` passes in
``config.attributes["connection"]``, inside the caller's transaction (online mode only)."""

from alembic import context

from station.store.schema import metadata

connection = context.config.attributes["connection"]
context.configure(connection=connection, target_metadata=metadata, render_as_batch=True)
with context.begin_transaction():
    context.run_migrations()
