"""Fuzz from the schema itself (issue 25): every key the configuration declares is broken in turn.

The cases are generated from :func:`station.config.schema.document` with each driver's keys (the demo's
simulated camera, Zaber turntable and emulator; the Aravis and V4L2 cameras and the GRBL turntable of
the example configurations): for every key a value below and above its range (or outside its choices,
too few or repeated items), values of the wrong type, the key removed when it is required, YAML
oddities (``yes``/``Off`` booleans, a 5000-digit integer, ``1e4`` read as text, ``0123`` read as 83,
``.nan``, a foreign tag, nesting beyond the limit), and for every section an unknown key and a scalar
in its place. The choices among the oddities and the wrong types are seeded.

Every case must give exactly one line naming its file and the broken field (its value and, for a value
out of range, the range as declared) and exit 2: all of them through ``harp config check`` in one real
process and in process (both the command and ``harp session run``, which must create nothing), and a
seeded few through real ``harp session run`` processes.
"""

from __future__ import annotations

import copy
import dataclasses
import random
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
import yaml

from drivers.settings import MAX_TEXT, REQUIRED, Setting, describe, shown
from station.cli import main
from station.config.schema import Section, document

REPO = Path(__file__).resolve().parents[2]
BASES = ("demo.yaml", "aravis-zaber.yaml", "v4l2-grbl.yaml")
OPTIONAL_SECTIONS = {"intrinsics": "demo-intrinsics.yaml"}
"""Optional sections with a required key, given to the demo as the shipped configuration that shows each
of them has it, so that every key of theirs is broken beside valid others (issue 23)."""
RAW = "RAW-YAML-PLACEHOLDER"
SEED = 2025


@dataclass(frozen=True)
class Case:
    what: str  # e.g. "capture.timeout_s above its range"
    text: str  # the configuration file
    field: str  # the field the line must name (a prefix for nesting)
    needles: tuple[str, ...]  # further text the line must hold


def expanded(sec: Section, data: Any) -> Section:
    """``sec`` with each driver section given the keys of the driver ``data`` names."""
    if sec.drivers:
        sec = sec.with_driver(data["driver"])
    keys = {k: expanded(v, (data or {}).get(k) or {}) if isinstance(v, Section) else v for k, v in sec.keys.items()}
    return dataclasses.replace(sec, keys=keys)


def put(data: dict, path: str, value: Any) -> None:
    *head, last = path.split(".")
    for k in head:
        if not isinstance(data.get(k), dict):
            data[k] = {}
        data = data[k]
    data[last] = value


def drop(data: dict, path: str) -> None:
    *head, last = path.split(".")
    for k in head:
        data = data[k]
    del data[last]


def outside(s: Setting) -> list[tuple[str, Any, str]]:
    """``(what, value, index)`` values the declaration ``s`` refuses by their range, choices or length
    (``index``: the list item the line names, ``""`` for the value itself)."""
    out: list[tuple[str, Any, str]] = []
    integer = s.kind in ("integer", "integers")
    step = 1 if integer else 0.5
    if s.choices:
        if isinstance(s.choices[0], str):
            out.append(("outside its choices", "not-" + s.choices[0], ""))
        else:
            out.append(("outside its choices", max(s.choices) + 1, ""))
    elif s.low is not None and s.high is not None:
        below = s.low if s.low_open else s.low - step
        above = s.high if s.high_open else s.high + step
        if s.kind in ("numbers", "integers"):
            least = max(s.length[0], 1)
            good = [s.low + (0 if integer else 0.25) * k + (1 if s.low_open else 0) for k in range(least)]
            good = [int(v) for v in good] if integer else good
            out += [("an item below its range", [below, *good[1:]], "[0]"),
                    ("an item above its range", [*good[:-1], above], f"[{least - 1}]")]  # fmt: skip
            if s.length[0] > 1:
                out.append(("too few items", good[:1], ""))
            if s.length[1] is not None:
                out.append(("too many items", good + [good[-1]] * (s.length[1] + 1 - len(good)), ""))
            if s.unique and least >= 2:
                out.append(("a repeated item", [good[0]] * least, ""))
        else:
            out += [("below its range", int(below) if integer else float(below), ""),
                    ("above its range", int(above) if integer else float(above), "")]  # fmt: skip
    if s.kind == "text" and not s.choices:
        out += [("empty", "", ""), ("too long", "x" * (MAX_TEXT + 1), ""), ("on two lines", "a\nb", "")]
    return out


WRONG = {
    "integer": [2.5, "7", True, [1], {"a": 1}],
    "number": ["abc", True, [1.0], {"a": 1}],
    "text": [5, True, ["a"], {"a": "b"}, 0.5],
    "boolean": ["maybe", 1, 0.0, []],
    "numbers": ["0, 1", 5, {"a": 1}, [1, "x"]],
    "integers": ["0, 0, 8, 8", 5, [0, 0, 8, 8.5]],
    "value": [[1], {"a": 1}],
    "mapping": [5, "text", [1], True],
}
"""Values of the wrong type per kind (the seeded generator picks two of each key's)."""

