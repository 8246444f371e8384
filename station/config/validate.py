"""Reading and validating a configuration file into :class:`station.config.schema.Config`.

Every problem is reported as a :class:`~station.config.errors.ConfigError` whose message is ONE
line naming the file, the dotted path of the field and what was expected, e.g.::

    configs/demo.yaml: capture.frames_per_orientation: expected an integer >= 1, got 'two'
"""

from __future__ import annotations

import dataclasses
import math
import os
from collections.abc import Mapping
from pathlib import Path
from types import MappingProxyType
from typing import Any

import yaml

from drivers import CAMERA_DRIVERS, TURNTABLE_DRIVERS
from pipeline.fitspec import AUTO, parse_choice
from pipeline.resample import DEFAULT_T
from station.config.devices import check_what_the_devices_allow
from station.config.errors import ConfigError, shown
from station.config.reader import ConfigReadError, load_yaml, read_config_text
from station.config.schema import (
    EMULATOR_PORT,
    OVERLAY_RETENTION,
    CaptureConfig,
    CheckConfig,
    Config,
    DeviceConfig,
    HarpConfig,
    PipelineConfig,
    QAConfig,
    ReportConfig,
    RetryConfig,
    SimulationConfig,
    StationConfig,
    TurntableConfig,
    config_keys,
    keys_of,
)
from station.equipment import Identity, Optics, optic_problem, optics_keys
from station.store.errors import StoreError
from station.store.location import parse_store, user_store_path

_MISSING = object()


class _Section:
    """A mapping being validated, knowing its dotted path and the file."""

    def __init__(self, file: Path, path: str, data: Any, known: tuple[str, ...] | None = None):
        self.file, self.path = file, path
        if not isinstance(data, Mapping):
            raise ConfigError(file, path or "(top level)", f"expected a mapping, got {shown(data)}")
        self.data = data
        if known is not None:
            for key in data:
                if key not in known:
                    raise ConfigError(file, self._p(key), f"unknown field; expected one of {', '.join(known)}")

    def _p(self, key: str) -> str:
        return f"{self.path}.{key}" if self.path else str(key)

    def err(self, key: str, expected: str, value: Any = _MISSING) -> ConfigError:
        got = "missing" if value is _MISSING else f"got {shown(value)}"
        return ConfigError(self.file, self._p(key), f"expected {expected}, {got}")

    def get(self, key: str, default: Any = _MISSING) -> Any:
        if key in self.data and self.data[key] is not None:
            return self.data[key]
        if default is _MISSING:
            raise self.err(key, "a value")
        return default

    def section(self, key: str, known: tuple[str, ...] | None = None, optional: bool = False):
        if optional and self.data.get(key) is None:
            return _Section(self.file, self._p(key), {}, known)
        if key not in self.data:
            raise self.err(key, "a mapping")
        return _Section(self.file, self._p(key), self.data[key], known)

    def _given(self, key: str, default: Any, kind: str) -> Any:
        """The value of ``key``, ``default`` when absent or null, an error when there is none."""
        v = self.data.get(key, _MISSING)
        if v is _MISSING or v is None:
            if default is _MISSING:
                raise self.err(key, kind)
            return _MISSING
        return v

    def string(self, key: str, default: Any = _MISSING) -> str:
        v = self._given(key, default, "a string")
        if v is _MISSING:
            return default
        if isinstance(v, bool) or not isinstance(v, (str, int, float)):
            raise self.err(key, "a string", v)
        v = str(v)
        if not v.strip():
            raise self.err(key, "a non-empty string", v)
        return v

    def number(
        self,
        key: str,
        default: Any = _MISSING,
        *,
        min: float | None = None,
        positive: bool = False,
        integer: bool = False,
    ) -> Any:
        kind = "an integer" if integer else "a number"
        if positive:
            kind += " > 0"
        elif min is not None:
            kind += f" >= {min:g}"
        v = self._given(key, default, kind)
        if v is _MISSING:
            return default
        ok = isinstance(v, int) if integer else isinstance(v, (int, float))
        if isinstance(v, bool) or not ok or (not integer and not math.isfinite(v)):
            raise self.err(key, kind, v)
        if (positive and not v > 0) or (min is not None and v < min):
            raise self.err(key, kind, v)
        return int(v) if integer else float(v)

    def boolean(self, key: str, default: Any = _MISSING) -> bool:
        v = self._given(key, default, "true or false")
        if v is _MISSING:
            return default
        if not isinstance(v, bool):
            raise self.err(key, "true or false", v)
        return v

    def number_list(self, key: str, *, min_len: int = 1) -> tuple[float, ...]:
        v = self.data.get(key, _MISSING)
        expected = f"a list of at least {min_len} number{'s' if min_len > 1 else ''}"
        if v is _MISSING or v is None:
            raise self.err(key, expected)
        if not isinstance(v, list) or len(v) < min_len:
            raise self.err(key, expected, v)
        for i, item in enumerate(v):
            if isinstance(item, bool) or not isinstance(item, (int, float)) or not math.isfinite(item):
                raise ConfigError(self.file, f"{self._p(key)}[{i}]", f"expected a number, got {shown(item)}")
        if len(set(v)) != len(v):
            raise self.err(key, "a list without repeated values", v)
        return tuple(float(x) for x in v)


