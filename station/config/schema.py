"""The station configuration's schema: the frozen dataclasses a configuration file becomes, each
field declared once with its type, unit, range and meaning.

A configuration file describes one station (camera, turntable, harp), the lens and camera body
being calibrated (their identities and, optionally, the optics an export needs: :class:`Optics`),
what to capture (focus settings, orientations, frames per orientation, exposure), the pipeline
parameters, the QA thresholds and where the profile store lives. Relative paths are relative to
the directory holding the configuration file.

Every key of the file is a field of these dataclasses, declared with :func:`drivers.settings.setting` (its type is
the field's annotation; its unit, range, default and meaning the :class:`drivers.settings.Setting`
in the field's metadata) or a section (:func:`section`: a nested dataclass). The keys of the
camera and turntable sections after ``driver`` are the chosen driver's (its class's ``SETTINGS``,
declared beside the driver), those of ``simulation.emulator`` the Zaber emulator's
(:data:`drivers.sim.zaber_emulator.SETTINGS`). :func:`document` gives the whole file as a tree of
:class:`Section` — what :mod:`station.config.validate` checks, what the README's configuration
reference lists (``scripts/config_reference.py``) and what the fuzz test breaks key by key.
"""

from __future__ import annotations

import dataclasses
import functools
import types
import typing
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from types import MappingProxyType
from typing import Any

from drivers import CAMERA_DRIVERS, TURNTABLE_DRIVERS, driver_settings
from drivers.settings import REQUIRED, SEED_MAX, Setting, fields_of, setting
from drivers.sim.zaber_emulator import SETTINGS as EMULATOR_SETTINGS
from pipeline.fitspec import (
    AUTO,
    CHOICE_FOLDS,
    CHOICE_FOLDS_PLAIN,
    DEGREE_BOUNDS,
    FIELD_AUTO,
    FIELD_CHOICES,
    STRINGS_CHOICES,
    STRINGS_KINKS,
    FitSpec,
    parse_choice,
)
from pipeline.resample import DEFAULT_T
from station.config.errors import ConfigError
from station.equipment import Identity, Optics, optics_keys
from station.store.location import SQLITE, StoreLocation, parse_store

#: turntable ``port`` value meaning "the emulator started by station.session.simulated"
EMULATOR_PORT = "emulator"

OVERLAY_RETENTION = ("all", "failed", "none")
"""Values of ``report.overlays``: which per-orientation overlays a session report keeps (every focus
setting's, only those of a focus setting that failed QA, none)."""


def section(factory: Any = REQUIRED, doc: str = "", *, yaml: str | None = None, drivers: str | None = None) -> Any:
    """A dataclass field that is a section (a nested dataclass) of the configuration file.

    ``factory`` builds its default (None: an optional section that is None when absent;
    :data:`~drivers.settings.REQUIRED`: it must be given); ``drivers`` (``camera`` or ``turntable``)
    says which driver table the section's ``driver`` key names.
    """
    meta = {"section": doc, "yaml": yaml, "drivers": drivers}
    if factory is REQUIRED:
        return field(metadata=meta)
    if factory is None:
        return field(default=None, metadata=meta)
    return field(default_factory=factory, metadata=meta)


# --------------------------------------------------------------------- data
@dataclass(frozen=True)
class DeviceConfig:
    """A driver name plus that driver's own settings (passed to ``from_config``)."""

    driver: str = setting(doc="the driver")
    settings: Mapping[str, Any] = field(default_factory=lambda: MappingProxyType({}), metadata={"driver_settings": 1})

    def as_driver_config(self, **overrides) -> dict:
        """The mapping handed to :func:`drivers.open_camera` / ``open_turntable``."""
        d = {"driver": self.driver, **dict(self.settings)}
        d.update(overrides)
        return d


