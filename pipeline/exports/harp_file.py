"""The writers of harp's own model file, as YAML (``harp``) and JSON (``json``)."""

from __future__ import annotations

import json
from typing import Any

from pipeline.exports.source import Export, ExportOptions, ExportSource
from pipeline.exports.statement import hash_comments
from pipeline.model_file import FORMAT_VERSION, model_file_text
from pipeline.plain import json_default

HARP_FORMAT_NAME = "harp-distortion-model"


def harp_model_doc(src: ExportSource) -> dict[str, Any]:
    """The model-file record of a source (the layout of :mod:`pipeline.model_file`)."""
    return {
        "format": HARP_FORMAT_NAME,
        "format_version": FORMAT_VERSION,
        **({"stamp": list(src.stamp)} if src.stamp else {}),
        "model": src.model.to_dict(),
        "image": {"width": int(src.width), "height": int(src.height)},
        "merit": dict(src.merit),
        "provenance": dict(src.provenance),
        **({"intrinsics": src.intrinsics.to_dict()} if src.intrinsics is not None else {}),
    }


def write_json(src: ExportSource, opt: ExportOptions) -> Export:
    return Export("json", (json.dumps(harp_model_doc(src), indent=2, default=json_default) + "\n").encode())


def write_harp(src: ExportSource, opt: ExportOptions) -> Export:
    text = model_file_text(
        src.model,
        width=src.width,
        height=src.height,
        merit=dict(src.merit),
        provenance=dict(src.provenance),
        intrinsics=src.intrinsics,
    )
    head = hash_comments(src.stamp)
    return Export("harp", (head + text).encode())
