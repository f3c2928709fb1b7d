"""The command line's own words: every `--help` renders whole and explains every option with its
default, `run` is a command of its own with the bare form's options, and an `--out` where nothing
can be written is refused in one line naming the real cause, on every command that takes one."""

from __future__ import annotations

import argparse
import errno
import os
import re
import shutil
import subprocess
import sys
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

from hoh_cosim.cli import _main_parser, main
from hoh_cosim.commands import ArgumentParser
from hoh_cosim.errors import ConfigError
from hoh_cosim.results import check_writable

ROOT = Path(__file__).resolve().parents[2]
CIRCLES = ROOT / "scenarios" / "circles.yaml"
SCENARIOS = ROOT / "scenarios"
POSES = ROOT / "tests" / "data" / "poses_seed_tool.csv"


def _parsers(
    parser: argparse.ArgumentParser, path: str
) -> Iterator[tuple[str, argparse.ArgumentParser]]:
    yield path, parser
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, child in action.choices.items():
                yield from _parsers(child, f"{path} {name}")


PARSERS = dict(_parsers(_main_parser(), "hoh-cosim"))


def _options(parser: argparse.ArgumentParser) -> list[argparse.Action]:
    """The options a user reads about: not the positionals, --help or --version."""
    skip = (argparse._HelpAction, argparse._VersionAction, argparse._SubParsersAction)
    return [a for a in parser._actions if a.option_strings and not isinstance(a, skip)]


def _rendered(parser: argparse.ArgumentParser, action: argparse.Action) -> str:
    """The option's entry in its parser's --help, as the parser's formatter writes it."""
    formatter = parser.formatter_class(prog=parser.prog)
    formatter.add_argument(action)
    return " ".join(formatter.format_help().split())


