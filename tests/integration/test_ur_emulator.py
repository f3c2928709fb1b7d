"""The runner's real RTDE path, end to end: unmodified ur_rtde and `hoh-cosim hw run` against the
loopback UR controller (`hoh_cosim.rehearsal.ur_controller`), backed by the rehearsal world's arm, with the
FT-150 and FSE103 from the rehearsal's emulators.

ur_rtde always uses the ports 29999, 30003 and 30004, so every emulator here gets a loopback address
of its own (127.0.W.x, W the pytest-xdist worker's number, so that two workers never pick the same);
ur_rtde skips its remote-control check only for 127.0.0.1, so the others also exercise the
dashboard's `is in remote control`.
"""

from __future__ import annotations

import math
import os
import re
import signal
import socket
import struct
import subprocess
import sys
import time
from collections import Counter
from pathlib import Path

import numpy as np
import pytest
import rtde_control
import rtde_receive

from hoh_cosim.control.supervisor import STOP_FLAGS, Status
from hoh_cosim.errors import RunError
from hoh_cosim.hardware.robot import RtdeRobot
from hoh_cosim.hardware.session_log import read_session
from hoh_cosim.rehearsal import rtde_protocol as rtde
from hoh_cosim.rehearsal.rehearse import write_truth_calibration
from hoh_cosim.rehearsal.ur_controller import UrController, wait_for
from hoh_cosim.rehearsal.world import RehearsalWorld, WorldSetup
from tests.rtde_guide_client import GuideClient
from tests.xdist_groups import REAL_TIME

pytestmark = REAL_TIME


def _worker() -> int:
    """pytest-xdist's worker number (gw3: 3), 0 without xdist."""
    return int(os.environ.get("PYTEST_XDIST_WORKER", "gw0").removeprefix("gw"))


# a worker's own range: _free() only sees what is bound now, another worker may bind it next
_HOSTS = (f"127.0.{_worker()}.{i}" for i in range(11, 255))
WATCHDOG_HZ = 5.0  # 200 ms: a VM stall of 40 ms must not trip it, a dead runner must


def _free(host: str) -> str:
    for port in (29999, 30003, 30004):
        with socket.socket() as s:
            s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            s.bind((host, port))
    return host


def next_host() -> str:
    for host in _HOSTS:
        try:
            return _free(host)
        except OSError:
            continue
    raise AssertionError("no loopback address free")


def write_config(tmp_path: Path, world: RehearsalWorld, host: str) -> Path:
    write_truth_calibration(world.truth, tmp_path / "calibration.json")
    config = tmp_path / "rig.yaml"
    config.write_text(
        f"robot: {{host: {host}, watchdog_hz: {WATCHDOG_HZ}}}\n"
        f"ft150: {{host: 127.0.0.1, port: {world.ft_port}}}\n"
        f"probe: {{device: {world.pty_name}}}\n"
        "calibration: calibration.json\n"
        "rebias: {samples: 100}\n"
        "log_dir: sessions\n"
    )
    return config


def hw_run(config: Path, log: Path, *args: str) -> subprocess.Popen:
    """`hoh-cosim hw run` in a process of its own, its output into `log` + ".out" (a file, not a
    pipe: the session log's writer process inherits it and may outlive a killed runner)."""
    with Path(f"{log}.out").open("w") as out:
        return subprocess.Popen(
            [sys.executable, "-m", "hoh_cosim", "hw", "run", str(config), "--log", str(log), *args],
            stdout=out,
            stderr=subprocess.STDOUT,
            text=True,
        )


def finished(process: subprocess.Popen, log: Path, timeout_s: float) -> str:
    try:
        process.wait(timeout_s)
    finally:
        process.kill()
        process.wait(5)
    return Path(f"{log}.out").read_text()


def emulator_events(ur: UrController) -> str:
    """What the emulated controller did, for a failure's message."""
    ur.said("")  # collects the events
    return "\nemulator:\n" + "\n".join(text for _, text in ur.events[-40:])


