"""Reading a configuration file safely: bounded bytes, bounded YAML, no YAML 1.1 surprises.

A configuration path is read the way images are (:func:`station.bounded_read.read_regular_file`): a
regular file only (a FIFO, a device or a directory is refused at once, never opened for a blocking
read), at most :data:`MAX_CONFIG_BYTES`. The YAML document is composed (not yet constructed) and its
node tree checked before any value is built, each problem one :class:`station.config.ConfigError`
naming the field's path (raised here as :class:`ConfigReadError`, which :mod:`station.config` turns
into its ``ConfigError`` with the file's name):

* nesting deeper than :data:`MAX_DEPTH` levels (a configuration has four);
* an integer with more than :data:`MAX_DIGITS` digits (Python refuses to build one of more than
  4300 digits, and no field of a station needs more than a few);
* a mapping key that is not a string (``1: x`` — YAML reads it as the integer 1);
* a key given twice in one mapping (PyYAML keeps the last one without a word);
* a tag outside the core schema (``!!python/object...``, ``!!binary``, ``!custom``);
* a boolean spelled the YAML 1.1 way (``yes``, ``no``, ``on``, ``off``, any case): PyYAML reads
  ``yes`` as true, which a user writing a name or a serial meant as text; write ``true`` or
  ``false``, or quote the text.

References
----------
.. [1] YAML 1.1 boolean type, https://yaml.org/type/bool.html (the spellings PyYAML resolves).
.. [2] Python's integer string conversion length limit, ``sys.set_int_max_str_digits`` (3.11).
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from station.bounded_read import BoundedReadError, read_regular_file
from station.errors import HarpError

MAX_CONFIG_BYTES = 1 << 20
"""A configuration file's largest size (1 MiB; the shipped ones are under 4 kB)."""

MAX_DEPTH = 16
"""Deepest nesting of mappings and lists accepted (a station configuration has four levels)."""

MAX_DIGITS = 30
"""Most digits of an integer in a configuration (the largest field, a seed, needs 20)."""

_PLAIN_BOOLEANS = {"true", "false"}

_CORE_TAGS = {f"tag:yaml.org,2002:{t}" for t in ("str", "int", "float", "bool", "null", "seq", "map", "timestamp")}
"""The tags a configuration's values may carry: the YAML core schema's (and timestamps, which a text field
then refuses with "quote it"); ``!!python/...``, ``!!binary``, ``!!set`` and custom tags are refused."""


class ConfigReadError(HarpError, ValueError):
    """A configuration file refused before its values are read: ``field`` (a dotted path or
    ``(file)``) and what was ``expected``."""

    def __init__(self, field: str, expected: str):
        self.field = field
        self.expected = expected
        super().__init__(f"{field}: {expected}")


def read_config_text(path: str | os.PathLike) -> str:
    """The text of the configuration file ``path``, or :class:`ConfigReadError`."""
    p = Path(path)
    try:
        data = read_regular_file(p, MAX_CONFIG_BYTES, what="a configuration file")
    except BoundedReadError as exc:
        raise ConfigReadError("(file)", exc.reason) from None
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ConfigReadError("(file)", f"expected UTF-8 text (byte {exc.start} is not)") from None


def load_yaml(text: str) -> Any:
    """The YAML document ``text`` as Python values, after :func:`check_yaml_nodes` on its node tree.

    One pass: the node tree is composed once (by libyaml where PyYAML has it: a list of 100000
    orientations in about a second instead of ten), checked, then constructed.
    """
    import yaml

    loader = getattr(yaml, "CSafeLoader", yaml.SafeLoader)(text)
    try:
        try:
            node = loader.get_single_node()
        except RecursionError:
            raise ConfigReadError("(file)", f"nesting deeper than {MAX_DEPTH} levels") from None
        except yaml.YAMLError as exc:
            if "nesting depth" in str(getattr(exc, "problem", "")):  # libyaml's own limit
                raise ConfigReadError("(file)", f"nesting deeper than {MAX_DEPTH} levels") from None
            raise
        if node is None:
            return None
        check_yaml_nodes(node)
        return loader.construct_document(node)
    finally:
        loader.dispose()


def check_yaml_nodes(root: Any) -> None:
    """Refuse what :mod:`station.config.reader` lists, naming the field (dotted path) where it is."""
    import yaml

    stack: list[tuple[Any, str, int]] = [(root, "", 1)]
    visited: set[int] = set()
    while stack:
        node, where, depth = stack.pop()
        if id(node) in visited:  # an alias of a node already checked: not walked again (no alias bomb)
            continue
        visited.add(id(node))
        name = where or "(top level)"
        if node.tag not in _CORE_TAGS:
            raise ConfigReadError(
                name,
                f"the tag {node.tag.replace('tag:yaml.org,2002:', '!!')!r} is not a configuration value "
                f"(line {node.start_mark.line + 1}); remove it",
            )
        if depth > MAX_DEPTH:
            raise ConfigReadError(name, f"nesting deeper than {MAX_DEPTH} levels")
        if isinstance(node, yaml.MappingNode):
            seen: set[str] = set()
            for key, value in node.value:
                if not (isinstance(key, yaml.ScalarNode) and key.tag == "tag:yaml.org,2002:str"):
                    shown = key.value if isinstance(key, yaml.ScalarNode) else "a mapping or list"
                    raise ConfigReadError(
                        name, f"keys must be names, got {shown!r} (line {key.start_mark.line + 1}); quote it"
                    )
                if key.value in seen:
                    raise ConfigReadError(
                        name, f"the key {key.value!r} is given twice (line {key.start_mark.line + 1}); YAML keeps "
                        "only the last: give it once",
                    )  # fmt: skip
                seen.add(key.value)
                stack.append((value, f"{where}.{key.value}" if where else str(key.value), depth + 1))
        elif isinstance(node, yaml.SequenceNode):
            for i, item in enumerate(node.value):
                stack.append((item, f"{name}[{i}]", depth + 1))
        elif isinstance(node, yaml.ScalarNode):
            if node.tag == "tag:yaml.org,2002:bool" and node.value.lower() not in _PLAIN_BOOLEANS:
                raise ConfigReadError(
                    name,
                    f"{node.value!r} is read by YAML as a boolean; write true or false, or quote it for text",
                )
            if node.tag == "tag:yaml.org,2002:int":
                digits = sum(ch.isdigit() for ch in node.value)
                if digits > MAX_DIGITS:
                    raise ConfigReadError(name, f"an integer of {digits} digits (at most {MAX_DIGITS})")
