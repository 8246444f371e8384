"""The one bounded reader of input files: regular files only, never a blocking open, size-limited.

Images (:mod:`station.imageio`), configuration files (:mod:`station.config.reader`) and TCA files
are read through :func:`read_regular_file`, so that a FIFO, a device or an endless file given where a
file is expected is refused in one line instead of hanging or exhausting memory.
"""

from __future__ import annotations

import os
import stat
from pathlib import Path


class BoundedReadError(OSError):
    """A file that :func:`read_regular_file` refuses: ``reason`` is one line without the path.

    Not a HarpError: each reader says what the file was meant to be, so each turns it into its own
    HarpError with the ``reason`` (:class:`station.imageio.ImageReadError`,
    :class:`station.config.ConfigError`, the TCA file's :class:`station.errors.InputError`)."""

    def __init__(self, path: str | os.PathLike, reason: str):
        self.path = str(path)
        self.reason = reason
        super().__init__(f"{self.path}: {reason}")


def read_regular_file(path: str | os.PathLike, max_bytes: int, what: str = "a file") -> bytes:
    """The bytes of the regular file ``path``, at most ``max_bytes``: the one bounded reader.

    What is not a regular file (a FIFO, a device, a socket, a directory) is refused before it is
    opened for reading, so that a read never blocks; a file that became one between the check and the
    open is refused too (opened non-blocking, checked again). Raises :class:`BoundedReadError` whose
    ``reason`` says what to give instead (``what``: "an image file", "a configuration file").
    """
    p = Path(path)
    try:
        st = os.stat(p)
    except FileNotFoundError:
        raise BoundedReadError(p, "no such file") from None
    except OSError as exc:
        raise BoundedReadError(p, f"cannot read: {exc.strerror or exc}") from None
    if stat.S_ISDIR(st.st_mode):
        raise BoundedReadError(p, f"is a directory, not {what}")
    if not stat.S_ISREG(st.st_mode):
        raise BoundedReadError(p, f"not a regular file ({file_kind(st.st_mode)}); give {what}")
    if not os.access(p, os.R_OK):
        raise BoundedReadError(p, "permission denied")
    if st.st_size > max_bytes:
        raise BoundedReadError(p, f"file too large for {what}: {st.st_size} bytes (at most {max_bytes})")
    try:
        fd = os.open(p, os.O_RDONLY | os.O_NONBLOCK)
    except OSError as exc:
        raise BoundedReadError(p, f"cannot read: {exc.strerror or exc}") from None
    with os.fdopen(fd, "rb") as f:
        if not stat.S_ISREG(os.fstat(f.fileno()).st_mode):
            raise BoundedReadError(p, f"not a regular file; give {what}")
        try:
            data = f.read(max_bytes + 1)
        except OSError as exc:
            raise BoundedReadError(p, f"cannot read: {exc.strerror or exc}") from None
    if len(data) > max_bytes:
        raise BoundedReadError(p, f"file too large for {what} (more than {max_bytes} bytes)")
    return data


def file_kind(mode: int) -> str:
    """What a ``st_mode`` that is not a regular file or directory is, in words."""
    if stat.S_ISCHR(mode):
        return "a character device"
    if stat.S_ISBLK(mode):
        return "a block device"
    if stat.S_ISFIFO(mode):
        return "a FIFO"
    if stat.S_ISSOCK(mode):
        return "a socket"
    return "not a plain file"
