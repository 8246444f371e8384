"""The bounded configuration reader (issue 25): no hang, no internal error, the field named."""

import os
import subprocess
import sys

import pytest
import yaml

from station.config import ConfigError, load_config
from station.config.reader import MAX_CONFIG_BYTES, MAX_DEPTH, MAX_DIGITS

from .test_config import demo_data, write


def error(tmp_path, text: str) -> ConfigError:
    p = tmp_path / "station.yaml"
    p.write_text(text)
    with pytest.raises(ConfigError) as exc:
        load_config(p)
    assert "\n" not in str(exc.value)
    return exc.value


def test_a_fifo_is_refused_at_once_by_config_check(tmp_path):
    fifo = tmp_path / "station.yaml"
    os.mkfifo(fifo)
    with pytest.raises(ConfigError, match="not a regular file \\(a FIFO\\); give a configuration file"):
        load_config(fifo)
    # the command too: one line, exit 2, and no writer needed on the FIFO (it would block before)
    r = subprocess.run(
        [sys.executable, "-m", "station.cli", "config", "check", str(fifo)],
        capture_output=True,
        text=True,
        timeout=60,
        start_new_session=True,
    )
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and str(fifo) in lines[0] and "FIFO" in lines[0] and "Traceback" not in r.stderr


def test_a_directory_and_an_oversized_file_are_refused(tmp_path):
    with pytest.raises(ConfigError, match="is a directory, not a configuration file"):
        load_config(tmp_path)
    big = tmp_path / "big.yaml"
    big.write_bytes(b"# " + b"x" * MAX_CONFIG_BYTES)
    with pytest.raises(ConfigError, match=f"at most {MAX_CONFIG_BYTES}"):
        load_config(big)


def test_a_5000_digit_integer_names_its_field(tmp_path):
    text = yaml.safe_dump(demo_data())
    assert "seed: " in text
    text = text.replace("seed: ", "seed: 9" + "1" * 4999 + "  # was ", 1)
    e = error(tmp_path, text)
    assert e.field.endswith("seed") and f"at most {MAX_DIGITS}" in e.expected and "5000 digits" in e.expected


def test_deep_nesting_names_where(tmp_path):
    deep = "a: " + "[" * 200 + "]" * 200 + "\n"
    e = error(tmp_path, deep)
    assert f"deeper than {MAX_DEPTH}" in str(e) and e.field.startswith("a")
    very = "a: " + "[" * 100000 + "]" * 100000 + "\n"  # beyond the composer's own recursion
    e = error(tmp_path, very)
    assert f"deeper than {MAX_DEPTH}" in str(e)


@pytest.mark.parametrize("spelling", ["yes", "no", "on", "Off"])
def test_a_yaml_1_1_boolean_is_refused_with_its_field(tmp_path, spelling):
    data = demo_data()
    text = yaml.safe_dump(data).replace(f"id: {data['station']['id']}", f"id: {spelling}", 1)
    assert f"id: {spelling}" in text
    e = error(tmp_path, text)
    assert e.field == "station.id" and f"'{spelling}' is read by YAML as a boolean" in e.expected


def test_true_and_false_stay_booleans(tmp_path):
    data = demo_data()
    p = write(tmp_path, data)
    assert load_config(p)  # the demo itself: its booleans are spelled true / false


def test_an_integer_mapping_key_is_refused(tmp_path):
    data = demo_data()
    text = yaml.safe_dump(data) + "1: x\n"
    e = error(tmp_path, text)
    assert e.field == "(top level)" and "keys must be names, got '1'" in e.expected
