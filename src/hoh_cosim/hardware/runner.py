"""The hardware runner: the same Estimator and HandGuidingController, driving a real UR5.

    connect the robot and the streams, wait for samples
    rebias: hold still, average `rebias.samples` FT-150 samples (and every probe sample meanwhile),
            refuse if the robot moves or the mean disagrees with the gravity model
    probe check (if `estimator.probe_correction.check_s` > 0): the loop runs, the estimator is not
            ready and the robot holds still while someone presses the probe tip, hand off the handle
    loop at the robot's rate until stopped:
        wait for the cycle's start (Pacer), read the robot's state and the latest samples
        Estimator.step (predicts every cycle, corrects when a sample's counter moved)
        HandGuidingController.step
        the supervisor: anything wrong -> stop the robot and end with the cause
        speedL, kick the watchdog, log the cycle, offer it to the observer (if any)
    finally: stop the robot, stop the streams, close the log

The loop never blocks on I/O: reader threads fill mailboxes, a writer process writes the log, and
an observer (the live view's feed, `hoh_cosim.hardware.feed`) is a bounded ring that drops frames
rather than wait. Time inside the blocks is the cycle number times the period, as in the
co-simulation.

Packet periods are measured during the rebias, not assumed (notes/hardware.md: the FT-150 has been
seen at 62.5, 100 and 200 Hz): the estimator's and the controller's expected periods are set to the
measured ones, so "stale" means three of the rig's own periods.
"""

from __future__ import annotations

import contextlib
import dataclasses
import gc
import math
import os
import sys
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from hoh_cosim.control.controller import HandGuidingController
from hoh_cosim.control.cycle import ControlBlocks, Reading, SensorSetup, control_cycle
from hoh_cosim.control.estimator import Estimator, import_filter_libraries
from hoh_cosim.control.gravity import GravityCalibration, GravityModel
from hoh_cosim.control.supervisor import (
    STARVED_TEXT,
    SessionPolicy,
    Status,
    Verdict,
    robot_cause,
    starved_cause,
)
from hoh_cosim.control.vectors import Vec
from hoh_cosim.errors import RunError
from hoh_cosim.hardware.config import HardwareConfig
from hoh_cosim.hardware.feed import CycleObserver
from hoh_cosim.hardware.pressure import Canary, CpuPressure
from hoh_cosim.hardware.robot import Robot, RobotState, named_problem
from hoh_cosim.hardware.session_log import CycleRecord, SessionLog, at_log_resolution
from hoh_cosim.hardware.streams import (
    Mailbox,
    RateCheck,
    ReaderThread,
    Sample,
    now,
    robust_period,
)
from hoh_cosim.params import leaves
from hoh_cosim.presets import Preset, changed_from

__all__ = [
    "CycleTiming",
    "LatencyHistogram",
    "Rebias",
    "Runner",
    "SessionResult",
    "Source",
    "speedl_acceleration",
]


class Source(Protocol):
    """A sensor stream as the runner sees it (FT150Stream, FSE103Port, LoadCellPort)."""

    mailbox: Mailbox

    rate_band_hz: tuple[float, float]  # the packet rates its datasheet allows

    def start(self) -> None: ...
    def stop(self) -> None: ...
    def describe(self) -> str: ...


class LatencyHistogram:
    """Durations counted in 1 µs bins up to `limit_s`, the largest kept exactly: percentiles to the
    microsecond in a fixed amount of memory, however long the session (a list of every cycle's
    figures grew by 32 kB a second at 500 Hz)."""

    def __init__(self, limit_s: float = 0.1, resolution_s: float = 1e-6) -> None:
        self.resolution_s = resolution_s
        self.counts = np.zeros(round(limit_s / resolution_s) + 1, dtype=np.int64)  # last: above
        self.n = 0
        self.max_s = math.nan

    def add(self, seconds: float) -> None:
        i = int(seconds / self.resolution_s) if seconds > 0.0 else 0
        self.counts[min(i, len(self.counts) - 1)] += 1
        self.n += 1
        if not seconds <= self.max_s:  # also the first one (max NaN)
            self.max_s = seconds

    def percentile_s(self, q: float) -> float:
        """The q-th percentile (0-100), as the upper edge of its bin; above the histogram's range,
        the largest duration seen."""
        if self.n == 0:
            return math.nan
        rank = max(1, math.ceil(q / 100.0 * self.n))
        i = int(np.searchsorted(np.cumsum(self.counts), rank))
        if i >= len(self.counts) - 1:
            return self.max_s
        return min((i + 1) * self.resolution_s, self.max_s)


