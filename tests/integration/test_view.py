"""The 3D view (hoh_cosim.view) as a person uses it: a short run's recording read back through
Rerun's own reader, a rehearsal watched through the runner's feed and then replayed, the feed
dropping frames for a consumer too slow for it, and the inputs refused before anything runs."""

from __future__ import annotations

import json
import socket
import subprocess
import sys
import time
import urllib.request
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest

from hoh_cosim.cli import main
from hoh_cosim.hardware.session_log import CycleRow
from tests.xdist_groups import REAL_TIME

rerun = pytest.importorskip("rerun", reason="the view needs rerun-sdk (the view or test extra)")
from rerun.chunk import RrdReader  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
CIRCLES = ROOT / "scenarios" / "circles.yaml"
LINKS = [f"/world/arm/link{i}" for i in range(1, 7)]


def chunks_by_entity(path: Path) -> dict[str, list]:
    """Every chunk of the recording at `path`, by entity, read with Rerun's reader."""
    out: dict[str, list] = {}
    for chunk in RrdReader(path).stream():
        out.setdefault(chunk.entity_path, []).append(chunk)
    return out


def seconds(column) -> list[float]:
    """A timeline's column (durations in ns) in seconds (a ns count not whole in µs has no
    `timedelta`)."""
    return [t * 1e-9 for t in column.cast("int64").to_pylist()]


def timed(chunks: list, timeline: str) -> list:
    return [c for c in chunks if not c.is_static and timeline in c.timeline_names]


def times_s(chunks: list, timeline: str) -> np.ndarray:
    """The entity's instants on `timeline` [s], in order."""
    values = []
    for chunk in timed(chunks, timeline):
        values += seconds(chunk.to_record_batch().column(timeline))
    return np.sort(np.array(values))


def column(chunks: list, timeline: str, name: str) -> tuple[np.ndarray, list]:
    """(instants [s], values) of one component of an entity, in time order."""
    pairs = []
    for chunk in timed(chunks, timeline):
        batch = chunk.to_record_batch()
        if name not in batch.schema.names:
            continue
        pairs += zip(
            seconds(batch.column(timeline)),
            batch.column(name).to_pylist(),
            strict=True,
        )
    pairs.sort(key=lambda p: p[0])
    return np.array([p[0] for p in pairs]), [p[1] for p in pairs]


def texts(chunks: list, timeline: str) -> list[str]:
    return [v[0] for v in column(chunks, timeline, "TextLog:text")[1]]


def assert_one_line(status: int, err: str, start: str) -> None:
    assert status == 2, err
    assert "Traceback" not in err
    assert err.count("\n") == 1, err
    assert err.startswith(f"hoh-cosim: {start}"), err


# --- a run ----------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def circles(tmp_path_factory) -> tuple[Path, Path]:
    """2 s of circles (the rebias and the hand's first push) with its view recorded."""
    folder = tmp_path_factory.mktemp("circles")
    out, rrd = folder / "run", folder / "circles.rrd"
    argv = ["run", str(CIRCLES), "--duration", "2", "--engine", "inprocess", "--quiet"]
    assert main([*argv, "--out", str(out), "--record-view", str(rrd)]) == 0
    return out, rrd


CIRCLES_RUN = pytest.mark.xdist_group("test_view-circles")  # the module's run, made once


