"""``harp export MODEL --format FORMAT [-o FILE]``: a harp correction for other software.

Formats (:data:`pipeline.exports.registry.FORMATS`)::

    opencv           OpenCV FileStorage YAML (XML with --xml or -o *.xml), pin-hole model,
                     12 coefficients (rational + thin prism); --coeffs 5, 8, 12 or 14
    opencv-fisheye   the same for cv::fisheye (Kannala-Brandt k1..k4)
    ros              ROS camera_info YAML, rational_polynomial (8); --coeffs 5: plumb_bob
    ros-equidistant  ROS camera_info YAML, equidistant (fisheye k1..k4)
    lensfun          lensfun database XML (ptlens); -o an existing database adds the lens to it
    mrcal            mrcal .cameramodel, LENSMODEL_OPENCV12 (--coeffs 8: OPENCV8)
    colmap           COLMAP cameras.txt: OPENCV (k1 k2 p1 p2) when as exact as the calibration, else
                     FULL_OPENCV (8 coefficients) or OPENCV_FISHEYE when the fisheye model is closer
                     (tried as auto tries it), or THIN_PRISM_FISHEYE when the fisheye was tried and
                     it is 20 % closer in max
    kalibr           Kalibr camchain YAML: pinhole-radtan (k1 k2 p1 p2), or pinhole-equi when the
                     fisheye model is closer (tried as auto tries it)
    lcp              Adobe lens profile (Lightroom, Camera Raw, RawTherapee): PerspectiveModel (OpenCV's 5
                     coefficients) or FisheyeModel (k1 k2), whichever is closer; filed under --focal-mm and
                     --distance (m); -o an existing profile of the lens adds this setting to it
    basalt           Basalt calibration JSON: kb4 (Kannala-Brandt fx fy cx cy k1..k4), camera only
                     (the IMU members are placeholders)
    metashape        Agisoft Metashape calibration XML: frame (k1 k2 k3 p1 p2, Metashape's p1/p2
                     swapped from OpenCV's, cx/cy from the image centre), or fisheye (k1..k4) when closer
    maps             .npz with float32 map_x, map_y for cv2.remap: exactly harp undistort's
    stmap            STMap, 32-bit float OpenEXR (Nuke/Natron): exactly harp undistort's, alpha = has a source
    stmap-redistort  the other STMap of a pair: a render of the corrected image (--overscan) back into the
                     lens' distortion
    json             the harp model file as JSON
    auto             opencv or opencv-fisheye, whichever converts closer (the fisheye model is
                     tried for a wide-angle calibration or when the pin-hole one is less exact
                     than the calibration)

Only the per-pixel maps hold the correction exactly; every other format holds the member of
its family closest to it over the whole image (:mod:`pipeline.exports.fit`). Each export
states its conversion error in the file and here: RMS and max modulo homography, the
residual ``d`` it leaves on a noise-free full-field harp and on the shots the model was
fitted on (a session's stored measurements, or the model file's images measured again when
they are still there unchanged; ``--shots`` names them, ``--no-shots`` skips them), next to
the model's own holdout ``d``. When the conversion error exceeds the holdout ``d``, a
warning says so on stderr.

Lens and camera: a session's profile carries the configuration's lens, camera body and
optics (nominal focal length, pixel pitch or sensor width, crop factor, mount); the options
override them. With the nominal focal length and the pixel pitch (or sensor width) the
camera matrix is nominal; otherwise the file says it is a placeholder scale.

Corrected image (``--size``, ``--scale``, ``--alpha``, ``--overscan``; :mod:`pipeline.corrected_frame`): the
same as ``harp undistort``'s with the same options; the maps and STMaps hold it, the OpenCV, ROS and mrcal
files state the rectification ``R`` and ``newK`` with which their consumer writes it.

Output: the file goes to ``-o FILE`` (written atomically) or to stdout (text formats); the
figures go to stdout with ``-o`` (stderr without, so that stdout stays the file), warnings
to stderr, one line each (``harp export: warning: ...``); ``--json`` (with ``-o``) prints
the figures as one JSON object instead. Exit codes: 0 the export was written (also with
warnings), 2 bad input or an error (one line on stderr, nothing written).
"""