@dataclass
class CycleTiming:
    """Compute time and start lateness of every cycle, summarised at the end."""

    compute: LatencyHistogram = field(default_factory=LatencyHistogram)
    late: LatencyHistogram = field(default_factory=LatencyHistogram)
    overruns: int = 0

    @property
    def cycles(self) -> int:
        return self.compute.n

    def add(self, compute_s: float, late_s: float) -> None:
        self.compute.add(compute_s)
        self.late.add(late_s)

    def summary(self) -> dict[str, float]:
        out: dict[str, float] = {"cycles": float(self.cycles), "overruns": self.overruns}
        for name, histogram in (("compute", self.compute), ("jitter", self.late)):
            if histogram.n:
                for q, label in ((50, "p50"), (99, "p99"), (99.9, "p99_9")):
                    out[f"{name}_{label}_ms"] = 1e3 * histogram.percentile_s(q)
                out[f"{name}_max_ms"] = 1e3 * histogram.max_s
        return out

    def report(self) -> str:
        s = self.summary()
        if "compute_p50_ms" not in s:
            return "no cycles ran"
        return (
            f"{int(s['cycles'])} cycles, {self.overruns} overruns; compute p50 "
            f"{s['compute_p50_ms']:.3f} / p99 {s['compute_p99_ms']:.3f} / max "
            f"{s['compute_max_ms']:.3f} ms; start jitter p50 {s['jitter_p50_ms']:.3f} / p99 "
            f"{s['jitter_p99_ms']:.3f} / p99.9 {s['jitter_p99_9_ms']:.3f} ms"
        )


@dataclass(frozen=True)
class Rebias:
    ft_bias: Vec  # [N, N·m] the session's sensor offset: mean reading minus the tool's weight
    probe_bias: Vec  # [N]
    ft_period_s: float  # measured
    probe_period_s: float  # measured (NaN without a probe)
    deviation: Vec  # mean minus (weight + calibrated offset), the check's figure


@dataclass
class SessionResult:
    cycles: int
    cause: str  # why the session ended
    clean: bool  # ended as asked (time up, interrupted), not by a fault
    timing: CycleTiming
    rebias: Rebias | None


REBIAS_RATE_TRIES = 3
"""Windows the rebias measures a stream's rate in before it refuses a rate off the datasheet."""


class RateRefusedError(RunError):
    """A stream's rate, measured in one rebias window, is outside its datasheet's band."""


def _measured(source: Source, samples: list[Sample], counts: list[int]) -> RateCheck:
    """The rate of the samples the rebias took (with their counts), on the device's own clock
    where every sample has its time stamp (FSE103: milliseconds, modulo 2**32), else on receipt
    times."""
    stamps = [s.device_ms for s in samples]
    if stamps and all(ms is not None for ms in stamps):
        steps = np.diff(np.array(stamps, dtype=np.int64)) % 2**32
        times, clock = 1e-3 * np.concatenate(([0], np.cumsum(steps))), "device time stamps"
    else:
        times, clock = np.array([s.received_s for s in samples]), "receipt times"
    return RateCheck(source.describe(), robust_period(counts, times), source.rate_band_hz, clock)


