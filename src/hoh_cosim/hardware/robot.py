"""The UR5 behind one small interface: read its state, command a speedL twist, stop it.

`RtdeRobot` is the real one, through ur-rtde's RTDEReceiveInterface and RTDEControlInterface (seed
000, section 2: the seed drove its UR5 over RTDE). The rehearsal's simulated robot
(`hoh_cosim.rehearsal.world.SimulatedRobot`) offers the same methods, so the runner cannot tell them
apart.

Safety (DESIGN.md §7, notes/hardware.md): the control interface uploads a URScript program that keeps
executing the last speed command, so a process that hangs or dies would leave the robot moving.
`pacer()` enables ur-rtde's watchdog (the controller stops the program when no command arrives for
`1/watchdog_hz` s) as the cycles start, the runner commands or kicks every cycle, and `stop()`
(speedStop, then stopScript) is called from a `finally`; it never raises, since it runs while
something else has already gone wrong. `hoh_cosim.rehearsal.ur_controller` serves a controller on loopback
for tests.
"""

from __future__ import annotations

import contextlib
import math
import os
import time
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from hoh_cosim.control.frames import rotvec_to_matrix
from hoh_cosim.control.vectors import Rot3, Vec, Vec3
from hoh_cosim.errors import RunError
from hoh_cosim.hardware.isolation import ends_without_cleanup

__all__ = [
    "ROBOT_MODE_RUNNING",
    "SAFETY_MODE_NORMAL",
    "Pacer",
    "Robot",
    "RobotState",
    "RtdeRobot",
    "named_problem",
]

ROBOT_MODE_RUNNING = 7
"""UR's robot mode when the arm is powered, brakes released and ready (RTDE `robot_mode`)."""
SAFETY_MODE_NORMAL = 1
"""UR's safety mode in normal operation (RTDE `safety_mode`); 2 is reduced, 3 protective stop."""
UNSEEN_S = 0.02
"""[s] Two looks at the controller's state further apart than this (ten e-series cycles) mean the
loop itself stalled: the time past it is not counted as the link's silence."""


@dataclass(frozen=True)
class RobotState:
    """What the loop needs of the robot in one cycle."""

    p_BT_B: Vec3  # TCP position [m]
    R_BT: Rot3  # TCP orientation
    twist_B: Vec  # actual TCP twist [v; ω] [m/s, rad/s]
    robot_mode: int
    safety_mode: int
    protective_stop: bool
    emergency_stop: bool
    program_running: bool
    timestamp_s: float  # the controller's own clock
    rotvec_BT: Vec3 | None = None  # R_BT as RTDE gives it, where the robot gives it so

    def problem(self) -> str | None:
        """Why the robot cannot be commanded now, or None."""
        if self.emergency_stop:
            return "the robot is emergency-stopped"
        if self.protective_stop:
            return "the robot is in a protective stop"
        if not self.program_running:
            return "the control program on the robot is not running"
        if self.robot_mode != ROBOT_MODE_RUNNING:
            return f"the robot is not running (robot mode {self.robot_mode})"
        return None


class Robot(Protocol):
    """The interface the runner drives; `RtdeRobot` and the rehearsal's simulated robot offer it."""

    period_s: float

    def connect(self) -> None: ...
    def pacer(self) -> Any: ...  # an object whose wait() starts each cycle, returning lateness
    def state(self) -> RobotState: ...
    def speed_l(self, twist_B: Vec, acceleration: float) -> None: ...
    def kick_watchdog(self) -> None: ...
    def stop(self) -> None: ...
    def close(self) -> None: ...
    def describe(self) -> str: ...


def named_problem(robot: Robot, state: RobotState, settle_s: float = 0.05) -> str | None:
    """`state.problem()`, with the reason for a stopped program if one comes within `settle_s`.

    The program's status and the safety status reach us over two RTDE connections (ur_rtde's
    control and receive interfaces), so a protective or emergency stop, which also stops the
    program, can show as "program not running" a packet before its safety bits arrive. The robot
    has stopped by then; reading it again for a few cycles costs nothing and names the first cause.
    """
    problem = state.problem()
    if problem is None or state.emergency_stop or state.protective_stop or state.program_running:
        return problem
    deadline = time.monotonic() + settle_s
    while time.monotonic() < deadline:
        time.sleep(robot.period_s)
        try:
            later = robot.state().problem()
        except RunError:  # the link went: the first reading stands
            break
        if later is not None and later != problem:
            return later
    return problem


