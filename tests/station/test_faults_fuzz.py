"""Fuzz (issue 14): malformed images and configurations never give a traceback.

Seeded and bounded: a few hundred images made by mutating valid small files of every format
(truncations, flipped bytes, rewritten header sizes, foreign headers, garbage) and a few hundred
configurations made by mutating the demo's (wrong types, missing and unknown keys, extreme values,
broken YAML). In process each must give a result or the module's one-line error; as whole
processes ``harp measure`` must exit 2 with exactly one line per bad file, no traceback, and the
good files measured; ``harp session run`` must exit 2 with one line.
"""

import json
import math
import struct
import subprocess
import sys
import time
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml

from pipeline.render import HarpScene, render_harp
from station.config import ConfigError, parse_config
from station.imageio import ImageReadError, read_grey

REPO = Path(__file__).resolve().parents[2]
DEMO = REPO / "configs" / "demo.yaml"
N_IMAGES = 240
N_CONFIGS = 160


def _valid_images(rng) -> list[tuple[str, bytes]]:
    out = []
    for ext in (".png", ".pgm", ".tif", ".jpg", ".bmp", ".webp"):
        for depth in (8, 16):
            if depth == 16 and ext in (".jpg", ".bmp", ".webp"):
                continue
            img = (rng.random((int(rng.integers(16, 48)), int(rng.integers(16, 48)))) * 255).astype(np.uint8)
            if depth == 16:
                img = img.astype(np.uint16) * 257
            ok, buf = cv2.imencode(ext, img)
            assert ok
            out.append((ext, buf.tobytes()))
    return out


def _mutate(rng, ext: str, data: bytes) -> bytes:
    d = bytearray(data)
    kind = int(rng.integers(0, 8))
    if kind == 0:  # truncated anywhere
        return bytes(d[: int(rng.integers(0, len(d)))])
    if kind == 1:  # bytes flipped
        for _ in range(int(rng.integers(1, 20))):
            d[int(rng.integers(0, len(d)))] ^= int(rng.integers(1, 256))
        return bytes(d)
    if kind == 2:  # header sizes rewritten: huge, zero, or ordinary
        value = int(rng.choice([0, 1, 100_000, 2**31 - 1, 2**32 - 1, 65535]))
        if ext == ".png":
            d[16:24] = struct.pack(">II", value, int(rng.choice([value, 1, 100_000])))
        elif ext == ".pgm":
            return f"P5\n{value} {value}\n255\n".encode() + bytes(d[-64:])
        elif ext == ".bmp":
            d[18:26] = struct.pack("<ii", value & 0x7FFFFFFF, -(value & 0x7FFFFFFF))
        else:
            pos = int(rng.integers(0, min(64, len(d) - 4)))
            d[pos : pos + 4] = struct.pack(">I", value)
        return bytes(d)
    if kind == 3:  # another format's header on this body
        heads = [b"\x89PNG\r\n\x1a\n", b"II*\x00", b"MM\x00*", b"\xff\xd8\xff", b"P5\n", b"BM", b"RIFF"]
        h = heads[int(rng.integers(0, len(heads)))]
        return h + bytes(d[len(h) :])
    if kind == 4:  # garbage of the right length
        return rng.integers(0, 256, len(d), dtype=np.uint8).tobytes()
    if kind == 5:  # nothing, or a header alone
        return bytes(d[: int(rng.integers(0, 12))])
    if kind == 6:  # a chunk inserted in the middle
        pos = int(rng.integers(0, len(d)))
        return (
            bytes(d[:pos]) + rng.integers(0, 256, int(rng.integers(1, 400)), dtype=np.uint8).tobytes() + bytes(d[pos:])
        )
    return bytes(d) + b"\x00" * int(rng.integers(1, 1000))  # trailing junk


@pytest.fixture(scope="module")
def malformed(tmp_path_factory):
    rng = np.random.default_rng(20141)
    base = tmp_path_factory.mktemp("fuzz-images")
    valid = _valid_images(rng)
    paths = []
    for k in range(N_IMAGES):
        ext, data = valid[k % len(valid)]
        p = base / f"m{k:03d}{ext}"
        p.write_bytes(_mutate(rng, ext, data))
        paths.append(p)
    good = []
    for k, angle in enumerate((10.0, 80.0)):
        img = render_harp(160, 120, HarpScene(angle_deg=angle, spacing_px=24.0), noise_sigma=1.0, seed=k).image
        g = base / f"good{k}.png"
        cv2.imwrite(str(g), img)
        good.append(g)
    return paths, good


def test_malformed_images_give_an_image_or_one_line_in_process(malformed):
    paths, _ = malformed
    t0 = time.monotonic()
    outcomes = {"read": 0, "refused": 0}
    for p in paths:
        try:
            img = read_grey(p)
        except ImageReadError as exc:
            msg = str(exc)
            assert msg.startswith(f"{p}: ") and "\n" not in msg, msg
            outcomes["refused"] += 1
        else:
            assert img.ndim == 2 and img.dtype in (np.uint8, np.uint16, np.float32)
            outcomes["read"] += 1
    assert outcomes["refused"] > N_IMAGES // 2 and outcomes["read"] > 0, outcomes  # both paths exercised
    assert time.monotonic() - t0 < 30


