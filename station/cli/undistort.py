"""``harp undistort MODEL IMAGE... -o DIR``: write distortion-corrected images.

Each image is resampled through the model's undistortion maps
(:func:`pipeline.undistort_maps.fast_undistortion_maps`, computed once per
image size and cached) with ``cv2.remap``; the output keeps the input's file
format, channels and bit depth, under the same file name in ``DIR``. The
model's image size must match the images'. An image that cannot be read or has
another size is named on stderr (one line) and skipped; the others are still
corrected. Exit 0 on success, 2 on bad input.

``--size WxH``, ``--scale S``, ``--alpha A``, ``--overscan`` choose the corrected image
(:mod:`pipeline.corrected_frame`; default: the photo's size and scale, its centre kept): the same
as the exports' (maps, STMaps, and the ``R`` / ``newK`` of the OpenCV, ROS and mrcal files) with the
same options.

``--tca FILE`` (a ``harp tca --out`` file) corrects lateral chromatic aberration too:
green through the model, red and blue each through its own correction, the model after
the channel's TCA field (:class:`pipeline.models.tca_model.ChannelModel`,
:math:`U_c(x) = U_g(T_c(x))`), so that the three channels of the corrected image
coincide. It needs colour images (BGR as OpenCV reads them); a grey one is refused.
"""

from __future__ import annotations

import time
from pathlib import Path

import cv2
import numpy as np

from pipeline.corrected_frame import corrected_frame
from pipeline.model_file import read_model_file
from pipeline.models.tca_model import ChannelModel
from pipeline.undistort_maps import DEFAULT_STEP_PX, fast_undistortion_maps
from station.cli.commands import COMMANDS
from station.cli.frame_options import add_frame_options, frame_choice
from station.cli.say import say
from station.colour import read_tca_file
from station.errors import InputError
from station.exit_codes import EXIT_ERROR, EXIT_OK
from station.files import atomic_write_bytes
from station.inputs import read_image

INTERPOLATIONS = {"linear": cv2.INTER_LINEAR, "cubic": cv2.INTER_CUBIC, "lanczos": cv2.INTER_LANCZOS4}
WRITABLE = (".pgm", ".ppm", ".pnm", ".png", ".tif", ".tiff", ".jpg", ".jpeg", ".bmp")


class UndistortError(InputError):
    """One-line message for the user."""


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "undistort",
        help=COMMANDS["undistort"],
        description=("Write distortion-corrected images (same format, channels and bit depth) into DIR."),
    )
    p.add_argument("model", metavar="MODEL", help="harp model file")
    p.add_argument("images", metavar="IMAGE", nargs="+", help="distorted images")
    p.add_argument(
        "-o", "--out", dest="output_dir", metavar="DIR", required=True, help="directory for corrected images"
    )
    p.add_argument(
        "--interpolation",
        choices=sorted(INTERPOLATIONS),
        default="lanczos",
        help="resampling kernel (default lanczos: on a synthetic harp it keeps corrected strings "
        "straight to 0.001 px where cubic leaves 0.008 px and linear 0.013 px)",
    )
    p.add_argument("--overwrite", action="store_true", help="replace existing files in DIR")
    p.add_argument(
        "--tca",
        metavar="FILE",
        help="also correct lateral chromatic aberration: red and blue through their own fields (a harp tca --out file)",
    )
    add_frame_options(p)
    p.set_defaults(func=run)


def undistort_image(img: np.ndarray, maps, interpolation=cv2.INTER_LANCZOS4) -> np.ndarray:
    """Corrected image (the maps' size, the input's dtype and channels), pixels from outside the input set to 0."""
    return cv2.remap(img, maps.map_x, maps.map_y, interpolation, borderMode=cv2.BORDER_CONSTANT, borderValue=0)


