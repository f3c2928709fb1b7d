"""Devices without hardware, for rehearsing the hardware runner: the same bytes, the same timing.

A `World` runs in a process of its own (so it never competes with the runner for the interpreter)
and advances the simulated world of this package in real time, 1 ms a tick:

- the arm under speedL, the tool, the phantom and the operator's hand (`Plant`, `Operator`);
- an FT-150 stream server on loopback: the FT-150 model's packets, as the URCap's daemon writes
  them, to one TCP client at a time (a second client is turned away);
- an FSE103 on a pseudo-terminal in raw mode: the FSE103 model's packets as serial frames; or
  instead (`WorldSetup.probe_sensor`) the load cell's Arduino there, the load cell model's readings
  as its ASCII lines (`hoh_cosim.hardware.loadcell`), its faults the model's parameters
  (`WorldSetup.loadcell`: saturated, open circuit, a drifting zero); or no probe sensor;
- the robot's side of `SimulatedRobot`: state out and commands in through shared memory, with the UR
  controller's habits: the watchdog (no kick for 1/watchdog_hz s: the program stops), speedStop,
  stopScript, a protective stop.

Faults (`hoh_cosim.rehearsal.faults`) are scheduled at world times, or injected while the world runs
(`RehearsalWorld.inject`, as a fault campaign does), each for a duration or for good.
"""

from __future__ import annotations

import contextlib
import dataclasses
import math
import multiprocessing as mp
import os
import pty
import queue
import socket
import threading
import time
import tty
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from hoh_cosim.control.cycle import PROBE_SENSORS
from hoh_cosim.control.frames import matrix_to_rotvec
from hoh_cosim.control.loadcell import R_SL_SEED
from hoh_cosim.control.vectors import Vec
from hoh_cosim.errors import ConfigError, RunError
from hoh_cosim.hardware.robot import ROBOT_MODE_RUNNING, SAFETY_MODE_NORMAL, Pacer, RobotState
from hoh_cosim.rehearsal.faults import FAULTS, Fault
from hoh_cosim.rehearsal.planted import Planted
from hoh_cosim.rehearsal.priorities import HARDWARE_PRIORITY
from plant_models.arm import ArmParams
from plant_models.breathing import Breathing, BreathingParams
from plant_models.loadcell import LoadCellParams, LoadCellSensor
from plant_models.operator import TASKS, Operator, OperatorParams
from plant_models.plant import Plant, PlantParams
from plant_models.sensors import FSE103Params, FSE103Sensor, FT150Params, FT150Sensor
from plant_models.tissue import PhantomParams
from plant_models.tool import ToolModel

__all__ = [
    "FAULTS",
    "Fault",
    "RehearsalWorld",
    "SeqLock",
    "SimulatedRobot",
    "WorldSetup",
    "as_hardware",
    "process_context",
]

WORLD_DT = 1e-3

# shared memory: [sequence, values...], written under a sequence lock (no lock a reader could
# wait on: the runner must never wait for another process)
# p, R, twist, [mode, safety, protective, emergency, program, time], q, qd, the TCP's wrench,
# the orientation as a rotation vector (as RTDE gives it; computed here, not in the runner's loop)
_STATE = 3 + 9 + 6 + 6 + 6 + 6 + 6 + 3
_NO_ACCELERATION = np.zeros(1)
_COMMAND = 6 + 4 + 1  # twist, [acceleration, kick time, stop, sequence], the task's go
# the world's health before its first tick: the loop's longest stall [s] and the world time it
# began at (RehearsalWorld.stall), the world time after the arm's last moving tick (last_moving)
# and after the last tick whose command asked it to move (last_commanded), the probe's frames the
# pseudo-terminal refused whole or in part (probe_refused)
_HEALTH = (0.0, math.nan, math.nan, math.nan, 0.0)
TASK_LEAD_S = 0.5
"""[s] With no `task_start_s`, the hand takes the handle this long after `start_task()`."""
_HELD = 1e9  # [s] a task start that waits for start_task()


