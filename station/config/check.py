"""Checks of a station configuration that need no device: ``harp config check`` and ``harp session run``.

:func:`station.config.load_config` validates every field on its own (types, ranges, known
keys). :func:`check_config` adds what only the whole configuration tells, without opening
anything:

* **errors** (the session could not succeed, :class:`~station.config.ConfigError`, one line
  naming the field): a session locks focus at each of ``focus.settings`` before it captures,
  so a camera whose driver sets focus only through a configured feature must name it
  (:data:`FOCUS_SETTING`: the GenICam driver needs ``focus_feature``); a configuration that
  can lock focus on nothing is refused before any device is opened or directory created;
* **warnings** (true on this machine now, may be fine where the station runs): a turntable
  port that does not exist here, a store or sessions directory that cannot be created; and a plan
  that puts the strings along the pixel grid at some turntable angle (:func:`grid_warning`), or whose
  fitted shots give fewer string orientations than the model it names needs (:func:`support_warning`) or than a
  residual field needs when ``pipeline.field`` is ``auto`` (:func:`field_warning`: the session would add none);
  and a store URL that holds a password, which every session directory's copy of the configuration would keep
  (:func:`password_warning`).
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

from pipeline.fitspec import FIELD_AUTO
from pipeline.orientations import (
    ORIENTATION_SEPARATION_DEG,
    REQUIRED_ORIENTATIONS_POLY,
    distinct_orientations,
    orientation_shortfall,
)
from station.config.devices import port_missing
from station.config.errors import ConfigError
from station.config.schema import Config
from station.store.errors import StoreError
from station.store.location import without_password

GRID_ANGLE_DEG = 2.0
""":func:`check_config` warns of a plan whose strings are expected within this angle (degrees) of the pixel rows or
columns at some turntable angle (:func:`grid_warning`). A harp set there by hand lies within a degree of the grid,
where an edge's sub-pixel phase drifts slowly along it and the detector's and a Bayer demosaic's phase error stays
after the along-edge smoother: on the realistic renderer 0.03 px RMS at 0.25-1 degree, 0.011 px at 2, 0.002 px at 8
and beyond (``benchmarks/grid_angle.py``, ``benchmarks/RESULTS-edges.md``)."""

GRID_LISTED = 4
"""Turntable angles :func:`grid_warning` names; beyond, it counts them (one line whatever the plan)."""

FOCUS_SETTING = {"aravis": "focus_feature"}
"""Camera drivers that lock focus only through a configured setting: driver -> the setting's key."""


@dataclass(frozen=True)
class ConfigCheck:
    """What :func:`check_config` found: ``errors`` (the session cannot run) and ``warnings``; ``plan_warnings``
    those of the warnings about what the session would do (the plan: strings along the pixel grid, a model or a
    field the shots cannot support; a store password its copy of the configuration would keep), which ``harp
    session run`` repeats before it captures; the others (a port or a directory missing here) the run refuses with
    its own one-line error."""

    errors: list[ConfigError] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    plan_warnings: list[str] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return not self.errors


def check_config(config: Config) -> ConfigCheck:
    """The checks of the module docstring on a loaded configuration."""
    errors: list[ConfigError] = []
    warnings: list[str] = []
    cam = config.station.camera
    key = FOCUS_SETTING.get(cam.driver)
    if key is not None and not cam.settings.get(key):
        settings = ", ".join(f"{f:g}" for f in config.focus_settings)
        errors.append(
            config.error(
                f"station.camera.{key}",
                f"expected the camera's focus feature (a session locks focus at each of focus.settings: "
                f"{settings}); without it the {cam.driver} driver can lock focus on nothing. "
                f"Name the vendor's focus feature (see `harp devices`)",
            )
        )
    if port_missing(config):  # what harp session run refuses (station.config.devices.check_port)
        port = config.station.turntable.port
        warnings.append(
            f"{config.path}: station.turntable.port: {port!r} does not exist on this machine "
            f"(plug the turntable in, or see `harp devices` for the ports found)"
        )
    sessions = Path(config.sessions_dir)
    if sessions.exists() and not sessions.is_dir():
        errors.append(
            config.error(
                "store.sessions_dir",
                f"expected a directory for the sessions, {sessions} is a file; name a directory (it is created)",
            )
        )
    targets = [("store.sessions_dir", config.sessions_dir)]
    if config.store_path is not None:
        targets.append(("store.path", config.store_path.parent))
    for where, directory in targets:
        reason = _not_creatable(Path(directory))
        if reason:
            warnings.append(f"{config.path}: {where}: {directory}: {reason}")
    checks = (grid_warning, support_warning, field_warning, password_warning)
    plan = [w for w in (check(config) for check in checks) if w]
    return ConfigCheck(errors, warnings + plan, plan)


def grid_offset_deg(angle_deg: float) -> float:
    """How far a line at ``angle_deg`` (degrees, any) lies from the nearest pixel row or column: 0..45 degrees."""
    a = angle_deg % 90.0
    return min(a, 90.0 - a)


