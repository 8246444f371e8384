"""One configuration value declared once, beside what it configures: its type, unit, range and meaning.

A :class:`Setting` is the declaration of one key of a configuration file. The drivers declare their
sections with it (each driver class's ``SETTINGS``, checked by :func:`drivers.config_keys.check_config_keys`
in ``from_config``), the station declares its own fields with it (the metadata of the dataclasses of
:mod:`station.config.schema`). :func:`problem` is the one check of a value against its declaration, and
:func:`describe` the one way a declaration is written: in every "expected ..." message and in the
README's configuration reference (``scripts/config_reference.py``).

Kinds (:data:`KINDS`):

* ``integer`` — a YAML integer (not a boolean, not a float such as ``2.0``);
* ``number`` — an integer or a finite float (``.nan`` and ``.inf`` are refused);
* ``boolean`` — ``true`` or ``false``;
* ``text`` — a YAML string on one line (a number is refused: ``serial: 0123`` is the integer 83 to
  YAML 1.1, so text that looks like a number must be quoted);
* ``numbers`` (``integers``) — a list of numbers (integers), each within the range; ``length`` bounds
  the count, ``unique`` refuses repeats;
* ``value`` — any one scalar (text, number or boolean: a value written to a device feature as is);
* ``mapping`` — a mapping whose keys another declaration gives (a driver's section).

A dataclass declares its fields with :func:`setting` (the kind comes from the field's annotation,
:func:`fields_of`): the station's configuration (:mod:`station.config.schema`) and its lens and camera
body (:mod:`station.equipment`).

A range is ``[low, high]``, an end excluded with ``low_open`` / ``high_open`` (``(0, 10]``); ``choices``
replaces it with a list of values. ``nullable`` lets ``null`` stand for "not set" (the default).

References
----------
.. [1] YAML 1.1 integer and float types (the octal ``0123``, the float needing a dot),
   https://yaml.org/type/int.html, https://yaml.org/type/float.html
"""

from __future__ import annotations

import dataclasses
import datetime
import functools
import math
import types
import typing
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

Kind = Literal["integer", "number", "boolean", "text", "numbers", "integers", "value", "mapping"]
KINDS: tuple[Kind, ...] = ("integer", "number", "boolean", "text", "numbers", "integers", "value", "mapping")

MAX_TEXT = 200
"""Longest text value of a configuration (names, serials, paths, URLs)."""

SEED_MAX = 2**64 - 1
"""Largest random seed (numpy's generators take any non-negative integer; 64 bits are plenty)."""


class _NoDefault:
    def __repr__(self) -> str:
        return "REQUIRED"


REQUIRED: Any = _NoDefault()
"""The default of a setting that must be given."""


@dataclass(frozen=True)
class Setting:
    """The declaration of one configuration key (module docstring).

    ``kind`` may be None only where the type is written elsewhere (a dataclass field's annotation,
    from which :mod:`station.config.schema` fills it in). ``default`` is the value when the key is
    absent (:data:`REQUIRED`: it must be given); a dataclass field's default is its own.
    """

    doc: str
    kind: Kind | None = None
    unit: str = ""
    low: float | None = None
    high: float | None = None
    low_open: bool = False
    high_open: bool = False
    choices: tuple[Any, ...] = ()
    length: tuple[int, int | None] = (0, None)  # numbers: the count of items (at least, at most)
    unique: bool = False
    nullable: bool = False
    default: Any = None

    @property
    def has_range(self) -> bool:
        return self.low is not None or self.high is not None

    def range_text(self, with_unit: bool = True) -> str:
        """``[0.05, 600] s``, ``(0, 10] mm``, ``>= 1``, ``one of 8, 16`` or ``""`` (no range)."""
        if self.choices:
            return "one of " + ", ".join(plain(c) for c in self.choices)
        unit = f" {self.unit}" if self.unit and with_unit else ""
        if self.low is not None and self.high is not None:
            lo, hi = "(" if self.low_open else "[", ")" if self.high_open else "]"
            return f"{lo}{plain(self.low)}, {plain(self.high)}{hi}{unit}"
        if self.low is not None:
            return f"{'>' if self.low_open else '>='} {plain(self.low)}{unit}"
        if self.high is not None:
            return f"{'<' if self.high_open else '<='} {plain(self.high)}{unit}"
        return unit.strip()

    def inside(self, v: float) -> bool:
        """``v`` (a finite number) within the range (or one of the choices)."""
        if self.choices:
            return v in self.choices
        if self.low is not None and (v <= self.low if self.low_open else v < self.low):
            return False
        if self.high is not None and (v >= self.high if self.high_open else v > self.high):
            return False
        return True


