"""Station configuration: YAML validated on load into frozen dataclasses.

A configuration file describes one station (camera, turntable, harp), the
lens and camera body being calibrated (their identities and, optionally, the
optics an export needs: :class:`Optics`), what to capture (focus settings,
orientations, frames per orientation, exposure), the pipeline parameters,
the QA thresholds and where the profile store lives. Relative paths are
relative to the directory holding the configuration file.

The keys each section accepts are the fields of its dataclass (:func:`keys_of`;
the top level, ``focus`` and ``store`` from :class:`Config`'s field metadata,
:func:`config_keys`), so a field added to a dataclass is a key of the file.

Every problem is reported as a :class:`ConfigError` whose message is ONE line
naming the file, the dotted path of the field and what was expected, e.g.::

    configs/demo.yaml: capture.frames_per_orientation: expected an integer >= 1, got 'two'
"""

from __future__ import annotations

import dataclasses
import math
import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Any

import yaml

from drivers import CAMERA_DRIVERS, TURNTABLE_DRIVERS
from pipeline.fitspec import KINDS, FitSpec
from pipeline.resample import DEFAULT_T
from station.store.errors import StoreError
from station.store.location import SQLITE, StoreLocation, parse_store, user_store_path

AUTO_MODEL = "auto"
"""``pipeline.model`` meaning: chosen per focus setting by cross-validation (:mod:`pipeline.select`)."""

#: values of ``pipeline.model``: a model kind of :mod:`pipeline.fitspec`, or auto
FIT_MODELS = (*KINDS, AUTO_MODEL)

#: turntable ``port`` value meaning "the emulator started by station.session.simulated"
EMULATOR_PORT = "emulator"


class ConfigError(ValueError):
    """A configuration problem; ``str()`` is one line naming file and field."""

    def __init__(self, file: str | os.PathLike, field_path: str, expected: str):
        self.file = str(file)
        self.field = field_path
        self.expected = expected
        super().__init__(f"{self.file}: {field_path}: {expected}")


# --------------------------------------------------------------------- data
@dataclass(frozen=True)
class DeviceConfig:
    """A driver name plus that driver's own settings (passed to ``from_config``)."""

    driver: str
    settings: Mapping[str, Any] = field(default_factory=lambda: MappingProxyType({}))

    def as_driver_config(self, **overrides) -> dict:
        """The mapping handed to :func:`drivers.open_camera` / ``open_turntable``."""
        d = {"driver": self.driver, **dict(self.settings)}
        d.update(overrides)
        return d


@dataclass(frozen=True)
class TurntableConfig(DeviceConfig):
    port: str = ""
    steps_per_degree: float | None = None

    def as_driver_config(self, **overrides) -> dict:
        d = {"driver": self.driver, **dict(self.settings), "port": self.port}
        if self.steps_per_degree is not None:
            d["steps_per_degree"] = self.steps_per_degree
        d.update(overrides)
        return d


@dataclass(frozen=True)
class HarpConfig:
    """The calibration harp: string geometry and its angle at stage 0°.

    ``offset_deg`` is the angle of the strings in the image (pipeline angle
    convention) when the turntable is at 0°; ``direction`` is +1 when a
    positive stage move increases that angle, -1 otherwise.
    """

    string_width_mm: float
    string_spacing_mm: float
    offset_deg: float = 0.0
    direction: int = 1

    def expected_angle(self, stage_deg: float) -> float:
        return (self.offset_deg + self.direction * stage_deg) % 180.0


@dataclass(frozen=True)
class StationConfig:
    id: str
    camera: DeviceConfig
    turntable: TurntableConfig
    harp: HarpConfig


@dataclass(frozen=True)
class Identity:
    maker: str
    model: str
    serial: str

    def label(self) -> str:
        return f"{self.maker} {self.model} #{self.serial}"


def _optic(section: str, check: tuple[float, float] | None, unit: str, doc: str) -> Any:
    """An :class:`Optics` field: which YAML section holds it, its plausible range and unit."""
    return field(default=None, metadata={"section": section, "range": check, "unit": unit, "doc": doc})