class Runner:
    """One hand-guiding session on a robot and two sensor streams."""

    def __init__(
        self,
        config: HardwareConfig,
        robot: Robot,
        ft: Source,
        probe: Source | None,
        calibration: GravityCalibration,
        log: SessionLog | None = None,
        *,
        announce: Callable[[str], None] = lambda message: None,
        observer: CycleObserver | None = None,
    ) -> None:
        self.config = config
        self.robot = robot
        self.ft = ft
        self.probe = probe
        self.calibration = calibration
        self.log = log
        self.announce = announce
        # offered every cycle and every event, after the log (a bounded, dropping feed: `feed`)
        self.observer = observer
        self.stop_requested = threading.Event()
        self.timing = CycleTiming()
        self._pressure = CpuPressure()
        self._canary: Canary | None = None  # from the rebias on: see run
        self._commanded_s = math.inf  # perf_counter of the last command or kick
        self._k = 0

    # --- start-up ------------------------------------------------------------------------------

    def _wait_for_samples(self, timeout_s: float) -> None:
        deadline = time.monotonic() + timeout_s
        for source in (self.ft, self.probe):
            if source is None:
                continue
            while source.mailbox.latest()[1] == 0:
                if time.monotonic() > deadline:
                    why = source.mailbox.error or "no sample arrived"
                    raise RunError(f"{source.describe()}: no data within {timeout_s:g} s ({why})")
                time.sleep(0.01)

    def _starved(self, before: str) -> str | None:
        """The starved loop's cause when the robot's watchdog has passed since our last command."""
        return starved_cause(self.policy(), before, time.perf_counter() - self._commanded_s)

    def _hold(self, pacer: Any) -> RobotState:
        """One cycle of standing still (zero twist, watchdog kicked); the state read."""
        pacer.wait()
        state = self.robot.state()
        starved = self._starved("a cycle of standing still")
        if starved is not None:
            raise RunError(starved)
        problem = named_problem(self.robot, state)
        if problem is not None:
            raise RunError(f"{self.robot.describe()}: {problem}")
        starved = self._starved("the command to stand still")
        if starved is not None:
            raise RunError(starved)
        self.robot.speed_l(np.zeros(6), self.config.robot.acceleration)
        self.robot.kick_watchdog()
        self._commanded_s = time.perf_counter()
        return state

    def rebias(self, pacer: Any) -> Rebias:
        """Average the sensors while the robot holds still; check against the gravity model.

        A stream whose rate measures outside its datasheet's band is measured again, up to
        `REBIAS_RATE_TRIES` windows in all, each miss announced: on receipt times a machine that
        holds a reader back for a while and then hands it the backlog at once makes a stream look
        fast, and it seldom does so twice in a row; a device that really sends at another rate
        is refused after the last window."""
        for attempt in range(1, REBIAS_RATE_TRIES + 1):
            try:
                return self._rebias_once(pacer)
            except RateRefusedError as exc:
                if attempt == REBIAS_RATE_TRIES:
                    raise RunError(f"rebias refused: {exc}") from None
                self.announce(f"rebias: {exc}; measuring again")
                self._event("remeasure", str(exc))
        raise AssertionError("unreachable")

    def _rebias_once(self, pacer: Any) -> Rebias:
        cfg = self.config.rebias
        _, ft_start = self.ft.mailbox.latest()
        probe_start = self.probe.mailbox.latest()[1] if self.probe is not None else 0
        ft_samples: list[Sample] = []
        probe_samples: list[Sample] = []
        ft_counts: list[int] = []  # each sample's count: several may arrive between two cycles
        probe_counts: list[int] = []
        seen_ft, seen_probe = ft_start, probe_start
        R_BS_sum = np.zeros((3, 3))
        deadline = time.monotonic() + cfg.timeout_s
        while len(ft_samples) < cfg.samples:
            if time.monotonic() > deadline:
                raise RunError(
                    f"rebias: only {len(ft_samples)} of {cfg.samples} FT-150 samples in "
                    f"{cfg.timeout_s:g} s ({self.ft.mailbox.error or 'the stream is slow'})"
                )
            state = self._hold(pacer)
            speed = float(np.linalg.norm(state.twist_B[:3]))
            if speed > cfg.max_speed_m_s:
                raise RunError(
                    f"rebias refused: the robot moves at {1e3 * speed:.1f} mm/s (at most "
                    f"{1e3 * cfg.max_speed_m_s:.1f} mm/s while the sensors are averaged)"
                )
            sample, count = self.ft.mailbox.latest()
            if count > seen_ft and sample is not None:  # a sample per count change: the newest
                ft_samples.append(sample)
                ft_counts.append(count)
                R_BS_sum += state.R_BT @ self.config.robot.R_TS
                seen_ft = count
            if self.probe is not None:
                probe_sample, probe_count = self.probe.mailbox.latest()
                if probe_count > seen_probe and probe_sample is not None:
                    probe_samples.append(probe_sample)
                    probe_counts.append(probe_count)
                    seen_probe = probe_count
        values = np.array([s.values for s in ft_samples])
        if not np.all(np.isfinite(values)):
            raise RunError("rebias refused: the FT-150 sent non-finite values")
        # the filters are tuned to the packet periods measured here: a rate the device cannot
        # have (a stall and a burst, another device) is refused, not handed to them
        rates = [_measured(self.ft, ft_samples, ft_counts)]
        if self.probe is not None and probe_samples:
            rates.append(_measured(self.probe, probe_samples, probe_counts))
        for rate in rates:
            problem = rate.problem()
            if problem is not None:
                raise RateRefusedError(problem)
        U, _, Vt = np.linalg.svd(R_BS_sum / len(ft_samples))
        R_BS = U @ Vt  # the mean orientation, a rotation again
        weight = GravityModel(self.calibration.tool, self.calibration.gravity_B).weight_S(R_BS)
        mean = values.mean(axis=0)
        deviation = mean - weight - self.calibration.bias
        worst_force = float(np.max(np.abs(deviation[:3])))
        worst_torque = float(np.max(np.abs(deviation[3:])))
        if worst_force > cfg.tolerance_N or worst_torque > cfg.tolerance_Nm:
            raise RunError(
                "rebias refused: the wrist reading is "
                f"{np.round(deviation, 3).tolist()} N, N·m away from the calibrated tool's weight "
                f"and offset (tolerance {cfg.tolerance_N} N, {cfg.tolerance_Nm} N·m): is someone "
                "touching the probe, or is the calibration for another tool?"
            )
        probe_bias = np.zeros(3)
        if probe_samples:
            probe_values = np.array([s.values for s in probe_samples])
            if not np.all(np.isfinite(probe_values)):
                raise RunError(
                    f"rebias refused: the {self.probe.describe()} sent non-finite values"
                )
            probe_bias = probe_values.mean(axis=0)
        elif self.probe is not None:
            raise RunError(f"rebias: {self.probe.describe()} sent nothing while averaging")
        return Rebias(
            ft_bias=mean - weight,
            probe_bias=probe_bias,
            ft_period_s=rates[0].period_s,
            probe_period_s=rates[1].period_s if len(rates) > 1 else math.nan,
            deviation=deviation,
        )

    def blocks(self, rebias: Rebias) -> tuple[Estimator, HandGuidingController]:
        """The estimator and controller for this session: the calibrated tool, the measured
        biases (no further rebias) and the measured packet periods, given to both blocks."""
        estimator_params = dataclasses.replace(
            self.config.estimator,
            tool=self.calibration.tool,
            g_B=self.calibration.gravity_B,
            ft_rebias_packets=0,
            ft_bias=rebias.ft_bias,
            probe_rebias_packets=0,
            probe_bias=rebias.probe_bias,
        )
        # the measured periods, where the rebias could measure them; else the configured ones
        configured = SensorSetup.of(estimator_params)
        ft_period, probe_period = rebias.ft_period_s, rebias.probe_period_s
        sensors = SensorSetup(
            ft_period if math.isfinite(ft_period) else configured.ft_period_s,
            probe_period if math.isfinite(probe_period) else configured.probe_period_s,
            configured.use_probe,
        )
        estimator_params, controller_params = sensors.apply(
            estimator_params, self.config.controller
        )
        controller = HandGuidingController(controller_params)
        controller.prepare(self.robot.period_s)
        return Estimator(estimator_params), controller

    def policy(self) -> SessionPolicy:
        """The supervisor's policy for this session's devices and limits."""
        return SessionPolicy(
            limits=self.config.controller.limits,
            stale_stop_s=self.config.stale_stop_s,
            stale_stop_max_s=STARVED_STALE_FACTOR * self.config.stale_stop_s,
            robot=self.robot.describe(),
            ft=self.ft.describe(),
            probe=self.probe.describe() if self.probe is not None else None,
            watchdog_s=1.0 / self.config.robot.watchdog_hz,
        )

    # --- the loop --------------------------------------------------------------------------------

    def run(self, seconds: float | None = None) -> SessionResult:
        """Connect, rebias and guide until `seconds` pass, `stop_requested` is set or something goes
        wrong. The robot is stopped on every way out."""
        rebias: Rebias | None = None
        cause, clean = "", False
        sources = [s for s in (self.ft, self.probe) if s is not None]
        canary: Canary | None = None
        try:
            # a filter imports its library when it is built or first stepped (up to a second):
            # imported now, not between two of the watchdog's cycles below
            import_filter_libraries(self.config.estimator)
            # ... and hold-on-release's filter gain (scipy's Riccati solver): computed now for the
            # robot's period, so that building the blocks after the rebias finds it made
            HandGuidingController(self.config.controller).prepare(self.robot.period_s)

            self.robot.connect()
            for source in sources:
                source.start()
            self._wait_for_samples(5.0)
            canary = self._canary = Canary()  # ordinary tasks' starvation (the loop reads it)
            # from the first command on, the robot's watchdog wants a kick every cycle: nothing slow
            # (a garbage collection, building the blocks) may come between two cycles
            with _realtime_interpreter(
                self.config.robot.realtime_priority,
                self.announce,
                getattr(self.robot, "helper_thread_ids", ()),
            ):
                pacer = self.robot.pacer()
                self.announce("rebias: hold still")
                rebias = self.rebias(pacer)
                estimator, controller = self.blocks(rebias)
                self._hold(pacer)
                self._event("rebias", _rebias_text(rebias))
                self._log_parameters(estimator, controller, rebias)
                self._hold(pacer)
                self.announce(f"rebias done: {_rebias_text(rebias)}")
                if estimator.checking and self.probe is not None:
                    self.announce(
                        "probe check: hands off the handle; press the probe tip in several "
                        f"directions for {estimator.params.probe_correction.check_s:g} s"
                    )
                cause, clean = self._loop(pacer, estimator, controller, seconds)
        except RunError as exc:
            cause = str(exc)
        except KeyboardInterrupt:
            cause, clean = "interrupted", True
        finally:
            if not clean:  # said at once: closing the robot's connection may itself fail
                self.announce(f"stopping: {cause}")
            self.robot.stop()
            for source in sources:
                source.stop()
            self._event("end", cause)
            if self.log is not None:
                self.log.close()
            self.robot.close()
            self._pressure.close()
            if canary is not None:
                canary.close()
        return SessionResult(self.timing.cycles, cause, clean, self.timing, rebias)

    def _loop(
        self,
        pacer: Any,
        estimator: Estimator,
        controller: HandGuidingController,
        seconds: float | None,
    ) -> tuple[str, bool]:
        """read → `control_cycle` → write, at the robot's rate."""
        period = self.robot.period_s
        n_max = None if seconds is None else round(seconds / period)
        blocks = ControlBlocks(estimator, controller, self.policy())
        policy = blocks.policy
        overruns_before = pacer.overruns  # the rebias's own are not the loop's
        pressure = self._pressure  # measured while a stream is stale, to name a starved machine
        canary = self._canary  # ordinary tasks' starvation, not counted as a device's silence
        assert canary is not None  # made by run
        # each stale stream's flag: the canary's figures when it turned stale (none: no stream is)
        since: dict[Status, tuple[float, ...]] = {}
        k = 0
        while n_max is None or k < n_max:
            if self.stop_requested.is_set():
                return "stopped on request", True
            late = pacer.wait()
            self.timing.overruns = pacer.overruns - overruns_before
            start = time.perf_counter()
            state = at_log_resolution(self.robot.state())  # what the log can hold: replayable
            # the robot's watchdog counts from our last command: past it, the robot has stopped
            # itself because this process stalled, whatever it reports now
            starved = starved_cause(policy, f"cycle {k}", time.perf_counter() - self._commanded_s)
            if starved is not None:
                self._event("stop", starved)
                return starved, False
            problem = named_problem(self.robot, state)
            if problem is not None:  # the robot stopped itself: nothing to compute
                self._event("stop", problem)
                return robot_cause(policy, problem), False
            ft, ft_count = self.ft.mailbox.latest()
            probe, probe_count = (
                self.probe.mailbox.latest() if self.probe is not None else (None, 0)
            )
            cycle = control_cycle(
                blocks,
                Reading(
                    state.p_BT_B,
                    state.R_BT @ self.config.robot.R_TS,
                    None if ft is None else ft.values,
                    ft_count,
                    None if probe is None else probe.values,
                    probe_count,
                ),
                k * period,
                period,
                ft_error=self.ft.mailbox.error,
                probe_error=self.probe.mailbox.error if self.probe is not None else None,
                overload=pressure.overload() if since else None,
                starved=self._starved_since(since),
                quiet=self._quiet(since),
            )
            was_stale = bool(since)
            if was_stale or cycle.verdict.status & _STALE:
                mark = canary.starved_s()
                for flag in _STALE_FLAGS:
                    if cycle.verdict.status & flag:
                        since.setdefault(flag, mark)
                    elif flag in since:  # the stream is back: say what was not counted
                        self._not_counted(flag, canary.since(since.pop(flag)), policy)
            if bool(since) != was_stale:  # a pressure window per silence
                if since:
                    pressure.start()
                else:
                    pressure.stop()
            for event in cycle.events:
                self._event(event.name, event.detail)
                self.announce(event.announcement)
            cause = cycle.verdict.cause
            if cause is None:  # the watchdog counts between commands: a stall in this cycle too
                cause = starved_cause(
                    policy, f"the command of cycle {k}", time.perf_counter() - self._commanded_s
                )
                if cause is not None:  # logged as it was: nothing sent
                    cycle.verdict = Verdict(cycle.verdict.status, np.zeros(6), cause)
            if cause is None:
                self.robot.speed_l(
                    cycle.verdict.twist_B,
                    speedl_acceleration(
                        cycle.verdict.twist_B,
                        self.config.robot.acceleration,
                        float(cycle.command["brake_accel"][0]),
                    ),
                )
                self.robot.kick_watchdog()
                self._commanded_s = time.perf_counter()
            compute = time.perf_counter() - start
            self.timing.add(compute, late)
            self._k = k
            if self.log is not None or self.observer is not None:
                record = CycleRecord(k, k * period, cycle, state, ft, probe, compute, late)
                if self.log is not None:
                    self.log.record(record)
                if self.observer is not None:
                    self.observer.offer(record, None if self.log is None else self.log.row)
            if cause is not None:
                self._event("stop", cause)
                return cause, False
            k += 1
        return f"{seconds:g} s done", True

    def _starved_since(self, since: dict[Status, tuple[float, ...]]) -> dict[Status, float] | None:
        """For each stale stream, the most ordinary tasks were starved on any core since it
        turned stale."""
        if not since or self._canary is None:
            return None
        return {flag: self._canary.since(mark) for flag, mark in since.items()}

    def _quiet(self, since: dict[Status, tuple[float, ...]]) -> dict[Status, str] | None:
        """For each stale stream, what its reader got since its last sample."""
        if not since:
            return None
        t = now()
        readers = {Status.STALE_FT: self.ft, Status.STALE_PROBE: self.probe}
        return {
            flag: reader.mailbox.since_latest(t)
            for flag in since
            if (reader := readers[flag]) is not None
        }

    def _not_counted(self, flag: Status, discounted: float, policy: SessionPolicy) -> None:
        """Log the starved time a stream that came back did not have counted as its silence."""
        if discounted >= 0.0005:
            name = policy.ft if flag is Status.STALE_FT else policy.probe
            detail = f"{name}: {1e3 * discounted:.0f} {STARVED_TEXT}, not counted as its silence"
            self._event("starved", detail)

    # --- logging -------------------------------------------------------------------------------

    def _event(self, event: str, detail: str) -> None:
        if self.log is None and self.observer is None:
            return
        # before the robot told its period (it could not be reached), at the session's start
        period = self.robot.period_s
        t = self._k * period if math.isfinite(period) else 0.0
        if self.log is not None:
            self.log.event(self._k, t, event, detail)
        if self.observer is not None:
            self.observer.event(self._k, t, event, detail)

    def _log_parameters(
        self, estimator: Estimator, controller: HandGuidingController, rebias: Rebias
    ) -> None:
        self._event(
            "parameters",
            _parameters_json(
                estimator, controller, rebias, self.robot.period_s, self.config.preset
            ),
        )