def plain(v: Any) -> str:
    """A number as the messages and the reference write it (``5.0`` -> ``5``, ``1e-05``)."""
    if isinstance(v, float) and v.is_integer() and abs(v) < 1e15:
        return str(int(v))
    if isinstance(v, float):
        return f"{v:g}"
    return str(v)


def describe(s: Setting) -> str:
    """What ``s`` accepts, as the "expected ..." of a message: ``an integer in [1, 1000]``,
    ``a number in (0, 10] mm``, ``true or false``, ``one of all, failed, none``."""
    if s.choices:
        return s.range_text()
    rng = s.range_text()
    where = f" in {rng}" if s.low is not None and s.high is not None else (f" {rng}" if rng else "")
    kind = s.kind
    if kind == "integer":
        return f"an integer{where}"
    if kind == "number":
        return f"a number{where}"
    if kind == "boolean":
        return "true or false"
    if kind == "text":
        return f"a string (one line, at most {MAX_TEXT} characters)"
    if kind in ("numbers", "integers"):
        least, most = s.length
        count = f"at least {least}" if most is None else (f"{least}" if least == most else f"{least} to {most}")
        each = f" in {rng}" if s.low is not None and s.high is not None else ""
        return f"a list of {count} {kind}{each}" + (", without repeats" if s.unique else "")
    if kind == "value":
        return "a string, number or true/false"
    if kind == "mapping":
        return "a mapping"
    raise ValueError(f"setting {s.doc!r}: unknown kind {kind!r}")


def type_name(s: Setting) -> str:
    """The kind as the configuration reference names it (``integer``, ``list of numbers``...)."""
    names = {"numbers": "list of numbers", "integers": "list of integers", "value": "text, number or boolean"}
    return names.get(str(s.kind), str(s.kind)) + (" or null" if s.nullable else "")


def is_number(v: Any) -> bool:
    """A YAML integer or a finite float (never a boolean)."""
    return isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)


def problem(s: Setting, value: Any) -> str | None:
    """Why ``value`` does not satisfy ``s``: the "expected ..., got ..." text (None: it does).

    A list item is named by its index first: ``[2]: expected a number in [0, 360] deg, got '45deg'``
    (:func:`split_item` separates the two).
    """
    if value is None:
        return None if s.nullable else f"expected {describe(s)}, got null"
    got = f"got {shown(value)}"
    kind = s.kind
    if kind == "integer":
        ok = isinstance(value, int) and not isinstance(value, bool)
        if ok and s.inside(value):
            return None
        return f"expected {describe(s)}, {got}{_yaml_hint(value)}"
    if kind == "number":
        if is_number(value) and s.inside(float(value)):
            return None
        return f"expected {describe(s)}, {got}{_yaml_hint(value)}"
    if kind == "boolean":
        return None if isinstance(value, bool) else f"expected true or false, {got}"
    if kind == "text":
        if not isinstance(value, str):
            # a number, a boolean or a date YAML made of unquoted text (``serial: 0123`` is 83)
            quote = isinstance(value, int | float | datetime.date)
            return f"expected {describe(s)}, {got}" + (
                "; quote it (YAML read the unquoted text as a value)" if quote else ""
            )
        if not value.strip() or len(value) > MAX_TEXT or any(ord(c) < 32 or c == "\x7f" for c in value):
            return f"expected {describe(s)}, {got}"
        if s.choices and value not in s.choices:
            return f"expected {describe(s)}, {got}"
        return None
    if kind == "value":
        if isinstance(value, bool | int | str) or is_number(value):
            return None
        return f"expected {describe(s)}, {got}"
    if kind in ("numbers", "integers"):
        least, most = s.length
        if not isinstance(value, list) or len(value) < least or (most is not None and len(value) > most):
            return f"expected {describe(s)}, {got}"
        item = Setting(s.doc, "number" if kind == "numbers" else "integer", s.unit, s.low, s.high, s.low_open,
                       s.high_open)  # fmt: skip
        for i, v in enumerate(value):
            p = problem(item, v)
            if p is not None:
                return f"[{i}]: {p}"
        if s.unique and len({float(v) for v in value}) != len(value):
            return f"expected {describe(s)}, {got}"
        return None
    if kind == "mapping":
        return None if isinstance(value, dict) else f"expected a mapping, {got}"
    raise ValueError(f"setting {s.doc!r}: unknown kind {kind!r}")


