"""Station configuration: YAML validated on load into frozen dataclasses.

The package, one module per job:

* :mod:`station.config.schema` — the dataclasses a configuration becomes, each key declared once with its
  type, unit, range and meaning (:func:`drivers.settings.setting`); :func:`document`, the file as a tree;
* :mod:`station.config.errors` — :class:`ConfigError`, one line naming the file and the field;
* :mod:`station.config.reader` — the bounded reader (regular files only, size and YAML limits);
* :mod:`station.config.validate` — :func:`load_config` / :func:`parse_config`, the one validator;
* :mod:`station.config.devices` — the drivers created (not opened), what the devices allow;
* :mod:`station.config.check` — what only the whole configuration tells (``harp config check``);
* :mod:`station.config.reference` — the configuration reference of the README, from the schema.

Every problem is reported as a :class:`ConfigError` whose message is ONE line
naming the file, the dotted path of the field, the value and what is allowed, e.g.::

    configs/demo.yaml: capture.timeout_s: expected a number in [0.1, 600] s, got 0.001
"""

from station.config.devices import ROTARY_RANGE, check_port
from station.config.errors import ConfigError
from station.config.schema import (
    EMULATOR_PORT,
    OVERLAY_RETENTION,
    CaptureConfig,
    CheckConfig,
    Config,
    DeviceConfig,
    HarpConfig,
    IntrinsicsConfig,
    PipelineConfig,
    QAConfig,
    ReportConfig,
    RetryConfig,
    Section,
    SimulationConfig,
    StationConfig,
    TurntableConfig,
    document,
)
from station.config.validate import load_config, parse_config
from station.equipment import Identity, Optics, optic_problem, optics_keys

__all__ = [
    "EMULATOR_PORT",
    "OVERLAY_RETENTION",
    "ROTARY_RANGE",
    "CaptureConfig",
    "CheckConfig",
    "Config",
    "ConfigError",
    "DeviceConfig",
    "HarpConfig",
    "Identity",
    "IntrinsicsConfig",
    "Optics",
    "PipelineConfig",
    "QAConfig",
    "ReportConfig",
    "RetryConfig",
    "Section",
    "SimulationConfig",
    "StationConfig",
    "TurntableConfig",
    "check_port",
    "document",
    "load_config",
    "optic_problem",
    "optics_keys",
    "parse_config",
]
