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
        speedL, kick the watchdog, log the cycle
    finally: stop the robot, stop the streams, close the log

The loop never blocks on I/O: reader threads fill mailboxes, a writer process writes the log. Time
inside the blocks is the cycle number times the period, as in the co-simulation.

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
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from hoh_cosim.control.controller import HandGuidingController
from hoh_cosim.control.estimator import Estimator
from hoh_cosim.control.gravity import GravityCalibration, GravityModel
from hoh_cosim.control.limits import Status
from hoh_cosim.control.vectors import Vec
from hoh_cosim.errors import RunError
from hoh_cosim.hardware.config import HardwareConfig
from hoh_cosim.hardware.robot import Robot, RobotState
from hoh_cosim.hardware.session_log import SessionLog
from hoh_cosim.hardware.streams import Mailbox, ReaderThread, Sample
from hoh_cosim.params import leaves

__all__ = ["CycleTiming", "Rebias", "Runner", "SessionResult", "Source"]


class Source(Protocol):
    """A sensor stream as the runner sees it (FT150Stream, FSE103Port)."""

    mailbox: Mailbox

    def start(self) -> None: ...
    def stop(self) -> None: ...
    def describe(self) -> str: ...


@dataclass
class CycleTiming:
    """Compute time and start lateness of every cycle, summarised at the end."""

    compute_s: list[float] = field(default_factory=list)
    late_s: list[float] = field(default_factory=list)
    overruns: int = 0

    def summary(self) -> dict[str, float]:
        out: dict[str, float] = {"cycles": float(len(self.compute_s)), "overruns": self.overruns}
        for name, values in (("compute", self.compute_s), ("jitter", self.late_s)):
            if values:
                a = 1e3 * np.asarray(values)
                for q, label in ((50, "p50"), (99, "p99"), (99.9, "p99_9")):
                    out[f"{name}_{label}_ms"] = float(np.percentile(a, q))
                out[f"{name}_max_ms"] = float(a.max())
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