ODDITIES = {
    "integer": ["yes", "Off", "9" * 5000, "1e4", "!!binary aGk=", "[" * 20 + "]" * 20],
    "number": ["yes", "on", "9" * 5000, "1e4", ".nan", "-.inf", "!!python/object/apply:os.system ['true']"],
    "text": ["yes", "Off", "0123", "2024-01-02", "!!binary aGk=", "[" * 20 + "]" * 20],
    "boolean": ["yes", "off", "!!binary aGk="],
    "numbers": ["[yes, 1]", "[1e4, 2]", "[.nan, 1]", "[" * 20 + "]" * 20],
    "integers": ["[yes, 1, 2, 3]", "[" * 20 + "]" * 20],
    "value": ["!!binary aGk=", "[" * 20 + "]" * 20],
    "mapping": ["!!binary aGk=", "[" * 20 + "]" * 20],
}
"""YAML text that PyYAML reads as something else than what a user meant (the generator picks two)."""


def oddity_expectation(raw: str, path: str) -> tuple[str, tuple[str, ...]]:
    """The field prefix and text the line must hold for the oddity ``raw`` at ``path``."""
    if raw.startswith("["):
        if raw.startswith("[["):
            return path, ("nesting deeper than 16",)
        bad = raw[1:].split(",")[0]
        return f"{path}[0]", ((f"'{bad}'",) if bad != ".nan" else ("got nan",))
    if raw.startswith("!!"):
        return path, (f"the tag '{raw.split()[0]}' is not a configuration value",)
    if raw.lower() in ("yes", "no", "on", "off"):
        return path, (f"'{raw}' is read by YAML as a boolean",)
    if raw.startswith("99999"):
        return path, ("an integer of 5000 digits",)
    if raw == "1e4":
        return path, ("got '1e4' (YAML reads it as text",)
    if raw == "0123":
        return path, ("got 83; quote it",)
    if raw == "2024-01-02":
        return path, ("got datetime.date(2024, 1, 2); quote it",)
    return path, (f"got {raw.lstrip('.').replace('-.', '-')}",)


def dump(data: dict, raw: str | None = None) -> str:
    dumper = getattr(yaml, "CSafeDumper", yaml.SafeDumper)  # libyaml where there is one: a thousand files
    text = yaml.dump(data, Dumper=dumper, default_flow_style=None, sort_keys=False, allow_unicode=True)
    return text if raw is None else text.replace(RAW, raw, 1)


def generate() -> list[Case]:
    rng = random.Random(SEED)
    cases: list[Case] = []
    seen: set[str] = set()
    for base in BASES:
        text = (REPO / "configs" / base).read_text()
        original = yaml.safe_load(text)
        original["store"] = {"path": "p.sqlite", "sessions_dir": "sessions"}
        if base == "demo.yaml":
            for name, shown_in in OPTIONAL_SECTIONS.items():
                original.setdefault(name, yaml.safe_load((REPO / "configs" / shown_in).read_text())[name])
        tree = expanded(document(), original)

        def walk(sec: Section):
            yield sec
            for spec in sec.keys.values():
                if isinstance(spec, Section):
                    yield from walk(spec)

        for sec in walk(tree):
            for path, s in ((sec.key_path(k), v) for k, v in sec.keys.items() if isinstance(v, Setting)):
                key = path if not (sec.driver and path.startswith("station.")) else f"{sec.driver}:{path}"
                if key in seen or (base != "demo.yaml" and not sec.driver):
                    continue  # the station's own keys are broken once, on the demo
                seen.add(key)

                def case(what, value, field, needles, raw=None):
                    d = copy.deepcopy(original)
                    put(d, path, RAW if raw is not None else value)
                    cases.append(Case(f"{base}: {path} {what}", dump(d, raw), field, needles))

                for what, value, index in outside(s):
                    needles = (f"got {shown(value if not index else value[int(index[1:-1])])}",)
                    if what not in ("too few items", "too many items", "a repeated item"):
                        needles += (s.range_text() if s.kind != "text" or s.choices else describe(s),)
                    case(what, value, path + index, needles)
                for value in rng.sample(WRONG[str(s.kind)], 2):
                    field, got = path, value
                    if isinstance(value, list) and len(value) < s.length[0]:
                        # as many items as the key needs, so that the wrong type is what is refused
                        value = value + [k + 2 for k in range(s.length[0] - len(value))]
                    if isinstance(value, list) and s.kind in ("numbers", "integers"):  # the first bad item named
                        i = next(i for i, v in enumerate(value) if isinstance(v, str) or (v != int(v)))
                        field, got = f"{path}[{i}]", value[i]
                    case(f"of the wrong type ({value!r})", value, field, ("expected ", f"got {shown(got)}"))
                for raw in rng.sample(ODDITIES[str(s.kind)], 2):
                    items = raw.count(",") + 1
                    if raw.startswith("[") and not raw.startswith("[[") and items < s.length[0]:
                        # as many items as the key needs, so that the oddity is what is refused
                        raw = raw[:-1] + "".join(f", {k + 2}" for k in range(s.length[0] - items)) + "]"
                    field, needles = oddity_expectation(raw, path)
                    case(f"as the YAML {raw[:20]!r}", None, field, needles, raw=raw)
                if s.default is REQUIRED:
                    d = copy.deepcopy(original)
                    drop(d, path)
                    cases.append(Case(f"{base}: {path} missing", dump(d), path, ("missing",)))
            # every section: an unknown key, and a scalar in its place
            if sec.path and f"{sec.driver}:{sec.path}" not in seen:
                seen.add(f"{sec.driver}:{sec.path}")
                d = copy.deepcopy(original)
                put(d, f"{sec.path}.unknown_key_{rng.randrange(100)}", 1)
                unknown = next(k for k in _at(d, sec.path) if k.startswith("unknown_key_"))
                cases.append(Case(f"{base}: {sec.path} with an unknown key", dump(d), f"{sec.path}.{unknown}",
                                  ("unknown",)))  # fmt: skip
                d = copy.deepcopy(original)
                put(d, sec.path, 5)
                cases.append(Case(f"{base}: {sec.path} a number", dump(d), sec.path, ("expected a mapping, got 5",)))
    return cases


