"""The ``harp`` entry point: whatever a command lets through is one line on stderr and exit 2."""

import errno

import pytest

import station.cli.export
from station.cli import main


def _raising(exc):
    def run(args):
        raise exc

    return run


def test_unexpected_error_is_one_line_exit_2(monkeypatch, capsys):
    monkeypatch.setattr(station.cli.export, "run", _raising(KeyError("centre\nmissing")))
    assert main(["export", "lens.yaml", "--format", "json"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("harp export: internal error: KeyError:")
    assert "HARP_DEBUG=1" in err and "Traceback" not in err
    monkeypatch.setenv("HARP_DEBUG", "1")
    with pytest.raises(KeyError):
        main(["export", "lens.yaml", "--format", "json"])


def test_os_error_names_the_file_and_what_to_do(monkeypatch, capsys):
    full = OSError(errno.ENOSPC, "No space left on device", "/srv/out/lens.yaml")
    monkeypatch.setattr(station.cli.export, "run", _raising(full))
    assert main(["export", "lens.yaml", "--format", "json"]) == 2
    assert capsys.readouterr().err == (
        "harp export: /srv/out/lens.yaml: No space left on device; "
        "free some space on that file system and run the command again\n"
    )
    monkeypatch.setattr(station.cli.export, "run", _raising(MemoryError()))
    assert main(["export", "lens.yaml", "--format", "json"]) == 2
    assert capsys.readouterr().err.count("\n") == 1


def test_a_ctrl_c_that_python_wrapped_in_another_error_is_still_exit_130(monkeypatch, capsys):
    """A Ctrl-C landing while a class is made (a dataclass's field) reaches the command as
    ``RuntimeError: Error calling __set_name__ ...`` (its cause the KeyboardInterrupt): not an
    internal error, the interrupt it is."""

    def run(args):
        class Field:
            def __set_name__(self, owner, name):
                raise KeyboardInterrupt  # the Ctrl-C, arriving here

        class Frame:
            extra = Field()

    monkeypatch.setattr(station.cli.export, "run", run)
    assert main(["export", "lens.yaml", "--format", "json"]) == 130
    assert capsys.readouterr().err == "harp: interrupted\n"


def test_a_commands_error_is_printed_once_by_the_entry_point(tmp_path, capsys):
    points = tmp_path / "edges.txt"  # harp measure raises its InputError; the entry point prints it
    assert main(["measure", str(tmp_path / "missing.png"), "--points", str(points)]) == 2
    assert capsys.readouterr().err == (
        f"harp measure: {points}: unknown points format '.txt': give a file name ending in .json or .npz\n"
    )


def test_a_harp_error_carries_its_exit_code_and_is_one_line(monkeypatch, capsys):
    from station.errors import HarpError
    from station.profile_choice import FailedQA

    monkeypatch.setattr(station.cli.export, "run", _raising(FailedQA("lens at focus 2:\nfailed QA")))
    assert main(["export", "lens.yaml", "--format", "json"]) == 1
    assert capsys.readouterr().err == "harp export: lens at focus 2: failed QA\n"

    class Odd(HarpError):
        exit_code = 3

    monkeypatch.setattr(station.cli.export, "run", _raising(Odd("no")))
    assert main(["export", "lens.yaml", "--format", "json"]) == 3
    assert capsys.readouterr().err == "harp export: no\n"


@pytest.mark.parametrize(
    "argv, line",
    [
        (["profile", "show", "--id", "abc"], "harp profile show: argument --id: invalid int value: 'abc'"),
        (["measure"], "harp measure: the following arguments are required: IMAGE"),
        (["export", "lens.yaml"], "harp export: the following arguments are required: --format"),
        (["qa", "s", "--max-holdout-d", "-3"], "harp qa: argument --max-holdout-d: expected a positive number"),
        (["session", "frob"], "harp session: argument ACTION: invalid choice: 'frob' (choose from 'run', "),
        (["measure", "x.png", "--bogus"], "harp measure: unrecognized arguments: --bogus (see harp measure --help)"),
        (
            ["profile", "show", "--id", "1", "--bogus"],
            "harp profile show: unrecognized arguments: --bogus (see harp profile show --help)",
        ),
    ],
)
def test_a_usage_error_is_one_line_naming_the_option_exit_2(argv, line, capsys):
    # argparse printed its usage block first: two to five lines, and "harp: unrecognized arguments"
    with pytest.raises(SystemExit) as exc:
        code = main(argv)
        raise SystemExit(code)
    err = capsys.readouterr().err
    assert exc.value.code == 2 and err.count("\n") == 1 and err.startswith(line), err
    assert "usage:" not in err and err.rstrip().endswith("--help)")
