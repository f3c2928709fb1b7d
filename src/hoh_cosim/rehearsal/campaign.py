"""A fault campaign: many short rehearsals through the real `hoh-cosim hw run`, each with one to
three faults drawn at random, and the invariants a safe session must keep checked on every one.

A run is a rig in miniature: the rehearsal world (the arm, the operator's hand, the FT-150 stream on
loopback, the FSE103 on a pseudo-terminal), the loopback UR controller on an address of its own, and
`hoh-cosim hw run` in a process (and process session) of its own, driving the arm through ur-rtde
exactly as on a robot. Once the runner says its rebias is done the hand takes the handle and the
faults come, at wall-clock times drawn from the run's seed:

    ft_stall ft_garbage ft_nan ft_spike ft_disconnect    the FT-150 stream (the world's faults)
    probe_unplug probe_garbage probe_framing force_spike the FSE103 (the world's faults)
    protective_stop emergency_stop rtde_drop             the UR controller (`UrController.inject`)
    program_stopped                                      the dashboard's `stop`, as from a pendant
    runner_kill                                          SIGKILL to the runner's process
    cpu_hog                                              a busy process on every core

Per run the invariants (`Run.violations` names each one broken):

- a fault that calls for a stop stops the session, and the arm stands still within the fault's own
  detection time (`Kind.detect_s`: the stale-stream limit, the link's silence limit, the robot's
  watchdog) plus the watchdog's period plus `BRAKE_S`; faults that call for none do not stop it.
  A silent stream's stop comes later by the time ordinary tasks were starved meanwhile, which the
  runner does not count as the device's silence and names (in the cause, or in a `starved` event
  when the stream came back): the bound grows by it, and a stream fault whose silence was
  discounted so may stop the session or not;
- the session's cause names the first fault that called for a stop (the runner's last words and the
  log's `end` event), and the runner exits with its own status (0 done, 1 stopped; -9 only when it
  was the one killed; never killed by a signal of its own making, such as ur-rtde's SIGABRT);
- the log is complete: finished, every message strict JSON valid against its channel's schema, and
  its last cycle within a second of the session's end (of the kill, for runner_kill);
- no process of the runner's session is left behind.

A stream may also fall silent with no fault of ours: the machine itself starves ordinary tasks, the
kernel worker that delivers the stream's bytes among them (a loaded machine, a virtual CPU the host
holds back). The runner ends such a session at its cap on a stale stream's age (1 s), whatever it
discounted, and its cause says how much of the silence was starved. Such a stop is the machine's
(`Run.machine_stop`) when the cause says the counted silence stayed under the stale limit (the cap
ended it), the stream's last sample came before every fault injected that could stop the session,
silence that stream or load the machine (cpu_hog), and the arm stood still within the stale-stream zeroing (three of the stream's
periods), the watchdog's period and `BRAKE_S` of the silence's start. The faults that came after it
are not judged (the runner could not see them); every other invariant still is. Such runs are
counted apart (`machine_stops`), never hidden among the faults'.

The emulated devices stand for hardware of their own, so their loops run above the runner's
priority; a machine can still hold them back (a virtual CPU the host deschedules, a kernel call
that waits on an ordinary worker). Each run records the longest time the world's loop or the UR
controller's stood still (`rig_stall_ms`); `rig_stalls` counts the runs where it reached
`RIG_STALL_S`. Their violations stay violations: such a run says nothing about the runner, and is
re-run from its seed.

The run's seed is the campaign's seed plus its number, and a run depends on its seed alone: a failing
run is re-run alone with `--runs 1 --seed <its seed>`. The first fault's kind cycles through the kinds
with the seed (any `len(KINDS)` runs in a row start with every kind once, so every kind is injected);
the rest is drawn.
"""

from __future__ import annotations

import contextlib
import csv
import json
import math
import os
import re
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterable, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from hoh_cosim.control.supervisor import STARVED_TEXT
from hoh_cosim.errors import ConfigError
from hoh_cosim.hardware.session_log import ORPHANED_CAUSE
from hoh_cosim.rehearsal.faults import FAULTS
from hoh_cosim.rehearsal.priorities import LOOP_PRIORITY

__all__ = [
    "BRAKE_S",
    "KINDS",
    "CampaignFault",
    "Run",
    "draw_faults",
    "run_campaign",
    "stream_figures",
    "summarise",
]

BRAKE_S = 0.3
"""[s] What braking may add to a fault's detection time before the arm stands still: speedStop at the
runner's 2 m/s² from the hand-guiding speed limit of 0.25 m/s takes 0.125 s, with a margin for the
emulated controller's cycle and a busy machine."""

