"""Station configuration: YAML validated on load into frozen dataclasses.

The package, one module per job:

* :mod:`station.config.schema` — the dataclasses a configuration becomes (its keys are their fields);
* :mod:`station.config.errors` — :class:`ConfigError`, one line naming the file and the field;
* :mod:`station.config.reader` — the bounded reader (regular files only, size and YAML limits);
* :mod:`station.config.validate` — :func:`load_config` / :func:`parse_config`, every field checked;
* :mod:`station.config.devices` — what the configuration asks of its devices, known without them;
* :mod:`station.config.check` — what only the whole configuration tells (``harp config check``).

Every problem is reported as a :class:`ConfigError` whose message is ONE line
naming the file, the dotted path of the field and what was expected, e.g.::

    configs/demo.yaml: capture.frames_per_orientation: expected an integer >= 1, got 'two'
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
    "Optics",
    "PipelineConfig",
    "QAConfig",
    "ReportConfig",
    "RetryConfig",
    "SimulationConfig",
    "StationConfig",
    "TurntableConfig",
    "check_port",
    "config_keys",
    "keys_of",
    "load_config",
    "optic_problem",
    "optics_keys",
    "parse_config",
]