_STALE_FLAGS = (Status.STALE_FT, Status.STALE_PROBE)
_STALE = Status.STALE_FT | Status.STALE_PROBE
STARVED_STALE_FACTOR = 4.0
"""A stale stream ends the session after `stale_stop_s` of its silence counted while ordinary tasks
could run, and after this many times `stale_stop_s` in any case (`SessionPolicy.stale_stop_max_s`)."""


def _helper_threads() -> list[threading.Thread]:
    """The threads that serve the loop: the sensor readers."""
    return [t for t in threading.enumerate() if isinstance(t, ReaderThread)]


def _set_fifo(thread_id: int, priority: int) -> None:
    os.sched_setscheduler(thread_id, os.SCHED_FIFO, os.sched_param(priority))


@contextlib.contextmanager
def _realtime_interpreter(
    priority: int | None,
    announce: Callable[[str], None],
    native_helpers: Sequence[int] = (),
    switch_interval_s: float = 2e-4,
) -> Iterator[None]:
    """The interpreter and the scheduler tuned for the loop, and restored after it.

    - The GIL changes hands every `switch_interval_s` instead of every 5 ms, so a reader or the log
      writer busy in Python delays a waking loop by at most that much.
    - No cyclic garbage collection during the loop (everything made before it is frozen out of the
      collector's view, and the loop makes no reference cycles); a collection of a large heap takes
      milliseconds, longer than an e-series cycle.
    - With `priority` (Linux, and the right to use it): the loop thread runs SCHED_FIFO at that
      priority and the threads serving it one below, so no ordinary process delays them; the
      readers must be raised too, or the loop would wait for a GIL held by a descheduled reader;
      so must the robot's own threads (`native_helpers`, thread ids: ur-rtde's receivers, which
      its speedL waits on: left at the default priority, a busy machine starved them for 130 ms
      at the first command, past the robot's watchdog).
    """
    previous = sys.getswitchinterval()
    gc.collect()
    gc.freeze()
    gc.disable()
    sys.setswitchinterval(switch_interval_s)
    raised: list[int] = []
    if priority is not None:
        try:
            _set_fifo(0, priority)
            raised.append(0)
            helpers = [t.native_id for t in _helper_threads() if t.native_id is not None]
            for thread_id in [*helpers, *native_helpers]:
                _set_fifo(thread_id, max(1, priority - 1))
                raised.append(thread_id)
        except (OSError, AttributeError) as exc:
            announce(f"note: real-time priority {priority} refused ({exc}); running without it")
    try:
        yield
    finally:
        for thread_id in raised:
            with contextlib.suppress(OSError):
                os.sched_setscheduler(thread_id, os.SCHED_OTHER, os.sched_param(0))
        sys.setswitchinterval(previous)
        gc.enable()
        gc.unfreeze()