STALE_S = 0.25  # the supervisor's default stale_stop_s (SessionPolicy)
STALE_PERIODS = 3.0  # LimitParams.stale_periods: a stream this many periods old zeroes the command
PERIODS_S = {"ft150": 0.005, "fse103": 0.02}  # the emulated devices' sample periods
LINK_SILENCE_S = 0.1  # RtdeRobot.silence_s: no new controller state for this long, the link is gone
WATCHDOG_HZ = 20.0  # the rig's robot watchdog here (hoh_cosim.hardware.config's default)
RIG_STALL_S = 0.05
"""[s] The emulated devices stand for hardware of their own that no load here can hold back: a run in
which the world's loop or the UR controller's stood still this long (half the runner's limit on the
controller's silence, the robot watchdog's period) did not face the rig it claims to, and the
summary counts it (`rig_stalls`); its violations stay violations."""
SESSION_S = 3.5  # [s] the session after the rebias; the faults come between FIRST_S and LAST_S
FIRST_S, LAST_S = 1.0, 2.5  # [s] after the rebias (the hand comes at 0.5 s)
ENDED = re.compile(r"^session ended: (.*)$", re.M)


@dataclass(frozen=True)
class Kind:
    """One kind of fault: how long it lasts, whether it calls for a stop, and what names it."""

    name: str
    durations_s: tuple[float, float] | None  # drawn uniformly; None: a moment, or for good
    stops: Callable[[float], bool | None]  # duration -> must stop / must not / either may happen
    cause: str = ""  # a regular expression the session's cause matches when this kind stopped it
    detect_s: float = 0.0  # [s] how long after the fault the runner may take to see it
    stream: str = ""  # the stream a stale-stream stop names (a regular expression), if any

    def calls_for_stop(self, duration_s: float) -> bool | None:
        return self.stops(duration_s)


def _stall_stops(duration_s: float) -> bool | None:
    # a stream silent for the stale limit ends the session; within 50 ms of it either outcome is
    # right (the last sample before the stall, the cycle that looks, a busy machine)
    if duration_s > STALE_S + 0.05:
        return True
    if duration_s < STALE_S - 0.05:
        return False
    return None


def _always(duration_s: float) -> bool:
    return True


def _never(duration_s: float) -> bool:
    return False


_FT = r"FT-150 stream at \S+"
_PROBE = r"FSE103 on \S+"
KINDS = {
    kind.name: kind
    for kind in (
        Kind("ft_stall", (0.02, 0.8), _stall_stops, _FT + ": no new sample", STALE_S, _FT),
        Kind("ft_garbage", None, _never),
        Kind("ft_nan", (0.02, 0.2), _always, _FT + " sent a non-finite value"),
        Kind("ft_spike", (0.005, 0.05), _never),
        # the reader tries again after 0.5 s, past the stale limit however short the outage
        Kind("ft_disconnect", (0.1, 1.0), _always, _FT + ": no new sample", STALE_S, _FT),
        Kind("probe_unplug", None, _always, _PROBE, STALE_S, _PROBE),
        Kind("probe_garbage", None, _never),
        # the parser tries the other framing where the detected one fails and locks on its first
        # 3 frames (hoh_cosim.hardware.fse103): 60 ms at 50 Hz, well inside the stale limit
        Kind("probe_framing", None, _never),
        Kind("force_spike", (0.1, 0.5), _always, r"reached the 25 N stop", 0.05),
        Kind("protective_stop", None, _always, r"the robot is in a protective stop"),
        Kind("emergency_stop", None, _always, r"the robot is emergency-stopped"),
        Kind(
            "rtde_drop",
            (0.5, 3.0),
            _always,
            r"the connection to the controller was lost",
            LINK_SILENCE_S,
        ),
        Kind(
            "program_stopped",
            None,
            _always,
            r"the control program on the robot is not running",
        ),
        Kind("runner_kill", None, _always, re.escape(ORPHANED_CAUSE)),
        Kind("cpu_hog", (0.5, 2.5), _never),
    )
}
# what the rehearsal world injects; the protective stop, a world fault too, comes from the UR
# controller here, beside the emergency stop
WORLD_KINDS = frozenset(FAULTS) - {"protective_stop"}


@dataclass(frozen=True)
class CampaignFault:
    """`kind` at `at_s` after the runner's rebias, lasting `duration_s` (0: a moment or for good)."""

    kind: str
    at_s: float
    duration_s: float = 0.0

    def text(self) -> str:
        lasting = f"+{self.duration_s:.3f}" if self.duration_s else ""
        return f"{self.kind}@{self.at_s:.3f}{lasting}"

    @property
    def stops(self) -> bool | None:
        return KINDS[self.kind].calls_for_stop(self.duration_s)


