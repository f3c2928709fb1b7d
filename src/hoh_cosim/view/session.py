"""A robot session in the view: live from the runner's feed, or a session log re-played.

Live (`hw run`, `hw rehearse`): `start_session_view` starts a `hoh_cosim.hardware.feed.RowFeed`
whose consumer, `session_view`, runs in a process of its own: it opens the view (a port in use is
refused there, and the refusal reaches the command line before the session starts), then takes the
rows the runner handed over (one every 20 ms of session time, `SESSION_RATE_HZ`), finds the arm's
joints from each logged TCP pose (`scene.ArmTracker`), and sends them with the session's events.
Frames the view could not take in time are dropped by the feed and counted, said at the end in the
view's log. After the session the recording (if any) is finished, and a live view stays served
until the command ends it.

Replay (`replay LOG.mcap --view`): the log's robot poses, estimates and sent commands, and the
replay's recomputed command beside the logged one.

The rehearsal's phantom is drawn where its world puts it (a plane `phantom_below_m` under the home
pose's tip), at rest: the world's breathing runs on the world's own clock, which the session does
not log. A real patient is not drawn.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from hoh_cosim.errors import ConfigError, HohError
from hoh_cosim.view import SESSION_RATE_HZ
from hoh_cosim.view.scene import ArmTracker, Scene
from hoh_cosim.view.stream import ViewStream
from hoh_cosim.view.track import Track, rows_track, session_track

__all__ = [
    "TIMELINE",
    "log_replay",
    "rehearsal_phantom",
    "session_scene",
    "session_view",
    "start_session_view",
]

TIMELINE = "session_time"

BLOCK_S = 0.2
"""[s] The view takes the rows handed over in blocks this far apart: five wake-ups a second, each
sending a block of ten rows (a send per row cost the loop's core more than the rows do)."""

_QUIET_EVENTS = frozenset({"mode", "parameters"})
"""Events the view does not repeat: the mode's changes it shows from the rows themselves, the
parameters (a page of JSON) it leaves to the log."""


def rehearsal_phantom(phantom_below_m: float | None) -> Any:
    """The rehearsal world's phantom (`hoh_cosim.rehearsal.world`): a plane this far under the tip
    at the arm's home pose, or None."""
    if phantom_below_m is None:
        return None
    from hoh_cosim.view.scene import ToolGeometry, tcp_pose
    from plant_models.arm import HOME_Q
    from plant_models.tissue import PhantomParams

    tip_z = float(tcp_pose(HOME_Q, ToolGeometry.of())[2, 3])
    return PhantomParams(shape="plane", plane_point_B=[0.0, 0.0, tip_z - phantom_below_m])


def session_scene(controller: Any, phantom_below_m: float | None = None, note: str = "") -> Scene:
    """A session's scene: the controller's limits and fixture, the project's tool, the rehearsal's
    phantom if any."""
    return Scene.of(controller, None, rehearsal_phantom(phantom_below_m), note=note)


def _with_joints(track: Track, tracker: ArmTracker) -> Track:
    T = np.tile(np.eye(4), (len(track), 1, 1))
    T[:, :3, :3], T[:, :3, 3] = track.R_BT, track.p_BT_B
    track.q = tracker.track(T)
    return track


def _event_texts(stream: ViewStream, events: list[tuple[int, float, str, str]]) -> None:
    for _, t, event, detail in events:
        if event not in _QUIET_EVENTS:
            stream.text(t, f"{event}: {detail}", "WARN" if event == "stop" else "INFO")


def session_view(
    reader: Any, scene: Scene, web_port: int | None, record: str | None, title: str
) -> None:
    """The feed's consumer (`hoh_cosim.hardware.feed`): the session in the view."""
    try:
        stream = ViewStream(scene, title=title, timeline=TIMELINE, web_port=web_port, record=record)
    except ConfigError as exc:
        reader.refuse(str(exc))
        return
    except HohError as exc:
        reader.fail(str(exc))
        return
    reader.ready(stream.url or "")
    tracker = ArmTracker(scene.tool)
    last_t = 0.0
    try:
        while True:
            ending = reader.ending  # once so, what is left is taken, then the loop ends
            rows = reader.take(0.0)
            _event_texts(stream, reader.events())
            if len(rows):
                track = _with_joints(rows_track(rows), tracker)
                stream.log(track)
                last_t = float(track.t[-1])
            if ending:
                break
            reader.pause(BLOCK_S)
        if reader.abandoned:
            stream.abandon()
            return
        _event_texts(stream, reader.events())
        if reader.dropped:
            stream.text(
                last_t,
                f"view: {reader.dropped} of {reader.dropped + reader.received} frames dropped "
                "(the view fell behind; the robot never waited for it)",
                "WARN",
            )
        path = stream.finish()
    except BaseException:
        stream.abandon()
        raise
    reader.finished("" if path is None else str(path))
    if stream.url is not None:
        reader.wait_stop()
    stream.close()


def start_session_view(
    scene: Scene, *, web_port: int | None, record: str | Path | None, title: str
) -> tuple[Any, str | None]:
    """The runner's feed with the view as its consumer, started (refused with one line, before
    the session, if it cannot start): (the feed, the live view's address or None)."""
    from hoh_cosim.hardware.feed import RowFeed

    feed = RowFeed(
        session_view,
        (scene, web_port, None if record is None else str(record), title),
        rate_hz=SESSION_RATE_HZ,
    )
    url = feed.start()
    return feed, url or None


def log_replay(result: Any, stream: ViewStream) -> None:
    """A replay (`hoh_cosim.hardware.replay.ReplayResult`) in the view: the session's poses,
    estimates and logged commands, the recomputed commands beside them."""
    replayed = dict(zip(result.cycles.tolist(), result.new["twist_B"], strict=True))
    track = session_track(result.session, 1.0 / SESSION_RATE_HZ, replayed)
    tracker = ArmTracker(stream.scene.tool)
    for start in range(0, len(track), 500):
        stream.log(_with_joints(track.rows(slice(start, start + 500)), tracker))
    events = [
        (int(m.get("k", 0)), float(m.get("t", 0.0)), str(m["event"]), str(m.get("detail", "")))
        for m in result.session.messages.get("/events", [])
    ]
    _event_texts(stream, events)
