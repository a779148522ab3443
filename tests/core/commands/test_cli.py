"""The command-line front: dispatch, exit codes and one-line errors."""

import subprocess
import sys

import pytest

from zoopraxis import cli
from zoopraxis.core.errors import ZoopraxisError


def run_zoopraxis(*args):
    return subprocess.run([sys.executable, "-m", "zoopraxis", *args], capture_output=True,
                          text=True, timeout=120)


def test_info_prints_versions():
    import numpy

    result = run_zoopraxis("info")
    assert result.returncode == 0, result.stderr
    lines = result.stdout.splitlines()
    assert lines[0].startswith(f"zoopraxis {cli.manifest_version()} (")
    assert f"numpy {numpy.__version__}" in lines
    assert any(line.startswith("bpy ") for line in lines)
    assert result.stderr == ""


def test_info_does_not_import_bpy(capsys):
    before = "bpy" in sys.modules
    assert cli.main(["info"]) == 0
    assert ("bpy" in sys.modules) == before
    assert "scipy " in capsys.readouterr().out


def test_manifest_version_matches_pyproject():
    import tomllib

    with open(cli.__file__.replace("cli.py", "pyproject.toml"), "rb") as file:
        assert tomllib.load(file)["project"]["version"] == cli.manifest_version()


def test_unknown_command_exits_2_with_one_line():
    result = run_zoopraxis("trak")
    assert result.returncode == 2
    assert result.stdout == ""
    [line] = result.stderr.splitlines()
    assert line.startswith("zoopraxis: error: unknown command 'trak' (available: ")
    assert "info" in line


def test_no_command_prints_usage_and_exits_2(capsys):
    assert cli.main([]) == 2
    assert "info" in capsys.readouterr().err
    assert cli.main(["--help"]) == 0
    assert "usage: zoopraxis COMMAND" in capsys.readouterr().out


@pytest.fixture
def command(monkeypatch):
    """Register ``handler`` as command ``probe`` through the real table and lazy import."""
    def add(handler):
        monkeypatch.setattr(cli, "_probe", handler, raising=False)
        monkeypatch.setitem(cli.COMMANDS, "probe", ("cli", "_probe", "test command"))
    return add


def test_zoopraxis_error_exits_2_with_one_line(command, capsys):
    def handler(argv):
        raise ZoopraxisError(f"markers.json: frame 3, view cam1: unknown joint '{argv[0]}'\nmore")

    command(handler)
    assert cli.main(["probe", "l_kne"]) == 2
    captured = capsys.readouterr()
    assert captured.err == ("zoopraxis probe: error: markers.json: frame 3, view cam1: "
                            "unknown joint 'l_kne' more\n")


def test_ctrl_c_exits_130(command, capsys):
    def handler(argv):
        raise KeyboardInterrupt

    command(handler)
    assert cli.main(["probe"]) == 130
    assert capsys.readouterr().err == "zoopraxis probe: cancelled\n"


def test_handler_gets_remaining_args_and_its_code_is_returned(command):
    seen = []
    command(lambda argv: seen.append(argv) or 7)
    assert cli.main(["probe", "--out", "r.json"]) == 7
    assert seen == [["--out", "r.json"]]
    command(lambda argv: None)
    assert cli.main(["probe"]) == 0


def test_argparse_exit_becomes_return_code(capsys):
    assert cli.main(["info", "--help"]) == 0
    assert cli.main(["info", "--bogus"]) == 2
    assert "unrecognized arguments: --bogus" in capsys.readouterr().err


def test_other_errors_keep_their_traceback(command):
    def handler(argv):
        raise RuntimeError("a bug")

    command(handler)
    with pytest.raises(RuntimeError, match="a bug"):
        cli.main(["probe"])