def arm_speed(world: RehearsalWorld) -> float:
    return float(np.linalg.norm(world._state.read()[12:15]))


def last_log_time(log: Path) -> float:
    """The log time of the session log's last /robot message, Unix seconds."""
    from mcap.reader import make_reader

    with log.open("rb") as stream:
        times = [m.log_time for _, _, m in make_reader(stream).iter_messages(topics=["/robot"])]
    return max(times) / 1e9


@pytest.fixture
def rig(tmp_path):
    """A world whose hand starts circling at 7 s, and a UR e-series controller on its own address."""
    setup = WorldSetup(robot_rate_hz=500.0, task="circle", task_start_s=7.0)
    with RehearsalWorld(setup) as world, UrController(world, next_host()) as ur:
        yield world, ur, write_config(tmp_path, world, ur.host)


def test_hw_run_guides_the_emulated_robot_through_ur_rtde(rig, tmp_path):
    world, ur, config = rig
    log = tmp_path / "session.mcap"
    process = hw_run(config, log, "--seconds", "9")
    output = finished(process, log, 120)
    assert process.returncode == 0, output + emulator_events(ur)
    session = read_session(log)
    assert session.complete
    # ur_rtde talked to the controller as to a robot: program uploaded, watchdog set, speedL
    assert ur.said(r"^program started")
    assert ur.said(rf"^watchdog {WATCHDOG_HZ:g} Hz")
    assert ur.said(r"^command 10$")  # speedL
    assert ur.said(r"^program stopped: stopped by the client")  # stopScript at the end
    # the hand's circle moved the arm, and the arm followed the admittance law's command
    p = session.series("/robot", "p_BT_B")
    assert np.ptp(p[:, 0]) > 0.01
    sent = session.series("/command", "sent_B")[:, :3]
    moved = session.series("/robot", "twist_B")[:, :3]
    assert np.max(np.abs(sent)) > 0.005
    # A cycle whose FT-150 or probe sample came late (a busy machine) is stale: the supervisor sends
    # zero. That step is no lag of the arm's and no error of the admittance law's, so the two
    # checks below leave such cycles out, and ask for enough of the others to mean something.
    status = session.series("/command", "status").astype(int)
    stopped = (status & int(STOP_FLAGS)) != 0
    # the arm follows the sent twist late by the RTDE round trip, a cycle of the program and its
    # acceleration limit (1.5 m/s²: 40 ms to reach 6 cm/s): look up to 100 ms later; a zero step
    # takes it as long, so not within 100 ms (50 cycles) of a stopped cycle
    settled = np.convolve(stopped, np.ones(51, dtype=int))[: stopped.size] == 0
    assert np.count_nonzero(settled) > 1000, Counter(
        Status(int(flags)).describe() for flags in status[stopped]
    ).most_common(3)
    axis = int(np.argmax(np.ptp(sent, axis=0)))
    x, y = sent[:, axis], moved[:, axis]

    def followed(n: int) -> tuple[np.ndarray, np.ndarray]:
        """The sent twist, and the arm's n cycles later, where the command had settled."""
        keep = settled[: x.size - n]
        return x[: x.size - n][keep], y[n:][keep]

    lag = max(range(51), key=lambda n: np.corrcoef(*followed(n))[0, 1])
    assert np.corrcoef(*followed(lag))[0, 1] > 0.97
    slope = np.polyfit(*followed(lag), 1)[0]
    assert slope == pytest.approx(1.0, abs=0.15)
    # the command follows the estimated hand force (eq. 10: 0.0125 m/(s·N) beyond 0.95 N): where
    # nothing stopped or limited it, the twist sent is the law's, and it follows the force
    clean = status == 0
    np.testing.assert_array_equal(
        session.series("/command", "sent_B")[clean],
        session.series("/command", "twist_law_B")[clean],
    )
    force = session.series("/estimate", "F_hand_B")[:, 0]
    strong = (np.abs(force) > 2.0) & clean
    assert np.count_nonzero(strong) > 200
    assert np.corrcoef(force[strong], sent[strong, 0])[0, 1] > 0.95
    # and the robot stands still afterwards
    assert wait_for(lambda: arm_speed(world) < 1e-9, 1.0)