def _close_fds(*fds: int) -> None:
    for fd in fds:
        with contextlib.suppress(OSError):
            os.close(fd)


class SeqLock:
    """One writer, any readers, no waiting: the writer makes the sequence odd, writes, makes it
    even; a reader copies and keeps the copy only if the sequence was even and unchanged around it."""

    def __init__(self, shared: Any) -> None:
        self.array = np.frombuffer(shared, dtype=np.float64)
        self.last = self.array[1:].copy()

    def write(self, values: Vec, at: slice | int = slice(None)) -> None:
        data = self.array[1:]
        self.array[0] += 1.0
        data[at] = values
        self.array[0] += 1.0

    def read(self, tries: int = 1000) -> Vec:
        """The latest consistent copy. A writer caught mid-write is not waited for beyond `tries`:
        it may be a process that the scheduler has put aside (on a busy machine),
        so the previous copy, at most one write old, is returned instead."""
        for _ in range(tries):
            before = self.array[0]
            copy = self.array[1:].copy()
            if before % 2.0 == 0.0 and self.array[0] == before:
                self.last = copy
                return copy
        return self.last.copy()


@dataclass(frozen=True)
class WorldSetup:
    """What to rehearse: the robot's rate, the operator's task, the sensors, the faults."""

    robot_rate_hz: float = 500.0
    watchdog_hz: float = 20.0
    task: str = "circle"
    # the hand takes the handle then (after the runner's rebias); None: TASK_LEAD_S after
    # `RehearsalWorld.start_task()`, which a rehearsal calls once the rebias is done
    task_start_s: float | None = 4.0
    phantom_below_m: float | None = None  # a flat phantom this far below the tip (press tasks)
    # the phantom breathes (plant_models.breathing: this depth, 15 breaths a minute, 10 %
    # irregular, seeded); 0: it stays still
    breathing_m: float = 0.0
    # the hand lets go of the handle this long after it took it, and takes it again at retake_s
    # (plant_models.operator's let_go_s and retake_s; 0: never); a view task then moves on to the
    # next view a second later
    let_go_s: float = 0.0
    retake_s: float = 0.0
    ft_rate_hz: float = 200.0
    probe_framing: str = "seed18"
    probe_byte_order: str = "little"
    seed: int = 1
    faults: tuple[Fault, ...] = field(default_factory=tuple)
    # the runner's probe check after its rebias: the hand pushes the probe's tip a few times for
    # this long first, and takes the handle as it ends (0: no check)
    probe_check_s: float = 0.0
    # the patient moves away from the probe (plant_models.breathing: away_m over away_time_s)
    # away_s after the hand took the handle (away_m 0: never)
    away_m: float = 0.0
    away_s: float = 0.0
    away_time_s: float = 0.3
    ft_host: str = "127.0.0.1"  # where the FT-150 stream listens
    ft_port: int = 0  # 0: any free port (the URCap's daemon uses 63351)
    # the probe sensor on the pseudo-terminal: fse103, loadcell (mounted as eq. 3 says) or none;
    # the load cell's model parameters carry its faults (saturated, open_circuit,
    # zero_drift_N_per_min)
    probe_sensor: str = "fse103"
    loadcell: LoadCellParams = field(default_factory=LoadCellParams)
    # sensor faults from the start, for `hw check --rehearse --fault` (rehearsal.planted)
    planted: Planted = field(default_factory=Planted)
    hand_seed: int | None = None  # the hand's draws (pushes, tremor) from it; None: its own

    def __post_init__(self) -> None:
        if self.probe_sensor not in PROBE_SENSORS:
            raise ConfigError(
                f"probe_sensor: expected one of {', '.join(PROBE_SENSORS)}, "
                f"got {self.probe_sensor!r}"
            )
        framing = [f.kind for f in self.faults if f.kind == "probe_framing"]
        if framing and self.probe_sensor != "fse103":
            raise ConfigError(
                f"faults: probe_framing switches the FSE103's framing; the probe sensor is "
                f"{self.probe_sensor}"
            )
        if self.task not in TASKS:
            raise ConfigError(f"task: expected one of {', '.join(TASKS)}, got {self.task!r}")
        if self.breathing_m and self.phantom_below_m is None:
            raise ConfigError("breathing_m: a breathing phantom needs phantom_below_m, got None")


