"""A UR controller on loopback: the dashboard server, RTDE and the script port, backed by the arm of
a rehearsal world, so that the unmodified ur_rtde client and our unmodified runner talk to it as to
a robot.

    with RehearsalWorld(WorldSetup(robot_rate_hz=500.0)) as world, UrController(world) as ur:
        ... RTDEControlInterface("127.0.0.1") / hoh-cosim hw run with robot.host: 127.0.0.1 ...
        ur.inject("protective_stop")

What it serves (ports chosen by the caller, defaults 29999, 30003, 30004; ur_rtde itself always uses
the defaults, so a test gives each emulator its own loopback address, 127.0.0.x):
- the dashboard server: the banner and the replies ur_rtde reads (`PolyscopeVersion`, `get serial
  number`, `is in remote control`, `stop`), the status queries, and what a lab script uses (`get
  robot model`, `get loaded program`, `isProgramSaved`, `get operational mode`, `clear operational
  mode`, `power on` / `off`, `brake release`, `load`, `play`, `pause`) with UR's documented replies;
- RTDE protocols 1 and 2 (`hoh_cosim.rehearsal.rtde_protocol`): version, controller version (5.11 in
  e-series mode, 500 Hz; 3.15 in CB3 mode, 125 Hz), output recipes streamed every floor(rate / f)
  cycles (NOT_FOUND for what it does not have or model, `NOT_EMULATED`; an out-of-range frequency
  refused with a reason), input recipes (IN_USE for an input another connection writes), start,
  pause, data both ways, clients' text messages into its log, text messages for what it refuses;
- the script port: a program uploaded there starts running (`runtime_state` PLAYING), and then does
  what ur_rtde's control script does for the commands our runner uses, through the same registers:
  the command in `input_int_register_0`, its arguments in `input_double_register_*`, "ready" (1) and
  "done" (2) in `output_int_register_0`; speedL (10), speedStop (15), getStepTime (26), protective
  stop (31), setWatchdog (35: the program stops when `input_int_register_0` is not written for
  1/f s, as `rtde_set_watchdog(..., "stop")` does), stop (255). Any other command halts the program
  with a text message: it is not emulated.
- robot and safety state from the world's arm: TCP pose and speed, joint angles and speeds, the
  TCP's external wrench, robot mode, safety mode and status bits, runtime state, robot status
  bits, and as the `timestamp` the controller's own clock: a whole number of its periods (2 ms on
  an e-series, 8 ms on a CB3), from the world's time when the controller started. A controller
  never skips a cycle: when this machine holds the emulator back, the cycles it missed are sent
  late, each with its own timestamp (up to `BACKLOG_S` of them; a longer stall skips the rest,
  and the clock still moves by whole periods), so lateness shows only as late delivery, as on a
  controller whose client is slow; `inject()` puts the robot in a
  protective stop or an emergency stop, or drops the link (nothing passes either way, as with a
  pulled cable; after a while the controller closes the sockets and refuses new ones for as long).

What it does not prove: URScript timing on a real controller, the controller's trajectory generator,
its safety system. It proves that our code and ur_rtde talk correctly and that our safety reactions
work.
"""

from __future__ import annotations

import contextlib
import math
import queue
import re
import select
import socket
import struct
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from hoh_cosim.rehearsal import rtde_protocol as rtde
from hoh_cosim.rehearsal.world import as_hardware, process_context

__all__ = ["BACKLOG_S", "INJECTIONS", "STALL_EVENT_S", "UrController"]

STALL_EVENT_S = 0.02
"""A cycle of the controller's loop that starts this long [s] after the one before (ten e-series
cycles) is an event of its log, "stalled N ms": the machine held the emulated controller back."""

BACKLOG_S = 1.0
"""[s] At most this much of the cycles a stall of this machine held back is sent late."""

# what the dashboard server refuses in local control (UR's e-series replies)
_CONTROL_COMMANDS = {"power", "brake", "load", "play", "stop", "pause", "unlock", "shutdown"}
# A dashboard command is read up to this many bytes (UR's are under 300): a longer line is an
# unknown command, answered as one, and a line without end costs no more memory than this.
_DASHBOARD_LINE_BYTES = 4096
_LOCAL_CONTROL = (
    "Command is not allowed due to safety reasons, please switch robot to Remote Control mode and "
    "reconnect to port 29999"
)
# outputs the guide lists that the emulator does not model (no joint dynamics, I/O or tool
# electronics): refused at set-up as NOT_FOUND rather than sent as zeros that look like data
NOT_EMULATED = frozenset(
    {
        "target_qdd", "target_current", "target_moment", "actual_current", "joint_control_output",
        "actual_execution_time", "actual_tool_accelerometer", "actual_momentum",
        "actual_robot_current", "actual_joint_voltage", "elbow_position", "elbow_velocity",
        "analog_io_types", "standard_analog_input0", "standard_analog_input1",
        "standard_analog_output0", "standard_analog_output1", "io_current", "tool_mode",
        "tool_analog_input_types", "tool_analog_input0", "tool_analog_input1",
        "tool_output_voltage", "tool_output_current", "tool_temperature", "payload_cog",
        "payload_inertia", "actual_current_as_torque", "script_control_line", "ft_raw_wrench",
        "joint_position_deviation_ratio", "collision_detection_ratio",
    }
)  # fmt: skip
INJECTIONS = ("protective_stop", "emergency_stop", "drop_connection", "clear")