# A SIGKILL mid-motion, a protective or emergency stop and a dropped link are among the faults of
# `hoh-cosim hw campaign` (tests/integration/test_campaign.py), with stricter checks than a test
# of each had here: the arm still within a stated bound, the cause, the exit status, the log.


def test_ur_rtde_on_a_cb3_runs_at_125_hz(tmp_path):
    with (
        RehearsalWorld(WorldSetup(robot_rate_hz=125.0, task_start_s=1e6)) as world,
        UrController(world, next_host(), series="cb3") as ur,
    ):
        robot = RtdeRobot(ur.host, watchdog_hz=WATCHDOG_HZ)
        robot.connect()
        try:
            assert robot.period_s == pytest.approx(0.008)
            state = robot.state()
            assert state.program_running
            assert state.problem() is None
            np.testing.assert_allclose(state.p_BT_B, world._state.read()[0:3], atol=1e-3)
            pacer = robot.pacer()
            for _ in range(60):  # 0.48 s of commands at the controller's rate
                pacer.wait()
                robot.speed_l(np.array([0.02, 0, 0, 0, 0, 0]), 1.0)
                robot.kick_watchdog()
            # every speedL reached the program (a kick in the same cycle would have erased it)
            assert robot.state().twist_B[0] == pytest.approx(0.02, abs=1e-3)
        finally:
            robot.stop()
            robot.close()
        assert not ur.said(r"dashboard 'PolyscopeVersion'")  # a CB3: ur_rtde does not ask


# --- what a real controller refuses ---------------------------------------------------------------


class RawRtde:
    """A bare RTDE client: our own packages, to send what ur_rtde never would."""

    def __init__(self, host: str) -> None:
        self.sock = socket.create_connection((host, 30004), timeout=5.0)

    def ask(self, kind: str, payload: bytes = b"") -> rtde.Package:
        self.sock.sendall(rtde.pack(kind, payload))
        while True:
            package = rtde.read_package(self.sock)
            if package.kind not in ("U", "M"):  # the answer, past data and text messages
                return package

    def close(self) -> None:
        self.sock.close()