class Pacer:
    """An absolute schedule of cycle starts: sleep until shortly before each, then spin.

    `wait()` returns the lateness of the cycle's start [s] (its jitter). A cycle that starts more
    than a whole period late is an overrun: the schedule then restarts from now instead of running
    the missed cycles back to back.
    """

    def __init__(self, period_s: float, spin_s: float = 3e-4) -> None:
        self.period_s = period_s
        self.spin_s = spin_s
        self.next_s: float | None = None
        self.overruns = 0

    def wait(self) -> float:
        now = time.perf_counter()
        if self.next_s is None:
            self.next_s = now
            return 0.0
        self.next_s += self.period_s
        target = self.next_s
        if target - now > self.spin_s:
            time.sleep(target - now - self.spin_s)
        while (now := time.perf_counter()) < target:
            pass
        late = now - target
        if late > self.period_s:
            self.overruns += 1
            self.next_s = now
        return late


class _RtdePacer:
    """Cycle starts from ur-rtde's own period helpers (`initPeriod` / `waitPeriod`), with the same
    lateness figures as `Pacer` measured around them."""

    def __init__(self, control: Any, period_s: float) -> None:
        self.control = control
        self.period_s = period_s
        self.started: Any = None
        self.next_s: float | None = None
        self.overruns = 0

    def wait(self) -> float:
        if self.started is not None:
            self.control.waitPeriod(self.started)
        self.started = self.control.initPeriod()
        now = time.perf_counter()
        if self.next_s is None:
            self.next_s = now
            return 0.0
        self.next_s += self.period_s
        late = max(0.0, now - self.next_s)
        if late > self.period_s:
            self.overruns += 1
            self.next_s = now
        return late


def _thread_ids() -> set[int]:
    """This process's threads (Linux: /proc/self/task), empty where that cannot be read."""
    try:
        return {int(name) for name in os.listdir("/proc/self/task")}
    except OSError:
        return set()


_ABANDONED: list[Any] = []  # ur-rtde interfaces never destroyed (see RtdeRobot.close())


RECEIVED = [
    "timestamp",
    "actual_TCP_pose",
    "actual_TCP_speed",
    "robot_mode",
    "safety_mode",
    "safety_status_bits",
]
"""What `RtdeRobot.state` reads through ur-rtde's receive interface: only these are asked for (its
default is every output it knows, at 500 Hz)."""


