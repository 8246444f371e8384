"""The station configuration's schema: the frozen dataclasses a configuration file becomes.

A configuration file describes one station (camera, turntable, harp), the
lens and camera body being calibrated (their identities and, optionally, the
optics an export needs: :class:`Optics`), what to capture (focus settings,
orientations, frames per orientation, exposure), the pipeline parameters,
the QA thresholds and where the profile store lives. Relative paths are
relative to the directory holding the configuration file.

The keys each section accepts are the fields of its dataclass (:func:`keys_of`;
the top level, ``focus`` and ``store`` from :class:`Config`'s field metadata,
:func:`config_keys`), so a field added to a dataclass is a key of the file.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from types import MappingProxyType
from typing import Any

from pipeline.fitspec import FitSpec, parse_choice
from pipeline.resample import DEFAULT_T
from station.config.errors import ConfigError
from station.equipment import Identity, Optics
from station.store.location import SQLITE, StoreLocation, parse_store

#: turntable ``port`` value meaning "the emulator started by station.session.simulated"
EMULATOR_PORT = "emulator"


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
    model: str = "radial"  # a fit label (pipeline.fitspec.parse: radial4+tangential, poly5) or auto
    # each given term sets the label's (older configurations spell the spec so); None: the label's
    degree: int | None = None
    tangential: bool | None = None  # radial model: decentering terms p1, p2
    prism: bool | None = None  # radial model: thin-prism terms s1..s4
    center_prior: bool | None = None  # radial model: pull the distortion centre towards the image centre
    bootstrap: int = 0  # replicates for the field uncertainty (0: not computed)
    seed: int = 0  # of the bootstrap resampling
    workers: int = 1  # processes for the cross-validation / bootstrap fits

    @property
    def spec(self) -> FitSpec | None:
        """What to fit (:class:`pipeline.fitspec.FitSpec`): ``model`` read by
        :func:`pipeline.fitspec.parse_choice` (None for ``auto``: chosen by cross-validation)
        with the terms given beside it; the radial-only terms are ignored for ``poly``.
        ValueError (one line) for a label or degree the fit does not allow."""
        spec = parse_choice(self.model)
        if spec is None:
            return None
        terms = {"degree": self.degree}
        if spec.kind == "radial":
            terms.update(tangential=self.tangential, prism=self.prism, center_prior=self.center_prior)
        return replace(spec, **{k: v for k, v in terms.items() if v is not None})


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
    for every serial; its ``range`` metadata is what the file may give."""

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
    # a zoom lens (issue 23): the focal lengths (mm, > 0, >= 2 distinct) a zoom session calibrates, each an
    # ordinary session at every focus setting; () none
    zoom_settings: tuple[float, ...] = field(default=(), metadata={"yaml": "zoom.settings"})
    # the camera's zoom feature value at each focal length (device units: the simulator's are mm,
    # V4L2 zoom_absolute's and GenICam Zoom's the device's); () the focal lengths themselves
    zoom_positions: tuple[float, ...] = field(default=(), metadata={"yaml": "zoom.positions"})
    # the focal length (mm, > 0) of this session: set in the part of a zoom session that captures it
    focal: float | None = field(default=None, metadata={"yaml": "zoom.focal"})

    @property
    def store(self) -> StoreLocation:
        """Where this station's profile store is (:mod:`station.store.location`)."""
        if self.store_url is not None:
            return parse_store(self.store_url, self.base_dir)
        assert self.store_path is not None
        return StoreLocation(SQLITE, path=self.store_path)

    def error(self, field_path: str, expected: str) -> ConfigError:
        return ConfigError(self.path, field_path, expected)


def keys_of(cls: type) -> tuple[str, ...]:
    """The YAML keys of a section: the fields of its dataclass, in order."""
    return tuple(f.name for f in dataclasses.fields(cls))


def config_keys(section: str = "") -> tuple[str, ...]:
    """The keys of the top level (``""``) or of ``focus`` / ``store`` / ``zoom``, from :class:`Config`'s field metadata."""
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