from __future__ import annotations

import json
import math
import sys
from collections.abc import Mapping
from dataclasses import replace
from pathlib import Path

from pipeline.plain import finite_or_none, plain
from pipeline.resample import DEFAULT_T
from station.cli.commands import COMMANDS
from station.cli.frame_options import add_frame_options, frame_choice
from station.cli.say import warn
from station.equipment import optic_problem
from station.errors import InputError
from station.exit_codes import EXIT_OK
from station.files import atomic_write_bytes
from station.lensfun_databases import installed_databases

LENSFUN_TYPE_CHOICES = ("auto", "rectilinear", "fisheye", "equisolid", "stereographic", "orthographic", "fisheye_thoby")
"""``--lensfun-type``: auto and :data:`pipeline.models.lensfun_model.LENSFUN_TYPES`, spelled here so
that parsing the options imports no numerical module (a test checks they agree)."""

FORMAT_CHOICES = (
    "auto",
    "opencv",
    "opencv-fisheye",
    "ros",
    "ros-equidistant",
    "lensfun",
    "mrcal",
    "colmap",
    "kalibr",
    "lcp",
    "basalt",
    "metashape",
    "maps",
    "stmap",
    "stmap-redistort",
    "json",
)
"""The ``--format`` values (the registry's formats other than ``harp``, plus ``auto``)."""

LENS_OPTIONS = {  # option -> (LensInfo field, kind)
    "lens_maker": ("lens_maker", str),
    "lens_model": ("lens_model", str),
    "lens_serial": ("lens_serial", str),
    "camera_maker": ("camera_maker", str),
    "camera_model": ("camera_model", str),
    "mount": ("mount", str),
    "focal_mm": ("focal_mm", float),
    "pixel_pitch_um": ("pixel_pitch_um", float),
    "sensor_width_mm": ("sensor_width_mm", float),
    "crop": ("crop_factor", float),
}


class ExportError(InputError):
    """One-line message for the user."""


def add_export_options(p) -> None:
    """The options ``harp export`` and ``harp profile export`` share."""
    p.add_argument("--format", required=True, choices=FORMAT_CHOICES, help="export format (listed below)")
    p.add_argument("-o", "--out", dest="output", metavar="FILE", help="write here (default: stdout, text formats only)")
    p.add_argument(
        "--coeffs",
        type=int,
        default=None,
        help="opencv/auto: 5, 8, 12 (default) or 14 coefficients; ros: 5 or 8 (default); mrcal: 8 or 12 (default)",
    )
    p.add_argument("--xml", action="store_true", help="opencv: FileStorage XML instead of YAML (also -o *.xml)")
    p.add_argument(
        "--focal-px",
        dest="focal_px",
        type=float,
        default=None,
        help="opencv/ros/mrcal: focal length of the camera matrix in pixels",
    )
    p.add_argument(
        "--lensfun-model", choices=("ptlens", "poly5", "poly3"), default="ptlens", help="lensfun distortion model"
    )
    p.add_argument(
        "--lensfun-type",
        choices=LENSFUN_TYPE_CHOICES,
        default="auto",
        help="lensfun lens type (projection): auto tries the fisheye types too for a wide lens and writes the "
        "closest; a fisheye type needs --focal-mm (lensfun converts the geometry with it)",
    )
    p.add_argument(
        "--lensfun-no-center",
        action="store_true",
        help="lensfun: keep the distortion centre at the image centre (no <center> element)",
    )
    c = p.add_argument_group("colour and light (lensfun: <tca> and <vignetting>; opencv: per-channel coefficients)")
    c.add_argument(
        "--tca",
        metavar="FILE",
        help="the red and blue channels' TCA (a harp tca --out file): lensfun <tca>, or opencv "
        "distortion_coefficients_red / _blue with the same camera matrix",
    )
    c.add_argument("--vignetting", metavar="FILE", help="the lens's vignetting (a harp vignetting --out file)")
    c.add_argument(
        "--lensfun-tca", choices=("poly3", "linear"), default="poly3", help="lensfun TCA model (default poly3)"
    )
    c.add_argument(
        "--aperture",
        metavar="F",
        type=float,
        help="f-number the vignetting shots were taken at (default: the one the vignetting file was written with)",
    )
    c.add_argument(
        "--distance",
        metavar="M",
        type=float,
        help="focus distance (m) the vignetting is filed under (default: the vignetting file's, else 1000), "
        "and the lcp profile (default: none stated)",
    )
    g = p.add_argument_group("lens and camera (override what the profile records)")
    g.add_argument("--lens-maker", metavar="TEXT")
    g.add_argument("--lens-model", metavar="TEXT")
    g.add_argument("--lens-serial", metavar="TEXT")
    g.add_argument("--camera-maker", metavar="TEXT", help="camera body maker")
    g.add_argument("--camera-model", metavar="TEXT", help="camera body model")
    g.add_argument("--mount", metavar="TEXT", help="lens mount as lensfun names it, e.g. 'Canon EF'")
    g.add_argument("--crop", metavar="FACTOR", help="the camera's crop factor (lensfun scales by it)")
    g.add_argument("--focal-mm", metavar="MM", help="nominal focal length (lensfun files the calibration under it)")
    g.add_argument("--pixel-pitch-um", metavar="UM", help="pixel pitch of the images, micrometres")
    g.add_argument("--sensor-width-mm", metavar="MM", help="width of the sensor area the image covers (or a pitch)")
    g.add_argument("--camera-name", metavar="NAME", help="ros: camera_name (default: from the camera body)")
    s = p.add_mutually_exclusive_group()
    s.add_argument(
        "--shots",
        nargs="+",
        metavar="IMAGE",
        help="the shots the model was fitted on, if they moved (their residual d is stated)",
    )
    s.add_argument("--no-shots", action="store_true", help="do not measure the fitting shots again")
    p.add_argument("--json", action="store_true", help="with -o: print the figures as one JSON object")
    add_frame_options(p)