# RTDE runtime_state, robot_mode, safety_mode and the safety_status_bits ur_rtde reads
STOPPED, PLAYING, PAUSED = 1, 2, 4  # RTDE runtime_state
ROBOT_MODE_POWER_OFF, ROBOT_MODE_IDLE, ROBOT_MODE_RUNNING = 3, 5, 7
_MODE_NAMES = {
    ROBOT_MODE_POWER_OFF: "POWER_OFF",
    ROBOT_MODE_IDLE: "IDLE",
    ROBOT_MODE_RUNNING: "RUNNING",
}
SAFETY_NORMAL, SAFETY_PROTECTIVE, SAFETY_ROBOT_EMERGENCY = 1, 3, 7
BIT_NORMAL, BIT_PROTECTIVE, BIT_ROBOT_EMERGENCY, BIT_EMERGENCY = 0, 2, 6, 7
# robot_status_bits: power on, program running
STATUS_POWER_ON, STATUS_PROGRAM_RUNNING = 1, 2

CMD_NONE, CMD_SPEEDL, CMD_SPEED_STOP, CMD_STEPTIME = 0, 10, 15, 26
CMD_PROTECTIVE_STOP, CMD_WATCHDOG, CMD_STOP_SCRIPT = 31, 35, 255
# the commands the real script answers within the cycle (done, then ready again)
_REALTIME = {6, 9, 10, 11, 24, 25, 26, 27, 38, 58, 66, 67, 68, 69, 70, 71}
_EMULATED = {CMD_SPEEDL, CMD_SPEED_STOP, CMD_STEPTIME, CMD_PROTECTIVE_STOP, CMD_WATCHDOG}
STOP_DECELERATION = 10.0  # [m/s²] what the script's own stops use (stopl(10))

VERSIONS = {
    "e": ((5, 11, 1, 108318), "URSoftware 5.11.1.108318 (Dec 06 2021)", 500.0),
    "cb3": ((3, 15, 7, 106331), "URSoftware 3.15.7.106331 (Mar 11 2021)", 125.0),
}


@dataclass
class _Connection:
    sock: socket.socket
    outputs: tuple[list[str], list[str], struct.Struct, float] | None = None
    inputs: dict[int, tuple[list[str], list[str], struct.Struct]] = field(default_factory=dict)
    started: bool = False
    every: int = 1  # send every n-th controller cycle
    version: int = 1  # the RTDE protocol version: 1 until the client asks for 2 (UR's guide)
    lock: threading.Lock = field(default_factory=threading.Lock)

    def send(self, data: bytes) -> None:
        with self.lock:
            self.sock.sendall(data)


class UrController:
    """The emulated controller in a process of its own (ur_rtde's Python calls hold the
    interpreter while they wait for the controller, so it cannot share a process with its client):
    `start()` opens the three ports, `inject()` injects a fault, `stop()` ends it."""

    def __init__(
        self,
        world: Any,
        host: str = "127.0.0.1",
        *,
        dashboard_port: int = 29999,
        script_port: int = 30003,
        rtde_port: int = 30004,
        series: str = "e",
        remote_control: bool = True,
    ) -> None:
        if series not in VERSIONS:
            raise ValueError(f"series: expected one of {', '.join(VERSIONS)}, got {series!r}")
        self.world = world
        self.options = {
            "host": host,
            "ports": {"dashboard": dashboard_port, "script": script_port, "rtde": rtde_port},
            "series": series,
            "remote_control": remote_control,
        }
        self.host = host
        self.rate_hz = VERSIONS[series][2]
        self.events: list[tuple[float, str]] = []
        context = process_context()
        self._control = context.Queue()
        self._events = context.Queue()
        self._process = context.Process(
            target=_emulator_main,
            args=(self.options, world.state, world.command, self._control, self._events),
            name="ur-controller",
            daemon=True,
        )

    def start(self, timeout_s: float = 30.0) -> UrController:
        self._process.start()
        deadline = time.monotonic() + timeout_s
        while not self.said("^listening|^cannot listen"):
            if not self._process.is_alive() or time.monotonic() > deadline:
                self.stop()
                raise RuntimeError(f"UR emulator did not start: {self._last()}")
            time.sleep(0.02)
        if self.said("^cannot listen"):
            self.stop()
            raise RuntimeError(f"UR emulator: {self._last()}")
        return self

    def _drain(self) -> None:
        with contextlib.suppress(queue.Empty):
            while True:
                self.events.append(self._events.get_nowait())

    def _last(self) -> str:
        self._drain()
        return self.events[-1][1] if self.events else "no message"

    def said(self, pattern: str) -> bool:
        """Whether an event matching the regular expression `pattern` happened."""
        self._drain()
        return any(re.search(pattern, text) for _, text in self.events)

    def inject(self, kind: str, refuse_s: float = 5.0) -> None:
        """A protective stop, an emergency stop, a dropped connection (every socket closed, new
        connections refused for `refuse_s`), or `clear` (the stops released, as from the pendant)."""
        if kind not in INJECTIONS:
            raise ValueError(f"inject: expected one of {', '.join(INJECTIONS)}, got {kind!r}")
        self._control.put(("inject", kind, refuse_s))

    def stop(self) -> None:
        if self._process.is_alive():
            self._control.put(("stop",))
            self._process.join(5.0)
            if self._process.is_alive():
                self._process.kill()
                self._process.join(1.0)
        self._drain()

    def __enter__(self) -> UrController:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()


