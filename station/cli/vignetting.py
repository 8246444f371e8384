"""``harp vignetting IMAGE... --angles A... [--model FILE] [--flat-field FILE] [--json] [-o FILE]``: vignetting.

The lens's relative illumination from the back-lit sheet between the strings of harp shots
(linear images, or camera RAW files read by LibRaw: the green plane of the mosaic, black level
subtracted, not demosaiced) taken at several turntable angles (:mod:`station.vignetting`): the back-light's own
unevenness turns with the harp, the lens's vignetting does not, so the angles (one per image,
degrees, counter-clockwise in the image) separate the two. A distortion model file
(``--model``, from ``harp calibrate``) places the samples on the harp. Printed: the relative
illumination at the centre, the middles of the edges and the corners (the fit and lensfun's
``pa`` model), its range over the image, the back-light's unevenness, lensfun's ``pa``
coefficients ``k1 k2 k3`` with their conversion error, per image the edges, samples and
exposure. ``--json`` prints one JSON object (what ``--out`` writes, as YAML or JSON by the
suffix). ``--flat-field`` writes the flat-field image, the whole image size: a shot divided by
it is corrected.

Bad input (an angle count that is not one per image, fewer than two shots, angles that do not
separate the back-light from the lens, an unreadable image or RAW file, a model for another size): one line
on stderr, exit 2, nothing written.
"""

from __future__ import annotations

import json
from pathlib import Path

from pipeline.resample import DEFAULT_T
from station.cli.commands import COMMANDS
from station.cli.inputs import positive_int
from station.errors import InputError
from station.exit_codes import EXIT_OK
from station.files import atomic_write_bytes, atomic_write_text
from station.tables import is_terminal, print_table
from station.vignetting import flat_field_tiff, vignetting_document, vignetting_of

TIFF_SUFFIXES = (".tif", ".tiff")


def register(subparsers) -> None:
    p = subparsers.add_parser("vignetting", help=COMMANDS["vignetting"], description=__doc__.split("\n\n")[0])
    p.add_argument(
        "images",
        metavar="IMAGE",
        nargs="+",
        help="linear harp shots (PGM/PNG/TIFF, 16-bit best, or camera RAW files: their green plane), harp turned between",
    )
    p.add_argument(
        "--angles",
        metavar="A",
        type=float,
        nargs="+",
        required=True,
        help="the turntable angle of each image, degrees (one per image, in order)",
    )
    p.add_argument("--model", metavar="MODEL.yaml", help="distortion model file (harp calibrate) placing samples")
    p.add_argument(
        "--axis",
        metavar=("X", "Y"),
        type=float,
        nargs=2,
        help="the turntable axis in the image, pixels (default the image centre)",
    )
    p.add_argument(
        "--flat-field",
        metavar="FILE.tiff",
        help="write the flat-field image (divide a shot by it): a TIFF of the whole image size, see --flat-field-depth",
    )
    p.add_argument(
        "--flat-field-depth",
        type=int,
        choices=(32, 16),
        default=32,
        help="32 (default): 32-bit float relative illumination V, 1.0 at the image centre; "
        "16: 16-bit integers round(65535 V / max V), the brightest pixel 65535",
    )
    p.add_argument("--focal-mm", type=float, help="focal length for lensfun's <vignetting> element (with --aperture)")
    p.add_argument("--aperture", type=float, help="f-number for lensfun's <vignetting> element")
    p.add_argument(
        "--distance", type=float, default=1000.0, help="focus distance (m) for lensfun's element (default 1000)"
    )
    p.add_argument(
        "-t", "--t", type=positive_int, default=DEFAULT_T, help=f"along-edge subsampling (default {DEFAULT_T})"
    )
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("-o", "--out", metavar="FILE", help="write the fit and lensfun's pa terms (.yaml or .json)")
    p.set_defaults(func=run)