def draw_faults(seed: int, kinds: Sequence[str]) -> tuple[CampaignFault, ...]:
    """One run's faults from its seed alone: one to three, the first of kind kinds[seed % n], in
    the order they come."""
    rng = np.random.default_rng([seed, 0x4641554C])  # "FAUL": a stream of this module's own
    n = int(rng.integers(1, 4))
    chosen = [kinds[seed % len(kinds)]] + [str(k) for k in rng.choice(kinds, size=n - 1)]
    # the cycled kind comes first, so that a stop of a later fault never keeps it out
    times = sorted(float(t) for t in rng.uniform(FIRST_S, LAST_S, size=n))
    faults = []
    for kind, at_s in zip(chosen, times, strict=True):
        span = KINDS[kind].durations_s
        duration_s = float(rng.uniform(*span)) if span is not None else 0.0
        faults.append(CampaignFault(kind, round(at_s, 3), round(duration_s, 3)))
    return tuple(faults)


@dataclass
class Run:
    """One run's faults, what happened and the invariants it broke."""

    number: int
    seed: int
    faults: tuple[CampaignFault, ...]
    injected: list[tuple[CampaignFault, float]] = field(default_factory=list)  # (fault, monotonic)
    expected: str = ""  # "stop", "go on" or "either"
    first_kind: str = ""  # the kind whose stop came first (expected), "" for none
    cause: str = ""
    returncode: int | None = None
    stopped: bool = False
    standstill_s: float = math.nan  # from the first stopping fault to the arm standing still
    bound_s: float = math.nan
    messages: int = 0
    # each stream as the runner received it over the session: mean rate [Hz], longest gap [s]
    rates_hz: dict[str, float] = field(default_factory=dict)
    gaps_s: dict[str, float] = field(default_factory=dict)
    wall_s: float = 0.0
    machine_stop: bool = False  # stopped by a stream the machine starved, before any fault of ours
    # the longest time the emulated devices (the world's loop, the UR controller's) stood still [s]
    rig_stall_s: float = math.nan
    probe_refused: int = 0  # the probe's frames its pseudo-terminal refused (RehearsalWorld)
    violations: list[str] = field(default_factory=list)

    def row(self) -> dict[str, object]:
        return {
            "run": self.number,
            "seed": self.seed,
            "faults": " ".join(f.text() for f in self.faults),
            "injected": " ".join(f.kind for f, _ in self.injected),
            "expected": self.expected,
            "first_kind": self.first_kind,
            "stopped": int(self.stopped),
            "machine_stop": int(self.machine_stop),
            "cause": self.cause,
            "returncode": self.returncode,
            "fault_to_standstill_ms": _ms(self.standstill_s),
            "bound_ms": _ms(self.bound_s),
            "log_messages": self.messages,
            **{
                f"{name}_{figure}": value
                for name in STREAMS
                for figure, value in (
                    ("hz", _round(self.rates_hz.get(name, math.nan), 1)),
                    ("gap_ms", _ms(self.gaps_s.get(name, math.nan))),
                )
            },
            "rig_stall_ms": _ms(self.rig_stall_s),
            "probe_refused": self.probe_refused,
            "wall_s": round(self.wall_s, 2),
            "violations": "; ".join(self.violations),
        }


def _ms(seconds: float) -> str:
    return "" if math.isnan(seconds) else f"{1e3 * seconds:.1f}"


def _round(x: float, digits: int) -> str:
    return "" if math.isnan(x) else f"{x:.{digits}f}"


STREAMS = ("ft150", "fse103")
"""The sensor channels of the session log whose rates a run reports."""
STREAM_KINDS = frozenset(k for k in WORLD_KINDS if k.startswith(("ft_", "probe_")))
"""The faults that interrupt a stream: a run with none of them shows the devices' own rates."""


# --- one run -------------------------------------------------------------------------------------


class _Monitor(threading.Thread):
    """The arm's motion, as the world itself keeps it: the world time of its last moving tick
    (`RehearsalWorld.last_moving`), put on this process's monotonic clock by the world's time
    stamps sampled every 2 ms. A sampler at ordinary priority alone would take its own late
    turns on a busy machine for a late standstill (seen: 426 ms after a runner_kill, the world's
    own loop never more than 3 ms late)."""

    def __init__(self, world) -> None:
        super().__init__(name="campaign-monitor", daemon=True)
        self.world = world
        self.offset_s = math.inf  # monotonic minus world time, at the sample read soonest
        self.moving_at_end = False
        self.last_moving_s = math.nan  # the world's, once done
        self.last_commanded_s = math.nan  # the world's last command to move, once done
        self.done = threading.Event()

    def run(self) -> None:
        while not self.done.is_set():
            state = self.world._state.read()
            self.offset_s = min(self.offset_s, time.monotonic() - float(state[23]))
            self.moving_at_end = float(np.linalg.norm(state[12:18])) > 1e-9
            time.sleep(0.002)
        self.last_moving_s = self.world.last_moving()
        self.last_commanded_s = self.world.last_commanded()

    def standstill_after(self, t: float) -> float:
        """When the arm came to rest for good after `t` (monotonic), NaN if it never did."""
        if self.moving_at_end:
            return math.nan
        if math.isnan(self.last_moving_s):
            return t
        return max(t, self.last_moving_s + self.offset_s)

    def late(self, t: float) -> str:
        """What a standstill later than its bound after `t` (monotonic) comes with: when the
        world last read a command to move, after `t`, so that a late command to rest is told
        from an arm that did not follow one."""
        if math.isnan(self.last_commanded_s):
            return "the world never read a command to move"
        after = self.last_commanded_s + self.offset_s - t
        if after <= 0.0:
            return "the world read no command to move after it"
        return f"the world read a command to move until {_ms(after)} ms after it"


