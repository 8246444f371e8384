"""``harp tca IMAGE... [--t 30] [--degree 3] [--json] [-o FILE]``: lateral chromatic aberration.

Each shot (a camera RAW file, measured per CFA plane on the mosaic without demosaicing,
or a colour PNG/TIFF/PPM/JPEG, per channel) is measured per channel
(:mod:`station.colour`); the red and blue fields are fitted against green over all shots
(:func:`pipeline.tca.fit_tca`: shots with the harp at two or more orientations), and
converted to lensfun's linear and poly3 TCA models. Printed per image and channel: edges,
d, d_max and the median offset of the channel's edges from green's; per channel: the TCA
seen (RMS offset), what the field leaves (residual), the field's size over the image and
lensfun's terms with their conversion error. ``--json`` prints one JSON object (what
``--out`` writes, as YAML or JSON by the suffix).

Bad input (a RAW file LibRaw cannot read, a grey image from a monochrome camera, shots of
different sizes, edges of one orientation only): one line on stderr, exit 2.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from pipeline.resample import DEFAULT_T
from pipeline.tca import channel_offsets
from station.cli.commands import COMMANDS
from station.cli.inputs import positive_int
from station.colour import fit_channels, measure_colour_file, tca_document
from station.exit_codes import EXIT_OK
from station.files import atomic_write_text
from station.tables import is_terminal, print_table


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "tca",
        help=COMMANDS["tca"],
        description=__doc__.split("\n\n")[0],
    )
    p.add_argument("images", metavar="IMAGE", nargs="+", help="colour or camera RAW harp shots, harp turned between")
    p.add_argument(
        "-t", "--t", type=positive_int, default=DEFAULT_T, help=f"along-edge subsampling (default {DEFAULT_T})"
    )
    p.add_argument("--degree", type=positive_int, default=3, help="total degree of each channel's field (default 3)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("-o", "--out", metavar="FILE", help="write the fields and lensfun terms (.yaml or .json)")
    p.set_defaults(func=run)


def run(args) -> int:
    shots = []
    for path in args.images:
        shots.append(measure_colour_file(path, t=args.t))
    fits, lensfun = fit_channels(shots, args.images, degree=args.degree)
    doc = tca_document(fits, lensfun, args.images)
    per_image = []
    for path, m in zip(args.images, shots):
        rows = []
        offsets = channel_offsets(m)
        for name, pm in m.planes.items():
            obs = offsets.get(name[0])
            off = 0.0 if obs is None else float(np.median(np.abs(obs.offset))) if len(obs.offset) else float("nan")
            rows.append({"plane": name, "edges": pm.n_lines, "d": pm.d, "d_max": pm.d_max, "median_offset_px": off})
        per_image.append({"path": str(path), "pattern": m.pattern, "planes": rows})
    doc["per_image"] = per_image
    if args.out:
        out = Path(args.out)
        if out.suffix.lower() == ".json":
            text = json.dumps(doc, indent=2) + "\n"
        else:
            import yaml

            text = yaml.safe_dump({k: v for k, v in doc.items() if k != "per_image"}, sort_keys=False)
        atomic_write_text(out, text)
    if args.json:
        print(json.dumps(doc))
        return EXIT_OK
    columns = ("image", "pattern", "plane", "edges", "d (px)", "d_max (px)", "median offset from green (px)")
    planes = [
        (img["path"], img["pattern"], r["plane"], str(r["edges"]), f"{r['d']:.4f}", f"{r['d_max']:.4f}")
        + (f"{r['median_offset_px']:.4f}",)
        for img in per_image
        for r in img["planes"]
    ]
    print_table(columns, planes, title="colour planes", right=columns[3:])
    if not is_terminal():
        print()  # a blank line after the table
    for c, f in fits.items():
        print(
            f"channel {c}: TCA seen {f.offset_rms:.4f} px RMS, left by the field {f.residual_rms:.4f} px; "
            f"field up to {f.field_max:.3f} px ({f.n_edges} edges)"
        )
    for k, v in lensfun.items():
        print(
            f"lensfun {k}: red {', '.join(f'{x:.7g}' for x in v.model.red)}; blue {', '.join(f'{x:.7g}' for x in v.model.blue)}"
        )
        for line in v.lines():
            print(f"  {line}")
    if args.out:
        print(f"wrote {args.out}")
    return EXIT_OK