class RtdeRobot:
    """A UR controller over RTDE with ur-rtde (installed with `pip install "hoh-cosim[hardware]"`)."""

    def __init__(
        self,
        host: str,
        *,
        frequency_hz: float = -1.0,
        watchdog_hz: float = 20.0,
        stop_deceleration: float = 2.0,
        rt_priority: int = 0,
    ) -> None:
        self.host = host
        self.rt_priority = rt_priority
        self.frequency_hz = frequency_hz
        self.watchdog_hz = watchdog_hz
        self.stop_deceleration = stop_deceleration
        self.period_s = 1.0 / frequency_hz if frequency_hz > 0 else math.nan
        self._control: Any = None
        self._receive: Any = None
        self._commanded = False  # a speedL since the last kick (see kick_watchdog)
        self.silence_s = 0.1  # no new controller state for this long: the link is gone
        self._last_timestamp = math.nan
        self._last_change = self._last_look = time.monotonic()
        self._lost = False
        self._watchdog_on = False
        self.helper_thread_ids: tuple[int, ...] = ()  # ur-rtde's own threads, once connected

    def describe(self) -> str:
        return f"UR controller at {self.host} (RTDE)"

    def connect(self) -> None:
        self._lost = self._watchdog_on = self._commanded = False
        self._last_timestamp = math.nan
        self._last_change = self._last_look = time.monotonic()
        try:
            import rtde_control
            import rtde_receive
        except ImportError:
            raise RunError('ur-rtde is not installed: pip install "hoh-cosim[hardware]"') from None
        before = _thread_ids()
        try:
            self._receive = rtde_receive.RTDEReceiveInterface(
                self.host, self.frequency_hz, RECEIVED, rt_priority=self.rt_priority
            )
            self._control = rtde_control.RTDEControlInterface(
                self.host, self.frequency_hz, rt_priority=self.rt_priority
            )
        except RuntimeError as exc:
            self.close()
            raise RunError(f"{self.describe()}: cannot connect: {exc}") from None
        # the threads ur-rtde started (its receivers): a real-time loop must raise them with
        # itself, or wait on them (its rt_priority argument left them at the default here)
        self.helper_thread_ids = tuple(sorted(_thread_ids() - before))
        if math.isnan(self.period_s):
            self.period_s = self._step_time()

    def _step_time(self) -> float:
        """The controller's cycle. ur-rtde's getStepTime returns the register the control program
        writes when asked, as it is when asked: the first call after the program starts reads 0,
        so ask until the answer is a cycle (measured on the emulated controller)."""
        for _ in range(50):
            step = float(self._control.getStepTime())
            if 0.0 < step <= 0.1:
                return step
            time.sleep(0.005)
        self.stop()
        raise RunError(f"{self.describe()}: the controller did not tell its cycle time")

    def pacer(self) -> _RtdePacer:
        """The cycles' clock; the watchdog starts here, with the first paced cycle: from now on a
        command or a kick goes out every cycle. (Started in connect(), it stopped the program
        while the runner waited for the sensors' first samples, on the emulated controller.)"""
        control, _ = self._need()
        if not self._watchdog_on:
            if not control.setWatchdog(self.watchdog_hz):
                self.stop()
                raise RunError(f"{self.describe()}: the watchdog could not be enabled")
            self._watchdog_on = True
        return _RtdePacer(control, self.period_s)

    def _need(self) -> tuple[Any, Any]:
        if self._control is None or self._receive is None:
            raise RunError(f"{self.describe()}: not connected")
        return self._control, self._receive

    def state(self) -> RobotState:
        control, receive = self._need()
        # ur-rtde's getters keep returning the last values when the connection is gone, and a
        # silent link (a pulled cable) closes nothing for seconds: the controller's clock must move
        if not (receive.isConnected() and control.isConnected()):
            self._lost = True
            raise RunError(f"{self.describe()}: the connection to the controller was lost")
        timestamp = float(receive.getTimestamp())
        now = time.monotonic()
        # The link's silence counts only while this process looked: a loop that did not come here
        # for a while (this process starved) saw nothing, and ur-rtde's receiver, starved with
        # it, may not have caught up yet; the robot's watchdog judges such a stall (the runner's
        # starved cause), not this check. Seen: "no new state for 148 ms" from a loop that the
        # controller saw send nothing for 202 ms.
        unseen = now - self._last_look - UNSEEN_S
        self._last_look = now
        if unseen > 0.0:
            self._last_change += unseen
        if timestamp != self._last_timestamp:
            self._last_timestamp, self._last_change = timestamp, now
        elif now - self._last_change > self.silence_s:
            self._lost = True
            raise RunError(
                f"{self.describe()}: the connection to the controller was lost (no new state for "
                f"{1e3 * (now - self._last_change):.0f} ms)"
            )
        pose = receive.getActualTCPPose()
        return RobotState(
            p_BT_B=np.array(pose[:3], dtype=float),
            R_BT=rotvec_to_matrix(pose[3:]),
            twist_B=np.array(receive.getActualTCPSpeed(), dtype=float),
            robot_mode=int(receive.getRobotMode()),
            safety_mode=int(receive.getSafetyMode()),
            protective_stop=bool(receive.isProtectiveStopped()),
            emergency_stop=bool(receive.isEmergencyStopped()),
            program_running=bool(control.isProgramRunning()),
            timestamp_s=timestamp,
            rotvec_BT=np.array(pose[3:], dtype=float),
        )

    def speed_l(self, twist_B: Vec, acceleration: float) -> None:
        control, _ = self._need()
        self._commanded = True
        if not control.speedL([float(x) for x in twist_B], float(acceleration), 0.0):
            # refused: name why, as the robot reports it now (a stop may have come since state(),
            # its safety bits perhaps a packet after the stopped program: named_problem)
            problem = named_problem(self, self.state())
            raise RunError(
                f"{self.describe()}: speedL was refused" + (f": {problem}" if problem else "")
            )

    def kick_watchdog(self) -> None:
        """Kick the watchdog, unless a speedL went out since the last kick: that was the kick.

        ur-rtde's control program reads its command register (`input_int_register_0`, also the
        watchdog's) once per controller cycle, and kickWatchdog writes 0 there. Sent right after a
        speedL in the same cycle, the kick overwrote the speedL before the program saw it: on the
        emulated controller at 125 Hz no speedL of a whole session got through."""
        control, _ = self._need()
        if self._commanded:
            self._commanded = False
            return
        control.kickWatchdog()

    def stop(self) -> None:
        control = self._control
        if control is None or self._lost:
            # a controller that cannot hear us cannot be stopped from here (ur-rtde's stopScript
            # would wait minutes for it): its watchdog stops the program and the arm
            return
        with contextlib.suppress(Exception):
            control.speedStop(self.stop_deceleration)
        with contextlib.suppress(Exception):
            control.stopScript()

    def close(self) -> None:
        if self._lost or ends_without_cleanup():
            # Lost: ur-rtde's own threads are reconnecting by now; a disconnect() racing them
            # aborted the process (measured on the emulated controller), and the interfaces'
            # destructors disconnect too. In a process that ends with os._exit (`hw run`'s and `hw
            # calibrate`'s session, the program already stopped): a disconnect is half a second
            # per interface for nothing. Either way: keep them alive, their sockets go with the
            # process.
            _ABANDONED.extend(i for i in (self._control, self._receive) if i is not None)
            self._control = self._receive = None
            return
        # Dropped, not disconnect()ed: ur-rtde's disconnect() ends in a fixed half-second sleep
        # (holding the interpreter's lock) and its destructor calls it again, so an explicit call
        # cost a second per interface where the destructor alone costs half of it (measured).
        self._control = self._receive = None
