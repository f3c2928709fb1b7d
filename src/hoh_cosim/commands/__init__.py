"""The command families of `hoh-cosim`: argument parsing and wiring, no logic a library caller needs.

Each family module has `add_commands(sub)` (its subcommands on the main parser) and
`run_command(args)` (run it if `args` names one of its commands, else None):

    cosim      the scenario run, build-fmus, export, identify-gravity
    hardware   hw run | calibrate | sensors | rehearse, replay
    study      sweep, report, tune, probe-correction, study clinical
"""

from __future__ import annotations

import argparse

__all__ = ["EXIT_BAD_INPUT", "EXIT_FAILED", "EXIT_OK", "ArgumentParser", "add_set_option"]

EXIT_OK = 0
EXIT_FAILED = 1
EXIT_BAD_INPUT = 2


class ArgumentParser(argparse.ArgumentParser):
    """argparse that reports usage mistakes as one line with exit status 2 (its own default too)."""

    def error(self, message: str) -> None:  # type: ignore[override]
        self.exit(EXIT_BAD_INPUT, f"{self.prog}: {message} (see --help)\n")


def add_set_option(parser: argparse.ArgumentParser, help: str, metavar: str = "C.P=V") -> None:
    """`--set` (repeatable) into `args.overrides`: parameter overrides as `component.parameter=value`
    texts, which `hoh_cosim.cosim.scenario.load_scenario` (or the runner's config) checks."""
    parser.add_argument(
        "--set", dest="overrides", action="append", default=[], metavar=metavar, help=help
    )