def formats_epilog() -> str:
    """The list of formats of the module docstring, for ``--help``."""
    block = __doc__.split("Formats (:data:`pipeline.exports.registry.FORMATS`)::", 1)[1].split("\n\n")[1]
    return "formats:\n" + block + "\n\nexit codes: 0 written (also with warnings), 2 bad input or an error"


def register(subparsers) -> None:
    import argparse

    p = subparsers.add_parser(
        "export",
        epilog=formats_epilog(),
        formatter_class=argparse.RawDescriptionHelpFormatter,
        help=COMMANDS["export"],
        description=(
            "Export a harp model file for other software (OpenCV pin-hole or fisheye, ROS camera_info, "
            "lensfun, mrcal, COLMAP, Kalibr, Basalt, Metashape, per-pixel maps, STMap, JSON), stating the conversion error in pixels."
        ),
    )
    p.add_argument("model", metavar="MODEL", help="harp model file (from harp calibrate or a session)")
    add_export_options(p)
    p.set_defaults(func=run)


# ------------------------------------------------------------------ options
def lens_overrides(args) -> dict:
    """The :class:`~pipeline.exports.lens.LensInfo` fields the options set (checked; ExportError)."""
    out = {}
    for opt, (name, kind) in LENS_OPTIONS.items():
        raw = getattr(args, opt, None)
        if raw is None:
            continue
        flag = "--" + opt.replace("_", "-")
        if kind is float:
            try:
                value = float(raw)
            except ValueError:
                raise ExportError(f"{flag}: expected a number, got {raw!r}") from None
            problem = optic_problem(name, value)
            if problem is not None:
                raise ExportError(f"{flag}: expected {problem}, got {raw}")
        else:
            value = str(raw)
            if not value.strip():
                raise ExportError(f"{flag}: expected a non-empty text")
        out[name] = value
    if "pixel_pitch_um" in out and "sensor_width_mm" in out:
        raise ExportError("--pixel-pitch-um and --sensor-width-mm are alternatives: give one")
    return out