def _at(data: dict, path: str) -> dict:
    for k in path.split("."):
        data = data[k]
    return data


@pytest.fixture(scope="module")
def written(tmp_path_factory) -> list[tuple[Path, Case]]:
    root = tmp_path_factory.mktemp("config-fuzz")
    out = []
    for i, c in enumerate(generate()):
        p = root / f"c{i:04d}.yaml"
        p.write_text(c.text)
        out.append((p, c))
    return out


def lines_by_file(stderr: str, prefix: str) -> dict[str, list[str]]:
    by: dict[str, list[str]] = {}
    for line in stderr.splitlines():
        assert line.startswith(prefix), line
        name = line[len(prefix) :].split(": ", 1)[0]
        by.setdefault(name, []).append(line)
    return by


def assert_named(case: Case, line: str, path: Path) -> None:
    rest = line.split(f"{path}: ", 1)[1]
    field, _, message = rest.partition(": ")
    nested = field.startswith(case.field + "[") and (case.field.endswith("]") is False)
    assert field == case.field or nested, (case.what, line)
    for needle in case.needles:
        assert needle in message, (case.what, needle, line)


def test_the_generator_covers_every_key_of_the_schema(written):
    cases = [c for _, c in written]
    assert len(cases) > 900
    broken = {c.what.split(": ", 1)[1].split(" ", 1)[0] for c in cases}
    assert {p for p, _ in document().leaves()} <= broken
    for driver_key in ("station.camera.bit_depth", "station.camera.roi", "station.camera.discard_frames",
                       "station.turntable.tolerance_microsteps", "station.turntable.feed",
                       "simulation.emulator.speed_deg_s"):  # fmt: skip
        assert driver_key in broken
    assert any("above its range" in c.what for c in cases) and any("YAML '9999" in c.what for c in cases)


def test_each_broken_key_is_one_named_line_and_exit_2_in_process(written, capsys, tmp_path):
    paths = [str(p) for p, _ in written]
    assert main(["config", "check", *paths]) == 2
    out, err = capsys.readouterr()
    assert out == ""
    by = lines_by_file(err, "harp config: ")
    assert sorted(by) == sorted(paths)  # every file named, on one line each
    for p, case in written:
        (line,) = by[str(p)]
        assert_named(case, line, p)
    # harp session run: the same line for each, and nothing created
    for p, case in written:
        assert main(["session", "run", str(p), "--quiet", "--out", str(tmp_path / "sessions")]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and err.startswith(f"harp session: {p}: "), (case.what, err)
        assert_named(case, err.strip(), p)
    assert not (tmp_path / "sessions").exists()


def test_each_broken_key_through_the_real_processes(written, tmp_path):
    from tests.station.processes import run_process

    paths = [str(p) for p, _ in written]
    r = run_process([sys.executable, "-m", "station.cli", "config", "check", *paths], cwd=REPO, timeout=600)
    assert r.returncode == 2 and r.stdout == "" and "Traceback" not in r.stderr
    by = lines_by_file(r.stderr, "harp config: ")
    assert sorted(by) == sorted(paths)
    for p, case in written:
        (line,) = by[str(p)]
        assert_named(case, line, p)
    for p, case in random.Random(SEED).sample(written, 3):
        r = run_process(
            [sys.executable, "-m", "station.cli", "session", "run", str(p), "--quiet", "--out", str(tmp_path / "s")],
            cwd=REPO,
            timeout=120,
        )
        assert r.returncode == 2 and r.stderr.count("\n") == 1 and "Traceback" not in r.stderr, (case.what, r.stderr)
        assert_named(case, r.stderr.strip(), p)
    assert not (tmp_path / "s").exists()