class _SharedWorld:
    """The world's shared memory, as the emulator's process sees it."""

    def __init__(self, state: Any, command: Any) -> None:
        from hoh_cosim.rehearsal.world import SeqLock

        self._state, self._command = SeqLock(state), SeqLock(command)


def _emulator_main(options: dict, state: Any, command: Any, control: Any, events: Any) -> None:
    as_hardware()  # the robot's controller is hardware of its own
    emulator = _Emulator(_SharedWorld(state, command), events=events, **options)
    try:
        emulator.start()
    except OSError as exc:
        events.put((time.monotonic(), f"cannot listen: {exc}"))
        return
    try:
        while True:
            message = control.get()
            if message[0] == "stop":
                break
            if message[0] == "inject":
                emulator.inject(message[1], message[2])
    finally:
        emulator.stop()


class _Emulator:
    """The controller itself: threads for the ports and the controller's cycle."""

    def __init__(
        self,
        world: Any,
        host: str,
        ports: dict[str, int],
        series: str,
        remote_control: bool,
        events: Any = None,
    ) -> None:
        self.world = world
        self.host = host
        self.ports = ports
        self.queue = events
        self.version, self.polyscope, self.rate_hz = VERSIONS[series]
        self.remote_control = remote_control
        self.lock = threading.RLock()
        self.inputs: dict[str, Any] = {name: 0 for name in rtde.INPUTS}
        self.registers_out: dict[str, Any] = {}
        self.owner: dict[str, _Connection] = {}  # input variable -> the connection that writes it
        self.connections: list[_Connection] = []
        self.sockets: list[socket.socket] = []
        self.runtime_state = STOPPED
        self.robot_mode = ROBOT_MODE_RUNNING  # powered, brakes released: a rig ready for work
        self.loaded: str | None = None  # the program `load` loaded (a name: there are no files)
        self.playing_loaded = False  # the running program is the loaded one, not a script
        self.protective = self.emergency = False
        self.executing = False
        self.speed_l_active = False
        self.acceleration = 0.0  # speedL's a of the last speedL
        self.last_cmd = -1
        self.silent_until = 0.0
        self.outbox: list[tuple[str, str, int]] = []
        self.twist = np.zeros(6)
        self.watchdog_hz = 0.0
        self.kicked = time.monotonic()
        self.refuse_until = 0.0
        self.cycles = 0
        self.clock_s = 0.0  # [s] the controller's clock: the timestamp of the last cycle
        self._stop = threading.Event()
        self._threads: list[threading.Thread] = []
        self._listeners: dict[str, socket.socket] = {}

    # --- life cycle -----------------------------------------------------------------------------

    def start(self) -> _Emulator:
        self._open_listeners()
        self._spawn(self._accept_loop, "ur-accept")
        self._spawn(self._control_loop, "ur-control")
        self._event(f"listening on {self.host}, ports {self.ports}")
        return self

    def _close_listeners(self) -> None:
        with self.lock:
            listeners, self._listeners = self._listeners, {}
        for listener in listeners.values():
            with contextlib.suppress(OSError):
                listener.close()

    def _open_listeners(self) -> None:
        listeners = {}
        for name, port in self.ports.items():
            listener = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
            listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            try:
                listener.bind((self.host, port))
            except OSError as exc:
                listener.close()
                for other in listeners.values():
                    other.close()
                raise OSError(f"{self.host}:{port}: {exc.strerror}") from None
            listener.listen(8)
            listeners[name] = listener
        with self.lock:
            self._listeners = listeners

    def stop(self) -> None:
        self._stop.set()
        self._drop_all()
        self._close_listeners()
        for thread in self._threads:
            if thread is not threading.current_thread():
                thread.join(2.0)
        with self.lock:  # the world's command has one writer at a time
            self._command(np.zeros(6))

    def _spawn(self, target: Any, name: str, *args: Any) -> None:
        self._threads = [t for t in self._threads if t.is_alive()]
        thread = threading.Thread(target=target, args=args, name=name, daemon=True)
        self._threads.append(thread)
        thread.start()

    def _event(self, text: str) -> None:
        if self.queue is not None:
            self.queue.put((time.monotonic(), text))

    # --- faults ---------------------------------------------------------------------------------

    def inject(self, kind: str, refuse_s: float) -> None:
        self._event(f"inject {kind}")
        with self.lock:
            if kind == "protective_stop":
                self.protective = True
                self._halt("protective stop")
            elif kind == "emergency_stop":
                self.emergency = True
                self._halt("emergency stop")
            elif kind == "clear":
                self.protective = self.emergency = False
        if kind == "drop_connection":
            # the link goes down, as a pulled cable: the sockets stay open but nothing passes
            # either way; then the controller gives up on them, and listens again later
            with self.lock:
                self.silent_until = time.monotonic() + refuse_s
                self.refuse_until = self.silent_until + refuse_s
            self._spawn(self._end_silence, "ur-silence")

    def _end_silence(self) -> None:
        while time.monotonic() < self.silent_until and not self._stop.is_set():
            time.sleep(0.02)
        self._close_listeners()
        self._drop_all()

    def _drop_all(self) -> None:
        with self.lock:
            sockets, self.sockets = self.sockets, []
            self.connections = []
            self.owner = {}
        for sock in sockets:
            with contextlib.suppress(OSError):
                sock.shutdown(socket.SHUT_RDWR)
            with contextlib.suppress(OSError):
                sock.close()

    # --- the arm --------------------------------------------------------------------------------

    def _command(self, twist: np.ndarray) -> None:
        """The twist the arm model follows (the world's speedL input), with speedL's `a` while
        speedL runs (the arm takes it only to brake to rest), else the stops' deceleration."""
        a = self.acceleration if self.speed_l_active else STOP_DECELERATION
        self.world._command.write(np.concatenate([twist, [a]]), slice(0, 7))

    def _halt(self, why: str) -> None:
        """The program stops and the arm with it (lock held)."""
        if self.runtime_state == PLAYING:
            self._event(f"program stopped: {why}")
        self.runtime_state = STOPPED
        self.executing = self.speed_l_active = False
        self.twist = np.zeros(6)
        self.watchdog_hz = 0.0
        self._command(self.twist)

    def _state(self) -> dict[str, Any]:
        s = self.world._state.read(tries=3)
        p, twist, flags = s[0:3], s[12:18], s[18:24]
        q, qd, wrench, rotvec = s[24:30], s[30:36], s[36:42], s[42:45]
        safety_mode = SAFETY_NORMAL
        bits = 1 << BIT_NORMAL
        if self.protective or flags[2] > 0.5:
            safety_mode, bits = SAFETY_PROTECTIVE, 1 << BIT_PROTECTIVE
        if self.emergency:
            safety_mode = SAFETY_ROBOT_EMERGENCY
            bits = (1 << BIT_ROBOT_EMERGENCY) | (1 << BIT_EMERGENCY)
        running = self.runtime_state == PLAYING
        pose = list(p) + list(rotvec)  # the world publishes the orientation as UR reports it
        return {
            "timestamp": self.clock_s,  # the controller's own clock (`_control_loop`)
            "actual_TCP_pose": pose,
            "target_TCP_pose": pose,
            "actual_TCP_speed": list(twist),
            "target_TCP_speed": list(self.twist),
            "actual_q": list(q),
            "target_q": list(q),
            "actual_qd": list(qd),
            "target_qd": list(qd),
            "actual_TCP_force": list(wrench),
            "tcp_force_scalar": float(np.linalg.norm(wrench[:3])),
            "actual_digital_input_bits": 0,  # nothing is wired to the emulated controller's I/O
            "actual_digital_output_bits": 0,
            "output_bit_registers0_to_31": 0,  # the program sets no output bit
            "output_bit_registers32_to_63": 0,
            "robot_mode": ROBOT_MODE_POWER_OFF if self.emergency else self.robot_mode,
            "joint_mode": [253] * 6,  # JOINT_RUNNING_MODE
            "safety_mode": safety_mode,
            "safety_status": safety_mode,
            "safety_status_bits": bits,
            "runtime_state": self.runtime_state,
            "robot_status_bits": STATUS_POWER_ON | (STATUS_PROGRAM_RUNNING if running else 0),
            "speed_scaling": 1.0,
            "target_speed_fraction": 1.0,
            "actual_main_voltage": 48.0,
            "actual_robot_voltage": 48.0,
            "joint_temperatures": [30.0] * 6,
            "payload": 0.48,
        }

    # --- the program ----------------------------------------------------------------------------

    def _program_cycle(self, now: float) -> None:
        """One cycle of the uploaded program (lock held): read the command register, act, answer."""
        if self.runtime_state != PLAYING or self.playing_loaded:
            return  # a loaded .urp plays without moving: the emulator cannot run PolyScope files
        if self.protective or self.emergency:
            self._halt("the robot is stopped by its safety system")
            return
        if self.watchdog_hz > 0 and now - self.kicked > 1.0 / self.watchdog_hz:
            self._event(f"watchdog: no command for {1e3 * (now - self.kicked):.0f} ms")
            self._halt("watchdog")
            return
        cmd = int(self.inputs["input_int_register_0"])
        out = self.registers_out
        if cmd in _REALTIME:
            if cmd not in _EMULATED:
                self._unsupported(cmd)
                return
            self._process(cmd)
            out["output_int_register_0"] = 1
        elif cmd == CMD_NONE:
            self.executing = False
            out["output_int_register_0"] = 1
        elif not self.executing:
            if cmd != CMD_STOP_SCRIPT and cmd not in _EMULATED:
                self._unsupported(cmd)
                return
            self.executing = True
            self._process(cmd)
            if self.runtime_state == PLAYING:
                out["output_int_register_0"] = 2

    def _unsupported(self, cmd: int) -> None:
        text = f"command {cmd} is not emulated: the program stops"
        self._halt(text)
        self._broadcast((text, "UR emulator", 1))

    def _process(self, cmd: int) -> None:
        d = [float(self.inputs[f"input_double_register_{i}"]) for i in range(8)]
        if cmd == CMD_SPEEDL:
            self.twist = np.array(d[:6])
            self.acceleration = d[6]  # speedL's a (register 6; 7 is its time)
            self.speed_l_active = True
        elif cmd == CMD_SPEED_STOP:
            self.twist = np.zeros(6)
            self.speed_l_active = False
        elif cmd == CMD_STEPTIME:
            self.registers_out["output_double_register_0"] = 1.0 / self.rate_hz
        elif cmd == CMD_PROTECTIVE_STOP:
            self.protective = True
            self._event("protective stop (requested by the program)")
            self._halt("protective stop")
            return
        elif cmd == CMD_WATCHDOG:
            self.watchdog_hz = d[0]
            self.kicked = time.monotonic()
            self._event(f"watchdog {d[0]:g} Hz")
        elif cmd == CMD_STOP_SCRIPT:
            self._halt("stopped by the client")
            return
        if cmd != self.last_cmd:  # a new command, not its repetition every cycle
            self._event(f"command {cmd}")
        self.last_cmd = cmd
        self._command(self.twist)

    def _start_program(self, text: str) -> None:
        with self.lock:
            self.registers_out = {"output_int_register_0": 1, "output_int_register_2": 0}
            self.inputs["input_int_register_0"] = 0
            self.executing = self.speed_l_active = False
            self.twist = np.zeros(6)
            self.watchdog_hz = 0.0
            self.kicked = time.monotonic()
            if self.protective or self.emergency or self.robot_mode != ROBOT_MODE_RUNNING:
                self._event("program refused: the robot is stopped or not powered and released")
                return
            self.runtime_state, self.playing_loaded = PLAYING, False
        self._event(f"program started ({len(text)} bytes)")

    # --- the controller's cycle -----------------------------------------------------------------

    def _control_loop(self) -> None:
        period = 1.0 / self.rate_hz
        # the controller's clock counts whole periods, from the world's time at the start
        first = math.floor(float(self.world._state.read(tries=3)[23]) / period)
        start = last = time.perf_counter()
        done = 0  # cycles run, or skipped by a stall longer than BACKLOG_S
        backlog = max(1, round(BACKLOG_S * self.rate_hz))
        while not self._stop.is_set():
            delay = start + done * period - time.perf_counter()
            if delay > 0:
                time.sleep(delay)
            started = time.perf_counter()
            if started - last > STALL_EVENT_S:  # the machine held the controller back: in its log
                self._event(f"stalled {1e3 * (started - last):.0f} ms")
            last = started
            due = int((started - start) / period) + 1  # cycles whose time has come
            done = max(done, due - backlog)
            cycles = range(done, due) if due > done else range(done, done + 1)
            done = cycles[-1] + 1
            now = time.monotonic()
            with self.lock:
                self._program_cycle(now)
                state = self._state()
                state.update(self.registers_out)
                state.update(self.echoed())
                connections = list(self.connections)
                self.cycles = cycles[-1] + 1
                outbox, self.outbox = self.outbox, []
            if now < self.silent_until:
                continue
            for conn in connections:
                if not conn.started:
                    continue
                try:
                    for text, source, level in outbox:
                        conn.send(rtde.text_message(text, source, level, conn.version))
                    if conn.outputs is None:
                        continue
                    names, types, layout, _ = conn.outputs
                    recipe = 1 if conn.version == 2 else None
                    for cycle in cycles:
                        if (cycle + 1) % conn.every:
                            continue
                        # a register nobody wrote reads 0, as on a controller; every other
                        # output is in the state or was refused at set-up (NOT_EMULATED)
                        state["timestamp"] = self.clock_s = (first + cycle) * period
                        values = [
                            state.get(n, rtde.zero(t)) for n, t in zip(names, types, strict=True)
                        ]
                        conn.send(rtde.encode_values(recipe, layout, values))
                except OSError:
                    self._forget(conn)

    def echoed(self) -> dict[str, Any]:
        """The input registers, which a controller also offers as outputs."""
        return {k: v for k, v in self.inputs.items() if k in rtde.OUTPUTS}

    def _broadcast(self, message: tuple[str, str, int]) -> None:
        """A text message (text, source, level), queued (the lock may be held): the cycle sends
        it to every started client, in the client's protocol version."""
        self.outbox.append(message)

    def _forget(self, conn: _Connection) -> None:
        with self.lock:
            if conn in self.connections:
                self.connections.remove(conn)
            for name in [n for n, c in self.owner.items() if c is conn]:
                del self.owner[name]
        self._close(conn.sock)

    def _close(self, sock: socket.socket) -> None:
        """Close a connection whose handler has ended (the client closed or quit, or it failed):
        kept open, each would hold a file descriptor until the controller stops."""
        with self.lock:
            if sock in self.sockets:
                self.sockets.remove(sock)
        with contextlib.suppress(OSError):
            sock.close()

    # --- sockets ----------------------------------------------------------------------------------

    def _silent(self) -> bool:
        return time.monotonic() < self.silent_until

    def _accept_loop(self) -> None:
        handlers = {"dashboard": self._dashboard, "script": self._script, "rtde": self._rtde}
        while not self._stop.is_set():
            if not self._listeners or self._silent():  # the link is down: nobody answers
                if not self._listeners and time.monotonic() >= self.refuse_until:
                    with self.lock, contextlib.suppress(OSError):
                        if not self._stop.is_set():
                            self._open_listeners()
                            self._event("listening again")
                time.sleep(0.05)
                continue
            with self.lock:
                by_socket = {listener: name for name, listener in self._listeners.items()}
            try:
                ready, _, _ = select.select(list(by_socket), [], [], 0.05)
            except (OSError, ValueError):
                continue  # a listener closed meanwhile
            for listener in ready:
                try:
                    sock, _ = listener.accept()
                except OSError:
                    continue
                sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
                # a client that stops reading is dropped, not waited for: the cycle goes on
                sock.setsockopt(
                    socket.SOL_SOCKET, socket.SO_SNDTIMEO, struct.pack("ll", 0, 200_000)
                )
                with self.lock:
                    self.sockets.append(sock)
                name = by_socket[listener]
                self._spawn(self._serve, f"ur-{name}", handlers[name], sock)

    def _serve(self, handler: Any, sock: socket.socket) -> None:
        """One connection, in a thread of its own: `handler` serves it, then it is closed."""
        try:
            handler(sock)
        finally:
            self._close(sock)

    def _received(self, sock: socket.socket) -> Iterator[bytes]:
        """What the client sends, until it closes; nothing while the link is down."""
        while not self._stop.is_set():
            data = sock.recv(65536)
            if not data:
                return
            if not self._silent():  # else lost on the way
                yield data

    def _dashboard(self, sock: socket.socket) -> None:
        with contextlib.suppress(OSError):
            sock.sendall(b"Connected: Universal Robots Dashboard Server\n")
            buffer = b""
            for data in self._received(sock):
                buffer += data
                while b"\n" in buffer:
                    line, buffer = buffer.split(b"\n", 1)
                    command = line[:_DASHBOARD_LINE_BYTES].decode(errors="replace").strip()
                    reply = self._dashboard_reply(command)
                    self._event(f"dashboard {command!r} -> {reply!r}")
                    sock.sendall(reply.encode() + b"\n")
                    if command == "quit":
                        return
                buffer = buffer[:_DASHBOARD_LINE_BYTES]  # an unfinished line: its start will do

    def _dashboard_reply(self, command: str) -> str:
        with self.lock:
            reply = self._dashboard_query(command)
            if reply is None:
                if command.split(" ", 1)[0] in _CONTROL_COMMANDS and not self.remote_control:
                    return _LOCAL_CONTROL
                reply = self._dashboard_action(command)
            return reply if reply is not None else f"could not understand: '{command}'"

    def _program_name(self) -> str:
        return self.loaded if self.loaded is not None else "<unnamed>"

    def _dashboard_query(self, command: str) -> str | None:
        """What the dashboard server answers to a question (lock held); None: not a question."""
        if command == "get robot model":
            return "UR5"
        if command == "get loaded program":
            return f"Loaded program: {self.loaded}" if self.loaded else "No program loaded"
        if command == "isProgramSaved":
            return f"true {self._program_name()}"
        if command == "get operational mode":
            return "NONE"  # no mode password set, as on a rig without one
        if command == "PolyscopeVersion":
            return self.polyscope
        if command == "get serial number":
            return "20195500001"
        if command == "is in remote control":
            return "true" if self.remote_control else "false"
        if command == "robotmode":
            mode = ROBOT_MODE_POWER_OFF if self.emergency else self.robot_mode
            return f"Robotmode: {_MODE_NAMES[mode]}"
        if command in ("safetystatus", "safetymode"):
            state = "NORMAL"
            if self.protective:
                state = "PROTECTIVE_STOP"
            if self.emergency:
                state = "ROBOT_EMERGENCY_STOP"
            return f"{command.capitalize()}: {state}"
        if command == "running":
            return f"Program running: {'true' if self.runtime_state == PLAYING else 'false'}"
        if command == "programState":
            state = {PLAYING: "PLAYING", PAUSED: "PAUSED"}.get(self.runtime_state, "STOPPED")
            name = (
                self._program_name()
                if self.playing_loaded or state == "STOPPED"
                else "rtde_control"
            )
            return f"{state} {name}"
        return None

    def _dashboard_action(self, command: str) -> str | None:
        """What the dashboard server does and answers (lock held); None: unknown."""
        running = self.runtime_state == PLAYING
        if command == "clear operational mode":
            return "No longer controlling the operational mode. Current operational mode: 'NONE'."
        if command == "power on":
            if self.robot_mode == ROBOT_MODE_POWER_OFF and not self.emergency:
                self.robot_mode = ROBOT_MODE_IDLE
            return "Powering on"
        if command == "power off":
            self._halt("power off")
            self.robot_mode = ROBOT_MODE_POWER_OFF
            return "Powering off"
        if command == "brake release":
            if self.robot_mode == ROBOT_MODE_POWER_OFF:
                self.robot_mode = ROBOT_MODE_IDLE
            if not self.emergency:
                self.robot_mode = ROBOT_MODE_RUNNING
            return "Brake releasing"
        if command.startswith("load "):
            name = command[5:].strip()
            if not name.endswith(".urp"):
                return f"File not found: {name}"
            if running:
                self._halt("load")
            self.loaded, self.runtime_state = name, STOPPED
            return f"Loading program: {name}"
        if command == "play":
            ready = self.robot_mode == ROBOT_MODE_RUNNING and not (
                self.protective or self.emergency
            )
            if self.loaded is None or not ready:
                return "Failed to execute: play"
            self.runtime_state, self.playing_loaded = PLAYING, True
            self._event(f"program started: {self.loaded}")
            return "Starting program"
        if command == "pause":
            if not running:
                return "Failed to execute: pause"
            self._halt("dashboard pause")
            self.runtime_state = PAUSED
            return "Pausing program"
        if command == "stop":
            if self.runtime_state not in (PLAYING, PAUSED):
                return "Failed to execute: stop"
            self._halt("dashboard stop")
            return "Stopped"
        if command == "unlock protective stop":
            if not self.protective or self.emergency:
                return "Failed to execute: unlock protective stop"
            self.protective = False
            return "Protective stop releasing"
        if command == "close safety popup":
            return "closing safety popup"
        if command == "quit":
            return "Disconnected"
        return None

    def _script(self, sock: socket.socket) -> None:
        """The script port: a program is `def name():` ... `end`, the first line unindented."""
        buffer = b""
        with contextlib.suppress(OSError):
            for data in self._received(sock):
                buffer += data
                text = buffer.decode(errors="replace")
                if text.startswith("def ") and text.rstrip().endswith("\nend"):
                    self._start_program(text)
                    buffer = b""
                elif not text.startswith("def ") and text.endswith("\n"):
                    self._event(f"script: a line outside a program ignored: {text.strip()[:60]!r}")
                    buffer = b""

    def _rtde(self, sock: socket.socket) -> None:
        conn = _Connection(sock)
        with self.lock:
            self.connections.append(conn)
        try:
            while not self._stop.is_set():
                package = rtde.read_package(sock)
                self._rtde_package(conn, package)
        except (OSError, ConnectionError, ValueError, struct.error) as exc:
            if not self._stop.is_set():
                self._event(f"rtde connection closed: {exc}")
        finally:
            self._forget(conn)

    def _reply(self, conn: _Connection, kind: str, payload: bytes) -> None:
        conn.send(rtde.pack(kind, payload))

    def _rtde_package(self, conn: _Connection, package: rtde.Package) -> None:
        if time.monotonic() < self.silent_until:
            return  # lost on the way
        kind, payload = package.kind, package.payload
        if kind == "V":
            version = struct.unpack(">H", payload[:2])[0] if len(payload) >= 2 else 0
            accepted = version in (1, 2) and not conn.started
            if accepted:
                conn.version = version
            self._event(f"rtde protocol {version} {'accepted' if accepted else 'refused'}")
            self._reply(conn, "V", bytes([1 if accepted else 0]))
        elif kind == "v":
            self._reply(conn, "v", struct.pack(">IIII", *self.version))
        elif kind == "O":
            self._setup_outputs(conn, payload)
        elif kind == "I":
            self._setup_inputs(conn, payload)
        elif kind == "S":
            ok = conn.outputs is not None or bool(conn.inputs)
            conn.started = ok
            self._event(f"rtde start {'accepted' if ok else 'refused: no recipe'}")
            self._reply(conn, "S", bytes([1 if ok else 0]))
        elif kind == "P":
            conn.started = False
            self._event("rtde pause")
            self._reply(conn, "P", bytes([1]))
        elif kind == "U":
            self._data(conn, payload)
        elif kind == "M":  # a client's message: into the controller's log, no reply (the guide)
            try:
                text, source, level = rtde.parse_text_message(payload)
            except ValueError as exc:
                self._event(f"rtde text message refused: {exc}")
                return
            name = rtde.LEVELS[level] if level < len(rtde.LEVELS) else f"level {level}"
            self._event(f"rtde message from {source} ({name}): {text}")
        else:
            self._event(f"rtde: unknown package type {package.type}")
            conn.send(
                rtde.text_message(f"unknown package type {package.type}", version=conn.version)
            )

    def _setup_outputs(self, conn: _Connection, payload: bytes) -> None:
        """Version 2: a frequency and names; version 1: names only, streamed at the controller's
        rate. The stream runs every floor(rate / frequency) cycles (UR's guide: "the output rate
        will be according to floor(125 / frequency)" on a CB3; the same rule at 500 Hz on an
        e-series). A frequency outside 0 < f <= rate or a name not found: recipe id 0 and an
        error text message saying why, and `start` is refused."""
        v2 = conn.version == 2
        if conn.started or (v2 and len(payload) < 8):
            why = "while started" if conn.started else "without a frequency"
            self._event(f"rtde output setup refused: {why}")
            self._reply(conn, "O", bytes([0]) if v2 else b"")
            return
        frequency = struct.unpack(">d", payload[:8])[0] if v2 else self.rate_hz
        text = payload[8:] if v2 else payload
        names = [n for n in text.decode(errors="replace").split(",") if n]
        types = [
            "NOT_FOUND" if n in NOT_EMULATED else rtde.OUTPUTS.get(n, "NOT_FOUND") for n in names
        ]
        missing = [n for n, t in zip(names, types, strict=True) if t == "NOT_FOUND"]
        problems = []
        if not 0 < frequency <= self.rate_hz:
            problems.append(
                f"output frequency {frequency:g} Hz is outside 0 < f <= {self.rate_hz:g} Hz"
            )
        elif math.isinf(self.rate_hz / frequency):  # every floor(rate / f) cycles: never
            problems.append(f"output frequency {frequency:g} Hz is too low to stream")
        if missing:
            problems.append(f"outputs not found: {', '.join(missing)}")
        if not names:
            problems.append("no outputs named")
        self._event(
            f"rtde outputs at {frequency:g} Hz: {len(names)} variables, {len(missing)} not found"
            + (f" ({', '.join(missing)})" if missing else "")
        )
        if problems:
            conn.outputs = None
            conn.send(rtde.text_message("; ".join(problems), "RTDE", 1, conn.version))
        else:
            conn.outputs = (names, types, rtde.recipe_format(types), frequency)
            conn.every = max(1, math.floor(self.rate_hz / frequency + 1e-9))
        recipe = bytes([0 if problems else 1]) if v2 else b""
        self._reply(conn, "O", recipe + ",".join(types).encode())

    def _setup_inputs(self, conn: _Connection, payload: bytes) -> None:
        names = [n for n in payload.decode(errors="replace").split(",") if n]
        if conn.started:
            self._event("rtde input setup refused: while started")
            self._reply(conn, "I", bytes([0]))
            return
        with self.lock:
            types = []
            for name in names:
                owner = self.owner.get(name)
                if name not in rtde.INPUTS:
                    types.append("NOT_FOUND")
                elif owner is not None and owner is not conn:
                    types.append("IN_USE")
                else:
                    types.append(rtde.INPUTS[name])
            ok = bool(names) and all(t in rtde.FORMATS for t in types)
            recipe = 0
            if ok:
                recipe = len(conn.inputs) + 1
                conn.inputs[recipe] = (names, types, rtde.recipe_format(types))
                for name in names:
                    self.owner[name] = conn
        if not ok:
            self._event(f"rtde input setup refused: {dict(zip(names, types, strict=True))}")
        self._reply(conn, "I", bytes([recipe]) + ",".join(types).encode())

    def _data(self, conn: _Connection, payload: bytes) -> None:
        if not payload:
            return
        recipe = payload[0]
        if not conn.started or recipe not in conn.inputs:
            why = "before start" if not conn.started else f"for unknown recipe {recipe}"
            self._event(f"rtde data refused: {why}")
            conn.send(rtde.text_message(f"data package {why} ignored", "RTDE", 1, conn.version))
            return
        names, types, layout = conn.inputs[recipe]
        try:
            values = rtde.decode_values(types, layout, payload[1:])
        except ValueError as exc:
            self._event(f"rtde data refused: {exc}")
            message = f"data package for recipe {recipe}: {exc}"
            conn.send(rtde.text_message(message, "RTDE", 1, conn.version))
            return
        with self.lock:
            for name, value in zip(names, values, strict=True):
                self.inputs[name] = value
            if "input_int_register_0" in names:
                self.kicked = time.monotonic()
                cmd = int(self.inputs["input_int_register_0"])
                if cmd and self.runtime_state != PLAYING:
                    self._event(f"command {cmd} ignored: no program is running")


def wait_for(predicate: Any, timeout_s: float, step_s: float = 0.01) -> bool:
    """Poll `predicate` until it is true or `timeout_s` passes."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(step_s)
    return bool(predicate())