def test_malformed_images_whole_process_keep_the_good_ones(malformed):
    paths, good = malformed
    inputs = [str(good[0]), *map(str, paths[:120]), str(good[1])]
    p = subprocess.run(
        [sys.executable, "-m", "station.cli", "measure", "--json", *inputs],
        capture_output=True,
        text=True,
        cwd=REPO,
        timeout=300,
    )
    assert p.returncode == 2 and "Traceback" not in p.stderr
    doc = json.loads(p.stdout)
    measured = [im["path"] for im in doc["images"]]
    assert measured[0] == str(good[0]) and measured[-1] == str(good[1])
    lines = p.stderr.strip().splitlines()
    assert all(line.startswith("harp measure: ") for line in lines), [l for l in lines if not l.startswith("harp")]
    failed = [e["path"] for e in doc["errors"]]
    assert len(lines) == len(failed) and all(f in line for f, line in zip(failed, lines))
    assert sorted(measured + failed) == sorted(inputs)  # every input either measured or named once


# ------------------------------------------------------------------------------ configurations
_ODD_VALUES = [None, "", "x" * 200, -1, 0, 1e308, -1e308, float("nan"), float("inf"), True, [], {}, [1, "a"],
               {"a": 1}, 3.5, 10**30, "0.5", [0.0, 0.0], [400, -30]]  # fmt: skip


def _paths(d, prefix=()):
    if isinstance(d, dict):
        for k, v in d.items():
            yield (*prefix, k)
            yield from _paths(v, (*prefix, k))
    elif isinstance(d, list):
        for i, v in enumerate(d):
            yield (*prefix, i)
            yield from _paths(v, (*prefix, i))


_LOADER = getattr(yaml, "CSafeLoader", yaml.SafeLoader)  # libyaml where there is one: the mutations only
_DUMPER = getattr(yaml, "CSafeDumper", yaml.SafeDumper)


def _mutated_configs(n: int):
    rng = np.random.default_rng(777)
    text = DEMO.read_text()
    base = yaml.load(text, Loader=_LOADER)
    keys = list(_paths(base))
    for _ in range(n):
        kind = int(rng.integers(0, 5))
        if kind == 4:  # broken YAML text
            cut = int(rng.integers(0, len(text)))
            junk = ["\t", ": :", "[", "{", "- - -", "\x00", "'", "&a *b", "? "][int(rng.integers(0, 9))]
            yield text[:cut] + junk + text[cut:]
            continue
        d = yaml.load(text, Loader=_LOADER)
        for _ in range(int(rng.integers(1, 4))):
            path = keys[int(rng.integers(0, len(keys)))]
            parent = d
            try:
                for k in path[:-1]:
                    parent = parent[k]
                if kind == 0 and isinstance(parent, dict):
                    parent.pop(path[-1], None)
                elif kind == 1 and isinstance(parent, dict):
                    parent[f"unknown_{int(rng.integers(0, 99))}"] = 1
                else:
                    parent[path[-1]] = _ODD_VALUES[int(rng.integers(0, len(_ODD_VALUES)))]
            except (KeyError, IndexError, TypeError):
                continue
        try:
            yield yaml.dump(d, Dumper=_DUMPER, allow_unicode=True)
        except (ValueError, yaml.YAMLError):
            continue


def test_mutated_configurations_are_valid_or_one_line_naming_the_field(tmp_path):
    t0 = time.monotonic()
    path = tmp_path / "station.yaml"
    refused = 0
    for text in _mutated_configs(N_CONFIGS):
        try:
            cfg = parse_config(text, path)
        except ConfigError as exc:
            msg = str(exc)
            assert msg.startswith(f"{path}: ") and "\n" not in msg and exc.field, msg
            refused += 1
        else:
            assert all(math.isfinite(v) for v in cfg.capture.orientations_deg + cfg.focus_settings)
            assert all(0 <= v < 360 for v in cfg.capture.orientations_deg)
    assert refused > N_CONFIGS // 2
    assert time.monotonic() - t0 < 30


def test_mutated_configurations_whole_process(tmp_path):
    texts = list(_mutated_configs(20))
    chosen = []
    for text in texts:  # the first two the schema refuses, run as `harp session run` (one process each)
        try:
            parse_config(text, tmp_path / "c.yaml")
        except ConfigError:
            chosen.append(text)
        if len(chosen) == 2:
            break
    for k, text in enumerate(chosen):
        cfg = tmp_path / f"c{k}.yaml"
        cfg.write_text(text)
        p = subprocess.run(
            [sys.executable, "-m", "station.cli", "session", "run", str(cfg), "--out", str(tmp_path / "s")],
            capture_output=True,
            text=True,
            cwd=REPO,
            timeout=120,
        )
        assert p.returncode == 2 and "Traceback" not in p.stderr and p.stderr.count("\n") == 1, p.stderr
        assert p.stderr.startswith(f"harp session: {cfg}: ")
    assert not (tmp_path / "s").exists()