@dataclass(frozen=True)
class Optics:
    """What the configuration says about the optics, for exports (every field optional).

    The harp measures the *shape* of the distortion, not these: they make an
    export's camera matrix nominal instead of a placeholder
    (:func:`pipeline.exports.lens.camera_matrix_choice`) and let lensfun
    applications find the lens (:mod:`pipeline.exports.lensfun`). In the YAML
    file ``focal_mm`` and ``mount`` belong to ``lens``, the others to
    ``camera_body`` (each field's ``section`` metadata); ``pixel_pitch_um`` and
    ``sensor_width_mm`` are alternatives (give one).
    """

    focal_mm: float | None = _optic("lens", (0.1, 10000.0), "mm", "the nominal focal length (at this zoom setting)")
    mount: str | None = _optic("lens", None, "", "the lens mount, as lensfun names it (e.g. 'Canon EF')")
    pixel_pitch_um: float | None = _optic(
        "camera_body", (0.2, 100.0), "micrometres", "the pixel pitch of the images (after any binning)"
    )
    sensor_width_mm: float | None = _optic(
        "camera_body", (0.5, 200.0), "mm", "the width of the sensor area the image covers"
    )
    crop_factor: float | None = _optic(
        "camera_body", (0.1, 20.0), "", "the crop factor (35 mm diagonal / sensor diagonal)"
    )

    def to_dict(self) -> dict[str, Any]:
        """The fields that are set (for a model file's provenance)."""
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(self) if getattr(self, f.name) is not None}

    @classmethod
    def from_dict(cls, d: Any) -> Optics:
        """The optics of a :meth:`to_dict` mapping; a value that is not valid is left out."""
        if not isinstance(d, Mapping):
            return cls()
        kw: dict[str, Any] = {}
        for f in dataclasses.fields(cls):
            v = d.get(f.name)
            if f.metadata["range"] is None:
                if isinstance(v, str) and v.strip():
                    kw[f.name] = v
            elif optic_problem(f.name, v) is None and v is not None:
                kw[f.name] = float(v)
        return cls(**kw)


def optics_keys(section: str) -> tuple[str, ...]:
    """The :class:`Optics` keys of YAML section ``section`` (``lens`` or ``camera_body``)."""
    return tuple(f.name for f in dataclasses.fields(Optics) if f.metadata["section"] == section)


def optic_problem(name: str, value: Any) -> str | None:
    """Why ``value`` is not valid for :class:`Optics` field ``name`` (the 'expected ...' text), or None.

    Numbers must lie in a plausible range for their unit, which catches a value
    written in the wrong unit (a pitch of 0.0057 is millimetres, not µm).
    """
    (f,) = [f for f in dataclasses.fields(Optics) if f.name == name]
    if value is None:
        return None
    lo_hi = f.metadata["range"]
    if lo_hi is None:
        if isinstance(value, str) and value.strip():
            return None
        return f"{f.metadata['doc']} (a non-empty string)"
    lo, hi = lo_hi
    unit = f" in {f.metadata['unit']}" if f.metadata["unit"] else ""
    expected = f"{f.metadata['doc']}{unit} ({lo:g}..{hi:g})"
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        return expected
    if not lo <= value <= hi:
        return expected
    return None


@dataclass(frozen=True)
class RetryConfig:
    attempts: int = 3
    backoff_s: float = 0.2  # first wait; doubles after each failure


@dataclass(frozen=True)
class CheckConfig:
    """Acceptance of a captured shot (re-captured when a check fails)."""

    min_lines: int = 4
    angle_tolerance_deg: float = 3.0
    max_saturated_fraction: float = 0.01  # of pixels at the top code value
    min_dynamic_range: float = 0.2  # (p99 - p1) / full scale
    max_recaptures: int = 2
    # px: harp live's focus check, the median 10-90 % string edge width (a sharp harp: 1.3-2 px;
    # the live demo's lens 0.17 off its best focus: 4 px); the session itself does not assess focus
    max_edge_width_px: float = 3.0


@dataclass(frozen=True)
class CaptureConfig:
    orientations_deg: tuple[float, ...]
    frames_per_orientation: int = 1
    exposure_us: float = 10000.0
    gain_db: float = 0.0
    settle_s: float = 0.0
    timeout_s: float = 5.0
    move_timeout_s: float = 60.0
    checks: CheckConfig = field(default_factory=CheckConfig)
    retries: RetryConfig = field(default_factory=RetryConfig)


