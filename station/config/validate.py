"""The one validator of a configuration file: :func:`load_config` / :func:`parse_config`.

Three passes, each problem one :class:`~station.config.errors.ConfigError` naming the file, the
dotted path of the field, what was expected (its range and unit) and the value found::

    configs/demo.yaml: capture.timeout_s: expected a number in [0.1, 600] s, got 0.001

1. :func:`check_document` walks the document (:func:`station.config.schema.document`) over the
   YAML: every section a mapping, no unknown key, every value of its kind and within its range
   (:func:`drivers.settings.problem`), a driver section with the chosen driver's own keys;
2. the values become the frozen dataclasses of :mod:`station.config.schema`;
3. what only several fields tell (:func:`check_across`): the strings narrower than their spacing, one
   of ``pixel_pitch_um`` and ``sensor_width_mm``, a fit label and degree the model allows, ``zoom``'s
   settings, positions and focal, one of ``store.path``
   and ``store.url`` and a URL that parses, a frame timeout longer than the exposure, the emulator
   port of a simulated station, and what the devices allow (:mod:`station.config.devices`).
"""

from __future__ import annotations

import dataclasses
import os
import typing
from collections.abc import Mapping
from pathlib import Path
from types import MappingProxyType
from typing import Any

import yaml

from drivers.settings import REQUIRED, Setting, describe, fields_of, plain, problem, shown, split_item
from pipeline.board import parse_board
from pipeline.fitspec import AUTO, parse_choice
from pipeline.orientations import holdout_problem
from station.config.devices import check_the_devices
from station.config.errors import ConfigError
from station.config.reader import ConfigReadError, load_yaml, read_config_text
from station.config.schema import (
    EMULATOR_PORT,
    Config,
    DeviceConfig,
    HarpConfig,
    Section,
    SimulationConfig,
    StationConfig,
    TurntableConfig,
    document,
    unoptional,
    with_model,
)
from station.equipment import Identity, Optics, optics_keys
from station.store.errors import StoreError
from station.store.location import parse_store, user_store_path


def load_config(path: str | os.PathLike, base_dir: str | os.PathLike | None = None) -> Config:
    """Read and validate a station configuration file.

    Parameters
    ----------
    path : path of the YAML file.
    base_dir : directory against which relative paths are resolved; defaults
        to the directory of ``path`` (a session directory passes the directory
        of the original configuration, so paths keep their meaning).

    Raises
    ------
    ConfigError : one line naming the file, the field and what was expected.
    """
    path = Path(path)
    try:
        text = read_config_text(path)
    except ConfigReadError as exc:
        raise ConfigError(path, exc.field, exc.expected) from None
    return parse_config(text, path, base_dir)


def parse_config(text: str, path: str | os.PathLike, base_dir: str | os.PathLike | None = None) -> Config:
    """Validate configuration ``text`` as if read from ``path`` (see :func:`load_config`)."""
    path = Path(path).absolute()
    base = Path(base_dir).absolute() if base_dir is not None else path.parent
    try:
        data = load_yaml(text)
    except ConfigReadError as exc:
        raise ConfigError(path, exc.field, exc.expected) from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f"line {mark.line + 1}" if mark is not None else "(file)"
        problem_text = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        raise ConfigError(path, where, f"expected valid YAML: {problem_text}") from None
    if data is None:
        raise ConfigError(path, "(top level)", "expected a mapping, got an empty file")
    check_document(document(), data, path)
    config = _config(data, path, base)
    check_across(config)
    return config


# ------------------------------------------------------------------ pass 1: the document
def check_document(sec: Section, data: Any, file: Path) -> None:
    """Raise :class:`ConfigError` at the first key of ``data`` that ``sec`` does not declare, or whose
    value is missing, of another kind or out of its range (the module docstring, pass 1)."""
    if not isinstance(data, Mapping):
        raise ConfigError(file, sec.path or "(top level)", f"expected a mapping, got {shown(data)}")
    if sec.drivers:
        s = sec.keys["driver"]
        assert isinstance(s, Setting)
        name = data.get("driver")
        if name is None:
            raise ConfigError(file, sec.key_path("driver"), f"expected a {sec.drivers} driver, {describe(s)}, missing")
        text = problem(s, name)
        if text is not None:
            raise ConfigError(
                file, sec.key_path("driver"), f"expected a {sec.drivers} driver, {text.removeprefix('expected ')}"
            )
        sec = sec.with_driver(name)
    for key in data:
        if key not in sec.keys:
            known = ", ".join(k for k in sec.keys if k != "driver")
            if sec.driver:
                expected = f"unknown key for the {sec.driver} {sec.drivers} (known: {known})"
            else:
                expected = f"unknown field; expected one of {known}"
            raise ConfigError(file, sec.key_path(key), expected)
    for key, spec in sec.keys.items():
        value = data.get(key)
        if isinstance(spec, Section):
            if value is None:
                if spec.required:
                    raise ConfigError(file, spec.path, "expected a mapping, missing")
                continue
            check_document(spec, value, file)
            continue
        if value is None and not (key in data and spec.nullable):
            if spec.default is REQUIRED:
                raise ConfigError(file, sec.key_path(key), f"expected {describe(spec)}, missing")
            continue
        text = problem(spec, value)
        if text is not None:
            item, expected = split_item(text)
            raise ConfigError(file, sec.key_path(key) + item, expected)


