"""The `hoh-cosim` command: the main parser, assembled from the command families in
`hoh_cosim.commands`, and the exit status.

    hoh-cosim [run] SCENARIO.yaml [options]           (see hoh_cosim.commands.cosim)
    hoh-cosim build-fmus | export | identify-gravity   (see hoh_cosim.commands.cosim)
    hoh-cosim hw run|calibrate|sensors|rehearse ...    (see hoh_cosim.commands.hardware)
    hoh-cosim replay LOG.mcap [--set ...] [--out DIR]
    hoh-cosim sweep|report|tune|probe-correction ...   (see hoh_cosim.commands.study)
    hoh-cosim study clinical ...                       (see hoh_cosim.commands.study)

Exit status: 0 done; 2 the input is wrong (one line naming the file and the place); 1 the run failed.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from hoh_cosim import __version__
from hoh_cosim.commands import EXIT_BAD_INPUT, EXIT_FAILED, ArgumentParser
from hoh_cosim.commands import cosim as cosim_commands
from hoh_cosim.commands import hardware as hardware_commands
from hoh_cosim.commands import study as study_commands
from hoh_cosim.errors import HohError, RunError

__all__ = ["SUBCOMMANDS", "main"]

FAMILIES = (cosim_commands, hardware_commands, study_commands)
SUBCOMMANDS = (
    *cosim_commands.COMMANDS,
    "hw",
    "replay",
    "sweep",
    "report",
    "tune",
    "probe-correction",
    "study",
)


def _main_parser() -> argparse.ArgumentParser:
    parser = ArgumentParser(
        prog="hoh-cosim",
        description="Hand-over-hand control of a robot-held ultrasound probe.",
        epilog="A scenario runs with 'hoh-cosim run SCENARIO.yaml' or, short, "
        "'hoh-cosim SCENARIO.yaml'. Each command has its --help.",
    )
    parser.add_argument("--version", action="version", version=f"hoh-cosim {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=ArgumentParser)
    for family in FAMILIES:
        family.add_commands(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    try:
        return _main(argv)
    except SystemExit as exc:  # argparse: --help, --version, a usage mistake
        return exc.code if isinstance(exc.code, int) else EXIT_BAD_INPUT


def _main(argv: list[str]) -> int:
    try:
        if argv and not argv[0].startswith("-") and argv[0] not in SUBCOMMANDS:
            return cosim_commands.run_scenario_command(argv, SUBCOMMANDS)
        args = _main_parser().parse_args(argv)
        args.argv = argv[1:]
        for family in FAMILIES:
            status = family.run_command(args)
            if status is not None:
                return status
        _main_parser().print_help()
        return EXIT_BAD_INPUT
    except RunError as exc:
        print(f"hoh-cosim: {exc}", file=sys.stderr)
        return EXIT_FAILED
    except HohError as exc:
        print(f"hoh-cosim: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        print("hoh-cosim: interrupted", file=sys.stderr)
        return 130