def run_cli(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    status = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return status, out, err


def test_the_walk_finds_every_command():
    assert {"hoh-cosim run", "hoh-cosim hw rehearse", "hoh-cosim study clinical"} <= set(PARSERS)
    assert len(PARSERS) >= 20


@pytest.mark.parametrize("name", PARSERS)
def test_every_help_renders_without_a_stray_percent(name):
    text = PARSERS[name].format_help()
    assert "%%" not in text
    assert "%(" not in text


@pytest.mark.parametrize("name", PARSERS)
def test_every_option_says_what_it_does_and_its_default(name):
    parser = PARSERS[name]
    for action in _options(parser):
        option = "/".join(action.option_strings)
        assert (action.help or "").strip(), f"{name} {option}: no help"
        if action.nargs == 0 or action.required:  # a flag, or nothing to default to
            continue
        entry = _rendered(parser, action)
        assert "default" in entry, f"{name} {option}: the help does not say the default: {entry}"


def test_the_formatter_adds_a_default_the_help_does_not_mention():
    parser = ArgumentParser(prog="p")
    parser.add_argument("--rate", type=float, default=500.0, help="the rate in Hz")
    parser.add_argument("--mode", default="auto", help="the mode (default: found from the data)")
    parser.add_argument("--set", action="append", default=[], help="an override")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    entries = {a.dest: _rendered(parser, a) for a in _options(parser)}
    assert entries["rate"].endswith("the rate in Hz (default: 500.0)")
    assert entries["mode"].endswith("the mode (default: found from the data)")
    assert entries["set"].endswith("an override")  # nothing to show: its help must say it
    assert entries["quiet"].endswith("no progress bar")


# --- run ------------------------------------------------------------------------------------------


def test_run_is_the_first_command_with_a_help_line():
    commands = next(a for a in _main_parser()._actions if isinstance(a, argparse._SubParsersAction))
    assert next(iter(commands.choices)) == "run"
    helps = {a.dest: a.help for a in commands._choices_actions}
    assert helps["run"]


def test_run_help_shows_the_run_options(capsys):
    status, out, _ = run_cli(["run", "--help"], capsys)
    assert status == 0
    assert out.startswith("usage: hoh-cosim run ")
    for word in ("--engine", "--preset", "SCENARIO.yaml"):
        assert word in out


def test_the_bare_form_has_the_same_options_as_run(capsys):
    status, out, _ = run_cli([CIRCLES, "--help"], capsys)
    assert status == 0
    assert out.startswith("usage: hoh-cosim SCENARIO.yaml [options]")
    assert "%%" not in out
    bare = set(re.findall(r"^\s+(--[\w-]+)", out, re.M))
    run = {o for a in _options(PARSERS["hoh-cosim run"]) for o in a.option_strings}
    assert bare == run


@pytest.mark.parametrize("prefix", [[], ["run"]], ids=["bare", "run"])
def test_both_forms_reject_a_missing_scenario_in_one_line(tmp_path, capsys, prefix):
    missing = tmp_path / "nope.yaml"
    status, out, err = run_cli([*prefix, missing, "--engine", "inprocess"], capsys)
    assert status == 2
    assert err.startswith(f"hoh-cosim: {missing}: ")
    assert err.count("\n") == 1
    assert out == ""


def test_the_installed_command_lists_run_and_shows_its_help():
    exe = shutil.which("hoh-cosim", path=os.path.dirname(sys.executable))
    command = [exe] if exe else [sys.executable, "-m", "hoh_cosim"]
    top = subprocess.run([*command, "--help"], capture_output=True, text=True, timeout=60)
    assert top.returncode == 0, top.stderr
    assert re.search(r"^\s+run\s+\S", top.stdout, re.M), top.stdout
    run = subprocess.run([*command, "run", "--help"], capture_output=True, text=True, timeout=60)
    assert run.returncode == 0, run.stderr
    assert run.stdout.startswith("usage: hoh-cosim run ")
    assert "--engine" in run.stdout
    assert "--preset" in run.stdout


# --- --out where nothing can be written -----------------------------------------------------------


def _rig(directory: Path) -> Path:
    path = directory / "rig.yaml"
    path.write_text("robot: {host: 127.0.0.1}\nprobe: null\n", encoding="utf-8")
    return path


# each command that takes --out: its argv given the --out and a scratch directory; FILE: a file
FOLDER_COMMANDS: dict[str, Callable[[Path, Path], list[object]]] = {
    "bare run": lambda out, tmp: [CIRCLES, "--engine", "inprocess", "--quiet", "--out", out],
    "run": lambda out, tmp: ["run", CIRCLES, "--engine", "inprocess", "--quiet", "--out", out],
    "export": lambda out, tmp: ["export", CIRCLES, "--out", out],
    "build-fmus": lambda out, tmp: ["build-fmus", "--out", out],
    "sweep": lambda out, tmp: ["sweep", ROOT / "studies" / "slopes.yaml", "--out", out],
    "report": lambda out, tmp: ["report", "--quick", "--scenarios", SCENARIOS, "--out", out],
    "tune": lambda out, tmp: ["tune", "--scenarios", SCENARIOS, "--out", out],
    "probe-correction": lambda out, tmp: ["probe-correction", "--quick", "--out", out],
    "study clinical": lambda out, tmp: ["study", "clinical", "--quick", "--out", out],
    "replay": lambda out, tmp: ["replay", tmp / "session.mcap", "--out", out],
    "hw campaign": lambda out, tmp: ["hw", "campaign", "--runs", "1", "--out", out],
}
FILE_COMMANDS: dict[str, Callable[[Path, Path], list[object]]] = {
    "identify-gravity": lambda out, tmp: ["identify-gravity", POSES, "--out", out],
    "hw calibrate": lambda out, tmp: ["hw", "calibrate", _rig(tmp), "--out", out],
}

# where nothing can be written (as root too), and the cause the line must name
PLACES = {
    "proc": (lambda tmp: Path("/proc"), r"exists, but no file or folder can be created in it"),
    "under a file": (lambda tmp: tmp / "a-file", r"is a file, not a folder"),
    "sys": (lambda tmp: Path("/sys"), r": (Permission denied|Operation not permitted)$"),
}


def _place(name: str, tmp: Path) -> tuple[Path, str]:
    if sys.platform != "linux":
        pytest.skip("/proc and /sys are Linux's")
    where, cause = PLACES[name]
    (tmp / "a-file").write_text("not a folder\n", encoding="utf-8")
    return where(tmp), cause


def _assert_refused(status: int, out: str, err: str, option: str, cause: str) -> None:
    assert status == 2, err
    assert err.startswith(f"hoh-cosim: {option}: cannot write in "), err
    assert err.count("\n") == 1, err
    assert "Traceback" not in err
    assert "No such file or directory" not in err, err
    assert re.search(cause, err.strip()), err
    assert out == ""


@pytest.mark.parametrize("place", PLACES)
@pytest.mark.parametrize("command", FOLDER_COMMANDS)
def test_an_output_folder_that_cannot_be_made_is_refused_naming_the_cause(
    tmp_path, capsys, monkeypatch, command, place
):
    monkeypatch.chdir(tmp_path)
    parent, cause = _place(place, tmp_path)
    out = parent / "hoh-cosim-out"
    before = sorted(tmp_path.rglob("*"))
    status, stdout, err = run_cli(FOLDER_COMMANDS[command](out, tmp_path), capsys)
    _assert_refused(status, stdout, err, f"--out {out}", cause)
    assert sorted(tmp_path.rglob("*")) == before


@pytest.mark.parametrize("place", PLACES)
@pytest.mark.parametrize("command", FILE_COMMANDS)
def test_an_output_file_that_cannot_be_written_is_refused_naming_the_cause(
    tmp_path, capsys, monkeypatch, command, place
):
    monkeypatch.chdir(tmp_path)
    parent, cause = _place(place, tmp_path)
    out = parent / "calibration.json"
    argv = FILE_COMMANDS[command](out, tmp_path)
    before = sorted(tmp_path.rglob("*"))
    status, stdout, err = run_cli(argv, capsys)
    _assert_refused(status, stdout, err, f"--out {out}", cause)
    assert sorted(tmp_path.rglob("*")) == before


def test_folders_under_a_file_are_refused_naming_the_file(tmp_path, capsys):
    blocker = tmp_path / "a-file"
    blocker.write_text("not a folder\n", encoding="utf-8")
    out = blocker / "deeper" / "still" / "run"
    status, stdout, err = run_cli([CIRCLES, "--engine", "inprocess", "--out", out], capsys)
    _assert_refused(status, stdout, err, f"--out {out}", f": {blocker} is a file, not a folder$")


def test_a_refusal_leaves_no_folder_it_made(tmp_path, monkeypatch):
    def refuse(*args: object, **kwargs: object) -> None:
        raise PermissionError(errno.EACCES, "Permission denied")

    monkeypatch.setattr(tempfile, "mkstemp", refuse)
    with pytest.raises(ConfigError, match=r"^--out: cannot write in .*/a/b/c: Permission denied$"):
        check_writable(tmp_path / "a" / "b" / "c", "--out")
    assert list(tmp_path.iterdir()) == []


def test_a_read_only_file_system_is_named(tmp_path, monkeypatch):
    def refuse(*args: object, **kwargs: object) -> None:
        raise OSError(errno.EROFS, "Read-only file system")

    monkeypatch.setattr(tempfile, "mkstemp", refuse)
    with pytest.raises(ConfigError, match=r": it is on a read-only file system$"):
        check_writable(tmp_path, "--out")