# ------------------------------------------------------------------ pass 2: the dataclasses
def _value(s: Setting, v: Any) -> Any:
    if v is None:
        return None
    if s.kind == "number":
        return float(v)
    if s.kind == "integer":
        return int(v)
    if s.kind == "numbers":
        return tuple(float(x) for x in v)
    return v


def build(cls: type, data: Mapping[str, Any]) -> Any:
    """Dataclass ``cls`` of checked mapping ``data``: its :func:`~station.config.schema.setting` fields
    and sections, the defaults where a key is absent or null."""
    kw: dict[str, Any] = {}
    hints = typing.get_type_hints(cls)
    for f in dataclasses.fields(cls):
        v = data.get(f.name)
        if "section" in f.metadata:
            if v is not None:
                kw[f.name] = build(hints[f.name], v)
        elif "emulator_settings" in f.metadata:
            kw[f.name] = MappingProxyType(dict(v or {}))
    for name, s in fields_of(cls).items():
        if data.get(name) is not None:
            kw[name] = _value(s, data[name])
    return cls(**kw)


def _device(cls: type[DeviceConfig], data: Mapping[str, Any]) -> DeviceConfig:
    own = ("driver", "port", "steps_per_degree") if cls is TurntableConfig else ("driver",)
    settings = MappingProxyType({k: v for k, v in data.items() if k not in own})
    if cls is TurntableConfig:
        spd = data.get("steps_per_degree")
        return TurntableConfig(data["driver"], settings, str(data["port"]), None if spd is None else float(spd))
    return DeviceConfig(data["driver"], settings)


def _config(data: Mapping[str, Any], path: Path, base: Path) -> Config:
    st = data["station"]
    station = StationConfig(
        id=st["id"],
        camera=_device(DeviceConfig, st["camera"]),
        turntable=_device(TurntableConfig, st["turntable"]),
        harp=build(HarpConfig, st["harp"]),
    )
    optics = {}
    for part in ("lens", "camera_body"):
        for name in optics_keys(part):
            v = data[part].get(name)
            if v is not None:
                optics[name] = _value(fields_of(Optics)[name], v)
    store = data.get("store") or {}
    store_path, store_url = _store_of(store, path, base)
    given = {k: data[k] for k in ("capture", "pipeline", "qa", "report", "intrinsics") if data.get(k) is not None}
    if "pipeline" in given:
        given["pipeline"] = with_model(given["pipeline"])
    sections = {k: build(unoptional(typing.get_type_hints(Config)[k]), v) for k, v in given.items()}
    zoom = data.get("zoom") or {}
    zoom_values = {f: _value(fields_of(Config)[f], zoom.get(key)) for f, key in
                   (("zoom_settings", "settings"), ("zoom_positions", "positions"), ("focal", "focal"))
                   if zoom.get(key) is not None}  # fmt: skip
    return Config(
        path=path,
        base_dir=base,
        station=station,
        lens=build(Identity, data["lens"]),
        camera_body=build(Identity, data["camera_body"]),
        focus_settings=tuple(float(f) for f in data["focus"]["settings"]),
        **sections,
        store_path=store_path,
        store_url=store_url,
        sessions_dir=Path(os.path.normpath(base / store.get("sessions_dir", "sessions"))),
        simulation=None if data.get("simulation") is None else build(SimulationConfig, data["simulation"]),
        optics=Optics(**optics),
        **zoom_values,
    )


def _store_of(store: Mapping[str, Any], path: Path, base: Path) -> tuple[Path | None, str | None]:
    """``store.path`` (a file, relative to the configuration) or ``store.url`` (``sqlite:///`` or
    ``postgresql://``, :mod:`station.store.location`): at most one of them; neither is the per-user
    default store (:func:`~station.store.location.user_store_path`), the one every command finds."""
    if store.get("path") is not None and store.get("url") is not None:
        raise ConfigError(
            path, "store.path", "expected one of store.path (a SQLite file) and store.url (sqlite:/// or "
            "postgresql://), not both",
        )  # fmt: skip
    if store.get("url") is not None:
        url = store["url"]
        if "://" not in url:
            raise ConfigError(
                path, "store.url", f"expected a store URL (sqlite:///FILE or postgresql://user@host/database; a "
                f"file goes in store.path), got {shown(url)}",
            )  # fmt: skip
        try:
            loc = parse_store(url, base)
        except StoreError as exc:
            raise ConfigError(path, "store.url", f"expected a store URL: {exc}") from None
        return loc.path, url
    if store.get("path") is not None:
        return Path(os.path.normpath(base / store["path"])), None
    return user_store_path(), None