def export_options(args, existing: bytes | None = None, existing_name: str = "<existing>"):
    """The :class:`~pipeline.exports.source.ExportOptions` of the parsed options."""
    from pipeline.exports.source import ExportOptions  # defers scipy, yaml

    if args.focal_px is not None and not (math.isfinite(args.focal_px) and args.focal_px > 0):
        raise ExportError(f"--focal-px: expected a focal length > 0 px, got {args.focal_px:g}")
    xml = bool(args.xml or (args.output and Path(args.output).suffix.lower() == ".xml"))
    installed: tuple[tuple[str, str], ...] = ()
    if args.format == "lensfun":
        installed = installed_databases(exclude=args.output)
    focus_m = getattr(args, "distance", None) if args.format == "lcp" else None  # checked with --aperture
    return ExportOptions(
        coeffs=args.coeffs,
        focal_px=args.focal_px,
        xml=xml,
        lensfun_model=args.lensfun_model,
        lensfun_center=not args.lensfun_no_center,
        lensfun_type=args.lensfun_type,
        lensfun_tca=args.lensfun_tca,
        camera_name=args.camera_name,
        existing=existing,
        existing_name=existing_name,
        installed_lensfun=installed,
        focus_distance_m=focus_m,
        frame=frame_choice(args),
    )


def _existing_lensfun(args) -> bytes | None:
    """The database (lensfun) or lens profile (lcp) at ``-o`` when it is one (these exports add to it)."""
    from pipeline.exports.registry import FORMATS  # defers scipy, yaml

    if args.format not in ("lensfun", "lcp") or not args.output or not Path(args.output).is_file():
        return None
    try:
        data = Path(args.output).read_bytes()
    except OSError as exc:
        raise ExportError(f"{args.output}: cannot read ({exc.strerror or exc})") from None
    return data if FORMATS[args.format].sniff(data) else None


# ------------------------------------------------------------------- export
def export_profile(
    args, profile, *, model_dir=None, what: str | None = None, edges=None, stamp=None
) -> tuple[object, dict]:
    """Export ``profile`` as the options ask: ``(Export, figures)``; the file is not written.

    ``edges``: the fitting shots' :class:`~station.export_source.FittingEdges` when the
    caller knows them (default: found from the profile, unless the options say otherwise);
    ``stamp``: the lines the file states first (default: the profile's FAILED QA stamp, if any).

    Raises ExportError (one line) on bad options or a model the format cannot take.
    """
    from pipeline.exports.registry import FORMATS, write_export  # defers scipy, yaml
    from station.export_source import export_source  # defers scipy, yaml

    if args.json and not args.output:
        raise ExportError("--json needs -o FILE (without it stdout is the exported file)")
    if args.format in FORMATS and FORMATS[args.format].binary and not args.output:
        raise ExportError(f"--format {args.format} writes a binary file: give -o FILE{FORMATS[args.format].suffix}")
    lens = lens_overrides(args)
    existing = _existing_lensfun(args)
    options = export_options(args, existing, str(args.output))
    edges = _fitting_edges(args, profile, model_dir, edges)
    source = export_source(profile, lens=lens, edges=edges, stamp=stamp)
    left_out: list[str] = []
    stored = {**dict(profile.details.get("colour") or {}), "aperture": profile.optics.aperture}
    colour = colour_correction(args, source.width, source.height, stored, left_out)
    if colour is not None:
        source = replace(source, colour=colour)
    try:
        ex = write_export(args.format, source, options)
    except ValueError as exc:
        raise ExportError(f"{what}: {exc}" if what else str(exc)) from None
    if left_out:
        ex = replace(ex, warnings=(*ex.warnings, *left_out))
    return ex, figures(ex, source, edges)


TCA_FORMATS = ("lensfun", "opencv")
"""The formats that hold the TCA (``--tca``): lensfun's ``<tca>``, OpenCV's per-channel coefficients."""
VIGNETTING_FORMATS = ("lensfun",)
"""The formats that hold the vignetting (``--vignetting``)."""