def _period(samples: list[Sample]) -> float:
    times = np.array([s.received_s for s in samples])
    if len(times) < 3:
        return math.nan
    return float(np.median(np.diff(times)))


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
    ) -> None:
        self.config = config
        self.robot = robot
        self.ft = ft
        self.probe = probe
        self.calibration = calibration
        self.log = log
        self.announce = announce
        self.stop_requested = threading.Event()
        self.timing = CycleTiming()
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

    def _hold(self, pacer: Any) -> RobotState:
        """One cycle of standing still (zero twist, watchdog kicked); the state read."""
        pacer.wait()
        state = self.robot.state()
        problem = state.problem()
        if problem is not None:
            raise RunError(f"{self.robot.describe()}: {problem}")
        self.robot.speed_l(np.zeros(6), self.config.robot.acceleration)
        self.robot.kick_watchdog()
        return state

    def rebias(self, pacer: Any) -> Rebias:
        """Average the sensors while the robot holds still; check against the gravity model."""
        cfg = self.config.rebias
        _, ft_start = self.ft.mailbox.latest()
        probe_start = self.probe.mailbox.latest()[1] if self.probe is not None else 0
        ft_samples: list[Sample] = []
        probe_samples: list[Sample] = []
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
                R_BS_sum += state.R_BT @ self.config.robot.R_TS
                seen_ft = count
            if self.probe is not None:
                probe_sample, probe_count = self.probe.mailbox.latest()
                if probe_count > seen_probe and probe_sample is not None:
                    probe_samples.append(probe_sample)
                    seen_probe = probe_count
        values = np.array([s.values for s in ft_samples])
        if not np.all(np.isfinite(values)):
            raise RunError("rebias refused: the FT-150 sent non-finite values")
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
                raise RunError("rebias refused: the FSE103 sent non-finite values")
            probe_bias = probe_values.mean(axis=0)
        elif self.probe is not None:
            raise RunError(f"rebias: {self.probe.describe()} sent nothing while averaging")
        return Rebias(
            ft_bias=mean - weight,
            probe_bias=probe_bias,
            ft_period_s=_period(ft_samples),
            probe_period_s=_period(probe_samples) if probe_samples else math.nan,
            deviation=deviation,
        )

    def blocks(self, rebias: Rebias) -> tuple[Estimator, HandGuidingController]:
        """The estimator and controller for this session: the calibrated tool, the measured
        biases (no further rebias) and the measured packet periods."""
        estimator_params = dataclasses.replace(
            self.config.estimator,
            tool=self.calibration.tool,
            g_B=self.calibration.gravity_B,
            ft_rebias_packets=0,
            ft_bias=rebias.ft_bias,
            probe_rebias_packets=0,
            probe_bias=rebias.probe_bias,
        )
        controller_params = self.config.controller
        if math.isfinite(rebias.ft_period_s):
            estimator_params = dataclasses.replace(
                estimator_params, ft_packet_period_s=rebias.ft_period_s
            )
            controller_params = dataclasses.replace(
                controller_params, ft_period_s=rebias.ft_period_s
            )
        if math.isfinite(rebias.probe_period_s):
            estimator_params = dataclasses.replace(
                estimator_params, probe_packet_period_s=rebias.probe_period_s
            )
            controller_params = dataclasses.replace(
                controller_params, probe_period_s=rebias.probe_period_s
            )
        return Estimator(estimator_params), HandGuidingController(controller_params)

    # --- the loop --------------------------------------------------------------------------------

    def _cause(
        self, status: Status, estimate: dict[str, Vec], ft: Sample | None, probe: Sample | None
    ) -> str | None:
        """Why the session must stop now, or None (the supervisor, DESIGN.md §7)."""
        if ft is not None and not np.all(np.isfinite(ft.values)):
            return f"{self.ft.describe()} sent a non-finite value {np.round(ft.values, 3).tolist()}"
        if probe is not None and not np.all(np.isfinite(probe.values)):
            return (
                f"{self.probe.describe()} sent a non-finite value "  # type: ignore[union-attr]
                f"{np.round(probe.values, 3).tolist()}"
            )
        if status.ok:
            return None
        if status & Status.FORCE_STOP:
            force = float(np.linalg.norm(estimate["F_probe_B"]))
            return (
                f"probe contact force {force:.1f} N reached the "
                f"{self.config.controller.limits.probe_force_stop:g} N stop"
            )
        stale_stop = self.config.stale_stop_s
        if status & Status.STALE_FT:
            age = float(estimate["ft_age"][0])
            if age < stale_stop:  # a gap: the controller commands zero meanwhile
                return None
            why = self.ft.mailbox.error or "the stream stalled"
            return f"{self.ft.describe()}: no new sample for {1e3 * age:.0f} ms ({why})"
        if status & Status.STALE_PROBE and self.probe is not None:
            age = float(estimate["probe_age"][0])
            if age < stale_stop:
                return None
            why = self.probe.mailbox.error or "the stream stalled"
            return f"{self.probe.describe()}: no new sample for {1e3 * age:.0f} ms ({why})"
        return f"the controller stopped: {status.describe()}"

    def _check_command(self, twist: Vec) -> str | None:
        """The command itself, checked again outside the controller."""
        limits = self.config.controller.limits
        if not np.all(np.isfinite(twist)):
            return f"non-finite command {twist.tolist()}"
        v, w = float(np.linalg.norm(twist[:3])), float(np.linalg.norm(twist[3:]))
        if v > limits.max_linear_speed * (1 + 1e-9) or w > limits.max_angular_speed * (1 + 1e-9):
            return f"command above the speed limits: {v:.4f} m/s, {w:.4f} rad/s"
        return None

    def run(self, seconds: float | None = None) -> SessionResult:
        """Connect, rebias and guide until `seconds` pass, `stop_requested` is set or something goes
        wrong. The robot is stopped on every way out."""
        rebias: Rebias | None = None
        cause, clean = "", False
        sources = [s for s in (self.ft, self.probe) if s is not None]
        try:
            self.robot.connect()
            for source in sources:
                source.start()
            self._wait_for_samples(5.0)
            # from the first command on, the robot's watchdog wants a kick every cycle: nothing slow
            # (a garbage collection, building the blocks) may come between two cycles
            with _realtime_interpreter(self.config.robot.realtime_priority, self.announce):
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
        return SessionResult(len(self.timing.compute_s), cause, clean, self.timing, rebias)

    def _loop(
        self,
        pacer: Any,
        estimator: Estimator,
        controller: HandGuidingController,
        seconds: float | None,
    ) -> tuple[str, bool]:
        period = self.robot.period_s
        n_max = None if seconds is None else round(seconds / period)
        R_TS = self.config.robot.R_TS
        acceleration = self.config.robot.acceleration
        zero3 = np.zeros(3)
        ft_counter, probe_counter = np.zeros(1), np.zeros(1)
        k = 0
        # rebiased already: the check, if any, starts now
        checking = estimator.checking and self.probe is not None
        drifted = False
        overruns_before = pacer.overruns  # the rebias's own are not the loop's
        while n_max is None or k < n_max:
            if self.stop_requested.is_set():
                return "stopped on request", True
            late = pacer.wait()
            self.timing.overruns = pacer.overruns - overruns_before
            start = time.perf_counter()
            t = k * period
            state = self.robot.state()
            problem = state.problem()
            if problem is not None:
                self._event("stop", problem)
                return f"{self.robot.describe()}: {problem}", False
            ft, ft_count = self.ft.mailbox.latest()
            probe, probe_count = (
                self.probe.mailbox.latest() if self.probe is not None else (None, 0)
            )
            ft_counter[0], probe_counter[0] = ft_count, probe_count
            estimate = estimator.step(
                t,
                period,
                {
                    "wrench_S": ft.values if ft is not None else np.zeros(6),
                    "ft_counter": ft_counter,
                    "force_P": probe.values if probe is not None else zero3,
                    "probe_counter": probe_counter,
                    "R_BS": (state.R_BT @ R_TS).reshape(9),
                },
            )
            out = controller.step(t, period, {**estimate, "p_BT_B": state.p_BT_B})
            status = Status(int(out["status"][0]))
            if checking and not estimator.checking:
                checking = False
                text = _check_text(estimator)
                self._event("probe check", text)
                self.announce(f"probe check done: {text}")
            if checking:  # not ready by design: the controller commands zero, the robot holds
                status &= ~Status.NOT_READY
            if (estimate["probe_drift"][0] > 0.5) != drifted:
                drifted = not drifted
                mismatch = float(estimate["probe_mismatch"][0])
                text = (
                    f"the probe sensor disagrees with the wrist sensor by {mismatch:.1f} N across "
                    "the probe: recheck it"
                    if drifted
                    else f"the two sensors agree again ({mismatch:.1f} N)"
                )
                self._event("probe drift", text)
                self.announce(f"warning: {text}" if drifted else text)
            cause = self._cause(status, estimate, ft, probe) or self._check_command(out["twist_B"])
            sent = np.zeros(6) if cause else out["twist_B"]
            if cause is None:
                self.robot.speed_l(sent, acceleration)
                self.robot.kick_watchdog()
            compute = time.perf_counter() - start
            self.timing.compute_s.append(compute)
            self.timing.late_s.append(late)
            if self.log is not None:
                self._log_cycle(
                    k,
                    t,
                    state,
                    ft,
                    ft_count,
                    probe,
                    probe_count,
                    estimate,
                    out,
                    sent,
                    status,
                    compute,
                    late,
                )
            if cause is not None:
                self._event("stop", cause)
                return cause, False
            k += 1
        return f"{seconds:g} s done", True

    # --- logging -------------------------------------------------------------------------------

    def _event(self, event: str, detail: str) -> None:
        if self.log is not None:
            self.log.event(self._k, self._k * self.robot.period_s, event, detail)

    def _log_parameters(
        self, estimator: Estimator, controller: HandGuidingController, rebias: Rebias
    ) -> None:
        self._event(
            "parameters", _parameters_json(estimator, controller, rebias, self.robot.period_s)
        )

    def _log_cycle(
        self,
        k: int,
        t: float,
        state: RobotState,
        ft: Sample | None,
        ft_count: int,
        probe: Sample | None,
        probe_count: int,
        estimate: dict[str, Vec],
        out: dict[str, Vec],
        sent: Vec,
        status: Status,
        compute: float,
        late: float,
    ) -> None:
        log = self.log
        assert log is not None
        self._k = k
        row = log.row
        row.start(k, t, ft is not None, probe is not None)
        row.set("/robot.p_BT_B", state.p_BT_B)
        row.set("/robot.R_BT", state.R_BT.reshape(9))
        row.set("/robot.twist_B", state.twist_B)
        row.set("/robot.robot_mode", state.robot_mode)
        row.set("/robot.safety_mode", state.safety_mode)
        row.set("/robot.protective_stop", state.protective_stop)
        row.set("/robot.emergency_stop", state.emergency_stop)
        row.set("/robot.program_running", state.program_running)
        if ft is not None:
            row.set("/ft150.wrench_S", ft.values)
            row.set("/ft150.count", ft_count)
            row.set("/ft150.received_s", ft.received_s)
        if probe is not None:
            row.set("/fse103.force_P", probe.values)
            row.set("/fse103.count", probe_count)
            row.set("/fse103.received_s", probe.received_s)
            row.set("/fse103.device_ms", -1 if probe.device_ms is None else probe.device_ms)
        for name, value in estimate.items():
            row.set(f"/estimate.{name}", value)
        row.set("/command.twist_B", out["twist_B"])
        row.set("/command.twist_law_B", out["twist_law_B"])
        row.set("/command.status", int(status))
        row.set("/command.sent_B", sent)
        row.set("/timing.compute_s", compute)
        row.set("/timing.late_s", late)
        log.cycle()