def as_hardware() -> None:
    """Raise this process above ordinary ones, and above the runner, where the system permits: on
    a rig the emulated devices are separate hardware with their own clocks and CPUs, and they must
    keep their rates however busy the machine is, or a rehearsal would see silent devices and a
    stalled controller where there are none. SCHED_FIFO at HARDWARE_PRIORITY (needs CAP_SYS_NICE,
    as root has; threads started later inherit it), else nice -10, else the default priority (a
    loaded machine can then slow the devices; the rehearsal's rate check says so). The devices
    sleep between their ticks (a world tick is a fraction of a millisecond), so the rest of the
    machine keeps most of its time; the kernel keeps 5 % for ordinary processes in any case."""
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(HARDWARE_PRIORITY))
        return
    except (OSError, AttributeError):
        pass
    with contextlib.suppress(OSError):
        os.setpriority(os.PRIO_PROCESS, 0, -10)


def _world_main(
    setup: WorldSetup,
    state: Any,
    command: Any,
    ready: Any,
    stop: Any,
    injections: Any,
    health: Any = None,
) -> None:
    as_hardware()
    try:
        world = _World(setup, state, command, injections, health)
    except Exception as exc:  # report, do not hang the parent
        ready.put(("error", f"{type(exc).__name__}: {exc}"))
        return
    ready.put(("ready", world.ft_port, world.pty_name, world.truth()))
    try:
        world.run(stop)
    finally:
        world.close()