def colour_correction(args, width: int, height: int, stored=None, left_out: list[str] | None = None):
    """The :class:`~pipeline.exports.colour.ColourCorrection` of ``--tca`` and ``--vignetting`` (None without
    them); ExportError (one line) for a format that holds neither, a setting that is not positive, a file
    that cannot be read or is for another image size.

    ``stored``: the profile's own TCA and vignetting (``details["colour"]``, a colour camera's session:
    :mod:`station.session.colour`) and its f-number (``"aperture"``: the configuration's ``lens.aperture``),
    exported where the format holds them and no file is given (a file overrides); a stored vignetting without
    an f-number (neither ``--aperture`` nor the profile's) is left out, why appended to ``left_out`` (the
    export's warnings)."""
    tca_path, vig_path = getattr(args, "tca", None), getattr(args, "vignetting", None)
    for flag, value in (("--aperture", args.aperture), ("--distance", args.distance)):
        if value is not None and not (math.isfinite(value) and value > 0):
            raise ExportError(f"{flag}: expected a positive number, got {value:g}")
    if tca_path is None and vig_path is None:
        return _stored_colour(args, width, height, stored, left_out)
    if tca_path is not None and args.format not in TCA_FORMATS:
        raise ExportError(
            f"--tca: the {args.format} format holds no TCA; export it with --format lensfun (<tca>) or opencv "
            "(per-channel coefficients)"
        )
    if vig_path is not None and args.format not in VIGNETTING_FORMATS:
        raise ExportError(
            f"--vignetting: the {args.format} format holds no vignetting; export it with --format lensfun, or "
            "write the flat-field image with harp vignetting --flat-field"
        )
    from pipeline.exports.colour import DEFAULT_DISTANCE_M, ColourCorrection  # defers scipy
    from station.colour import read_tca_file  # defers scipy
    from station.vignetting import read_vignetting_file  # defers scipy

    tca = None if tca_path is None else read_tca_file(tca_path, width, height)
    fit, aperture, distance = None, None, None
    if vig_path is not None:
        fit, aperture, distance = read_vignetting_file(vig_path, width, height)
    aperture = args.aperture if args.aperture is not None else aperture
    distance = args.distance if args.distance is not None else distance
    if fit is not None and aperture is None:
        raise ExportError(
            f"--vignetting {vig_path}: lensfun files a vignetting under the f-number it was measured at: give "
            "--aperture F (or write the file with harp vignetting --focal-mm MM --aperture F)"
        )
    return ColourCorrection(tca, fit, aperture, DEFAULT_DISTANCE_M if distance is None else distance)


def _stored_colour(args, width: int, height: int, stored, left_out: list[str] | None):
    """:func:`colour_correction` from the profile's stored documents alone (None: none the format holds)."""
    stored = stored if isinstance(stored, Mapping) else {}
    tca_doc, vig_doc = stored.get("tca"), stored.get("vignetting")
    tca_doc = tca_doc if isinstance(tca_doc, dict) and "channels" in tca_doc else None
    vig_doc = vig_doc if isinstance(vig_doc, dict) and "fit" in vig_doc else None
    tca_doc = tca_doc if args.format in TCA_FORMATS else None
    vig_doc = vig_doc if args.format in VIGNETTING_FORMATS else None
    if tca_doc is None and vig_doc is None:
        return None
    from pipeline.exports.colour import DEFAULT_DISTANCE_M, ColourCorrection  # defers scipy
    from station.colour import tca_fields  # defers scipy
    from station.vignetting import vignetting_fit_of  # defers scipy

    where = "the profile's stored colour"
    tca = None if tca_doc is None else tca_fields(tca_doc, f"{where} (tca)", width, height)
    fit, aperture, distance = None, None, None
    if vig_doc is not None:
        fit, aperture, distance = vignetting_fit_of(vig_doc, f"{where} (vignetting)", width, height)
    aperture = next((a for a in (args.aperture, aperture, stored.get("aperture")) if a is not None), None)
    distance = args.distance if args.distance is not None else distance
    if fit is not None and aperture is None:
        if left_out is not None:
            left_out.append(
                "the profile's vignetting is left out: lensfun files a vignetting under the f-number it was "
                "measured at; give --aperture F (or lens.aperture in the station configuration)"
            )
        fit = None
    if tca is None and fit is None:
        return None
    return ColourCorrection(tca, fit, aperture, DEFAULT_DISTANCE_M if distance is None else distance)