def test_the_emulator_refuses_what_a_controller_refuses():
    with (
        RehearsalWorld(WorldSetup(task_start_s=1e6)) as world,
        UrController(world, next_host()) as ur,
    ):
        a, b = RawRtde(ur.host), RawRtde(ur.host)
        try:
            assert a.ask("V", struct.pack(">H", 3)).payload == b"\x00"  # only protocols 1, 2
            assert a.ask("V", struct.pack(">H", 2)).payload == b"\x01"
            reply = a.ask("O", struct.pack(">d", 125.0) + b"timestamp,warp_factor")
            assert reply.payload[0] == 0
            assert reply.payload[1:] == b"DOUBLE,NOT_FOUND"
            reply = a.ask("O", struct.pack(">d", 1000.0) + b"timestamp")
            assert reply.payload[0] == 0  # faster than the controller's 500 Hz
            reply = a.ask("O", struct.pack(">d", 125.0) + b"timestamp,actual_TCP_pose")
            assert reply.payload == b"\x01DOUBLE,VECTOR6D"
            reply = a.ask("I", b"input_int_register_0,input_double_register_0")
            assert reply.payload == b"\x01INT32,DOUBLE"
            # another client may not write the same registers
            reply = b.ask("I", b"input_int_register_0")
            assert reply.payload == b"\x00IN_USE"
            # data before start is refused with a text message
            a.sock.sendall(rtde.pack("U", b"\x01" + struct.pack(">id", 10, 0.5)))
            message = rtde.read_package(a.sock)
            assert message.kind == "M"
            assert b"before start" in message.payload
            assert a.ask("S").payload == b"\x01"
            # no set-up once started
            assert a.ask("I", b"input_int_register_1").payload[0] == 0
            # a command with no program running moves nothing
            a.sock.sendall(rtde.pack("U", b"\x01" + struct.pack(">id", 10, 0.5)))
            assert wait_for(lambda: ur.said(r"^command 10 ignored: no program is running"), 2.0)
            assert arm_speed(world) < 1e-9
            assert not ur.said(r"^command 10$")
        finally:
            a.close()
            b.close()

        # the registers are free again once the controller has seen both connections go
        def closed() -> int:
            ur.said("")  # collect the events
            return sum("rtde connection closed" in text for _, text in ur.events)

        assert wait_for(lambda: closed() >= 2, 5.0)
        # ur_rtde sees the same refusals
        with pytest.raises(RuntimeError, match="not found"):
            rtde_receive.RTDEReceiveInterface(ur.host, -1.0, ["timestamp", "warp_factor"])
        control = rtde_control.RTDEControlInterface(ur.host)
        try:
            with pytest.raises(RuntimeError, match="already in use"):
                rtde_control.RTDEControlInterface(ur.host)
        finally:
            control.stopScript()
            control.disconnect()
        assert ur.said(r"dashboard 'is in remote control' -> 'true'")


def test_a_command_the_emulator_does_not_know_stops_the_program():
    with (
        RehearsalWorld(WorldSetup(task_start_s=1e6)) as world,
        UrController(world, next_host()) as ur,
    ):
        control = rtde_control.RTDEControlInterface(ur.host)
        try:
            assert control.isProgramRunning()
            assert not control.moveJ([0.0, -1.57, 1.57, -1.57, -1.57, 0.0], 0.1, 0.1)
            assert wait_for(lambda: not control.isProgramRunning(), 1.0)
            assert ur.said(r"command 1 is not emulated")
        finally:
            control.disconnect()
        assert arm_speed(world) < 1e-9


def test_hw_rehearse_through_the_emulated_controller(tmp_path, capsys):
    from hoh_cosim.cli import main

    host = next_host()
    log = tmp_path / "rehearsal.mcap"
    args = ["--ur-emulator", host, "--seconds", "4", "--rebias-samples", "100", "--log", str(log)]
    status = main(["hw", "rehearse", *args])
    out = capsys.readouterr().out
    assert status == 0, out
    assert f"UR controller emulated on {host} (ur-rtde)" in out
    assert "session ended: 4 s done" in out
    session = read_session(log)
    assert session.complete
    assert np.ptp(session.series("/robot", "p_BT_B")[:, 0]) > 0.005  # the hand moved the arm


# --- hw emulate: the devices alone, for clients we did not write ----------------------------------


def _started(process: subprocess.Popen, timeout_s: float = 60.0) -> dict[str, str]:
    """The lines `hw emulate` prints until "ready": where each device is."""
    seen: dict[str, str] = {}
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        line = process.stdout.readline()
        if not line:
            raise AssertionError(f"hw emulate ended before it was ready: {seen}")
        if line.startswith("ready"):
            return seen
        key, _, rest = line.partition(" on ")
        seen[key.strip()] = rest.strip()
    raise AssertionError(f"hw emulate not ready within {timeout_s} s: {seen}")