def run(args) -> int:
    try:
        mf = read_model_file(args.model)
    except ValueError as exc:
        raise UndistortError(str(exc)) from None
    choice = frame_choice(args)
    try:
        frame = corrected_frame(mf.model, mf.width, mf.height, choice)
    except ValueError as exc:
        raise UndistortError(f"{args.model}: {exc}") from None
    if not choice.is_default:
        print(f"{frame.describe()} ({choice.describe()})")
    args.frame = frame
    channels = None
    if getattr(args, "tca", None):
        fields = read_tca_file(args.tca, mf.width, mf.height)
        channels = {ch: ChannelModel(mf.model, f) for ch, f in fields.items()}
    out_dir = Path(args.output_dir)
    if out_dir.exists() and not out_dir.is_dir():
        raise UndistortError(f"{out_dir}: exists and is not a directory")
    # check all inputs before writing anything
    names = set()
    for path in args.images:
        p = Path(path)
        if p.suffix.lower() not in WRITABLE:
            raise UndistortError(
                f"{p}: unsupported image type {p.suffix or '(none)'!r} (supported: {', '.join(WRITABLE)})"
            )
        target = out_dir / p.name
        if p.name in names:
            raise UndistortError(f"{p}: two input images named {p.name!r} would overwrite each other in {out_dir}")
        names.add(p.name)
        if target.exists() and target.resolve() == p.resolve():
            raise UndistortError(f"{p}: output would overwrite the input; choose another -o DIR")
        if target.exists() and not args.overwrite:
            raise UndistortError(f"{target}: already exists (use --overwrite)")
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise UndistortError(f"{out_dir}: cannot create the output directory ({exc.strerror or exc})") from None
    cache: dict[tuple[int, int], object] = {}
    status = EXIT_OK
    for path in args.images:  # a bad image is named on stderr; the others are still corrected
        try:
            _correct_one(args, mf, Path(path), out_dir, cache, channels)
        except InputError as exc:
            say("harp undistort", exc)
            status = EXIT_ERROR
    return status


def _maps(cache: dict, key: tuple, model, w: int, h: int, what: str, frame=None):
    """The undistortion maps of ``model`` for ``w x h`` images, computed once (``cache[key]``)."""
    if key not in cache:
        t0 = time.perf_counter()
        cache[key] = fast_undistortion_maps(model, w, h, step=DEFAULT_STEP_PX, frame=frame)
        m = cache[key]
        print(
            f"maps for {w}x{h}{what}{'' if frame is None else f' onto {frame.width}x{frame.height}'}: {time.perf_counter() - t0:.2f} s "
            f"(interpolation error <= {m.interp_error_px:.1e} px)"
        )
    return cache[key]


def _correct_one(args, mf, p: Path, out_dir: Path, cache: dict, channels: dict | None = None) -> None:
    """Correct one image into ``out_dir``; InputError (one line) if it cannot be."""
    img = read_image(p, grey=False)
    h, w = img.shape[:2]
    if (w, h) != (mf.width, mf.height):
        raise UndistortError(f"{p}: image is {w}x{h} but the model {args.model} is for {mf.width}x{mf.height} images")
    kernel = INTERPOLATIONS[args.interpolation]
    if channels is None:
        out = undistort_image(img, _maps(cache, (w, h), mf.model, w, h, "", args.frame), kernel)
    else:
        if img.ndim != 3 or img.shape[2] < 3:
            raise UndistortError(f"{p}: a grey image has no colour channels to correct for TCA; drop --tca for it")
        fw, fh = args.frame.width, args.frame.height
        out = np.zeros((fh, fw, img.shape[2]), img.dtype)
        for index, ch in ((2, "R"), (1, "G"), (0, "B")):  # OpenCV's BGR order
            model = mf.model if ch == "G" else channels[ch]
            maps = _maps(cache, (w, h, ch), model, w, h, f", {ch}", args.frame)
            out[..., index] = undistort_image(np.ascontiguousarray(img[..., index]), maps, kernel)
        if img.shape[2] > 3:  # an alpha channel follows the green (reference) geometry
            maps = _maps(cache, (w, h, "G"), mf.model, w, h, ", G", args.frame)
            out[..., 3:] = undistort_image(np.ascontiguousarray(img[..., 3:]), maps, kernel).reshape(fh, fw, -1)
    target = out_dir / p.name
    params = [cv2.IMWRITE_JPEG_QUALITY, 95] if p.suffix.lower() in (".jpg", ".jpeg") else []
    try:
        ok, encoded = cv2.imencode(p.suffix, out, params)
    except cv2.error:
        ok = False
    if not ok:
        raise UndistortError(f"{target}: OpenCV cannot write {out.dtype} images as {p.suffix}")
    atomic_write_bytes(target, encoded.tobytes())
    print(
        f"wrote {target} ({out.shape[1]}x{out.shape[0]}, {out.dtype}, {1 if out.ndim == 2 else out.shape[2]} channel(s))"
    )