def _helper_threads() -> list[threading.Thread]:
    """The threads that serve the loop: the sensor readers."""
    return [t for t in threading.enumerate() if isinstance(t, ReaderThread)]


def _set_fifo(thread_id: int, priority: int) -> None:
    os.sched_setscheduler(thread_id, os.SCHED_FIFO, os.sched_param(priority))


@contextlib.contextmanager
def _realtime_interpreter(
    priority: int | None, announce: Callable[[str], None], switch_interval_s: float = 2e-4
) -> Iterator[None]:
    """The interpreter and the scheduler tuned for the loop, and restored after it.

    - The GIL changes hands every `switch_interval_s` instead of every 5 ms, so a reader or the log
      writer busy in Python delays a waking loop by at most that much.
    - No cyclic garbage collection during the loop (everything made before it is frozen out of the
      collector's view, and the loop makes no reference cycles); a collection of a large heap takes
      milliseconds, longer than an e-series cycle.
    - With `priority` (Linux, and the right to use it): the loop thread runs SCHED_FIFO at that
      priority and the threads serving it one below, so no ordinary process delays them; the
      readers must be raised too, or the loop would wait for a GIL held by a descheduled reader.
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
            for thread in _helper_threads():
                if thread.native_id is not None:
                    _set_fifo(thread.native_id, max(1, priority - 1))
                    raised.append(thread.native_id)
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


def _check_text(estimator: Estimator) -> str:
    online = estimator.correction.online
    if online is None:
        return f"{estimator.params.probe_correction.kind} correction: nothing to identify"
    return f"online map identified from {online.updates} probe samples"


def _rebias_text(rebias: Rebias) -> str:
    return (
        f"FT-150 offset {np.round(rebias.ft_bias, 3).tolist()} N, N·m, "
        f"{1 / rebias.ft_period_s:.1f} Hz; probe offset {np.round(rebias.probe_bias, 3).tolist()} N"
        + (f", {1 / rebias.probe_period_s:.1f} Hz" if math.isfinite(rebias.probe_period_s) else "")
        + f"; off the calibration by {np.round(rebias.deviation, 3).tolist()}"
    )


def _parameters_json(
    estimator: Estimator, controller: HandGuidingController, rebias: Rebias, period_s: float
) -> str:
    import json

    return json.dumps(
        {
            "period_s": period_s,
            "estimator": {leaf.name: leaf.value for leaf in leaves(estimator.params)},
            "controller": {leaf.name: leaf.value for leaf in leaves(controller.params)},
            "ft_bias": rebias.ft_bias.tolist(),
            "probe_bias": rebias.probe_bias.tolist(),
        }
    )