def test_hw_emulate_serves_a_dashboard_client_ur_rtde_and_raw_sensor_readers(tmp_path):
    from universal_robots_clients.dashboard_client import send_command

    host = next_host()
    process = subprocess.Popen(
        [sys.executable, "-m", "hoh_cosim", "hw", "emulate", "--host", host, "--ft-port", "0",
         "--seconds", "120"],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        # a pytest-xdist worker's children inherit SIGINT ignored: give it Python's default
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )  # fmt: skip
    try:
        where = _started(process)
        assert where["UR controller"].startswith(f"{host} (e-series, 500 Hz)"), where
        ft_host, ft_port = where["FT-150 stream"].rsplit(":", 1)
        assert ft_host == host

        # the dashboard, as a lab script drives it (universal-robots-clients: one connection per
        # command, the greeting read and dropped, the reply line returned as it is)
        dialogue = [
            ("get robot model", "UR5"),
            ("get loaded program", "No program loaded"),
            ("load nothing.txt", "File not found: nothing.txt"),
            ("load /programs/scan.urp", "Loading program: /programs/scan.urp"),
            ("get loaded program", "Loaded program: /programs/scan.urp"),
            ("isProgramSaved", "true /programs/scan.urp"),
            ("get operational mode", "NONE"),
            ("power off", "Powering off"),
            ("robotmode", "Robotmode: POWER_OFF"),
            ("play", "Failed to execute: play"),
            ("power on", "Powering on"),
            ("robotmode", "Robotmode: IDLE"),
            ("brake release", "Brake releasing"),
            ("robotmode", "Robotmode: RUNNING"),
            ("play", "Starting program"),
            ("programState", "PLAYING /programs/scan.urp"),
            ("running", "Program running: true"),
            ("pause", "Pausing program"),
            ("programState", "PAUSED /programs/scan.urp"),
            ("stop", "Stopped"),
            ("programState", "STOPPED /programs/scan.urp"),
            ("pause", "Failed to execute: pause"),
        ]
        replies = [(command, send_command(host, command)) for command, _ in dialogue]
        assert replies == dialogue
        assert send_command(host, "clear operational mode").startswith(
            "No longer controlling the operational mode. Current operational mode: "
        )

        # RTDE through ur-rtde's receive interface: the arm's pose and the controller's clock
        # ur-rtde asks for every output it knows unless told: the emulator refuses the ones it
        # does not model (joint currents ...), so a client names what it reads
        receive = rtde_receive.RTDEReceiveInterface(host, 500.0, ["timestamp", "actual_TCP_pose"])
        try:
            first = receive.getTimestamp()
            time.sleep(0.3)
            assert receive.getTimestamp() > first
            assert len(receive.getActualTCPPose()) == 6
        finally:
            receive.disconnect()

        # the FT-150 stream's bytes and the FSE103's frames, as any reader gets them
        with socket.create_connection((host, int(ft_port)), timeout=5.0) as ft:
            received = b""
            deadline = time.monotonic() + 2.0
            while len(received) < 500 and time.monotonic() < deadline:
                received += ft.recv(4096)
        assert len(received) >= 500
        fd = os.open(where["FSE103"], os.O_RDONLY | os.O_NOCTTY)
        try:
            assert len(os.read(fd, 64)) > 0
        finally:
            os.close(fd)
    finally:
        process.send_signal(signal.SIGINT)
        try:
            output = process.communicate(timeout=30)[0]
        except subprocess.TimeoutExpired:
            process.kill()
            output = process.communicate()[0] + "\n(killed: Ctrl-C did not end it in 30 s)"
    assert process.returncode == 130, output  # Ctrl-C: "interrupted", as everywhere
    assert "interrupted" in output, output


