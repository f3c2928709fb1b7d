"""A live 3D view of runs, replays and robot sessions, in a browser, with Rerun (issue 54).

    hoh-cosim run SCENARIO --view | --record-view FILE.rrd      a co-simulation, live or kept
    hoh-cosim replay LOG.mcap --view | --record-view FILE.rrd   a session re-played
    hoh-cosim hw run | hw rehearse --view | --record-view ...   live on the robot
    hoh-cosim study clinical --record-view                      one .rrd per kept run
    python -m hoh_cosim.view screenshot REC.rrd --out shot.png  a recording in headless Chromium

    scene.py       the geometry, numpy only: the UR5's links, the tool, the surface, the limits
    track.py       what is shown, one row per shown instant, from a run, a session or a replay
    stream.py      Rerun: the entities, the blueprint, the web viewer, the .rrd written whole
    cosim.py       a run in the view: live through the master's observer, or after the run
    session.py     a robot session: the process the runner's feed drains into, and replay
    screenshot.py  a recording served on loopback, rendered by headless Chromium

Rerun is the optional `view` extra: its viewer ships inside the `rerun-sdk` wheel and serves a web
viewer from this machine, so the view works offline and in any browser. Nothing imports Rerun until
a view is opened (`require_rerun` first), and nothing below this package imports it: the hardware
runner only fills a bounded feed (`hoh_cosim.hardware.feed`) that another process drains into the
view.

How often: a run's view takes a row every 10 ms of simulation time (100 Hz), a session's every
20 ms (50 Hz); the master's 1 ms ticks and the robot's 2 ms cycles are more than a person or the
viewer can use.
"""

from __future__ import annotations

import shlex
import sys

from hoh_cosim.errors import ConfigError

__all__ = ["REQUIREMENT", "RUN_RATE_HZ", "SESSION_RATE_HZ", "install_command", "require_rerun"]

REQUIREMENT = "rerun-sdk>=0.41"
"""What the view needs (the `view` extra); 0.41 for `serve_grpc` and `serve_web_viewer`."""
RUN_RATE_HZ = 100.0
"""Rows a second of simulation time in a run's view."""
SESSION_RATE_HZ = 50.0
"""Rows a second of session time in a session's or a replay's view."""

_MINIMUM = (0, 41)


def install_command() -> str:
    """The command that installs the view's requirement into this interpreter's environment."""
    return f"{shlex.quote(sys.executable)} -m pip install {shlex.quote(REQUIREMENT)}"


def require_rerun(option: str = "--view") -> None:
    """Refuse `option` with one line, the exact command to run in it, when Rerun is not there (or
    older than the view needs)."""
    try:
        import rerun
    except ImportError:
        raise ConfigError(
            f"{option} needs Rerun (the view extra), which is not installed: run "
            f"{install_command()}"
        ) from None
    version = getattr(rerun, "__version__", "0")
    try:
        found = tuple(int(x) for x in version.split(".")[:2])
    except ValueError:
        found = _MINIMUM  # a development build: let it try
    if found < _MINIMUM:
        raise ConfigError(
            f"{option} needs Rerun 0.41 or newer, found {version}: run {install_command()}"
        )