@dataclass(frozen=True)
class TurntableConfig(DeviceConfig):
    """A turntable driver and its settings; ``port`` and ``steps_per_degree`` are two of the driver's
    keys the station also reads (the simulated station's emulator)."""

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
    positive stage move increases that angle, -1 otherwise. ``shift_direction_deg``: where the turntable axis
    moves in the image when a linear stage carrying the turntable moves forward (two-axis capture,
    ``capture.shift_positions_mm``); the image scale of a stage move is the harp's, the strings' pitch in
    the image over ``string_spacing_mm`` (:func:`station.calibration.axis_shifts_px`).
    """

    string_width_mm: float = setting(doc="the strings' diameter (less than their spacing)", unit="mm", low=0.0,
                                     high=10.0, low_open=True)  # fmt: skip
    string_spacing_mm: float = setting(doc="the distance between neighbouring strings", unit="mm", low=0.0,
                                       high=1000.0, low_open=True)  # fmt: skip
    offset_deg: float = setting(0.0, "the strings' angle in the image at stage 0", "deg", -360.0, 360.0)
    direction: int = setting(1, "+1 when a positive stage move increases the string angle", choices=(1, -1))
    shift_direction_deg: float | None = setting(None, "two-axis capture (capture.shift_positions_mm): the image "
                                                "direction in which the turntable axis moves for a positive "
                                                "linear-stage move, from +x (column) towards +y (row) (null: each "
                                                "position's axis searched, 4 or more orientations)", "deg", -360.0,
                                                360.0)  # fmt: skip

    def expected_angle(self, stage_deg: float) -> float:
        return (self.offset_deg + self.direction * stage_deg) % 180.0


@dataclass(frozen=True)
class StationConfig:
    id: str = setting(doc="the station's name, recorded with every profile")
    camera: DeviceConfig = section(doc="the camera: `driver` and the driver's keys", drivers="camera")
    turntable: TurntableConfig = section(doc="the turntable: `driver` and the driver's keys", drivers="turntable")
    harp: HarpConfig = section(doc="the calibration harp")


@dataclass(frozen=True)
class RetryConfig:
    attempts: int = setting(3, "tries of a device command before the session stops", "", 1, 100)
    backoff_s: float = setting(0.2, "the first wait between tries (doubles after each failure)", "s", 0.0, 60.0)


@dataclass(frozen=True)
class CheckConfig:
    """Acceptance of a captured shot (re-captured when a check fails)."""

    min_lines: int = setting(4, "string edges a shot must show (at most what the harp gives in the image)", "", 1,
                             1000)  # fmt: skip
    angle_tolerance_deg: float = setting(3.0, "largest difference of the strings' angle from the expected one",
                                         "deg", 0.0, 90.0, low_open=True)  # fmt: skip
    max_saturated_fraction: float = setting(0.01, "largest fraction of pixels at the top code value", "", 0.0, 1.0)
    min_dynamic_range: float = setting(0.2, "smallest (p99 - p1) / full scale", "", 0.0, 1.0)
    max_recaptures: int = setting(2, "re-captures of a shot that fails its checks before the session stops", "", 0,
                                  100)  # fmt: skip
    # px: harp live's focus check, the median 10-90 % string edge width (a sharp harp: 1.3-2 px;
    # the live demo's lens 0.17 off its best focus: 4 px); the session itself does not assess focus
    max_edge_width_px: float = setting(3.0, "harp live's focus check: the largest median 10-90 % edge width", "px",
                                       0.0, 100.0, low_open=True)  # fmt: skip


@dataclass(frozen=True)
class CaptureConfig:
    orientations_deg: tuple[float, ...] = setting(doc="turntable angles of the shots (within the turntable's "
                                                  "limits, [0, 360) without them)", unit="deg", low=-3600.0,
                                                  high=3600.0, length=(2, None), unique=True)  # fmt: skip
    frames_per_orientation: int = setting(doc="frames captured at each orientation", low=1, high=1000)
    exposure_us: float = setting(doc="exposure time", unit="µs", low=0.0, high=1e8, low_open=True)
    gain_db: float = setting(0.0, "sensor gain", "dB", -20.0, 60.0)
    settle_s: float = setting(0.0, "wait after each move before capturing", "s", 0.0, 60.0)
    timeout_s: float = setting(5.0, "wait for a frame (more than the exposure)", "s", 0.1, 600.0)
    move_timeout_s: float = setting(60.0, "wait for a turntable move", "s", 1.0, 3600.0)
    shift_positions_mm: tuple[float, ...] = setting((), "two-axis capture: linear-stage positions carrying the "
                                                    "turntable sideways (station.turntable.shift_axis), every "
                                                    "orientation taken at each (none: one axis place)", "mm", -1e5,
                                                    1e5, length=(2, None), unique=True)  # fmt: skip
    twin_deg: float | None = setting(None, "a twin: after the other orientations the turntable returns to this "
                                     "one of orientations_deg (at the first of shift_positions_mm) and takes it "
                                     "again, not fitted; the two shots tell a lens that moved between shots from a "
                                     "term of the lens (QA check twin_move; null: none)", "deg", -3600.0, 3600.0)  # fmt: skip
    checks: CheckConfig = section(CheckConfig, "acceptance of a captured shot")
    retries: RetryConfig = section(RetryConfig, "device commands tried again")

    @functools.cached_property  # (a plan of 100000 orientations asks for one at a time)
    def orientations(self) -> tuple[tuple[float | None, float], ...]:
        """Each orientation of the plan, ``(linear-stage position mm or None, turntable angle deg)``: the
        turntable angles ``orientations_deg`` at each of ``shift_positions_mm`` in turn (the stage moves least),
        or at the one axis place (position None) without them; then the twin (``twin_deg`` at the first place),
        if any. An orientation's index in this tuple is the ``orientation_idx`` of the plan, the frames and the
        manifest."""
        if not self.shift_positions_mm:
            plan = tuple((None, float(a)) for a in self.orientations_deg)
        else:
            plan = tuple((float(p), float(a)) for p in self.shift_positions_mm for a in self.orientations_deg)
        return plan if self.twin_deg is None else (*plan, (plan[0][0], float(self.twin_deg)))

    @functools.cached_property
    def twin(self) -> tuple[int, int] | None:
        """``(first, twin)``: the indices in :attr:`orientations` of the twin's orientation taken first and of the
        twin (the last), None without a twin (or with a ``twin_deg`` that is none of the plan's angles, which the
        configuration check refuses)."""
        if self.twin_deg is None:
            return None
        last = len(self.orientations) - 1
        first = next((o for o in range(last) if self.orientations[o] == self.orientations[last]), None)
        return None if first is None else (first, last)

    @functools.cached_property
    def fitted(self) -> tuple[int, ...]:
        """The indices in :attr:`orientations` of the shots the fit takes: every one but the twin (:attr:`twin`),
        which checks the fit instead."""
        n = len(self.orientations)
        return tuple(range(n - 1 if self.twin_deg is not None else n))

    @functools.cached_property
    def fitted_angles_deg(self) -> tuple[float, ...]:
        """The turntable angle of each fitted shot (:attr:`fitted`), in order."""
        return tuple(self.angles_deg[o] for o in self.fitted)

    def orientation_name(self, o: int) -> str:
        """How a session names orientation ``o`` of its plan to the user: its index, turntable angle, stage position
        (two-axis capture) and whether it is the twin."""
        mm = self.shifts_mm[o]
        where = f"{self.angles_deg[o]:g} deg" + ("" if mm is None else f" at {mm:g} mm")
        return f"orientation {o} ({where}{'' if o in self.fitted else ', the twin'})"

    @functools.cached_property
    def visits(self) -> tuple[int, ...]:
        """Per orientation of :attr:`orientations`, the plan's visit of its pose: 0 the first time, 1 the twin's
        return (a simulated camera renders a return's frames anew, :class:`drivers.protocols.IndexedCapture`)."""
        fitted = frozenset(self.fitted)  # one look-up per orientation, not a scan of the tuple
        return tuple(int(o not in fitted) for o in range(len(self.orientations)))

    @functools.cached_property
    def angles_deg(self) -> tuple[float, ...]:
        """The turntable angle of each orientation of the plan (:attr:`orientations`)."""
        return tuple(a for _, a in self.orientations)

    @functools.cached_property
    def shifts_mm(self) -> tuple[float | None, ...]:
        """The linear-stage position of each orientation of the plan (:attr:`orientations`; None: no stage)."""
        return tuple(p for p, _ in self.orientations)


@dataclass(frozen=True)
class PipelineConfig:
    t: int = setting(DEFAULT_T, "along-edge subsampling: one edge point kept in t (Tang et al. 2012)", "px", 1, 200)
    model: str = setting(AUTO, "what to fit: auto (chosen by cross-validation over the shots) or a fit label "
                         "(radial6+tangential+prism, radial4+tangential, poly5, ...); not given but degree or a "
                         "term given: radial, as older configurations spell it")  # fmt: skip
    # each given term sets the label's (older configurations spell the spec so); None: the label's
    degree: int | None = setting(None, "the model's degree (null: the label's; radial 1..10, poly 3..11)", "",
                                 min(b[0] for b in DEGREE_BOUNDS.values()), max(b[1] for b in DEGREE_BOUNDS.values()))  # fmt: skip
    tangential: bool | None = setting(None, "radial model: decentering terms p1, p2 (null: the label's)")
    prism: bool | None = setting(None, "radial model: thin-prism terms s1..s4 (null: the label's)")
    center_prior: bool | None = setting(None, "radial model: pull the distortion centre towards the image centre "
                                        "(null: the label's)")  # fmt: skip
    bootstrap: int = setting(0, "replicates for the field uncertainty (0: not computed)", "", 0, 10000)
    seed: int = setting(0, "seed of the bootstrap resampling", "", 0, SEED_MAX)
    workers: int = setting(1, "processes for the cross-validation and bootstrap fits", "", 1, 256)
    strings: str = setting(STRINGS_KINKS, "with 3 or more turntable angles: the profile's lens fitted with every "
                           "string's own bend separated and each string's kinks found and modelled (separate-kinks), "
                           "with the bends only (separate) or the lens fitted alone (ignore)",
                           choices=STRINGS_CHOICES)  # fmt: skip
    field: str = setting(FIELD_AUTO, "a residual field on top of the radial model: auto (added when it holds on "
                         "unseen orientations, cross-validated with the strings separated; needs 4 or more string "
                         "orientations) or none", choices=FIELD_CHOICES)  # fmt: skip
    choice_folds: str = setting(CHOICE_FOLDS_PLAIN, "model auto with turntable angles: the held-out shots judged as "
                                "they are (plain) or each fold fitted with the strings' bends separated and its "
                                "held-out shot judged without them (strings-separated)", choices=CHOICE_FOLDS)  # fmt: skip

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


SPEC_TERMS = ("degree", "tangential", "prism", "center_prior")
"""The ``pipeline`` keys that set a fit label's terms (:attr:`PipelineConfig.spec`)."""


def with_model(section: Mapping[str, Any]) -> Mapping[str, Any]:
    """A ``pipeline`` section with the model it means: one that gives a degree or a term (:data:`SPEC_TERMS`)
    without naming a model is an older configuration's spelling of a radial model (``model: radial`` was the
    default until 2026-12-06), and keeps that meaning; a section that gives neither is chosen (``auto``)."""
    if "model" in section or all(section.get(k) is None for k in SPEC_TERMS):
        return section
    return {**section, "model": "radial"}


@dataclass(frozen=True)
class QAConfig:
    max_holdout_d_px: float = setting(0.05, "largest held-out straightness d of a profile", "px", 0.0, 100.0,
                                      low_open=True)  # fmt: skip
    max_distortion_px: float | None = setting(None, "largest correction over the image, modulo homography", "px",
                                              0.0, 100000.0, low_open=True)  # fmt: skip
    max_reference_deviation_px: float | None = setting(None, "largest deviation from the golden reference", "px",
                                                       0.0, 1000.0, low_open=True)  # fmt: skip


@dataclass(frozen=True)
class ReportConfig:
    """What the session report keeps (:mod:`station.qa.report`)."""

    overlays: str = setting("all", "which overlays the session report keeps", choices=OVERLAY_RETENTION)


DEFAULT_BOARD_ANGLES = (0.0, 45.0, 90.0, 135.0, 180.0, 225.0, 270.0, 315.0)
"""Turntable angles of the board views (a board on a tilted wedge on the turntable: each angle turns
the tilt's direction, so the views are tilted every way with one axis)."""

DEFAULT_BOARD_TILTS = (20.0, 40.0)
"""Tilt-axis angles of the board views on a stage with a tilt axis (``intrinsics.placement: stage``)."""

BOARD_MIN_VIEWS = 3
"""The fewest board views a camera matrix is fitted from (:data:`pipeline.intrinsics.MIN_VIEWS`, which
imports cv2: a test holds the two equal)."""


BOARD_PLACEMENTS = ("turntable", "operator", "stage")
"""Who places the board for the camera-matrix stage (``intrinsics.placement``)."""


@dataclass(frozen=True)
class IntrinsicsConfig:
    """The session's camera-matrix stage (issue 23): after each focus setting's distortion is fitted, the
    station takes board views at that focus (the board on a tilted wedge on the turntable, one view per
    angle; or placed by the operator as each view asks, :mod:`pipeline.board_requests`) and fits the camera
    matrix with that distortion held fixed (:mod:`station.intrinsics`)."""

    board: str = setting(doc="the board: charuco:NXxNY:SQUARE_MM:MARKER_MM[:DICT] or chessboard:NXxNY:SQUARE_MM "
                         "(pipeline.board)")  # fmt: skip
    angles_deg: tuple[float, ...] = setting(DEFAULT_BOARD_ANGLES, "turntable angles of the board views (within the "
                                            "turntable's limits)", "deg", -3600.0, 3600.0,
                                            length=(BOARD_MIN_VIEWS, None), unique=True)  # fmt: skip
    min_views: int = setting(BOARD_MIN_VIEWS, "usable board views a camera matrix needs (fewer: the profile is "
                             "stored without one)", "", BOARD_MIN_VIEWS, 1000)  # fmt: skip
    skew: bool = setting(False, "fit the skew too (no export format holds it)")
    placement: str = setting("turntable", "who places the board: the turntable (on a wedge, one view per angle; "
                             "a camera the station can show the board), the operator (each view asked for on the "
                             "terminal and the live page) or the stage (the turntable and its tilt axis, "
                             "station.turntable.tilt_axis: one view per angle and tilt)",
                             choices=BOARD_PLACEMENTS)  # fmt: skip
    views: int = setting(6, "board views asked of the operator (placement: operator)", "", BOARD_MIN_VIEWS,
                         100)  # fmt: skip

    tilts_deg: tuple[float, ...] = setting(DEFAULT_BOARD_TILTS, "tilt-axis angles of the board views, each at "
                                           "every angle of angles_deg (placement: stage)", "deg", -90.0, 90.0,
                                           length=(1, None), unique=True)  # fmt: skip

    @property
    def n_views(self) -> int:
        """Board views per focus setting: one per angle on the turntable, ``views`` by the operator, one per
        angle and tilt on the stage."""
        if self.placement == "operator":
            return self.views
        return len(self.stage_views())

    def stage_views(self) -> list[tuple[float, float | None]]:
        """``(turntable angle, tilt)`` of each view on the turntable (tilt None: the wedge's) or the stage
        (each tilt in turn, at every angle: the tilt axis moves least)."""
        if self.placement == "stage":
            return [(a, t) for t in self.tilts_deg for a in self.angles_deg]
        return [(a, None) for a in self.angles_deg]


@dataclass(frozen=True)
class SimulationConfig:
    """Present only for a simulated station (see :mod:`station.session.simulated`).

    ``lens_spread``: the manufacturing spread of the simulated lens, in units of the population's
    (:func:`drivers.sim.lens.lens_unit`: decentre, tilt, k1 spread, one bad unit in 20), drawn from
    ``lens.serial`` so that every serial is its own reproducible lens; 0 is the nominal demo lens
    for every serial. ``lens_field_px``: the RMS of a residual field each unit carries besides
    (:func:`drivers.sim.lens.lens_field`: smooth, non-parametric, its shape drawn from the serial); 0: none.
    ``lens_centre_sd_px``: a lens whose distortion centre moves between turntable poses
    (:meth:`drivers.sim.camera.SimulatedCamera.lens_at`); 0: a stable lens."""

    harp_offset_deg: float = setting(0.0, "the strings' angle at stage 0 in the simulated world", "deg", -360.0,
                                     360.0)  # fmt: skip
    emulator: Mapping[str, Any] = field(
        default_factory=lambda: MappingProxyType({}), metadata={"emulator_settings": "the Zaber emulator's options"}
    )
    lens_spread: float = setting(0.0, "the simulated lens's manufacturing spread, drawn from lens.serial (0: the "
                                 "nominal demo lens for every serial)", "× the population's spread", 0.0, 5.0)  # fmt: skip
    lens_field_px: float = setting(0.0, "the RMS over the image of a residual field the simulated lens carries "
                                   "besides its radial, tangential and prism terms (smooth, no model's; its shape "
                                   "drawn from lens.serial; 0: none)", "px", 0.0, 1.0)  # fmt: skip
    lens_centre_sd_px: float = setting(0.0, "how far the simulated lens's distortion centre moves between turntable "
                                       "poses, as an image stabiliser or a focus group with play would (a normal "
                                       "draw per pose and axis, this its standard deviation; 0: a stable lens)",
                                       "px", 0.0, 50.0)  # fmt: skip
    shift_direction_deg: float = setting(0.0, "the image direction (from +x, the columns, towards +y, the rows) in "
                                         "which a positive move of the turntable's shift axis carries the turntable "
                                         "axis in the simulated world", "deg", -360.0, 360.0)  # fmt: skip


@dataclass(frozen=True, kw_only=True)
class Config:
    path: Path  # the file it was read from (absolute)
    base_dir: Path  # relative paths are resolved against this
    station: StationConfig = section(doc="the station's devices and harp", yaml="station")
    lens: Identity = section(doc="the lens calibrated (and its optics for exports)", yaml="lens")
    camera_body: Identity = section(doc="the camera body (and its optics for exports)", yaml="camera_body")
    focus_settings: tuple[float, ...] = setting(doc="lens focus positions, in the focus feature's units",
                                                low=-1e9, high=1e9, length=(1, None), unique=True,
                                                yaml="focus.settings")  # fmt: skip
    capture: CaptureConfig = section(doc="what to capture", yaml="capture")
    pipeline: PipelineConfig = section(PipelineConfig, "what to fit", yaml="pipeline")
    qa: QAConfig = section(QAConfig, "the QA thresholds", yaml="qa")
    report: ReportConfig = section(ReportConfig, "the session report", yaml="report")
    store_path: Path | None = setting(None, "the SQLite file of the profile store (null and no url: the per-user "
                                      "store)", yaml="store.path")  # fmt: skip
    store_url: str | None = setting(None, "the store as a URL (sqlite:///FILE or postgresql://...), instead of "
                                    "store.path", yaml="store.url")  # fmt: skip
    sessions_dir: Path = setting(Path("sessions"), "where session directories are created", yaml="store.sessions_dir")
    simulation: SimulationConfig | None = section(None, "present only for a simulated station", yaml="simulation")
    intrinsics: IntrinsicsConfig | None = section(None, "the camera-matrix stage: board views after each focus "
                                                  "setting's fit (absent: no camera matrix measured)",
                                                  yaml="intrinsics")  # fmt: skip
    optics: Optics = field(default_factory=Optics)  # from lens and camera_body
    # a zoom lens (issue 23): the focal lengths a zoom session calibrates, each an ordinary session at
    # every focus setting; () none
    zoom_settings: tuple[float, ...] = setting((), "a zoom session's focal lengths (none: a fixed lens)", "mm", 0.0,
                                               10000.0, low_open=True, length=(2, None), unique=True,
                                               yaml="zoom.settings")  # fmt: skip
    # the camera's zoom feature value at each focal length; () the focal lengths themselves
    zoom_positions: tuple[float, ...] = setting((), "the camera's zoom value at each focal length, in the device's "
                                                "units (none: the focal lengths)", "", -1e9, 1e9,
                                                yaml="zoom.positions")  # fmt: skip
    # the focal length of this session: set in the part of a zoom session that captures it
    focal: float | None = setting(None, "the focal length of this session (a zoom session's part)", "mm", 0.0,
                                  10000.0, low_open=True, yaml="zoom.focal")  # fmt: skip

    @property
    def store(self) -> StoreLocation:
        """Where this station's profile store is (:mod:`station.store.location`)."""
        if self.store_url is not None:
            return parse_store(self.store_url, self.base_dir)
        assert self.store_path is not None
        return StoreLocation(SQLITE, path=self.store_path)

    def error(self, field_path: str, expected: str) -> ConfigError:
        return ConfigError(self.path, field_path, expected)


# --------------------------------------------------------------- the document
@dataclass(frozen=True)
class Section:
    """A mapping of the configuration file: its dotted ``path`` (``""``: the top level), its keys in
    order (a :class:`~drivers.settings.Setting` or a :class:`Section` each), whether it must be given,
    and for a driver's section the table its ``driver`` key names (``camera``, ``turntable``) and, once
    chosen, the driver."""

    path: str
    keys: Mapping[str, Setting | Section]
    required: bool = True
    doc: str = ""
    drivers: str = ""
    driver: str = ""

    def key_path(self, key: str) -> str:
        return f"{self.path}.{key}" if self.path else key

    def with_driver(self, name: str) -> Section:
        """This driver section with the keys of driver ``name`` after ``driver``."""
        keys = dict(self.keys)
        keys.update(driver_settings(DRIVER_TABLES[self.drivers], name))
        return dataclasses.replace(self, keys=MappingProxyType(keys), driver=name)

    def leaves(self) -> list[tuple[str, Setting]]:
        """``(dotted path, setting)`` of every key below, in order."""
        out: list[tuple[str, Setting]] = []
        for key, spec in self.keys.items():
            if isinstance(spec, Section):
                out.extend(spec.leaves())
            else:
                out.append((self.key_path(key), spec))
        return out


DRIVER_TABLES: dict[str, Mapping[str, str]] = {"camera": CAMERA_DRIVERS, "turntable": TURNTABLE_DRIVERS}
"""The driver table a driver section names its driver from (:data:`drivers.CAMERA_DRIVERS`...)."""


def _section_of(cls: type, path: str, required: bool, doc: str, drivers: str = "", extra: Any = ()) -> Section:
    keys: dict[str, Setting | Section] = {}
    for f in dataclasses.fields(cls):
        if "section" in f.metadata:
            sub = typing.get_type_hints(cls)[f.name]
            keys[f.name] = _section_of(
                sub,
                f"{path}.{f.name}" if path else f.name,
                f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING,
                f.metadata["section"],
                f.metadata["drivers"] or "",
            )
        elif "emulator_settings" in f.metadata:
            keys[f.name] = Section(f"{path}.{f.name}", MappingProxyType(dict(EMULATOR_SETTINGS)), False,
                                   f.metadata["emulator_settings"])  # fmt: skip
    for name, s in fields_of(cls).items():
        if name == "driver" and drivers:
            s = dataclasses.replace(s, doc=f"the {drivers} driver", choices=tuple(sorted(DRIVER_TABLES[drivers])))
        keys[name] = s
    keys.update(extra)
    order = [f.name for f in dataclasses.fields(cls)]
    ordered = dict(sorted(keys.items(), key=lambda kv: order.index(kv[0]) if kv[0] in order else len(order)))
    return Section(path, MappingProxyType(ordered), required, doc, drivers)


@functools.cache
def document() -> Section:
    """The configuration file as a tree of :class:`Section` (the driver sections with ``driver`` only:
    :meth:`Section.with_driver` adds a driver's keys)."""
    top: dict[str, Any] = {}
    hints = typing.get_type_hints(Config)
    for f in dataclasses.fields(Config):
        where = f.metadata.get("yaml")
        if where is None:
            continue
        head, _, rest = where.partition(".")
        if "section" in f.metadata:
            extra = {n: s for n, s in fields_of(Optics).items() if n in optics_keys(head)}
            top[head] = _section_of(
                unoptional(hints[f.name]),
                head,
                f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING,
                f.metadata["section"],
                extra=extra,
            )
            continue
        s = fields_of(Config)[f.name]
        if not rest:
            top[head] = s
        else:
            top.setdefault(head, {})[rest] = s
    for head, v in list(top.items()):
        if isinstance(v, dict):
            required = any(s.default is REQUIRED for s in v.values())
            top[head] = Section(head, MappingProxyType(v), required, SECTION_DOCS.get(head, ""))
    return Section("", MappingProxyType(top), True, "the station configuration")


SECTION_DOCS = {
    "focus": "the focus settings of the session",
    "store": "where profiles and sessions are kept",
    "zoom": "a zoom lens: the focal lengths of a zoom session",
}
"""Meaning of the sections that gather :class:`Config` fields (``focus.settings``, ``store.*``)."""


def unoptional(annotation: Any) -> Any:
    if isinstance(annotation, types.UnionType):
        (annotation,) = [a for a in typing.get_args(annotation) if a is not type(None)]
    return annotation