class _Hog:
    """A busy process on every core for a while (the cpu_hog fault)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self.processes: list[subprocess.Popen] = []

    def start(self) -> None:
        with self._lock:
            for _ in range(os.cpu_count() or 1):
                self.processes.append(
                    subprocess.Popen([sys.executable, "-S", "-c", "while True: pass"])
                )

    def stop(self) -> None:
        with self._lock:
            processes, self.processes = self.processes, []
        for process in processes:
            process.kill()
            process.wait()


def _session_members(sid: int) -> list[int]:
    """The live processes of process session `sid` (Linux /proc), the session's leader included.
    A zombie has ended: only its parent, or init for an orphan, has yet to collect its status."""
    members = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            stat = (entry / "stat").read_text()
        except OSError:
            continue
        # pid (comm) state ppid pgrp session ...: comm may hold spaces and brackets
        fields = stat[stat.rfind(")") + 2 :].split()
        if len(fields) > 3 and int(fields[3]) == sid and fields[0] != "Z":
            members.append(int(entry.name))
    return members


def _dashboard(host: str, command: str) -> str:
    with socket.create_connection((host, 29999), timeout=2.0) as sock:
        stream = sock.makefile("rwb")
        stream.readline()  # the greeting
        stream.write(command.encode() + b"\n")
        stream.flush()
        return stream.readline().decode().strip()


def _write_rig(directory: Path, world, host: str, rt_priority: int | None) -> Path:
    from hoh_cosim.rehearsal.rehearse import write_truth_calibration

    write_truth_calibration(world.truth, directory / "calibration.json")
    priority = "" if rt_priority is None else f", realtime_priority: {rt_priority}"
    config = directory / "rig.yaml"
    config.write_text(
        f"robot: {{host: {host}, watchdog_hz: {WATCHDOG_HZ:g}{priority}}}\n"
        f"ft150: {{host: 127.0.0.1, port: {world.ft_port}}}\n"
        f"probe: {{device: {world.pty_name}}}\n"
        "calibration: calibration.json\n"
        "rebias: {samples: 100}\n"
        "log_dir: .\n"
    )
    return config


class _Hosts:
    """Loopback addresses whose UR ports are free, one per concurrent run (ur-rtde's ports are
    fixed: 29999, 30003, 30004)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._taken: set[str] = set()
        candidates = [f"127.0.{a}.{b}" for a in range(100, 110) for b in range(2, 255)]
        start = (os.getpid() * 97) % len(candidates)  # two campaigns at once seldom meet
        self._candidates = candidates[start:] + candidates[:start]

    def spoil(self, host: str) -> None:
        """Never lease `host` again: another program listens there."""
        with self._lock:
            self._candidates.remove(host)

    @contextlib.contextmanager
    def lease(self) -> Iterable[str]:
        with self._lock:
            host = next(h for h in self._candidates if h not in self._taken and _free(h))
            self._taken.add(host)
        try:
            yield host
        finally:
            with self._lock:
                self._taken.discard(host)


def _free(host: str) -> bool:
    try:
        for port in (29999, 30003, 30004):
            with socket.socket() as s:
                s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
                s.bind((host, port))
    except OSError:
        return False
    return True


def _wait(predicate: Callable[[], bool], timeout_s: float, step_s: float = 0.01) -> bool:
    deadline = time.monotonic() + timeout_s
    while not predicate():
        if time.monotonic() > deadline:
            return False
        time.sleep(step_s)
    return True


@contextlib.contextmanager
def _rig(hosts: _Hosts, setup, attempts: int = 5):
    """A run's world and UR controller, on a loopback address that was free: another program (a
    second campaign, a test) may take it between the check and the controller's listening, and
    then the next address is tried."""
    from hoh_cosim.rehearsal.ur_controller import UrController
    from hoh_cosim.rehearsal.world import RehearsalWorld

    for attempt in range(attempts):
        with hosts.lease() as host, RehearsalWorld(setup) as world:
            try:
                ur = UrController(world, host).start()
            except RuntimeError as exc:
                if "Address already in use" not in str(exc) or attempt == attempts - 1:
                    raise
                hosts.spoil(host)
                continue
            try:
                yield host, world, ur
            finally:
                ur.stop()
            return


