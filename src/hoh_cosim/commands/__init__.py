"""The command families of `hoh-cosim`: argument parsing and wiring, no logic a library caller needs.

Each family module has `add_commands(sub)` (its subcommands on the main parser) and
`run_command(args)` (run it if `args` names one of its commands, else None):

    cosim      the scenario run, build-fmus, export, identify-gravity
    hardware   hw run | calibrate | sensors | rehearse, replay
    study      sweep, report, tune, probe-correction, study clinical
"""

from __future__ import annotations

import argparse
from typing import Any

__all__ = [
    "EXIT_BAD_INPUT",
    "EXIT_FAILED",
    "EXIT_OK",
    "ArgumentParser",
    "HelpFormatter",
    "add_set_option",
]

EXIT_OK = 0
EXIT_FAILED = 1
EXIT_BAD_INPUT = 2


class HelpFormatter(argparse.HelpFormatter):
    """argparse's help, where an option that takes a value always says its default: its help says
    it (the word "default" in it), else " (default: X)" is added from the option's default. An
    option without one (None, or an empty list) must say in its help what happens when it is left
    out, e.g. "(default: runs/<scenario name>)" or "(default: none)"."""

    def _get_help_string(self, action: argparse.Action) -> str | None:
        help = action.help
        if (
            help
            and action.option_strings
            and action.nargs != 0
            and "default" not in help
            and action.default not in (None, argparse.SUPPRESS, [], ())
        ):
            help += " (default: %(default)s)"
        return help


class ArgumentParser(argparse.ArgumentParser):
    """argparse that reports usage mistakes as one line with exit status 2 (its own default too),
    and shows every option's default in its help (`HelpFormatter`)."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        kwargs.setdefault("formatter_class", HelpFormatter)
        super().__init__(*args, **kwargs)

    def error(self, message: str) -> None:  # type: ignore[override]
        self.exit(EXIT_BAD_INPUT, f"{self.prog}: {message} (see --help)\n")


def add_set_option(parser: argparse.ArgumentParser, help: str, metavar: str = "C.P=V") -> None:
    """`--set` (repeatable) into `args.overrides`: parameter overrides as `component.parameter=value`
    texts, which `hoh_cosim.cosim.scenario.load_scenario` (or the runner's config) checks."""
    parser.add_argument(
        "--set", dest="overrides", action="append", default=[], metavar=metavar, help=help
    )