@CIRCLES_RUN
def test_a_run_records_the_arm_probe_forces_and_plots_over_its_time(circles):
    _, rrd = circles
    entities = chunks_by_entity(rrd)
    for entity in [
        *LINKS,
        "/world/probe",
        "/world/forces/hand",
        "/world/forces/contact",
        "/world/command/twist",
        "/world/path/reference",
        "/plots/hand_force/hand",
        "/plots/hand_force/estimate",
        "/plots/contact_force/magnitude",
        "/plots/tip_speed/magnitude",
        "/plots/path_error/magnitude",
        "/log/controller",
    ]:
        assert timed(entities.get(entity, []), "sim_time"), entity
    for entity in ("/world/workspace", "/world/surface/shape", "/world/arm/base"):
        assert any(c.is_static for c in entities[entity]), entity
    # a row every 10 ms of simulation time, from the first 10 ms to the run's end
    for entity in ("/world/probe", *LINKS, "/plots/contact_force/magnitude"):
        t = times_s(entities[entity], "sim_time")
        assert len(t) == 200, entity
        assert t[0] == pytest.approx(0.01)
        assert t[-1] == pytest.approx(2.0)
        assert np.allclose(np.diff(t), 0.01)
    # the controller's mode and status: the rebias first
    log = texts(entities["/log/controller"], "sim_time")
    assert log[0] == "mode: stopped; status + estimator not ready (rebiasing)"


@CIRCLES_RUN
def test_the_recorded_probe_is_where_the_run_put_the_tip(circles):
    """The view's probe pose against the run's own signals, and the arm's drawn flange against
    the probe (the links come from the plant's joints, the probe from its TCP output)."""
    out, rrd = circles
    table = pq.read_table(out / "signals.parquet").to_pydict()
    signal_t = np.array(table["time"])
    p_BT = np.column_stack([table[f"plant.p_BT_B[{i}]"] for i in (1, 2, 3)])
    entities = chunks_by_entity(rrd)
    t, translations = column(entities["/world/probe"], "sim_time", "Transform3D:translation")
    rows = np.searchsorted(signal_t, t - 1e-9)
    assert np.allclose(signal_t[rows], t)
    assert np.allclose(np.array(translations), p_BT[rows], atol=1e-6)  # stored as float32

    from hoh_cosim.view.scene import ToolGeometry
    from plant_models.ur5 import DH

    _, link6 = column(entities["/world/arm/link6"], "sim_time", "Transform3D:translation")
    _, quaternion6 = column(entities["/world/arm/link6"], "sim_time", "Transform3D:quaternion")
    _, quaternion = column(entities["/world/probe"], "sim_time", "Transform3D:quaternion")
    from scipy.spatial.transform import Rotation

    # flange = L6 · Tz(d6); TCP = flange · T_ET; the tool's T_ET is a shift along the flange's z
    R6 = Rotation.from_quat(np.array(quaternion6)).as_matrix()
    tip_from_arm = np.array(link6) + R6[:, :, 2] * (DH[5][0] + ToolGeometry.of().T_ET[2, 3])
    assert np.allclose(tip_from_arm, np.array(translations), atol=1e-5)
    R_probe = Rotation.from_quat(np.array(quaternion)).as_matrix()
    assert np.allclose(R_probe[:, :, 2], R6[:, :, 2], atol=1e-5)


def test_a_recording_is_written_whole_or_not_at_all(tmp_path):
    """A view abandoned (a run that failed, Ctrl-C) leaves nothing under its name or beside it."""
    from hoh_cosim.cosim.scenario import load_scenario
    from hoh_cosim.view.cosim import CosimView

    view = CosimView(load_scenario(CIRCLES, duration_s=0.1), record=tmp_path / "x.rrd")
    assert [p.name.startswith(".x.rrd.") for p in tmp_path.iterdir()] == [True]  # in progress
    view.abandon()
    assert list(tmp_path.iterdir()) == []