def _rebias_text(rebias: Rebias) -> str:
    return (
        f"FT-150 offset {np.round(rebias.ft_bias, 3).tolist()} N, N·m, "
        f"{1 / rebias.ft_period_s:.1f} Hz; probe offset {np.round(rebias.probe_bias, 3).tolist()} N"
        + (f", {1 / rebias.probe_period_s:.1f} Hz" if math.isfinite(rebias.probe_period_s) else "")
        + f"; off the calibration by {np.round(rebias.deviation, 3).tolist()}"
    )


def _parameters_json(
    estimator: Estimator,
    controller: HandGuidingController,
    rebias: Rebias,
    period_s: float,
    preset: Preset | None,
) -> str:
    """The session's parameters as the log's "parameters" event: every leaf of both blocks, the
    preset and every value that differs from it (the rig file's, `--set`, the calibration's tool
    and the rig's sensors)."""
    import json

    changes = {}
    if preset is not None:
        for block, params in (("estimator", estimator.params), ("controller", controller.params)):
            for name, value in changed_from(preset.params[block], params).items():
                changes[f"{block}.{name}"] = value
    return json.dumps(
        {
            "period_s": period_s,
            "preset": None if preset is None else preset.label,
            "preset_changes": changes,
            "estimator": {leaf.name: leaf.value for leaf in leaves(estimator.params)},
            "controller": {leaf.name: leaf.value for leaf in leaves(controller.params)},
            "ft_bias": rebias.ft_bias.tolist(),
            "probe_bias": rebias.probe_bias.tolist(),
        }
    )


def speedl_acceleration(twist_B: np.ndarray, acceleration: float, brake_accel: float) -> float:
    """speedL's `a` for one command: the rig's `acceleration`, or the controller's braking
    deceleration after a release when that is larger and the command is rest (zero linear
    velocity). Never a larger `a` for a command away from rest: the controller's own clamp ramps
    such a command, and the robot follows it no faster than the rig allows."""
    if brake_accel > acceleration and not np.any(twist_B[:3]):
        return brake_accel
    return acceleration