@dataclass(frozen=True)
class PipelineConfig:
    t: int = DEFAULT_T
    model: str = "radial"
    degree: int | None = None  # None: the fit's default for the model
    tangential: bool = False  # radial model: decentering terms p1, p2
    prism: bool = False  # radial model: thin-prism terms s1..s4
    center_prior: bool = False  # radial model: pull the distortion centre towards the image centre
    bootstrap: int = 0  # replicates for the field uncertainty (0: not computed)
    seed: int = 0  # of the bootstrap resampling
    workers: int = 1  # processes for the cross-validation / bootstrap fits

    @property
    def spec(self) -> FitSpec | None:
        """What to fit (:class:`pipeline.fitspec.FitSpec`); ``None`` for ``model: auto``
        (chosen by cross-validation). The radial-only flags are ignored for ``poly``."""
        if self.model == AUTO_MODEL:
            return None
        if self.model == "poly":
            return FitSpec("poly", self.degree)
        return FitSpec(self.model, self.degree, self.tangential, self.prism, self.center_prior)


@dataclass(frozen=True)
class QAConfig:
    max_holdout_d_px: float = 0.05
    max_distortion_px: float | None = None
    max_reference_deviation_px: float | None = None


OVERLAY_RETENTION = ("all", "failed", "none")
"""Values of ``report.overlays``: which per-orientation overlays a session report keeps (every focus
setting's, only those of a focus setting that failed QA, none)."""


@dataclass(frozen=True)
class ReportConfig:
    """What the session report keeps (:mod:`station.qa.report`)."""

    overlays: str = "all"  # one of OVERLAY_RETENTION


@dataclass(frozen=True)
class SimulationConfig:
    """Present only for a simulated station (see :mod:`station.session.simulated`).

    ``lens_spread``: the manufacturing spread of the simulated lens, in units of the population's
    (:func:`drivers.sim.lens.lens_unit`: decentre, tilt, k1 spread, one bad unit in 20), drawn from
    ``lens.serial`` so that every serial is its own reproducible lens; 0 is the nominal demo lens
    for every serial."""

    harp_offset_deg: float = 0.0
    emulator: Mapping[str, Any] = field(default_factory=lambda: MappingProxyType({}))
    lens_spread: float = field(default=0.0, metadata={"range": (0.0, 5.0)})


def _at(yaml_path: str | None) -> Any:
    """Metadata of a :class:`Config` field: where it is in the YAML file (None: not from the file)."""
    return field(metadata={"yaml": yaml_path})


@dataclass(frozen=True)
class Config:
    path: Path = _at(None)  # the file it was read from (absolute)
    base_dir: Path = _at(None)  # relative paths are resolved against this
    station: StationConfig = _at("station")
    lens: Identity = _at("lens")
    camera_body: Identity = _at("camera_body")
    focus_settings: tuple[float, ...] = _at("focus.settings")
    capture: CaptureConfig = _at("capture")
    pipeline: PipelineConfig = _at("pipeline")
    qa: QAConfig = _at("qa")
    report: ReportConfig = _at("report")
    store_path: Path | None = _at("store.path")  # the SQLite file of the store (None: PostgreSQL, store_url)
    sessions_dir: Path = _at("store.sessions_dir")
    simulation: SimulationConfig | None = field(default=None, metadata={"yaml": "simulation"})
    optics: Optics = field(default_factory=Optics, metadata={"yaml": None})  # from lens and camera_body
    store_url: str | None = field(default=None, metadata={"yaml": "store.url"})  # as given: postgresql:// or sqlite:///

    @property
    def store(self) -> StoreLocation:
        """Where this station's profile store is (:mod:`station.store.location`)."""
        if self.store_url is not None:
            return parse_store(self.store_url, self.base_dir)
        assert self.store_path is not None
        return StoreLocation(SQLITE, path=self.store_path)

    def error(self, field_path: str, expected: str) -> ConfigError:
        return ConfigError(self.path, field_path, expected)


# --------------------------------------------------------------- validation
_MISSING = object()


def keys_of(cls: type) -> tuple[str, ...]:
    """The YAML keys of a section: the fields of its dataclass, in order."""
    return tuple(f.name for f in dataclasses.fields(cls))


def _range(cls: type, name: str) -> tuple[float, float]:
    """The ``range`` metadata of field ``name`` of dataclass ``cls``."""
    (f,) = [f for f in dataclasses.fields(cls) if f.name == name]
    lo, hi = f.metadata["range"]
    return float(lo), float(hi)


def config_keys(section: str = "") -> tuple[str, ...]:
    """The keys of the top level (``""``) or of ``focus`` / ``store``, from :class:`Config`'s field metadata."""
    out: list[str] = []
    for f in dataclasses.fields(Config):
        where = f.metadata.get("yaml")
        if where is None:
            continue
        head, _, rest = where.partition(".")
        key = head if not section else (rest if head == section else "")
        if key and key not in out:
            out.append(key)
    return tuple(out)