def _check_options(args) -> tuple[float, float, float] | None:
    """The options that need no image, checked before any is read."""
    if args.flat_field and Path(args.flat_field).suffix.lower() not in TIFF_SUFFIXES:
        raise InputError(f"--flat-field {args.flat_field}: the flat field is a TIFF: give a name ending in .tiff")
    if args.out and Path(args.out).suffix.lower() not in (".yaml", ".yml", ".json"):
        raise InputError(f"--out {args.out}: give a name ending in .yaml or .json")
    if (args.focal_mm is None) != (args.aperture is None):
        raise InputError("--focal-mm and --aperture go together (lensfun's <vignetting> element needs both)")
    if args.focal_mm is None:
        return None
    if not (args.focal_mm > 0 and args.aperture > 0 and args.distance > 0):
        raise InputError("--focal-mm, --aperture and --distance must be positive")
    return (args.focal_mm, args.aperture, args.distance)


def run(args) -> int:
    setting = _check_options(args)
    shots, model, fit, pa = vignetting_of(
        args.images, args.angles, t=args.t, model_path=args.model, axis=tuple(args.axis) if args.axis else None
    )
    doc = vignetting_document(fit, pa, shots, model_path=args.model, model=model, lensfun_setting=setting)
    flat = None
    if args.flat_field:
        data, scale = flat_field_tiff(fit, args.flat_field_depth)
        encoding = "float32 V" if args.flat_field_depth == 32 else f"uint16 round({scale:.6g} V)"
        doc["flat_field"] = {"path": args.flat_field, "depth": args.flat_field_depth, "scale": scale}
        flat = (data, encoding)
    if args.out:
        out = Path(args.out)
        if out.suffix.lower() == ".json":
            text = json.dumps(doc, indent=2) + "\n"
        else:
            import yaml

            text = yaml.safe_dump(doc, sort_keys=False)
        atomic_write_text(out, text)
    if flat is not None:
        atomic_write_bytes(args.flat_field, flat[0])
    if args.json:
        print(json.dumps(doc))
        return EXIT_OK
    _print(doc)
    if args.out:
        print(f"wrote {args.out}")
    if flat is not None:
        print(f"wrote {args.flat_field} ({fit.width}x{fit.height}, {flat[1]})")
    return EXIT_OK


def _print(doc: dict) -> None:
    columns = ("image", "angle (deg)", "edges", "samples", "exposure")
    rows = [
        (i["path"], f"{i['angle_deg']:g}", str(i["edges"]), str(i["samples"]), f"{i['exposure']:.4f}")
        for i in doc["images"]
    ]
    print_table(columns, rows, title="shots", right=columns[1:])
    if not is_terminal():
        print()
    ri = doc["relative_illumination"]
    columns = ("where", "x (px)", "y (px)", "relative illumination", "lensfun pa")
    rows = [
        (p["where"], f"{p['x']:g}", f"{p['y']:g}", f"{p['fit']:.4f}", f"{p['lensfun_pa']:.4f}") for p in ri["points"]
    ]
    print_table(columns, rows, title="relative illumination (1 at the centre)", right=columns[1:])
    if not is_terminal():
        print()
    lf = doc["lensfun"]
    print(f"relative illumination over the image: {ri['min']:.4f} to {ri['max']:.4f}")
    print(
        f"back-light uneven by {100 * doc['backlight_unevenness']:.1f} % (max/min over the image), separated by the "
        f"turntable; fit residual {100 * doc['residual_rms']:.2f} % RMS"
    )
    print(
        f"lensfun pa: k1 {lf['k1']:.6g}, k2 {lf['k2']:.6g}, k3 {lf['k3']:.6g}; conversion error "
        f"{100 * lf['conversion_error']['rms']:.3f} % RMS, {100 * lf['conversion_error']['max']:.3f} % max"
    )
    if "element" in lf:
        attrs = " ".join(f'{k}="{v}"' for k, v in lf["element"].items())
        print(f"lensfun: <vignetting {attrs}/>")