def run_one(
    number: int, seed: int, kinds: Sequence[str], out: Path, hosts: _Hosts, rt_priority: int | None
) -> Run:
    """Run `number` of a campaign: its faults drawn from `seed`, its files under out/run-NNNN."""
    from hoh_cosim.rehearsal.world import WorldSetup

    run = Run(number, seed, draw_faults(seed, kinds))
    started = time.monotonic()
    directory = out / f"run-{number:04d}"
    directory.mkdir(parents=True, exist_ok=True)
    log = directory / "session.mcap"
    output = directory / "runner.out"
    setup = WorldSetup(task="circle", task_start_s=None, seed=seed, watchdog_hz=WATCHDOG_HZ)
    hogs: list[_Hog] = []
    with _rig(hosts, setup) as (host, world, ur):
        config = _write_rig(directory, world, host, rt_priority)
        monitor = _Monitor(world)
        monitor.start()
        with output.open("w") as stream:
            process = subprocess.Popen(
                [
                    *(sys.executable, "-m", "hoh_cosim", "hw", "run", str(config)),
                    *("--log", str(log), "--seconds", f"{SESSION_S:g}"),
                ],
                stdout=stream,
                stderr=subprocess.STDOUT,
                start_new_session=True,  # its own session: what it leaves behind can be found
            )
        killed_at = math.nan
        try:
            if not _wait(
                lambda: "rebias done" in output.read_text() or process.poll() is not None, 90.0
            ):
                run.violations.append("the runner never finished its rebias")
            elif process.poll() is None:
                world.start_task()
                t0 = time.monotonic()
                for fault in run.faults:
                    if _wait(
                        lambda: process.poll() is not None, t0 + fault.at_s - time.monotonic()
                    ):
                        break  # the session is over: the later faults never came
                    if "stopping: " in output.read_text():
                        break  # the runner is on its way out
                    at = time.monotonic()
                    if fault.kind in WORLD_KINDS:
                        world.inject(fault.kind, fault.duration_s)
                    elif fault.kind == "rtde_drop":
                        ur.inject("drop_connection", fault.duration_s)
                    elif fault.kind in ("protective_stop", "emergency_stop"):
                        ur.inject(fault.kind)
                    elif fault.kind == "program_stopped":
                        _dashboard(host, "stop")
                    elif fault.kind == "runner_kill":
                        process.send_signal(signal.SIGKILL)
                        killed_at = at
                    elif fault.kind == "cpu_hog":
                        hogs.append(_Hog())
                        hogs[-1].start()
                        threading.Timer(fault.duration_s, hogs[-1].stop).start()
                    run.injected.append((fault, at))
            if process.poll() is None:
                try:
                    process.wait(SESSION_S + 30.0)
                except subprocess.TimeoutExpired:
                    run.violations.append("the runner did not end within 30 s of its session")
                    process.kill()
                    process.wait()
            _wait(lambda: False, 0.3)  # the arm's last moments, for the standstill
        finally:
            ur.said("")  # collects the controller's events, for the run's files
            (directory / "controller.log").write_text(
                "".join(f"{t:.4f} {text}\n" for t, text in ur.events)
            )
            run.rig_stall_s = max(
                [
                    world.stall()[0],
                    *(1e-3 * float(m[1]) for _, text in ur.events if (m := _STALLED.match(text))),
                ]
            )
            run.probe_refused = world.probe_refused()
            for hog in hogs:
                hog.stop()
            monitor.done.set()
            monitor.join()
            if process.poll() is None:
                process.kill()
                process.wait()
        run.returncode = process.returncode
        # the log's writer finishes the file once its runner is gone; then nothing may be left
        _wait(lambda: not _session_members(process.pid), 10.0, 0.05)
        left = _session_members(process.pid)
        if left:
            run.violations.append(f"processes left behind: {left}")
            for pid in left:
                with contextlib.suppress(OSError):
                    os.kill(pid, signal.SIGKILL)
    _judge(run, output.read_text(), log, monitor, killed_at)
    run.wall_s = time.monotonic() - started
    return run


_STALLED = re.compile(r"stalled (\d+) ms$")


