"""Durable files: the one atomic-write helper, and model files written with it.

:func:`atomic_write_bytes` writes through a temporary file in the same directory
(``.<name>.<random>.tmp``), fsyncs it, renames it into place and fsyncs the
directory, so a reader — or a session resumed after a kill — never sees a
half-written file; a temporary left by a kill matches ``.*.tmp*`` and is removed
when a session directory is reopened (:mod:`station.session.directory`).
:func:`write_model_file` writes a harp model file (:mod:`pipeline.model_file`, the
format) this way, :func:`write_profile` the model file of a :class:`station.profile.Profile`. :func:`sha256_file` is the checksum recorded for every input.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import tempfile
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:  # annotations only: an atomic write does not pay for the model file's imports (YAML)
    from pipeline.models.base import DistortionModel
    from station.profile import Profile


def atomic_write_bytes(path: str | os.PathLike, data: bytes) -> None:
    """Write ``data`` to ``path`` atomically (temporary in the same directory, fsync, rename, fsync dir)."""
    path = Path(path)
    directory = path.parent if str(path.parent) else Path(".")
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=directory)
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise
    with contextlib.suppress(OSError):  # make the rename durable (a platform may not fsync directories)
        dfd = os.open(directory, os.O_RDONLY)
        try:
            os.fsync(dfd)
        finally:
            os.close(dfd)


def atomic_write_text(path: str | os.PathLike, text: str) -> None:
    """:func:`atomic_write_bytes` of ``text`` in UTF-8."""
    atomic_write_bytes(path, text.encode("utf-8"))


def write_model_file(
    path: str | os.PathLike,
    model: DistortionModel,
    *,
    width: int,
    height: int,
    merit: dict[str, Any] | None = None,
    provenance: dict[str, Any] | None = None,
) -> Path:
    """Write ``model`` with image size, figures of merit and provenance to ``path`` atomically."""
    from pipeline.model_file import model_file_text

    atomic_write_text(path, model_file_text(model, width=width, height=height, merit=merit, provenance=provenance))
    return Path(path)


def write_profile(path: str | os.PathLike, profile: Profile) -> Path:
    """Write a profile's model file (:meth:`station.profile.Profile.to_model_file`) to ``path`` atomically."""
    atomic_write_text(path, profile.to_model_file().text())
    return Path(path)


def sha256_file(path: str | os.PathLike, chunk: int = 1 << 20) -> str:
    """Hex SHA-256 of a file's bytes."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        while block := f.read(chunk):
            h.update(block)
    return h.hexdigest()