class _Section:
    """A mapping being validated, knowing its dotted path and the file."""

    def __init__(self, file: Path, path: str, data: Any, known: tuple[str, ...] | None = None):
        self.file, self.path = file, path
        if not isinstance(data, Mapping):
            raise ConfigError(file, path or "(top level)", f"expected a mapping, got {_show(data)}")
        self.data = data
        if known is not None:
            for key in data:
                if key not in known:
                    raise ConfigError(file, self._p(key), f"unknown field; expected one of {', '.join(known)}")

    def _p(self, key: str) -> str:
        return f"{self.path}.{key}" if self.path else str(key)

    def err(self, key: str, expected: str, value: Any = _MISSING) -> ConfigError:
        got = "missing" if value is _MISSING else f"got {_show(value)}"
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
                raise ConfigError(self.file, f"{self._p(key)}[{i}]", f"expected a number, got {_show(item)}")
        if len(set(v)) != len(v):
            raise self.err(key, "a list without repeated values", v)
        return tuple(float(x) for x in v)


def _show(v: Any) -> str:
    s = repr(v)
    return s if len(s) <= 60 else s[:57] + "..."


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
    from station.config_reader import ConfigReadError, read_config_text

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
    from station.config_reader import ConfigReadError, load_yaml

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
        tangential=pp.boolean("tangential", False),
        prism=pp.boolean("prism", False),
        center_prior=pp.boolean("center_prior", False),
        bootstrap=pp.number("bootstrap", 0, min=0, integer=True),
        seed=pp.number("seed", 0, min=0, integer=True),
        workers=pp.number("workers", 1, min=1, integer=True),
    )
    if pipe.model not in FIT_MODELS:
        raise pp.err("model", f"a distortion model name (one of {', '.join(FIT_MODELS)})", pipe.model)
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

    _check_what_the_devices_allow(path, turntable, camera, orientations, focus_settings)

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
    )


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


ROTARY_RANGE = (0.0, 360.0)
"""Orientations of a rotary stage without configured ``limits``: ``[0, 360)`` degrees."""


def _check_what_the_devices_allow(
    path: Path,
    turntable: TurntableConfig,
    camera: DeviceConfig,
    orientations: tuple[float, ...],
    focus_settings: tuple[float, ...],
) -> None:
    """What can be known without the devices: orientations within the turntable's configured
    ``limits`` (inclusive) or, without them, ``[0, 360)`` for the rotary stages; focus settings
    within the simulated lens's range. The devices' own ranges are checked once they are open
    (:func:`station.session.devices.check_against_devices`)."""
    limits = turntable.settings.get("limits")
    if limits is not None:
        ok = (
            isinstance(limits, (list, tuple))
            and len(limits) == 2
            and all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in limits)
            and limits[0] < limits[1]
        )
        if not ok:
            raise ConfigError(path, "station.turntable.limits", f"expected [min, max] in degrees, got {_show(limits)}")
        lo, hi = float(limits[0]), float(limits[1])
        inside, shown = (lambda d: lo <= d <= hi), f"[{lo:g}, {hi:g}] (station.turntable.limits)"
    else:
        lo, hi = ROTARY_RANGE
        inside, shown = (lambda d: lo <= d < hi), f"[{lo:g}, {hi:g}) for a rotary stage"
    for i, deg in enumerate(orientations):
        if not inside(deg):
            raise ConfigError(path, f"capture.orientations_deg[{i}]", f"expected an angle in {shown}, got {deg:g}")
    if camera.driver == "sim":
        from drivers.sim.lens import FOCUS_RANGE

        for i, f in enumerate(focus_settings):
            if not FOCUS_RANGE[0] <= f <= FOCUS_RANGE[1]:
                raise ConfigError(
                    path,
                    f"focus.settings[{i}]",
                    f"expected a focus in [{FOCUS_RANGE[0]:g}, {FOCUS_RANGE[1]:g}] (the simulated lens), got {f:g}",
                )


def check_port(config: Config) -> None:
    """Fail early, naming the field, when the turntable port cannot be reached.

    A device path (``/dev/...`` or any absolute path) must exist; a URL
    (``socket://``, ``rfc2217://``, ``loop://``...) is left to the driver.
    """
    port = config.station.turntable.port
    if port == EMULATOR_PORT and config.simulation is not None:
        return
    if "://" in port:
        return
    if not os.path.exists(port):
        raise config.error("station.turntable.port", f"expected a reachable serial port, {port!r} does not exist")
