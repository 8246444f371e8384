"""The store's one error type: every store problem is a :class:`StoreError` with a one-line message
naming the store and, when there is one, what to do."""

from __future__ import annotations

from station.errors import HarpError


class StoreError(HarpError, RuntimeError):
    """A profile store problem; the message is one line naming the store.

    ``kind`` says what went wrong, for callers that act on it: ``"missing"`` (no store
    there), ``"damaged"`` (the store or a row cannot be read), ``"full"`` (no space left
    while writing), ``"busy"`` (other writers held it past the retry deadline),
    ``"unreachable"`` (cannot connect), ``"schema"`` (written by newer software), ``"older"``
    (written by older software, and opened with ``upgrade=False``: not upgraded), or ``"error"``.
    """

    def __init__(self, message: str, kind: str = "error"):
        super().__init__(" ".join(str(message).split()))
        self.kind = kind