def _fitting_edges(args, profile, model_dir, known):
    """The fitting shots' edges an export states its residual d on: none for the json format; else
    ``known`` when the caller gave them; none with ``--no-shots``; the ``--shots`` measured; else
    found from the profile (:func:`station.export_source.fitting_edges`)."""
    from station.export_source import FittingEdges, fitting_edges, measured_edges  # defers scipy, yaml

    if args.format == "json":
        return FittingEdges(None, "not used by the json format")
    if known is not None:
        return known
    if args.no_shots:
        return FittingEdges(None, "not measured (--no-shots)")
    if args.shots:
        try:
            model = f"the model {args.model}" if getattr(args, "model", None) else "the profile"
            return measured_edges(args.shots, profile.provenance.t or DEFAULT_T, (profile.width, profile.height), model)
        except ValueError as exc:
            raise ExportError(str(exc)) from None
    return fitting_edges(profile, model_dir)


def figures(ex, source, edges) -> dict:
    """The figures of an export as plain data (``--json``, and the lines printed)."""
    err = ex.error
    return {
        "format": ex.format,
        "conversion": None if err is None else plain(err.to_dict()),
        "holdout_d": finite_or_none(source.holdout_d),
        "fitting_shots": {"source": edges.source, "n_shots": edges.n_shots, "used": edges.edges is not None},
        "notes": list(ex.notes),
        "warnings": list(ex.warnings),
    }


def _px(v) -> str:
    return "-" if v is None else f"{v:.4f} px"


def figure_lines(fig: dict) -> list[str]:
    """The figures as the lines printed on the terminal."""
    lines = []
    c, fmt = fig["conversion"], fig["format"]
    if c is not None:
        lines.append(
            f"conversion error ({fmt}): RMS {c['rms_mod_h_px']:.4f} px, max {c['max_mod_h_px']:.4f} px modulo "
            f"homography; 4-corner normalised: RMS {c['rms_px']:.4f} px, max {c['max_px']:.4f} px "
            f"({c['n_points']} points over the whole image)"
        )
        shots = fig["fitting_shots"]
        if c.get("shots_d_px") is not None:
            on_shots = (
                f"{_px(c['shots_d_px'])} on the fitting shots (the harp correction: {_px(c['model_shots_d_px'])}; "
                f"{shots['source']})"
            )
        else:
            on_shots = f"not stated on the fitting shots ({shots['source']})"
        lines.append(
            f"residual d ({fmt}): {_px(c['d_px'])} on a noise-free full-field harp, {on_shots}; "
            f"the model's own holdout d: {_px(fig['holdout_d']) if fig['holdout_d'] is not None else 'not recorded'}"
        )
    lines += fig["notes"]
    return lines


def write_output(args, ex) -> None:
    """Write the export to ``-o`` atomically, or its text to stdout (ExportError on failure)."""
    if args.output:
        try:
            atomic_write_bytes(args.output, ex.data)
        except OSError as exc:
            raise ExportError(f"cannot write {args.output}: {exc.strerror or exc}") from None
    else:
        sys.stdout.write(ex.data.decode("utf-8"))
        sys.stdout.flush()


def report(args, ex, fig: dict, prog: str) -> None:
    """Print what was written, the figures and the warnings (see the module docstring)."""
    for w in ex.warnings:
        warn(prog, w)
    if args.json:
        print(json.dumps({"output": str(args.output), **fig}))
        return
    out = sys.stdout if args.output else sys.stderr
    if args.output:
        print(f"wrote {args.output} ({ex.format})", file=out)
    for line in figure_lines(fig):
        print(line, file=out)


def run(args) -> int:
    from pipeline.model_file import read_model_file  # defers yaml
    from station.profile import Profile  # defers yaml

    try:
        mf = read_model_file(args.model)
        profile = Profile.from_model_file(mf)
        ex, fig = export_profile(args, profile, model_dir=Path(args.model).parent)
        write_output(args, ex)
    except ValueError as exc:  # a model file that cannot be read or exported (an InputError goes on)
        raise ExportError(str(exc)) from None
    report(args, ex, fig, "harp export")
    return EXIT_OK