class _World:
    def __init__(
        self,
        setup: WorldSetup,
        state: Any,
        command: Any,
        injections: Any = None,
        health: Any = None,
    ) -> None:
        from hoh_cosim.hardware.fse103 import FRAMINGS, encode_frame
        from hoh_cosim.hardware.ft150 import encode_sample
        from hoh_cosim.hardware.loadcell import encode_line

        self.setup = setup
        self.encode_sample, self.encode_frame = encode_sample, encode_frame
        self.state, self.command = SeqLock(state), SeqLock(command)
        arm = ArmParams(rate_hz=setup.robot_rate_hz)
        phantom = PhantomParams(shape="none")
        if setup.phantom_below_m is not None:
            tip = Plant(PlantParams(arm=arm)).initial_outputs()["p_BT_B"]
            phantom = PhantomParams(
                shape="plane", plane_point_B=[0.0, 0.0, float(tip[2]) - setup.phantom_below_m]
            )
        tool = ToolModel()
        if setup.probe_sensor == "loadcell":  # the plant's probe force in the cell's frame L
            tool = dataclasses.replace(tool, R_SP=R_SL_SEED)
        self.plant = Plant(PlantParams(arm=arm, tool=tool, phantom=phantom))
        start = _HELD if setup.task_start_s is None else setup.task_start_s
        # a view task taken again moves on to the next view (the touch that hands back)
        next_view = setup.retake_s + 1.0 if setup.task == "view" and setup.retake_s else 0.0
        self.operator = Operator(
            OperatorParams(
                task=setup.task,
                start_s=start,
                let_go_s=setup.let_go_s,
                retake_s=setup.retake_s,
                next_s=next_view,
                probe_check_s=setup.probe_check_s,
            ),
            rng=None if setup.hand_seed is None else np.random.default_rng([setup.hand_seed, 2]),
        )
        self.breathing = (
            Breathing(
                BreathingParams(
                    amplitude_m=setup.breathing_m,
                    away_s=start + setup.away_s,
                    away_m=setup.away_m,
                    away_time_s=setup.away_time_s,
                ),
                rng=np.random.default_rng([setup.seed, 1]),
            )
            if setup.breathing_m > 0.0 or setup.away_m > 0.0
            else None
        )
        self._surface = {"surface_offset_m": np.zeros(1), "surface_rate_m_s": np.zeros(1)}
        self.task_held = setup.task_start_s is None
        self.go = False
        self._acceleration = np.zeros(1)  # speedL's a of the last command
        rng = np.random.default_rng(setup.seed)
        self.ft = FT150Sensor(FT150Params(rate_hz=setup.ft_rate_hz), rng=rng)
        self.probe: FSE103Sensor | LoadCellSensor | None = None
        self.encode_line = encode_line
        if setup.probe_sensor == "fse103":
            self.probe = FSE103Sensor(setup.planted.fse103_params(FSE103Params()), rng=rng)
        elif setup.probe_sensor == "loadcell":
            self.probe = LoadCellSensor(setup.loadcell, rng=rng)
        # the 40 N of force_spike as a compression of the cell (along -z_L), on the FSE103's z
        self.spike_axis_P = np.array([0.0, 0.0, -1.0 if setup.probe_sensor == "loadcell" else 1.0])
        self.listener = socket.create_server((setup.ft_host, setup.ft_port))
        self.listener.setblocking(False)
        self.ft_port = self.listener.getsockname()[1]
        self.client: socket.socket | None = None
        master, slave = pty.openpty()
        tty.setraw(master)
        tty.setraw(slave)
        # a device does not wait for its reader: with nobody reading, the frames are lost (a
        # blocking write would stall the whole world once the terminal's buffer is full)
        os.set_blocking(master, False)
        self.pty_master: int | None = master
        self.pty_slave = slave  # kept open so that the device exists until unplugged
        self.pty_name = os.ttyname(slave)
        self.faults = sorted(setup.faults, key=lambda f: f.at_s)
        self.injections = injections
        self.health = health if health is not None else list(_HEALTH)  # _HEALTH says what
        self.ending: dict[str, float] = {}  # world time at which a fault of that kind ends
        self.ft_stalled = self.protective = self.program_stopped = False
        self.ft_nan = self.nan_next = False
        self.spike = self.ft_spike = 0.0
        self.framing = setup.probe_framing
        self.other_framing = next(f for f in FRAMINGS if f != setup.probe_framing)
        self.outputs = self.plant.initial_outputs()
        self.hand = {"F_hand_B": np.zeros(3), "tau_hand_B": np.zeros(3), "F_tip_B": np.zeros(3)}
        self.p_SH_S = np.asarray(self.plant.params.tool.p_SH_S, dtype=float)

    def truth(self) -> dict[str, Any]:
        """What a perfect calibration would find: the tool and the FT-150's offset."""
        tool = self.plant.params.tool
        return {
            "mass_kg": tool.mass_kg,
            "com_m": tool.p_SC_S.tolist(),
            "bias": self.ft.params.offset.tolist(),
            "gravity_B": self.plant.params.g_B.tolist(),
        }

    # --- I/O -----------------------------------------------------------------------------------

    def _accept(self) -> None:
        with contextlib.suppress(BlockingIOError):
            client, _ = self.listener.accept()
            if self.client is None:
                client.setblocking(False)
                client.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
                self.client = client
            else:  # one client at a time, as the daemon
                client.close()

    def _send_ft(self, data: bytes) -> None:
        if self.client is None or self.ft_stalled:
            return
        try:
            self.client.sendall(data)
        except (BlockingIOError, OSError):
            self.client.close()
            self.client = None

    def _send_probe(self, data: bytes) -> None:
        if self.pty_master is None:
            return
        try:
            written = os.write(self.pty_master, data)
        except OSError:  # BlockingIOError: the buffer is full, nobody reads
            written = 0
        if written < len(data):  # a device drops what its line does not take; counted
            self.health[4] += 1.0

    def _fault(self, kind: str, t: float, duration_s: float = 0.0) -> None:
        if duration_s > 0.0:
            self.ending[kind] = t + duration_s
        if kind == "probe_unplug" and self.pty_master is not None:
            # Closing a pseudo-terminal hangs its line up, which may wait for the kernel's tty work
            # at ordinary priority. Suspected, not reproduced: in two CI campaigns the one run with
            # an unplug during a live session (seed 20) saw this loop stall, the emulated
            # controller's watchdog fire and RTDE state stop for 100 ms before the runner saw the
            # unplug. The device goes at once; the close itself runs off the loop.
            fds = (self.pty_master, self.pty_slave)
            self.pty_master = None
            threading.Thread(target=_close_fds, args=fds, name="probe-unplug", daemon=True).start()
        elif kind == "ft_stall":
            self.ft_stalled = True
        elif kind == "ft_garbage":
            self._send_ft(b"(( 1.2 , x7 ) junk \x00\xff ( 3 , 4 )")
        elif kind == "probe_garbage":
            self._send_probe(bytes(range(7, 40)))
        elif kind == "probe_framing":
            self.framing, self.other_framing = self.other_framing, self.framing
        elif kind == "ft_nan":
            self.ft_nan = duration_s > 0.0
            self.nan_next = not self.ft_nan
        elif kind == "ft_spike":
            self.ft_spike = 60.0
        elif kind == "ft_disconnect":
            # the daemon goes away: the connection closes and new ones are refused until it is back
            if self.client is not None:
                self.client.close()
                self.client = None
            self.listener.close()
        elif kind == "force_spike":
            self.spike = 40.0
        elif kind == "protective_stop":
            self.protective = True

    def _end(self, kind: str) -> None:
        """A fault of `kind` with a duration is over: the device is itself again."""
        if kind == "ft_stall":
            self.ft_stalled = False
        elif kind == "probe_framing":
            self.framing, self.other_framing = self.other_framing, self.framing
        elif kind == "ft_nan":
            self.ft_nan = False
        elif kind == "ft_spike":
            self.ft_spike = 0.0
        elif kind == "ft_disconnect":
            self.listener = socket.create_server((self.setup.ft_host, self.ft_port))
            self.listener.setblocking(False)
        elif kind == "force_spike":
            self.spike = 0.0
        elif kind == "protective_stop":
            self.protective = False

    def _faults_due(self, t: float) -> None:
        while self.faults and self.faults[0].at_s <= t:
            fault = self.faults.pop(0)
            self._fault(fault.kind, t, fault.duration_s)
        if self.injections is not None and round(t / WORLD_DT) % 10 == 0:  # every 10 ms
            with contextlib.suppress(queue.Empty):
                while True:
                    kind, duration_s = self.injections.get_nowait()
                    self._fault(kind, t, duration_s)
        for kind, end in list(self.ending.items()):
            if t >= end:
                del self.ending[kind]
                self._end(kind)

    # --- the robot's side of the shared memory ------------------------------------------------

    def _command(self, now: float) -> Vec:
        c = self.command.read()
        twist, kick, stop = c[:6], c[7], c[8]
        self._acceleration = c[6:7]
        self.go = c[10] > 0.5
        if stop > 0.5:
            self.program_stopped = True
        if kick > 0.0 and now - kick > 1.0 / self.setup.watchdog_hz:
            self.program_stopped = True  # the watchdog: the program on the robot halts
        if self.program_stopped or self.protective:
            self._acceleration = _NO_ACCELERATION  # the stop as before: the arm's own ramp
            return np.zeros(6)
        return twist

    def _publish(self, t: float) -> None:
        o = self.outputs
        flags = [
            float(ROBOT_MODE_RUNNING),
            3.0 if self.protective else float(SAFETY_MODE_NORMAL),
            float(self.protective),
            0.0,
            0.0 if self.program_stopped else 1.0,
            t,
        ]
        self.state.write(
            np.concatenate(
                [
                    o["p_BT_B"],
                    o["R_BT"],
                    o["twist_B"],
                    flags,
                    o["q"],
                    o["qd"],
                    self._tcp_wrench(),
                    matrix_to_rotvec(o["R_BT"]),
                ]
            )
        )

    def _tcp_wrench(self) -> Vec:
        """The external wrench on the tool at the TCP, in B [N, N·m], as a UR's `actual_TCP_force`
        reports it (the payload's weight and inertia compensated): the hand at the handle, the
        phantom and any push at the tip (the TCP)."""
        o, hand = self.outputs, self.hand
        force = hand["F_hand_B"] + hand["F_tip_B"] + o["F_contact_B"]
        p_BH = o["p_BS_B"] + o["R_BS"].reshape(3, 3) @ self.p_SH_S
        torque = hand["tau_hand_B"] + np.cross(p_BH - o["p_BT_B"], hand["F_hand_B"])
        return np.concatenate([force, torque])

    # --- the loop ------------------------------------------------------------------------------

    def run(self, stop: Any) -> None:
        pacer = Pacer(WORLD_DT, spin_s=0.0)  # sleep only: the world catches up when late
        k = 0
        start = last = time.perf_counter()
        while not stop.is_set():
            pacer.wait()
            now = time.perf_counter()
            if now - last > self.health[0]:  # the longest time the devices stood still
                self.health[0], self.health[1] = now - last, k * WORLD_DT
            last = now
            # after a stall of this process, catch up: the world keeps to real time
            behind = int((now - start) / WORLD_DT) - k
            for _ in range(max(1, min(behind, 50))):
                self._tick(k * WORLD_DT)
                k += 1
            self._publish(k * WORLD_DT)

    def _tick(self, t: float) -> None:
        self._faults_due(t)
        if round(t / WORLD_DT) % 20 == 0 and "ft_disconnect" not in self.ending:  # every 20 ms
            self._accept()
        twist = self._command(time.monotonic())
        if twist.any():
            self.health[3] = t + WORLD_DT
        if self.task_held and self.go:  # the rebias is done: the hand comes in a moment
            self.task_held = False
            params = self.operator.params
            changes: dict[str, float] = {}
            if params.probe_check_s > 0.0:  # the pushes from TASK_LEAD_S on, to the check's end
                start = t + max(params.probe_check_s, 2.0 * TASK_LEAD_S)
                changes["probe_check_s"] = start - t - TASK_LEAD_S
            else:
                start = t + TASK_LEAD_S
            changes["start_s"] = start
            if self.breathing is not None:  # the patient's move on the task's clock
                breath = self.breathing.params
                self.breathing.retune(dataclasses.replace(breath, away_s=start + self.setup.away_s))
            if params.task == "push_release":
                # it lets go release_s after the hand came (a scenario's task starts at 0 s), not
                # at that time of the world's clock, which the rebias has already run past
                changes["release_s"] = start + params.release_s
            self.operator.retune(dataclasses.replace(params, **changes))
        hand = self.hand = self.operator.step(t, WORLD_DT, self.outputs)
        if self.breathing is not None:
            breath = self.breathing.step(t, WORLD_DT, {})
            self._surface = {
                "surface_offset_m": breath["offset_m"],
                "surface_rate_m_s": breath["rate_m_s"],
            }
        self.outputs = self.plant.step(
            t,
            WORLD_DT,
            {
                **self._surface,
                "twist_cmd_B": twist,
                # speedL's a as sent: the arm takes it for a command to rest when it brakes
                # harder than the arm's own acceleration (a release), never otherwise
                "brake_accel": self._acceleration,
                "F_hand_B": hand["F_hand_B"],
                "tau_hand_B": hand["tau_hand_B"],
                "F_tip_B": hand["F_tip_B"],
            },
        )
        arm = self.outputs["twist_B"]
        if arm.dot(arm) > 1e-18:  # moving (above 1 nm/s): the campaign times standstills by it
            self.health[2] = t + WORLD_DT
        before = self.ft.clock.delivered
        ft = self.ft.step(t, WORLD_DT, {"wrench_S_true": self.outputs["wrench_S"]})
        if self.ft.clock.delivered != before:
            values = self.setup.planted.ft_values(ft["wrench_S"])
            if self.ft_spike:
                values = values + np.array([0.0, 0.0, self.ft_spike, 0.0, 0.0, 0.0])
            if self.nan_next or self.ft_nan:
                values, self.nan_next = np.full(6, math.nan), False
            self._send_ft(self.encode_sample(values))
        if self.probe is not None:
            self._probe_tick(t)

    def _probe_tick(self, t: float) -> None:
        probe_sensor = self.probe
        assert probe_sensor is not None
        before = probe_sensor.clock.delivered
        force = self.setup.planted.probe_force(self.outputs["force_P"])
        force = force + self.spike * self.spike_axis_P
        probe = probe_sensor.step(t, WORLD_DT, {"force_P_true": force})
        if probe_sensor.clock.delivered == before:
            return
        device_ms = int(1e3 * t) & 0xFFFFFFFF
        if isinstance(probe_sensor, LoadCellSensor):
            self._send_probe(self.encode_line(int(probe["count"][0]), device_ms))
            return
        self._send_probe(
            self.encode_frame(
                probe["force_P"],
                device_ms,
                framing=self.framing,
                byte_order=self.setup.probe_byte_order,
            )
        )

    def close(self) -> None:
        for closer in (
            lambda: self.client and self.client.close(),
            self.listener.close,
            lambda: self.pty_master is not None and os.close(self.pty_master),
            lambda: self.pty_master is not None and os.close(self.pty_slave),
        ):
            with contextlib.suppress(OSError):
                closer()