def split_item(text: str) -> tuple[str, str]:
    """``("[2]", "expected ...")`` of a :func:`problem` about a list item, ``("", text)`` otherwise."""
    if text.startswith("["):
        where, _, rest = text.partition(": ")
        return where, rest
    return "", text


def _yaml_hint(value: Any) -> str:
    """A number YAML 1.1 read as text (``1e4``: its floats need a dot): how to write it."""
    if isinstance(value, str):
        try:
            f = float(value)
        except ValueError:
            return ""
        if math.isfinite(f):
            return f" (YAML reads it as text: write {f:.10g}, unquoted, a float's exponent after a dot: 1.0e+4)"
    return ""


def shown(v: Any) -> str:
    """``v`` as a message quotes it: its repr, cut to 60 characters."""
    s = repr(v)
    return s if len(s) <= 60 else s[:57] + "..."


def setting(
    default: Any = REQUIRED,
    doc: str = "",
    unit: str = "",
    low: float | None = None,
    high: float | None = None,
    *,
    low_open: bool = False,
    high_open: bool = False,
    choices: tuple[Any, ...] = (),
    length: tuple[int, int | None] = (0, None),
    unique: bool = False,
    **where: Any,
) -> Any:
    """A dataclass field that is a key of a configuration file, declared once: ``default``
    (:data:`REQUIRED`: the key must be given; None: it may be null) and the :class:`Setting` in the
    field's metadata (``"setting"``), with ``where`` as further metadata (where the key sits in the
    file). The kind comes from the field's annotation (:func:`fields_of`)."""
    s = Setting(doc, None, unit, low, high, low_open, high_open, choices, length, unique, default is None, default)
    meta = {"setting": s, **where}
    if default is REQUIRED:
        return dataclasses.field(metadata=meta)
    return dataclasses.field(default=default, metadata=meta)


_ANNOTATION_KINDS: dict[Any, Kind] = {int: "integer", float: "number", bool: "boolean", str: "text", Path: "text"}


def _kind(annotation: Any) -> tuple[Kind, bool]:
    """``(kind, nullable)`` of a field annotation (``float | None`` -> ``("number", True)``)."""
    nullable = False
    if isinstance(annotation, types.UnionType) or typing.get_origin(annotation) is typing.Union:
        args = [a for a in typing.get_args(annotation) if a is not type(None)]
        nullable = len(args) < len(typing.get_args(annotation))
        (annotation,) = args
    if typing.get_origin(annotation) is tuple:
        return "numbers", nullable
    return _ANNOTATION_KINDS[annotation], nullable


@functools.cache
def fields_of(cls: type) -> dict[str, Setting]:
    """The :func:`setting` fields of dataclass ``cls``, their kind filled in from the annotation."""
    hints = typing.get_type_hints(cls)
    out = {}
    for f in dataclasses.fields(cls):
        s = f.metadata.get("setting")
        if s is not None:
            kind, nullable = _kind(hints[f.name])
            out[f.name] = dataclasses.replace(s, kind=kind, nullable=nullable or s.nullable)
    return out