def grid_warning(config: Config) -> str | None:
    """A warning when the plan expects the strings within :data:`GRID_ANGLE_DEG` of the pixel rows or columns at some
    turntable angle (``station.harp.expected_angle`` of each of ``capture.orientations_deg``), or None."""
    harp = config.station.harp
    near = []
    for stage in config.capture.orientations_deg:
        angle = harp.expected_angle(stage)
        if grid_offset_deg(angle) < GRID_ANGLE_DEG:
            near.append((stage, angle))
    if not near:
        return None
    at = ", ".join(f"{stage:g} deg (strings at {angle:.1f} deg)" for stage, angle in near[:GRID_LISTED])
    if len(near) > GRID_LISTED:
        at += f" and {len(near) - GRID_LISTED} more of the plan's {len(config.capture.orientations_deg)} angles"
    return (
        f"{config.path}: capture.orientations_deg: at turntable {at} the strings lie within {GRID_ANGLE_DEG:g} deg of "
        f"the pixel rows or columns (station.harp.offset_deg {harp.offset_deg:g}), where edges are measured several "
        "times worse (benchmarks/grid_angle.py): mount the harp a few degrees off the grid and set "
        "station.harp.offset_deg, or turn the plan's angles by a few degrees"
    )


def _fitted_directions(config: Config) -> list[float]:
    """The string directions (degrees) the plan's fitted shots are expected to give: ``station.harp.expected_angle``
    of each fitted turntable angle."""
    harp = config.station.harp
    return [harp.expected_angle(a) for a in config.capture.fitted_angles_deg]


def support_warning(config: Config) -> str | None:
    """A warning when the configuration names a model (``pipeline.model``, not ``auto``) that the plan's fitted shots
    cannot support well: fewer distinct string directions (``station.harp.expected_angle`` of each fitted turntable
    angle) than its terms need (:func:`pipeline.orientations.required_orientations`), which the session's profile
    and QA report would say after the session ("not well supported"); None otherwise."""
    try:
        spec = config.pipeline.spec
    except ValueError:  # a label the fit does not allow: load_config refuses it
        return None
    if spec is None:
        return None
    short = orientation_shortfall(spec, _fitted_directions(config))
    if short is None:
        return None
    need, have = short
    return (
        f"{config.path}: pipeline.model: {spec.label} needs >= {need} distinct string orientations "
        f"(>= {ORIENTATION_SEPARATION_DEG:g} deg apart) and the fitted shots of capture.orientations_deg give {have}: "
        "its fit would not be well supported (the profile and the QA report would say so); add turntable angles, or "
        "name a model with fewer terms (or auto)"
    )


def field_warning(config: Config) -> str | None:
    """A warning when ``pipeline.field`` is ``auto`` and the plan's fitted shots give fewer distinct string
    directions (``station.harp.expected_angle`` of each fitted turntable angle) than a residual field needs
    (:data:`pipeline.orientations.REQUIRED_ORIENTATIONS_POLY`): the session would then never add one, and say so only
    in the profile's reason after the session; None otherwise (``field: none`` says no field is wanted)."""
    if config.pipeline.field != FIELD_AUTO:
        return None
    have = distinct_orientations(_fitted_directions(config))
    if have >= REQUIRED_ORIENTATIONS_POLY:
        return None
    return (
        f"{config.path}: pipeline.field: auto adds a residual field only with >= {REQUIRED_ORIENTATIONS_POLY} distinct "
        f"string orientations (>= {ORIENTATION_SEPARATION_DEG:g} deg apart) and the fitted shots of "
        f"capture.orientations_deg give {have}: the session would fit no field; add turntable angles, or set "
        "pipeline.field: none"
    )


def password_warning(config: Config) -> str | None:
    """A warning when ``store.url`` holds a password: a session keeps a verbatim copy of its configuration
    (``config.yaml`` in its directory, read by anyone who can read the session), so the password would be
    copied into every session directory; psycopg reads it from ``~/.pgpass`` or ``$PGPASSWORD`` when
    the URL has none. The warning names the store without the password. None otherwise."""
    if config.store_url is None:
        return None
    try:
        loc = config.store
    except StoreError:  # load_config refuses a URL that is not one
        return None
    if not loc.has_password:
        return None
    return (
        f"{config.path}: store.url: {without_password(config.store_url)} holds a password, and every session "
        "directory keeps a copy of this configuration (config.yaml) with it: take it out of the URL and put it in "
        "~/.pgpass (or $PGPASSWORD), which the store's driver reads when the URL has none"
    )


def _not_creatable(directory: Path) -> str | None:
    """Why ``directory`` could not be created or written by this user (None: it can)."""
    p = directory
    while not p.exists():
        if p.parent == p:
            return "no existing parent directory"
        p = p.parent
    if not p.is_dir():
        return f"{p} is a file, not a directory"
    if not os.access(p, os.W_OK | os.X_OK):
        return f"{p} is not writable by this user"
    return None
