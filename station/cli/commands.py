"""The ``harp`` sub-commands: each name with its one-line help, readable without importing any
command module (``harp --help``, ``harp --version`` and a mistyped command import none of them).

The command ``NAME`` lives in the module ``station.cli.NAME`` (:func:`module_of`), whose
``register(subparsers)`` adds its parser with the help written here (:data:`COMMANDS`).
"""

from __future__ import annotations

COMMANDS: dict[str, str] = {
    "measure": "measure string straightness (d, d_max) in harp photos",
    "calibrate": "fit a lens distortion model from harp shots",
    "undistort": "correct images with a fitted model",
    "evaluate": "measure the residual distortion left by any correction",
    "export": "export a fitted model to OpenCV, ROS, lensfun, mrcal, COLMAP, Kalibr, LCP, Basalt, Metashape, maps, STMap or JSON",
    "session": "run, resume, plan or list calibration sessions",
    "profile": "list, show and export stored lens profiles",
    "qa": "factory QA verdict of a session or a stored lens",
    "live": "live set-up view: focus, exposure, strings and coverage (or one check with --once)",
    "serve": "the factory QA dashboard in the browser (read-only, over the profile store)",
    "reprocess": "re-measure and re-fit archived sessions with the current pipeline (local pool or Dask cluster)",
    "config": "check a station configuration",
    "devices": "cameras and serial ports found on this machine",
    "tca": "lateral chromatic aberration from colour or RAW harp shots",
    "intrinsics": "the camera matrix from board shots, with the harp's distortion held fixed",
    "vignetting": "vignetting (relative illumination, lensfun pa, flat field) from harp shots turned on the turntable",
}
"""Sub-command name -> its one-line help, in the order ``harp --help`` lists them."""


def module_of(name: str) -> str:
    """The module that holds the sub-command ``name``."""
    return f"station.cli.{name}"


def unknown_command(word: str) -> str:
    """The one line for a first word that is no command (said as ``harp: ...``): the closest command named,
    when one is close."""
    import difflib

    close = difflib.get_close_matches(word, COMMANDS, n=1, cutoff=0.6)
    hint = f"did you mean '{close[0]}'?" if close else "'harp --help' lists the commands"
    return f"unknown command '{word}'; {hint}"