def test_the_log_tells_mode_changes_and_status_bits_once_each(tmp_path):
    """A clamp that flickers every other row is told when it starts and once it has stayed off
    for STATUS_HOLD_S; a stale stream's flag at once, both ways; the mode at each change."""
    from hoh_cosim.control.supervisor import Status
    from hoh_cosim.view.scene import Scene
    from hoh_cosim.view.stream import ViewStream
    from hoh_cosim.view.track import Track

    n = 100  # 1 s at 100 Hz
    t = 0.01 * np.arange(n)
    status = np.zeros(n)
    status[10:50:2] = int(Status.ACCEL_CLAMPED)  # 0.10 to 0.48 s, every other row
    status[70] = int(Status.STALE_FT)  # one row
    mode = np.where(t < 0.7, 1.0, 2.0)
    track = Track(
        t=t,
        p_BT_B=np.tile([-0.1, -0.45, 0.25], (n, 1)),
        R_BT=np.tile(np.diag([1.0, -1.0, -1.0]), (n, 1, 1)),
        status=status,
        mode=mode,
    )
    stream = ViewStream(Scene.of(), title="t", timeline="sim_time", record=tmp_path / "t.rrd")
    stream.log(track.rows(slice(0, 30)))  # in two blocks: the state carries over
    stream.log(track.rows(slice(30, None)))
    stream.finish()
    entities = chunks_by_entity(tmp_path / "t.rrd")
    when, lines = column(entities["/log/controller"], "sim_time", "TextLog:text")
    assert [(round(w, 2), line[0]) for w, line in zip(when, lines, strict=True)] == [
        (0.0, "mode: guiding in the air"),
        (0.1, "status + acceleration clamped"),
        (0.59, "status - acceleration clamped"),  # off from 0.49 s, told once it held 0.1 s
        (0.7, "mode: guiding in contact; status + stale FT-150 data"),
        (0.71, "status - stale FT-150 data"),
    ]


# --- inputs refused before anything runs ----------------------------------------------------------


@pytest.mark.parametrize(
    ("where", "problem"),
    [
        ("missing/c.rrd", "the folder {tmp}/missing does not exist"),
        ("a-file/c.rrd", "the folder {tmp}/a-file is not a folder"),
        ("c.txt", "expected a file name ending in .rrd"),
    ],
)
def test_a_recording_that_cannot_be_written_is_refused_before_the_run(
    tmp_path, capsys, where, problem
):
    (tmp_path / "a-file").write_text("")
    path = tmp_path / where
    argv = [str(CIRCLES), "--engine", "inprocess", "--out", str(tmp_path / "run")]
    status = main([*argv, "--record-view", str(path)])
    err = capsys.readouterr().err
    assert_one_line(status, err, f"--record-view {path}: ")
    assert err.strip().endswith(problem.format(tmp=tmp_path))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a-file"]  # no run, no recording


def test_a_recording_in_an_immutable_folder_is_refused(tmp_path, capsys):
    locked = tmp_path / "locked"
    locked.mkdir()
    if subprocess.run(["chattr", "+i", str(locked)], capture_output=True).returncode != 0:
        pytest.skip("chattr +i is not possible here")
    try:
        status = main(["hw", "rehearse", "--record-view", str(locked / "r.rrd")])
        captured = capsys.readouterr()
    finally:
        subprocess.run(["chattr", "-i", str(locked)], check=True)
    assert_one_line(status, captured.err, f"--record-view {locked / 'r.rrd'}: cannot write in ")
    assert "starting the rehearsal world" not in captured.out


def test_a_port_in_use_is_named_before_the_run(tmp_path, capsys):
    with socket.socket() as taken:
        taken.bind(("0.0.0.0", 0))  # where Rerun's web viewer listens
        taken.listen()
        port = taken.getsockname()[1]
        argv = [str(CIRCLES), "--engine", "inprocess", "--out", str(tmp_path / "run")]
        status = main([*argv, "--view", "--view-port", str(port)])
    err = capsys.readouterr().err
    assert_one_line(status, err, f"--view-port {port}: the port is in use")
    assert not (tmp_path / "run").exists()


