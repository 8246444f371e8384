"""The ``argparse`` types the ``harp`` sub-commands share (their errors: :class:`station.errors.InputError`)."""

from __future__ import annotations

import argparse


def positive_int(text: str) -> int:
    """``argparse`` type: an integer >= 1."""
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer >= 1, got {text!r}") from None
    if v < 1:
        raise argparse.ArgumentTypeError(f"expected an integer >= 1, got {v}")
    return v


def port_number(text: str) -> int:
    """``argparse`` type: a TCP port to listen on, 0..65535 (0: any free port)."""
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected a port number in 0..65535 (0: any free port), got {text!r}"
        ) from None
    if not 0 <= v <= 65535:
        raise argparse.ArgumentTypeError(f"expected a port number in 0..65535 (0: any free port), got {v}")
    return v