def process_context() -> Any:
    """How the rehearsal's processes (the world, the UR controller) start: forked from a server
    process that has imported them once (multiprocessing's `forkserver`), which like `spawn` gives
    a process without the starter's threads and sockets, in about 20 ms instead of a second of
    imports per process (a campaign starts two per run); `spawn` where there is no fork server."""
    if "forkserver" not in mp.get_all_start_methods():
        return mp.get_context("spawn")
    context = mp.get_context("forkserver")
    context.set_forkserver_preload(
        ["hoh_cosim.rehearsal.world", "hoh_cosim.rehearsal.ur_controller"]
    )
    return context


class RehearsalWorld:
    """The world process, started and stopped from the runner's side."""

    def __init__(self, setup: WorldSetup) -> None:
        self.setup = setup
        context = process_context()
        self.state = context.RawArray("d", 1 + _STATE)
        self.command = context.RawArray("d", 1 + _COMMAND)
        self._state, self._command = SeqLock(self.state), SeqLock(self.command)
        self._ready = context.Queue()
        self._stop = context.Event()
        self._injections = context.Queue()
        self._health = context.RawArray("d", _HEALTH)
        self._process = context.Process(
            target=_world_main,
            args=(
                *(setup, self.state, self.command, self._ready, self._stop, self._injections),
                self._health,
            ),
            name="rehearsal-world",
            daemon=True,
        )
        self.ft_port = 0
        self.pty_name = ""
        self.truth: dict[str, Any] = {}

    def start(self, timeout_s: float = 60.0) -> RehearsalWorld:
        self._process.start()
        deadline = time.monotonic() + timeout_s
        while True:
            try:
                message = self._ready.get(timeout=0.2)
                break
            except queue.Empty:
                if not self._process.is_alive():
                    raise RunError(
                        f"the rehearsal world exited at start (status {self._process.exitcode})"
                    ) from None
                if time.monotonic() > deadline:
                    self.stop()
                    raise RunError(
                        f"the rehearsal world did not start within {timeout_s:g} s"
                    ) from None
        if message[0] == "error":
            self.stop()
            raise RunError(f"the rehearsal world failed to start: {message[1]}")
        _, self.ft_port, self.pty_name, self.truth = message
        return self

    def start_task(self) -> None:
        """Let the operator's hand come, TASK_LEAD_S from now (a world set up without
        `task_start_s`; otherwise nothing changes)."""
        self._command.write(np.array([1.0]), slice(10, 11))

    def inject(self, kind: str, duration_s: float = 0.0) -> None:
        """The fault `kind` now (within the world's next 10 ms), for `duration_s` (0: for good)."""
        Fault(0.0, kind, duration_s)  # checks the kind and the duration
        self._injections.put((kind, float(duration_s)))

    def robot(self) -> SimulatedRobot:
        return SimulatedRobot(self, 1.0 / self.setup.robot_rate_hz)

    def stall(self) -> tuple[float, float]:
        """The world loop's longest time between two of its turns so far [s] (a millisecond when
        it keeps real time; more when the machine held the emulated devices back, so that they
        sent nothing and the arm's state stood still) and the world time it began at [s]."""
        return float(self._health[0]), float(self._health[1])

    def last_moving(self) -> float:
        """The world time [s] at which the arm last moved (its speed above 1 nm/s), NaN if never:
        kept by the world tick by tick, whoever looks and however late."""
        return float(self._health[2])

    def last_commanded(self) -> float:
        """The world time [s] at which the arm's command, as the world read it, last asked for
        motion (a twist not zero), NaN if never: what tells a late standstill's two causes apart,
        a late command to rest or an arm that did not follow it."""
        return float(self._health[3])

    def probe_refused(self) -> int:
        """How many of the probe's frames its pseudo-terminal refused, whole or in part (the
        world writes without blocking and drops what the line does not take, as a device would)."""
        return int(self._health[4])

    def stop(self) -> None:
        self._stop.set()
        self._process.join(5.0)
        if self._process.is_alive():
            self._process.kill()
            self._process.join(1.0)

    def __enter__(self) -> RehearsalWorld:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()