def _range(cls: type, name: str) -> tuple[float, float]:
    """The ``range`` metadata of field ``name`` of dataclass ``cls``."""
    (f,) = [f for f in dataclasses.fields(cls) if f.name == name]
    lo, hi = f.metadata["range"]
    return float(lo), float(hi)


def _device(sec: _Section, key: str, table: Mapping[str, str], kind: str) -> _Section:
    dev = sec.section(key)
    name = dev.data.get("driver", _MISSING)
    if name is _MISSING or name is None:
        raise dev.err("driver", f"a {kind} driver name (one of {', '.join(sorted(table))})")
    if not isinstance(name, str) or name not in table:
        raise dev.err("driver", f"a {kind} driver name (one of {', '.join(sorted(table))})", name)
    return dev


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
        problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        raise ConfigError(path, where, f"expected valid YAML: {problem}") from None
    if data is None:
        raise ConfigError(path, "(top level)", "expected a mapping, got an empty file")
    top = _Section(path, "", data, config_keys())

    st = top.section("station", keys_of(StationConfig))
    cam = _device(st, "camera", CAMERA_DRIVERS, "camera")
    camera = DeviceConfig(cam.data["driver"], MappingProxyType({k: v for k, v in cam.data.items() if k != "driver"}))
    tt = _device(st, "turntable", TURNTABLE_DRIVERS, "turntable")
    turntable = TurntableConfig(
        driver=tt.data["driver"],
        settings=MappingProxyType(
            {k: v for k, v in tt.data.items() if k not in ("driver", "port", "steps_per_degree")}
        ),
        port=tt.string("port"),
        steps_per_degree=tt.number("steps_per_degree", None, positive=True),
    )
    hp = st.section("harp", keys_of(HarpConfig))
    direction = hp.number("direction", 1, integer=True)
    if direction not in (1, -1):
        raise hp.err("direction", "1 or -1", direction)
    harp = HarpConfig(
        string_width_mm=hp.number("string_width_mm", positive=True),
        string_spacing_mm=hp.number("string_spacing_mm", positive=True),
        offset_deg=hp.number("offset_deg", 0.0),
        direction=direction,
    )
    station = StationConfig(id=st.string("id"), camera=camera, turntable=turntable, harp=harp)

    optic_values: dict[str, Any] = {}

    def identity(key: str) -> Identity:
        s = top.section(key, (*keys_of(Identity), *optics_keys(key)))
        for name in optics_keys(key):
            v = s.data.get(name)
            problem = optic_problem(name, v)
            if problem is not None:
                raise s.err(name, problem, v)
            if v is not None:
                optic_values[name] = v if isinstance(v, str) else float(v)
        return Identity(s.string("maker"), s.string("model"), s.string("serial"))

    lens, body = identity("lens"), identity("camera_body")
    if "pixel_pitch_um" in optic_values and "sensor_width_mm" in optic_values:
        raise ConfigError(path, "camera_body.sensor_width_mm", "expected pixel_pitch_um or sensor_width_mm, not both")
    optics = Optics(**optic_values)

    fo = top.section("focus", config_keys("focus"))
    focus_settings = fo.number_list("settings")

    cp = top.section("capture", keys_of(CaptureConfig))
    ck = cp.section("checks", keys_of(CheckConfig), optional=True)
    d = CheckConfig()
    checks = CheckConfig(
        min_lines=ck.number("min_lines", d.min_lines, min=1, integer=True),
        angle_tolerance_deg=ck.number("angle_tolerance_deg", d.angle_tolerance_deg, positive=True),
        max_saturated_fraction=ck.number("max_saturated_fraction", d.max_saturated_fraction, min=0),
        min_dynamic_range=ck.number("min_dynamic_range", d.min_dynamic_range, min=0),
        max_recaptures=ck.number("max_recaptures", d.max_recaptures, min=0, integer=True),
        max_edge_width_px=ck.number("max_edge_width_px", d.max_edge_width_px, positive=True),
    )
    rt = cp.section("retries", keys_of(RetryConfig), optional=True)
    r = RetryConfig()
    retries = RetryConfig(
        attempts=rt.number("attempts", r.attempts, min=1, integer=True),
        backoff_s=rt.number("backoff_s", r.backoff_s, min=0),
    )
    orientations = cp.number_list("orientations_deg", min_len=2)
    capture = CaptureConfig(
        orientations_deg=orientations,
        frames_per_orientation=cp.number("frames_per_orientation", min=1, integer=True),
        exposure_us=cp.number("exposure_us", positive=True),
        gain_db=cp.number("gain_db", 0.0),
        settle_s=cp.number("settle_s", 0.0, min=0),
        timeout_s=cp.number("timeout_s", 5.0, positive=True),
        move_timeout_s=cp.number("move_timeout_s", 60.0, positive=True),
        checks=checks,
        retries=retries,
    )

    pp = top.section("pipeline", keys_of(PipelineConfig), optional=True)
    pipe = PipelineConfig(
        t=pp.number("t", DEFAULT_T, min=1, integer=True),
        model=pp.string("model", "radial"),
        degree=pp.number("degree", None, min=1, integer=True),
        tangential=pp.boolean("tangential", None),
        prism=pp.boolean("prism", None),
        center_prior=pp.boolean("center_prior", None),
        bootstrap=pp.number("bootstrap", 0, min=0, integer=True),
        seed=pp.number("seed", 0, min=0, integer=True),
        workers=pp.number("workers", 1, min=1, integer=True),
    )
    try:
        parse_choice(pipe.model)
    except ValueError as exc:
        raise ConfigError(
            path, "pipeline.model", f"expected a distortion model name (a fit label, or {AUTO}): {exc}"
        ) from None
    try:
        pipe.spec  # noqa: B018  (validates degree and terms against pipeline.fitspec)
    except ValueError as exc:
        raise ConfigError(path, "pipeline.degree", f"expected a degree the model allows: {exc}") from None

    qs = top.section("qa", keys_of(QAConfig), optional=True)
    q = QAConfig()
    qa = QAConfig(
        max_holdout_d_px=qs.number("max_holdout_d_px", q.max_holdout_d_px, positive=True),
        max_distortion_px=qs.number("max_distortion_px", None, positive=True),
        max_reference_deviation_px=qs.number("max_reference_deviation_px", None, positive=True),
    )

    rs = top.section("report", keys_of(ReportConfig), optional=True)
    report = ReportConfig(overlays=rs.string("overlays", ReportConfig.overlays))
    if report.overlays not in OVERLAY_RETENTION:
        raise rs.err("overlays", f"one of {', '.join(OVERLAY_RETENTION)}", report.overlays)

    so = top.section("store", config_keys("store"))
    store_path, store_url = _store_of(so, base)
    sessions_dir = Path(os.path.normpath(base / so.string("sessions_dir", "sessions")))

    simulation = None
    if "simulation" in top.data:
        sm = top.section("simulation", keys_of(SimulationConfig))
        emu = sm.section("emulator", optional=True)
        lo, hi = _range(SimulationConfig, "lens_spread")
        spread = sm.number("lens_spread", lo, min=lo)
        if spread > hi:
            raise sm.err("lens_spread", f"a number in [{lo:g}, {hi:g}] (times the population's spread)", spread)
        simulation = SimulationConfig(
            harp_offset_deg=sm.number("harp_offset_deg", 0.0),
            emulator=MappingProxyType(dict(emu.data)),
            lens_spread=spread,
        )
    elif turntable.port == EMULATOR_PORT:
        raise tt.err("port", f"a serial port or URL ('{EMULATOR_PORT}' needs a 'simulation' section)", turntable.port)

    check_what_the_devices_allow(path, turntable, camera, orientations, focus_settings)
    zoom_settings, zoom_positions, focal = _zoom_of(top)

    return Config(
        path=path,
        base_dir=base,
        station=station,
        lens=lens,
        camera_body=body,
        focus_settings=focus_settings,
        capture=capture,
        pipeline=pipe,
        qa=qa,
        report=report,
        store_path=store_path,
        store_url=store_url,
        sessions_dir=sessions_dir,
        simulation=simulation,
        optics=optics,
        zoom_settings=zoom_settings,
        zoom_positions=zoom_positions,
        focal=focal,
    )