def _judge(run: Run, said: str, log: Path, monitor: _Monitor, killed_at: float) -> None:
    """Check one run's invariants (see the module's docstring) and note every one broken."""
    from hoh_cosim.hardware.log_check import invalid_messages
    from hoh_cosim.hardware.session_log import read_session

    v = run.violations
    session = None
    try:
        session = read_session(log)
    except Exception as exc:  # any failure to read the log is the finding
        v.append(f"the log cannot be read: {type(exc).__name__}: {exc}")
    # a stream's silence while ordinary tasks were starved is not counted (the runner logs how
    # much it left out): a fault that silenced that stream may then end the session or not
    starved = [
        m["detail"]
        for m in (session.messages.get("/events", []) if session is not None else [])
        if m["event"] == "starved"
    ]

    def stops(fault: CampaignFault) -> bool | None:
        stream = KINDS[fault.kind].stream
        if fault.stops and stream and any(re.match(stream, detail) for detail in starved):
            return None
        return fault.stops

    match = ENDED.search(said)
    run.cause = match.group(1) if match else ""
    killed = not math.isnan(killed_at)
    # what the session ended with: the runner's words, or for a killed one its log's end
    end = _end_event(session) if session is not None else None
    if killed:
        run.cause = end["detail"] if end else ""
    # a stop of the machine's own: the faults that came after its silence began are not judged
    silence = _machine_silence(run, session)
    if silence is not None:
        stream, silent_from = silence
        run.machine_stop = True
        bound_s = STALE_PERIODS * PERIODS_S[stream] + 1.0 / WATCHDOG_HZ + BRAKE_S
        standstill_s = monitor.standstill_after(silent_from) - silent_from
        if not standstill_s <= bound_s:
            v.append(
                f"the arm stood still {_ms(standstill_s) or 'never'} ms after the {stream} fell "
                f"silent (bound {_ms(bound_s)} ms; {monitor.late(silent_from)})"
            )
    judged = [(f, at) for f, at in run.injected if silence is None or at < silence[1]]
    stopping = [(f, at) for f, at in judged if stops(f)]
    maybe = [(f, at) for f, at in judged if stops(f) is None]
    run.expected = "stop" if stopping else ("either" if maybe else "go on")
    run.stopped = killed or run.returncode == 1 or "stopping: " in said
    if run.returncode not in ((-signal.SIGKILL,) if killed else (0, 1)):
        v.append(f"the runner's exit status is {run.returncode}")
    # stop or not, and the first cause
    candidates = sorted(stopping + maybe, key=lambda fa: fa[1] + KINDS[fa[0].kind].detect_s)
    if stopping:
        first_stop = min(at + KINDS[f.kind].detect_s for f, at in stopping)
        # a fault seen up to 0.15 s before or after the first that must stop may be named
        named = [
            (f, at) for f, at in candidates if at + KINDS[f.kind].detect_s <= first_stop + 0.15
        ]
        # the fault the cause names is the one that stopped the session, and its time and bound
        # are the ones that count: a fault that may stop or not, named first but survived, does
        # not make a later stop late
        causes = [(f, at) for f, at in named if re.search(KINDS[f.kind].cause, run.cause)]
        fault, fault_at = causes[0] if causes else named[0]
        run.first_kind = fault.kind
        if not run.stopped:
            v.append(f"no stop after {run.first_kind}: {run.cause or 'no cause said'}")
        elif not causes:
            v.append(f"the cause does not name {'/'.join(f.kind for f, _ in named)}: {run.cause!r}")
        kind = KINDS[run.first_kind]
        # a stale stream's stop comes later by the time ordinary tasks were starved, which its
        # cause names (the supervisor does not count it as the device's silence)
        run.bound_s = kind.detect_s + 1.0 / WATCHDOG_HZ + BRAKE_S + _discounted_s(run.cause)
        run.standstill_s = monitor.standstill_after(fault_at) - fault_at
        if not run.standstill_s <= run.bound_s:
            v.append(
                f"the arm stood still {_ms(run.standstill_s) or 'never'} ms after the fault "
                f"(bound {_ms(run.bound_s)} ms; {monitor.late(fault_at)})"
            )
    elif maybe:
        if (
            run.stopped
            and not run.machine_stop
            and not any(re.search(KINDS[f.kind].cause, run.cause) for f, _ in maybe)
        ):
            v.append(f"a stop whose cause names none of the faults: {run.cause!r}")
    elif (run.stopped or run.returncode != 0) and not run.machine_stop:
        v.append(f"stopped though no fault called for it: {run.cause!r}")
    if session is None:
        return
    # the log: finished, strict and valid, and its last cycle near the session's end
    if not session.complete:
        v.append("the log is not finished")
    run.messages, problems = invalid_messages(log)
    if problems:
        v.append(f"{len(problems)} log messages invalid, the first: {problems[0]}")
    if end is None:
        v.append("the log has no end event")
    elif run.stopped and not killed and run.cause and end["detail"] != run.cause:
        v.append(f"the log's end says {end['detail']!r}, the runner said {run.cause!r}")
    for name, (rate_hz, gap_s) in stream_figures(session).items():
        run.rates_hz[name], run.gaps_s[name] = rate_hz, gap_s
    robot = session.messages.get("/robot", [])
    if killed:
        received = [m["received_s"] for m in session.messages.get("/ft150", [])]
        if not received or killed_at - max(received) > 1.0:
            v.append("the log's last FT-150 sample is more than 1 s before the kill")
    elif end is not None and (not robot or end["k"] - robot[-1]["k"] > 500):
        v.append("the log's last cycle is more than 1 s of cycles before its end")