def test_hw_emulate_refuses_a_host_off_loopback_unless_allowed():
    done = subprocess.run(
        [sys.executable, "-m", "hoh_cosim", "hw", "emulate", "--host", "192.0.2.1"],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode == 2
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1
    assert "192.0.2.1 is not a loopback address" in lines[0]
    assert "--allow-remote" in lines[0]


# --- RTDE as UR's guide describes it, through a client written from the guide ------------------


def test_hw_run_with_no_controller_at_the_address_ends_in_one_line_and_a_whole_log(tmp_path):
    setup = WorldSetup(robot_rate_hz=500.0, task="circle", task_start_s=7.0)
    with RehearsalWorld(setup) as world:
        config = write_config(tmp_path, world, next_host())  # nothing listens there
        log = tmp_path / "session.mcap"
        process = hw_run(config, log, "--seconds", "3")
        output = finished(process, log, 120)
    assert process.returncode == 1, output
    assert "Traceback" not in output, output
    assert re.search(
        r"^session ended: UR controller at [\d.]+ \(RTDE\): cannot connect", output, re.M
    )
    session = read_session(log)
    assert session.complete
    ends = [m for m in session.messages["/events"] if m["event"] == "end"]
    assert [m["t"] for m in ends] == [0.0], session.messages["/events"]


@pytest.fixture
def still_rig():
    """A world whose hand pushes the handle with 5 N along x from the start, behind an e-series."""
    setup = WorldSetup(robot_rate_hz=500.0, task="push_release", task_start_s=0.0)
    with RehearsalWorld(setup) as world, UrController(world, next_host()) as ur:
        yield world, ur


def test_protocol_1_outputs_come_without_a_recipe_id_at_the_controller_rate(still_rig):
    _, ur = still_rig
    with GuideClient(ur.host) as client:
        assert client.request_version(1)
        recipe, types = client.setup_outputs(["timestamp", "actual_q"])
        assert recipe is None  # version 1: the types only
        assert types == ["DOUBLE", "VECTOR6D"]
        assert client.start()
        stamps = [client.outputs()[0] for _ in range(200)]
    rate = (len(stamps) - 1) / (stamps[-1] - stamps[0])
    assert 400 < rate < 600  # every 2 ms cycle of the world's clock (500 Hz)


@pytest.mark.parametrize(("asked_hz", "every"), [(100.0, 5), (200.0, 2), (300.0, 1), (125.0, 4)])
def test_protocol_2_streams_every_floor_of_rate_over_frequency_cycles(still_rig, asked_hz, every):
    _, ur = still_rig
    with GuideClient(ur.host) as client:
        assert client.request_version(2)
        recipe, _ = client.setup_outputs(["timestamp"], asked_hz)
        assert recipe == 1
        assert client.start()
        stamps = [client.outputs()[0] for _ in range(60)]
    # the controller's clock between packages: exactly `every` cycles, however late they come
    assert np.diff(stamps) == pytest.approx([every * 0.002] * (len(stamps) - 1), abs=1e-9)


@pytest.mark.parametrize("asked_hz", [0.0, -5.0, 600.0])
def test_an_output_frequency_out_of_range_is_refused_at_set_up_with_a_reason(still_rig, asked_hz):
    _, ur = still_rig
    with GuideClient(ur.host) as client:
        assert client.request_version(2)
        recipe, _ = client.setup_outputs(["timestamp"], asked_hz)
        assert recipe == 0
        assert any("outside 0 < f <= 500 Hz" in m[0] for m in client.messages), client.messages
        assert not client.start()


def test_an_output_the_emulator_does_not_model_is_not_found_never_a_silent_zero(still_rig):
    _, ur = still_rig
    with GuideClient(ur.host) as client:
        assert client.request_version(2)
        recipe, types = client.setup_outputs(["actual_qd", "actual_current", "timestamp"], 125.0)
        assert recipe == 0
        assert types == ["VECTOR6D", "NOT_FOUND", "DOUBLE"]
        assert any("actual_current" in m[0] for m in client.messages)
        assert not client.start()


def test_the_tcp_force_is_the_hands_push_and_the_clock_is_the_controllers(still_rig):
    world, ur = still_rig
    with GuideClient(ur.host) as client:
        assert client.request_version(2)
        client.setup_outputs(["timestamp", "actual_TCP_force", "tcp_force_scalar", "actual_qd"])
        assert client.start()
        timestamp, wrench, scalar, qd = client.latest(0.5)
        world_time = float(world._state.read()[23])
    # the operator pushes 5 N along x at the handle (push_release): the TCP feels it
    assert wrench[:3] == pytest.approx([5.0, 0.0, 0.0], abs=1e-6)
    assert scalar == pytest.approx(5.0, abs=1e-6)
    assert qd == pytest.approx([0.0] * 6, abs=1e-12)  # nothing commands the arm: it stands
    # the controller's own clock: whole 2 ms periods, started from the world's time
    assert timestamp / 0.002 == pytest.approx(round(timestamp / 0.002), abs=1e-6)
    assert abs(timestamp - world_time) < 0.1


def _spin(stop) -> None:
    while not stop.is_set():
        pass


def test_a_cb3_stamps_exact_8_ms_steps_at_125_hz_with_both_cores_loaded():
    """A client written from UR's RTDE guide, a 125 Hz recipe from a CB3, while two busy processes
    load both cores: the timestamps step by exactly 8 ms (the controller's clock), however late
    the packets arrive."""
    import multiprocessing

    setup = WorldSetup(robot_rate_hz=125.0, task="push_release", task_start_s=0.0)
    context = multiprocessing.get_context("spawn")
    stop = context.Event()
    hogs = [context.Process(target=_spin, args=(stop,), daemon=True) for _ in range(2)]
    with RehearsalWorld(setup) as world, UrController(world, next_host(), series="cb3") as ur:
        for hog in hogs:
            hog.start()
        try:
            with GuideClient(ur.host) as client:
                assert client.request_version(2)
                recipe, _ = client.setup_outputs(["timestamp"], 125.0)
                assert recipe == 1
                assert client.start()
                stamps = [client.outputs()[0] for _ in range(250)]  # 2 s
        finally:
            stop.set()
            for hog in hogs:
                hog.join(5)
    assert np.diff(stamps) == pytest.approx([0.008] * (len(stamps) - 1), abs=1e-9)
    assert stamps[0] / 0.008 == pytest.approx(round(stamps[0] / 0.008), abs=1e-6)


def test_a_world_and_a_controller_the_machine_holds_back_measure_how_long(still_rig):
    # the campaign tells a run whose emulated devices stood still (rig_stall_ms) by these
    world, ur = still_rig
    time.sleep(0.2)
    for pid in (world._process.pid, ur._process.pid):
        os.kill(pid, signal.SIGSTOP)
    time.sleep(0.3)
    for pid in (world._process.pid, ur._process.pid):
        os.kill(pid, signal.SIGCONT)
    assert wait_for(lambda: ur.said(r"^stalled \d+ ms$"), 2.0)
    stalled = [int(text.split()[1]) for _, text in ur.events if text.startswith("stalled")]
    assert max(stalled) >= 250
    longest, at = world.stall()
    assert longest >= 0.25
    # the world time the stall began at: after the first turns, not after the time published now
    assert 0.1 < at <= float(world._state.read()[23])


def _look(robot: RtdeRobot, seconds: float) -> None:
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        robot.state()
        time.sleep(0.002)


def test_the_links_silence_counts_only_while_the_loop_looks(still_rig):
    # a frozen controller: nothing new arrives, as on a link whose state is stale
    _, ur = still_rig
    robot = RtdeRobot(ur.host, watchdog_hz=WATCHDOG_HZ)
    robot.connect()
    os.kill(ur._process.pid, signal.SIGSTOP)
    try:
        for _ in range(25):  # 50 ms of looks: not yet silent for 100 ms
            robot.state()
            time.sleep(0.002)
        time.sleep(0.3)  # the loop itself stalled: it saw nothing, so nothing counts
        robot.state()
        with pytest.raises(RunError, match=r"no new state for \d+ ms"):
            _look(robot, 1.0)  # looking again, the silence counts and ends it
    finally:
        os.kill(ur._process.pid, signal.SIGCONT)
        robot.stop()
        robot.close()


def test_a_clients_text_message_reaches_the_controllers_log(still_rig):
    _, ur = still_rig
    with GuideClient(ur.host) as client:
        assert client.request_version(2)
        client.text("calibration done", "lab script", 3)
        client.request_version(2)  # a request after it: the message has been read by then
    assert ur.said(r"^rtde message from lab script \(info\): calibration done$")


def test_actual_qd_follows_the_arm_under_speedl(still_rig):
    world, ur = still_rig
    assert math.isnan(world.last_moving())  # nothing has moved the arm yet
    control = rtde_control.RTDEControlInterface(ur.host, 500.0)
    try:
        with GuideClient(ur.host) as client:
            assert client.request_version(2)
            client.setup_outputs(["actual_qd", "actual_TCP_speed"], 500.0)
            assert client.start()
            deadline = time.monotonic() + 1.0
            while time.monotonic() < deadline:
                control.speedL([0.02, 0.0, 0.0, 0.0, 0.0, 0.0], 0.5, 0.0)
                time.sleep(0.01)
            qd, speed = client.latest(0.05)
    finally:
        control.speedStop()
        control.stopScript()
        control.disconnect()
    assert speed[0] == pytest.approx(0.02, abs=2e-3)
    assert max(abs(x) for x in qd) > 0.005  # joints turn for a TCP at 2 cm/s
    # stopped, the arm comes to rest in its ramp, and the world says when, on its own clock
    assert wait_for(lambda: float(world._state.read()[23]) > world.last_moving() + 0.2, 3.0)
    moved_until = world.last_moving()
    time.sleep(0.1)
    assert world.last_moving() == moved_until
    assert float(np.linalg.norm(world._state.read()[12:18])) <= 1e-9


def test_every_output_of_the_guide_is_emulated_a_register_or_refused():
    """No output is a silent zero: each is in the emulator's state, a register (0 until written,
    as on a controller), or refused at set-up (NOT_EMULATED)."""
    import multiprocessing

    from hoh_cosim.rehearsal import ur_controller, world

    state_memory = multiprocessing.RawArray("d", 1 + world._STATE)
    state_memory[4:13] = np.eye(3).reshape(9).tolist()  # R_BT: a rotation
    shared = ur_controller._SharedWorld(
        state_memory, multiprocessing.RawArray("d", 1 + world._COMMAND)
    )
    emulator = ur_controller._Emulator(
        shared, host="127.0.0.1", ports={}, series="e", remote_control=True
    )
    state = emulator._state()
    registers = {n for n in rtde.OUTPUTS if "register" in n}
    silent = set(rtde.OUTPUTS) - set(state) - registers - ur_controller.NOT_EMULATED
    assert silent == set()
    assert not (set(state) & ur_controller.NOT_EMULATED)


def test_a_session_child_leaves_its_rtde_connections_for_its_exit_to_close(still_rig):
    # `hw run`'s session process ends with os._exit (hoh_cosim.hardware.isolation): ur-rtde's
    # disconnect, a fixed half-second sleep per interface, would be paid for nothing there
    from hoh_cosim.hardware import robot as robot_module
    from hoh_cosim.hardware.isolation import ends_without_cleanup, in_child

    _, ur = still_rig

    def session() -> int:
        robot = RtdeRobot(ur.host, watchdog_hz=WATCHDOG_HZ)
        robot.connect()
        kept = len(robot_module._ABANDONED)
        robot.stop()
        robot.close()
        return 0 if ends_without_cleanup() and len(robot_module._ABANDONED) == kept + 2 else 3

    assert not ends_without_cleanup()
    assert in_child(session) == 0

    # the child's end closed both connections, and the controller saw it
    def closed() -> int:
        ur.said("")
        return sum(text.startswith("rtde connection closed") for _, text in ur.events)

    assert wait_for(lambda: closed() >= 2, 5.0), emulator_events(ur)
    assert ur.said(r"^program stopped: stopped by the client")