# ------------------------------------------------------------------ pass 3: across fields
def check_across(config: Config) -> None:
    """What only several fields tell (the module docstring, pass 3)."""
    harp = config.station.harp
    if not harp.string_width_mm < harp.string_spacing_mm:
        raise config.error(
            "station.harp.string_width_mm",
            f"expected less than station.harp.string_spacing_mm ({plain(harp.string_spacing_mm)} mm), got "
            f"{plain(harp.string_width_mm)}",
        )
    if config.optics.pixel_pitch_um is not None and config.optics.sensor_width_mm is not None:
        raise config.error("camera_body.sensor_width_mm", "expected pixel_pitch_um or sensor_width_mm, not both")
    try:
        parse_choice(config.pipeline.model)
    except ValueError as exc:
        raise config.error(
            "pipeline.model", f"expected a distortion model name (a fit label, or {AUTO}): {exc}"
        ) from None
    try:
        config.pipeline.spec  # noqa: B018  (validates degree and terms against pipeline.fitspec)
    except ValueError as exc:
        raise config.error("pipeline.degree", f"expected a degree the model allows: {exc}") from None
    _zoom(config)
    _intrinsics(config)
    cap = config.capture
    if not cap.timeout_s > cap.exposure_us / 1e6:
        raise config.error(
            "capture.timeout_s",
            f"expected more than the exposure (capture.exposure_us {plain(cap.exposure_us)} µs = "
            f"{plain(cap.exposure_us / 1e6)} s), got {plain(cap.timeout_s)}",
        )
    if cap.twin_deg is not None and cap.twin is None:
        raise config.error(
            "capture.twin_deg", f"expected one of capture.orientations_deg ({', '.join(plain(a) for a in cap.orientations_deg)}), "
            f"got {plain(cap.twin_deg)}",
        )  # fmt: skip
    tt = config.station.turntable
    if config.simulation is None and tt.port == EMULATOR_PORT:
        raise config.error(
            "station.turntable.port", f"expected a serial port or URL ('{EMULATOR_PORT}' needs a 'simulation' "
            f"section), got {tt.port!r}",
        )  # fmt: skip
    check_the_devices(config)
    # after the devices' own ranges (an angle out of them is named first)
    problem = holdout_problem(cap.fitted_angles_deg)
    if problem is not None:  # captured whole, then stopped at its first fit, every time it is resumed
        fitted = "" if cap.twin is None else " besides the twin (capture.twin_deg)"
        raise config.error(
            "capture.orientations_deg", f"expected turntable angles{fitted} a session can fit and hold out: {problem}; "
            f"add angles (three or more, e.g. 0, 60, 120), got {shown(list(cap.orientations_deg))}",
        )  # fmt: skip


def _zoom(config: Config) -> None:
    """``zoom``: ``settings`` (a zoom session's focal lengths) with optional ``positions`` (the camera's
    zoom value at each, as many), or ``focal`` (one focal length: a zoom session's part), not both."""
    if config.zoom_settings and config.focal is not None:
        raise config.error("zoom.focal", "expected zoom.settings (a zoom session) or zoom.focal (one focal length), "
                           "not both")  # fmt: skip
    if config.zoom_positions and not config.zoom_settings:
        raise config.error("zoom.positions", "expected zoom.settings beside it (the focal length of each position)")
    if config.zoom_positions and len(config.zoom_positions) != len(config.zoom_settings):
        raise config.error(
            "zoom.positions", f"expected one zoom position per focal length ({len(config.zoom_settings)}), got "
            f"{shown(list(config.zoom_positions))}",
        )  # fmt: skip


def _intrinsics(config: Config) -> None:
    """``intrinsics``: a board label :func:`pipeline.board.parse_board` reads, no more ``min_views`` than angles."""
    k = config.intrinsics
    if k is None:
        return
    try:
        parse_board(k.board)
    except ValueError as exc:
        raise config.error("intrinsics.board", f"expected a board label: {exc}") from None
    if k.placement == "operator":
        if k.min_views > k.views:
            raise config.error(
                "intrinsics.min_views", f"expected at most intrinsics.views ({k.views}), got {k.min_views}"
            )
    elif k.min_views > k.n_views:
        per = "angle" if k.placement == "turntable" else "angle and tilt (intrinsics.tilts_deg)"
        raise config.error(
            "intrinsics.min_views", f"expected at most one view per {per} of intrinsics.angles_deg "
            f"({k.n_views}), got {k.min_views}",
        )  # fmt: skip
