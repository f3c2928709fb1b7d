"""The runner's real RTDE path, end to end: unmodified ur_rtde and `hoh-cosim hw run` against the
loopback UR controller (`hoh_cosim.rehearsal.ur_controller`), backed by the rehearsal world's arm, with the
FT-150 and FSE103 from the rehearsal's emulators.

ur_rtde always uses the ports 29999, 30003 and 30004, so every emulator here gets a loopback address
of its own (127.0.W.x, W the pytest-xdist worker's number, so that two workers never pick the same);
ur_rtde skips its remote-control check only for 127.0.0.1, so the others also exercise the
dashboard's `is in remote control`.
"""

from __future__ import annotations

import dataclasses
import os
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

from hoh_cosim.calibration import write_calibration
from hoh_cosim.control.supervisor import STOP_FLAGS, Status
from hoh_cosim.hardware.robot import RtdeRobot
from hoh_cosim.hardware.session_log import read_session
from hoh_cosim.rehearsal import rtde_protocol as rtde
from hoh_cosim.rehearsal.rehearse import truth_calibration
from hoh_cosim.rehearsal.ur_controller import UrController, wait_for
from hoh_cosim.rehearsal.world import RehearsalWorld, WorldSetup
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
    # the world's truth, as a perfect `hoh-cosim hw calibrate` would write it
    zeros = np.zeros(6)
    calibration = dataclasses.replace(
        truth_calibration(world.truth),
        n_poses=32,
        condition_number=1.0,
        residual_rms_before=zeros,
        residual_max_before=zeros,
        residual_rms_after=zeros,
        residual_max_after=zeros,
    )
    write_calibration(tmp_path / "calibration.json", calibration)
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
    assert process.returncode == 0, output
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


def test_sigkill_mid_motion_the_watchdog_stops_the_arm_and_the_log_is_readable(rig, tmp_path):
    world, ur, config = rig
    log = tmp_path / "session.mcap"
    process = hw_run(config, log)
    try:
        assert wait_for(lambda: arm_speed(world) > 0.01, 60.0), "the arm never moved"
        time.sleep(1.5)
        killed, killed_unix = time.monotonic(), time.time()
        process.send_signal(signal.SIGKILL)
        process.wait(10)
        assert wait_for(lambda: arm_speed(world) < 1e-9, 1.0 / WATCHDOG_HZ + 0.3)
        stopped = time.monotonic() - killed
    finally:
        process.kill()
        process.wait(5)
    assert stopped < 1.0 / WATCHDOG_HZ + 0.3
    assert ur.said(r"^watchdog: no command for \d+ ms")
    assert ur.said(r"^program stopped: watchdog")
    # the log's writer notices that its runner is gone, writes what it has and closes the file
    assert wait_for(lambda: read_session(log).complete, 10.0)
    session = read_session(log)
    assert "end" not in [m["event"] for m in session.messages["/events"]]
    t = np.array([m["t"] for m in session.messages["/robot"]])
    assert t.size > 500
    # up to the last second before the kill. A message's log time is the session's start on the
    # wall clock plus its cycle's time, so it falls behind the wall clock by the runner's start-up
    # and by whatever the pacing lost (on a busy machine, seconds): the last cycle logged is timed
    # by when its FT-150 sample arrived (the monotonic clock), and log times only never run ahead
    received = session.series("/ft150", "received_s")
    assert 0.0 < killed - received[-1] < 1.5
    assert killed_unix - last_log_time(log) > 0.0


@pytest.mark.parametrize(
    ("fault", "cause"),
    [
        ("protective_stop", "the robot is in a protective stop"),
        ("emergency_stop", "the robot is emergency-stopped"),
        ("drop_connection", "the connection to the controller was lost"),
    ],
)
def test_an_injected_fault_stops_the_runner_and_names_the_cause(rig, tmp_path, fault, cause):
    world, ur, config = rig
    log = tmp_path / "session.mcap"
    process = hw_run(config, log, "--seconds", "30")
    try:
        assert wait_for(lambda: ur.said(r"^watchdog"), 60.0)
        assert wait_for(lambda: arm_speed(world) > 0.005, 30.0)
        ur.inject(fault)
    finally:
        output = finished(process, log, 30)
    ur.said("")  # collect the emulator's events, for the message
    assert cause in output, output + "\nemulator:\n" + "\n".join(text for _, text in ur.events)
    if fault == "drop_connection":
        # the runner stops and says why; then ur_rtde 1.6.5's own reconnecting thread may abort
        # the process on its way out ("terminate called ... read: End of file", SIGABRT)
        assert process.returncode in (1, -signal.SIGABRT, -signal.SIGSEGV), output
    else:
        assert process.returncode == 1, output
    assert wait_for(lambda: arm_speed(world) < 1e-9, 1.0)
    session = read_session(log)
    assert session.complete
    assert cause in session.messages["/events"][-1]["detail"]


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
            if package.kind != "U":
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
            assert a.ask("V", struct.pack(">H", 3)).payload == b"\x00"  # only protocol 2
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