_DISCOUNTED = re.compile(rf"(\d+) {re.escape(STARVED_TEXT)}")
_STALE_STOP = re.compile(
    rf"^(?P<name>{_FT}|{_PROBE}): no new sample for (?P<age>\d+) ms \(.*; "
    rf"(?P<starved>\d+) {re.escape(STARVED_TEXT)}\)$"
)


def _machine_silence(run: Run, session) -> tuple[str, float] | None:
    """(the stream, when it fell silent [monotonic s]) if the run's stop was the machine's own (see
    the module's docstring), else None."""
    match = _STALE_STOP.match(run.cause)
    if match is None or session is None:
        return None
    # the cap ended the session: the silence it counted, less the starved time, was under the limit
    if int(match["age"]) - int(match["starved"]) >= 1e3 * STALE_S:
        return None
    stream = "ft150" if re.match(_FT, match["name"]) else "fse103"
    received = [m["received_s"] for m in session.messages.get(f"/{stream}", [])]
    if not received:
        return None
    silent_from = max(received)
    for fault, at in run.injected:
        kind = KINDS[fault.kind]
        silences = bool(kind.stream) and re.match(kind.stream, match["name"]) is not None
        # our own busy processes load the machine: a silence after them is judged as usual too
        if at <= silent_from and (silences or fault.stops is not False or kind.name == "cpu_hog"):
            return None  # a fault of ours came first: it is judged as usual
    return stream, silent_from


def _discounted_s(cause: str) -> float:
    """The starved time [s] a stale stream's stop says it did not count as silence (0: none)."""
    match = _DISCOUNTED.search(cause)
    return 1e-3 * int(match.group(1)) if match else 0.0


def stream_figures(session) -> dict[str, tuple[float, float]]:
    """Each sensor stream as the runner received it over a logged session: its mean rate [Hz]
    (samples the device counted over the time they took to arrive) and its longest gap [s]."""
    figures = {}
    for name in STREAMS:
        messages = session.messages.get(f"/{name}", [])
        if len(messages) >= 2:
            counts = np.array([m["count"] for m in messages], dtype=float)
            times = np.array([m["received_s"] for m in messages], dtype=float)
            if times[-1] > times[0]:
                rate_hz = (counts[-1] - counts[0]) / (times[-1] - times[0])
                figures[name] = (float(rate_hz), float(np.diff(times).max()))
    return figures


def _end_event(session) -> dict | None:
    ends = [m for m in session.messages.get("/events", []) if m["event"] == "end"]
    return ends[-1] if ends else None


# --- the campaign --------------------------------------------------------------------------------


def run_campaign(
    runs: int,
    seed: int,
    workers: int,
    out: Path,
    kinds: Sequence[str] = tuple(KINDS),
    rt_priority: int | None = LOOP_PRIORITY,
    announce: Callable[[Run], None] = lambda run: None,
) -> list[Run]:
    """`runs` runs (seeds seed, seed + 1, ...) on `workers` threads, each runner's loop at
    SCHED_FIFO `rt_priority` (None: the default priority); each run announced when done."""
    for kind in kinds:
        if kind not in KINDS:
            raise ConfigError(f"--kinds: expected some of {', '.join(KINDS)}, got {kind!r}")
    hosts = _Hosts()
    done: list[Run] = []

    def one(number: int) -> Run:
        try:
            run = run_one(number, seed + number, kinds, out, hosts, rt_priority)
        except Exception as exc:  # the run's own finding; the campaign goes on
            run = Run(number, seed + number, draw_faults(seed + number, kinds))
            run.violations.append(f"the run failed: {type(exc).__name__}: {exc}")
        announce(run)
        return run

    with ThreadPoolExecutor(max_workers=workers) as pool:
        done = list(pool.map(one, range(runs)))
    return done