class SimulatedRobot:
    """The rehearsal's robot: `hoh_cosim.hardware.robot.Robot`'s methods over shared memory."""

    def __init__(self, world: RehearsalWorld, period_s: float) -> None:
        self.world = world
        self.period_s = period_s
        self._seq = 0.0

    def describe(self) -> str:
        return "simulated UR5 (rehearsal)"

    def connect(self) -> None:
        if not self.world._process.is_alive():
            raise RunError(f"{self.describe()}: the rehearsal world is not running")
        self._write(np.zeros(6), 1.0, stop=False)

    def pacer(self) -> Pacer:
        return Pacer(self.period_s)

    def state(self) -> RobotState:
        s = self.world._state.read(tries=3)
        return RobotState(
            p_BT_B=s[0:3],
            R_BT=s[3:12].reshape(3, 3),
            twist_B=s[12:18],
            robot_mode=int(s[18]),
            safety_mode=int(s[19]),
            protective_stop=bool(s[20]),
            emergency_stop=bool(s[21]),
            program_running=bool(s[22]),
            timestamp_s=float(s[23]),
            rotvec_BT=s[42:45],
        )

    def _write(self, twist: Vec, acceleration: float, *, stop: bool) -> None:
        self._seq += 1.0
        self.world._command.write(np.concatenate([twist, [acceleration]]), slice(0, 7))
        self.world._command.write(np.array([1.0 if stop else 0.0, self._seq]), slice(8, 10))

    def speed_l(self, twist_B: Vec, acceleration: float) -> None:
        self._write(twist_B, acceleration, stop=False)

    def kick_watchdog(self) -> None:
        self.world._command.write(np.array([time.monotonic()]), slice(7, 8))

    def stop(self, timeout_s: float = 1.0) -> None:
        """Stop the arm and the program; like ur-rtde's stopScript, return once the robot says
        the program has stopped (or after `timeout_s`, the world being gone)."""
        self._write(np.zeros(6), 0.0, stop=True)
        deadline = time.monotonic() + timeout_s
        while self.world._process.is_alive() and time.monotonic() < deadline:
            if not self.state().program_running:
                return
            time.sleep(0.001)

    def close(self) -> None:
        pass
