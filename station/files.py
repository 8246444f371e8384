"""Durable files: the one atomic-write helper, and model files written with it.

:func:`atomic_write_bytes` writes a regular file (or a new path) through a temporary
file in the same directory (``.<name>.<random>.tmp``), fsyncs it, renames it into
place and fsyncs the directory, so a reader — or a session resumed after a kill —
never sees a half-written file; a temporary left by a kill matches ``.*.tmp*`` and is
removed when a session directory is reopened (:mod:`station.session.directory`). A
failed write (a full disk) removes its temporary before the error reaches the caller.

What is not a regular file is written the way a plain ``open(path, "wb")`` would: ``-``
is standard output, a character or block device (``/dev/null``, ``/dev/stdout``) or a
FIFO is opened and written directly — never replaced by a regular file — and a symbolic
link is followed (the file it points to is replaced, the link stays). The result has the
mode a plain ``open()`` gives: an existing file keeps its mode (and, where the process
may, its owner), a new one gets ``0o666`` less the umask.

:func:`write_model_file` writes a harp model file (:mod:`pipeline.model_file`, the
format) this way, :func:`write_profile` the model file of a :class:`station.profile.Profile`.
:func:`sha256_file` is the checksum recorded for every input.
"""

from __future__ import annotations

import contextlib
import errno
import hashlib
import os
import stat
import sys
import tempfile
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:  # annotations only: an atomic write does not pay for the model file's imports (YAML)
    from pipeline.models.base import DistortionModel
    from station.profile import Profile


def atomic_write_bytes(path: str | os.PathLike, data: bytes) -> None:
    """Write ``data`` to ``path``: atomically for a regular file or a new path, directly for
    ``-`` (standard output), a device or a FIFO; a symlink is followed (see the module docstring).

    Raises ``OSError`` (``IsADirectoryError`` for a directory); nothing is left behind.
    """
    if os.fspath(path) == "-":
        out = getattr(sys.stdout, "buffer", None)
        if out is None:  # a text-only stream (a test double)
            sys.stdout.write(data.decode("utf-8"))
        else:
            out.write(data)
        sys.stdout.flush()
        return
    target = Path(os.path.realpath(path))  # a symlink is followed, as open() would
    try:
        st: os.stat_result | None = os.stat(target)
    except FileNotFoundError:
        st = None
    if st is not None and stat.S_ISDIR(st.st_mode):
        raise IsADirectoryError(errno.EISDIR, "is a directory", os.fspath(path))
    if st is not None and not stat.S_ISREG(st.st_mode):  # device, FIFO, socket: write it, never replace it
        with open(target, "wb") as f:
            f.write(data)
        return
    directory = target.parent
    fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".tmp", dir=directory)
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            if st is not None:
                os.fchmod(f.fileno(), stat.S_IMODE(st.st_mode))
                with contextlib.suppress(OSError):  # only root may give a file away
                    os.fchown(f.fileno(), st.st_uid, st.st_gid)
            else:
                os.fchmod(f.fileno(), 0o666 & ~current_umask())
            os.fsync(f.fileno())
        os.replace(tmp, target)
    except OSError as exc:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        if exc.filename is None:  # write()/fsync() errors name no file: name the one being written
            raise OSError(exc.errno, exc.strerror, os.fspath(path)) from None
        raise
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


def current_umask() -> int:
    """The process umask (read from ``/proc/self/status`` where it can be, without changing it)."""
    with contextlib.suppress(OSError, ValueError):
        with open("/proc/self/status", encoding="ascii") as f:
            for line in f:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    mask = os.umask(0o022)  # elsewhere: read by setting (not thread-safe, but only a fallback)
    os.umask(mask)
    return mask


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
    from pipeline.model_file import model_file_text  # defers cv2, numpy, yaml

    atomic_write_text(path, model_file_text(model, width=width, height=height, merit=merit, provenance=provenance))
    return Path(path)


def write_profile(path: str | os.PathLike, profile: Profile) -> Path:
    """Write a profile's model file (:meth:`station.profile.Profile.to_model_file`) to ``path`` atomically."""
    atomic_write_text(path, profile.to_model_file().text())
    return Path(path)


_OS_ACTIONS = {
    errno.ENOSPC: "free some space on that file system and run the command again",
    errno.EDQUOT: "free some space (disk quota exceeded) and run the command again",
    errno.EACCES: "check its permissions",
    errno.EPERM: "check its permissions",
    errno.EROFS: "the file system is read-only: choose a writable place",
    errno.ENOENT: "check the path",
    errno.ENOTDIR: "check the path",
    errno.EISDIR: "give a file, not a directory",
    errno.EIO: "the device reported an I/O error: check the disk",
}


def describe_os_error(exc: OSError, action: str | None = None) -> str:
    """One line for an ``OSError``: the file, the reason and what to do (``action`` overrides the default)."""
    where = exc.filename if exc.filename is not None else None
    reason = exc.strerror or type(exc).__name__
    todo = action if action is not None else _OS_ACTIONS.get(exc.errno or 0)
    text = f"{where}: {reason}" if where is not None else reason
    text = " ".join(text.split())  # one line whatever the file name holds
    return f"{text}; {todo}" if todo else text


def sha256_file(path: str | os.PathLike, chunk: int = 1 << 20) -> str:
    """Hex SHA-256 of a file's bytes."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        while block := f.read(chunk):
            h.update(block)
    return h.hexdigest()