def summarise(runs: Sequence[Run], seed: int) -> dict:
    """summary.json: runs, violations, and per kind the runs it was in, their violations and the
    times from fault to standstill of the runs it stopped first."""
    per_kind: dict[str, dict] = {}
    for kind in KINDS:
        within = [r for r in runs if any(f.kind == kind for f in r.faults)]
        if not within:
            continue
        first = [r.standstill_s for r in runs if r.first_kind == kind and r.stopped]
        per_kind[kind] = {
            "runs": len(within),
            "injected": sum(1 for r in runs for f, _ in r.injected if f.kind == kind),
            "violations": sum(1 for r in within if r.violations),
            "stopped_first": len(first),
            "fault_to_standstill_ms": _percentiles(first),
        }
    return {
        "runs": len(runs),
        "violations": sum(1 for r in runs if r.violations),
        "machine_stops": sum(1 for r in runs if r.machine_stop),
        "rig_stalls": sum(1 for r in runs if r.rig_stall_s >= RIG_STALL_S),
        "seed": seed,
        "kinds": per_kind,
        "fault_to_standstill_ms": _percentiles([r.standstill_s for r in runs if r.first_kind]),
        "streams": _streams(runs),
        "failed_runs": [
            {
                "run": r.number,
                "seed": r.seed,
                "violations": r.violations,
                "rig_stall_ms": None
                if math.isnan(r.rig_stall_s)
                else round(1e3 * r.rig_stall_s, 1),
            }
            for r in runs
            if r.violations
        ],
    }


def _streams(runs: Sequence[Run]) -> dict[str, dict]:
    """The devices' rates as the runners received them, over the runs whose faults left the streams
    alone (a CPU hog included): the lowest mean rate and the longest gap."""
    quiet = [r for r in runs if not any(f.kind in STREAM_KINDS for f, _ in r.injected)]
    figures = {}
    for name in STREAMS:
        rates = [r.rates_hz[name] for r in quiet if name in r.rates_hz]
        gaps = [r.gaps_s[name] for r in quiet if name in r.gaps_s]
        figures[name] = {
            "runs": len(rates),
            "lowest_rate_hz": round(min(rates), 1) if rates else None,
            "median_rate_hz": round(float(np.median(rates)), 1) if rates else None,
            "longest_gap_ms": round(1e3 * max(gaps), 1) if gaps else None,
        }
    return figures


def _percentiles(values: Sequence[float]) -> dict[str, float | None]:
    finite = np.asarray([x for x in values if math.isfinite(x)], dtype=float)
    if finite.size == 0:
        return {"p50": None, "p99": None, "max": None}
    return {
        "p50": round(1e3 * float(np.percentile(finite, 50)), 1),
        "p99": round(1e3 * float(np.percentile(finite, 99)), 1),
        "max": round(1e3 * float(finite.max()), 1),
    }


def table(summary: dict) -> str:
    """The printed table: per kind, runs, violations, fault to standstill p50 / p99 / max."""
    lines = [
        f"{'fault':16} {'runs':>5} {'violations':>10} {'stopped first':>13}  "
        "fault to standstill p50 / p99 / max [ms]"
    ]
    for kind, figures in summary["kinds"].items():
        p = figures["fault_to_standstill_ms"]
        times = "-" if p["p50"] is None else f"{p['p50']:.0f} / {p['p99']:.0f} / {p['max']:.0f}"
        lines.append(
            f"{kind:16} {figures['runs']:5d} {figures['violations']:10d} "
            f"{figures['stopped_first']:13d}  {times}"
        )
    p = summary["fault_to_standstill_ms"]
    times = "-" if p["p50"] is None else f"{p['p50']:.0f} / {p['p99']:.0f} / {p['max']:.0f}"
    lines.append(f"{'all':16} {summary['runs']:5d} {summary['violations']:10d} {'':13}  {times}")
    if summary["machine_stops"]:
        lines.append(
            f"stopped by this machine before any fault (a stream silent for the 1 s cap, most of "
            f"it with ordinary tasks starved): {summary['machine_stops']} runs"
        )
    if summary["rig_stalls"]:
        lines.append(
            f"runs whose emulated devices this machine held back for {1e3 * RIG_STALL_S:.0f} ms "
            f"or more (their loop's longest turn; in campaign.csv): {summary['rig_stalls']}"
        )
    for name, figures in summary["streams"].items():
        if figures["runs"]:
            lines.append(
                f"{name} in the {figures['runs']} runs that left it alone: lowest rate "
                f"{figures['lowest_rate_hz']} Hz, median {figures['median_rate_hz']} Hz, longest "
                f"gap {figures['longest_gap_ms']} ms"
            )
    return "\n".join(lines)


def write_results(runs: Sequence[Run], summary: dict, out: Path) -> None:
    """campaign.csv (one row per run) and summary.json, each written whole or not at all."""
    rows = [r.row() for r in runs]
    partial = out / "campaign.csv.partial"
    with partial.open("w", newline="") as stream:
        writer = csv.DictWriter(stream, fieldnames=list(Run(0, 0, ()).row()))
        writer.writeheader()
        writer.writerows(rows)
    partial.replace(out / "campaign.csv")
    partial = out / "summary.json.partial"
    partial.write_text(json.dumps(summary, indent=2) + "\n")
    partial.replace(out / "summary.json")