@pytest.mark.parametrize(
    "argv",
    [
        ["run", str(CIRCLES), "--engine", "inprocess", "--view"],
        ["hw", "rehearse", "--seconds", "1", "--record-view", "r.rrd"],
        ["replay", "no-such.mcap", "--view"],
        ["study", "clinical", "--quick", "--record-view", "--scenarios", str(ROOT / "scenarios")],
    ],
    ids=["run", "rehearse", "replay", "study"],
)
def test_without_rerun_the_view_is_refused_with_the_install_command(tmp_path, argv):
    """Rerun not importable (as where the view extra is not installed): one line with the
    command that installs it, exit 2, and nothing ran."""
    code = (
        "import sys; sys.modules['rerun'] = None; from hoh_cosim.cli import main; "
        f"sys.exit(main({argv!r}))"
    )
    done = subprocess.run(
        [sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True, timeout=120
    )
    option = "--view" if "--view" in argv else "--record-view"
    import shlex

    assert done.returncode == 2, done.stderr
    assert done.stderr == (
        f"hoh-cosim: {option} needs Rerun (the view extra), which is not installed: run "
        f"{shlex.quote(sys.executable)} -m pip install 'rerun-sdk>=0.41'\n"
    )
    assert done.stdout == ""
    assert list(tmp_path.iterdir()) == []


# --- live -----------------------------------------------------------------------------------------


def test_a_live_view_is_served_at_the_printed_address_until_ended(tmp_path):
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    process = subprocess.Popen(
        [
            *(sys.executable, "-m", "hoh_cosim", "run", str(CIRCLES), "--duration", "1"),
            *("--engine", "inprocess", "--quiet", "--out", str(tmp_path / "run")),
            *("--view", "--view-port", str(port)),
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        cwd=tmp_path,
    )
    with process:
        assert process.stdout is not None
        first = process.stdout.readline()
        assert first.startswith(f"view: http://127.0.0.1:{port}/?url=rerun%2Bhttp"), first
        url = first.split()[1]
        lines = [process.stdout.readline() for _ in range(2)]
        assert lines == [
            f"wrote {tmp_path / 'run'}\n",
            f"view: still served at {url} (Ctrl-C ends)\n",
        ]
        with urllib.request.urlopen(url, timeout=10) as page:  # the web viewer, from this machine
            assert page.status == 200
            assert b"rerun" in page.read().lower()
        process.terminate()  # a script ends it so; at a terminal, Ctrl-C
        process.communicate(timeout=30)
        assert process.returncode == 0


# --- the feed -------------------------------------------------------------------------------------


class _Cycle:
    """What the feed reads of the runner's record when it is given the log's row: the time."""

    def __init__(self, t: float) -> None:
        self.t = t


def test_the_feed_drops_frames_for_a_slow_consumer_and_never_waits(tmp_path):
    """A consumer that pauses 50 ms after each take, a ring of 8 rows, 3000 rows offered as fast
    as the loop can: were the feed to wait for the consumer, offering would take 3000 / 8 x 50 ms
    = 19 s. It takes a few milliseconds; the consumer gets the newest rows, in order, and the rest
    are counted as dropped."""
    from hoh_cosim.hardware.feed import RowFeed

    out = tmp_path / "got.json"
    feed = RowFeed(_slow_counter(), (0.05, str(out)), rate_hz=1e9, capacity=8)
    assert feed.start() == "slow"
    row = CycleRow()
    n = 3000
    longest = 0.0
    started = time.perf_counter()
    try:
        for k in range(n):
            row.start(k, 0.002 * k, True, True)
            before = time.perf_counter()
            feed.offer(_Cycle(0.002 * k), row)
            longest = max(longest, time.perf_counter() - before)
        offering = time.perf_counter() - started
        assert feed.written == n
        assert feed.finish() == str(out)
    finally:
        feed.close()
    got = json.loads(out.read_text())
    assert offering < 1.0, offering  # not 19 s: nothing waited
    assert longest < 0.05, longest  # no single offer waited a consumer's pause
    k = np.array(got["k"])
    assert got["dropped"] > 0
    assert got["received"] + got["dropped"] == n
    assert np.all(np.diff(k) > 0)  # in order, none twice
    assert k[-1] == n - 1  # the newest is never the one dropped


def _slow_counter():
    from tests.view_consumers import slow_counter

    return slow_counter


# --- a rehearsal, watched and replayed ------------------------------------------------------------


@pytest.fixture(scope="module")
def rehearsal(tmp_path_factory):
    """3 s of the circle task (after a 100-sample rebias) through the real runner, its cycles
    offered to the view's feed, the view recorded; then the log replayed into a view."""
    pytest.importorskip("serial")
    if sys.platform == "win32":
        pytest.skip("the rehearsal needs POSIX ptys")
    from hoh_cosim.rehearsal.rehearse import Rehearsal, rehearse
    from hoh_cosim.view.session import session_scene, start_session_view

    folder = tmp_path_factory.mktemp("rehearsal")
    log, live, replayed = folder / "s.mcap", folder / "session.rrd", folder / "replay.rrd"
    feed, url = start_session_view(
        session_scene(None), web_port=None, record=live, title="rehearsal"
    )
    assert url is None
    try:
        result = rehearse(Rehearsal(seconds=3.0, log_path=log, rebias_samples=100), observer=feed)
        assert feed.finish() == str(live)
    finally:
        feed.close()
    argv = ["replay", str(log), "--out", str(folder / "replay"), "--record-view", str(replayed)]
    assert main(argv) == 0
    return result, live, replayed


@REAL_TIME
def test_a_rehearsal_watched_through_the_feed_is_recorded(rehearsal):
    result, live, _ = rehearsal
    assert result.session.clean, result.session.cause
    entities = chunks_by_entity(live)
    for entity in [*LINKS, "/world/probe", "/world/forces/hand", "/plots/tip_speed/magnitude"]:
        t = times_s(entities[entity], "session_time")
        # a row every 20 ms of the session's time (the rows a starved view dropped are counted)
        assert t[0] == pytest.approx(0.0)
        assert t[-1] == pytest.approx(3.0, abs=0.021)
        assert np.all(np.diff(t) > 0.019)
        assert len(t) >= 0.8 * 150, (entity, len(t))
    log = texts(entities["/log/controller"], "session_time")
    assert "end: 3 s done" in log
    assert any(line.startswith("rebias: ") for line in log)
    shown = len(times_s(entities["/world/probe"], "session_time"))
    if shown < 150:
        assert f"view: {150 - shown} of 150 frames dropped" in " ".join(log)


@REAL_TIME
def test_a_replay_shows_the_logged_and_the_recomputed_commands_side_by_side(rehearsal):
    _, _, replayed = rehearsal
    entities = chunks_by_entity(replayed)
    for entity in (*LINKS, "/world/command/twist", "/world/command/replayed"):
        assert timed(entities[entity], "session_time"), entity
    t, logged = column(entities["/plots/command/logged"], "session_time", "Scalars:scalars")
    t2, again = column(entities["/plots/command/replayed"], "session_time", "Scalars:scalars")
    assert len(t) >= 0.8 * 150
    assert np.array_equal(t, t2)
    # a replay without --set reproduces the session: the two lines are one
    assert np.allclose(np.array(logged), np.array(again), atol=1e-9)
    assert np.max(np.abs(np.array(logged))) > 1.0  # mm/s: the hand moved the probe


# --- the screenshot's check -----------------------------------------------------------------------


def test_the_screenshot_check_finds_the_arm_in_the_docs_picture_and_not_in_a_blank_one(tmp_path):
    """The check `python -m hoh_cosim.view screenshot` applies (the command itself needs Chromium
    and some 15 s: docs/how-to/watch-a-run-live.md), on the page's own screenshot and on a picture
    of the viewer's background alone."""
    import matplotlib.image

    from hoh_cosim.view.screenshot import check_screenshot

    assert check_screenshot(ROOT / "docs" / "assets" / "view.png") is None
    blank = tmp_path / "blank.png"
    matplotlib.image.imsave(blank, np.full((100, 160, 3), 0.85))
    assert check_screenshot(blank) == (
        f"{blank}: 0 pixels of the arm's colour (at least 2000 expected): the arm does not show"
    )