def _zoom_of(top: _Section) -> tuple[tuple[float, ...], tuple[float, ...], float | None]:
    """``zoom``: ``settings`` (focal lengths, mm, > 0, at least 2) with optional ``positions`` (the
    camera's zoom value at each, as many), or ``focal`` (one focal length: a zoom session's part)."""
    if top.data.get("zoom") is None:
        return (), (), None
    zs = top.section("zoom", config_keys("zoom"))
    if "settings" in zs.data and "focal" in zs.data:
        raise zs.err("focal", "zoom.settings (a zoom session) or zoom.focal (one focal length), not both")
    if "settings" not in zs.data:
        if "positions" in zs.data:
            raise zs.err("positions", "zoom.settings beside it (the focal length of each position)")
        return (), (), zs.number("focal", positive=True)
    settings = zs.number_list("settings", min_len=2)
    for i, v in enumerate(settings):
        if not v > 0:
            raise ConfigError(zs.file, f"zoom.settings[{i}]", f"expected a focal length > 0 mm, got {shown(v)}")
    positions: tuple[float, ...] = ()
    if "positions" in zs.data:
        positions = zs.number_list("positions", min_len=len(settings))
        if len(positions) != len(settings):
            raise zs.err("positions", f"one zoom position per focal length ({len(settings)})", list(positions))
    return settings, positions, None


def _store_of(so: _Section, base: Path) -> tuple[Path | None, str | None]:
    """``store.path`` (a file, relative to the configuration) or ``store.url`` (``sqlite:///`` or
    ``postgresql://``, :mod:`station.store.location`): at most one of them; neither is the per-user
    default store (:func:`~station.store.location.user_store_path`), the one every command finds."""
    if "path" in so.data and "url" in so.data:
        raise so.err("path", "one of store.path (a SQLite file) and store.url (sqlite:/// or postgresql://), not both")
    if "path" not in so.data and "url" not in so.data:
        return user_store_path(), None
    if "path" in so.data:
        return Path(os.path.normpath(base / so.string("path"))), None
    url = so.string("url")
    try:
        loc = parse_store(url, base)
    except StoreError as exc:
        raise ConfigError(so.file, so._p("url"), f"expected a store URL: {exc}") from None
    return loc.path, url
