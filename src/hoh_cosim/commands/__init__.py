"""The command families of `hoh-cosim`: argument parsing and wiring, no logic a library caller needs.

Each family module has `add_commands(sub)` (its subcommands on the main parser) and
`run_command(args)` (run it if `args` names one of its commands, else None):

    cosim      the scenario run, build-fmus, export, identify-gravity
    hardware   hw run | calibrate | sensors | rehearse, replay
    study      sweep, report, tune, probe-correction, study clinical
"""

from __future__ import annotations

import argparse
import contextlib
import signal
import time
from collections.abc import Callable
from typing import Any

from hoh_cosim.errors import ConfigError

__all__ = [
    "EXIT_BAD_INPUT",
    "EXIT_FAILED",
    "EXIT_OK",
    "ArgumentParser",
    "HelpFormatter",
    "add_set_option",
    "add_view_options",
    "check_view_options",
    "linger",
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


def add_view_options(parser: argparse.ArgumentParser, what: str, live: bool = True) -> None:
    """--view, --record-view FILE.rrd and --view-port: the 3D view of `what` (hoh_cosim.view),
    `live` as it runs."""
    shown = "live, as it runs," if live else "once replayed"
    parser.add_argument(
        "--view",
        action="store_true",
        help=f"show {what} {shown} in a 3D view in the browser (Rerun's web viewer served from "
        "this machine; its address is printed), served until Ctrl-C; needs the view extra "
        "(default: no view)",
    )
    parser.add_argument(
        "--record-view",
        metavar="FILE.rrd",
        help=f"keep the view of {what} as a Rerun recording, written whole at the end; open it "
        "later with 'python -m hoh_cosim.view serve FILE.rrd' or Rerun's 'rerun FILE.rrd' "
        "(default: none)",
    )
    parser.add_argument(
        "--view-port",
        type=int,
        default=9090,
        metavar="PORT",
        help="the web viewer's port for --view (default: 9090)",
    )


def check_view_options(args: argparse.Namespace) -> bool:
    """Whether a view is asked for; refused with one line, before anything runs, without Rerun,
    with a port out of range or a recording that cannot be written."""
    if not (args.view or args.record_view):
        return False
    from hoh_cosim.view import require_rerun

    require_rerun("--view" if args.view else "--record-view")
    if args.view and not 1 <= args.view_port <= 65535:
        raise ConfigError(f"--view-port: expected a port 1 to 65535, got {args.view_port}")
    if args.record_view:
        from hoh_cosim.view.stream import check_record_path

        check_record_path(args.record_view)
    return True


def linger(url: str | None, close: Callable[[], None]) -> None:
    """Keep a live view (at `url`; None: none) served until Ctrl-C (or SIGTERM, from a script
    that started it), then `close` it."""
    previous = None
    try:
        if url is None:
            return
        with contextlib.suppress(KeyboardInterrupt):
            previous = signal.signal(signal.SIGTERM, _interrupted)  # before a script reads on
            print(f"view: still served at {url} (Ctrl-C ends)", flush=True)
            while True:
                time.sleep(0.5)
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)
        close()


def _interrupted(signum: int, frame: Any) -> None:
    raise KeyboardInterrupt
