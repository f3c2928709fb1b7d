"""One control cycle, the same for the runner on the robot, its rehearsal and replay.

    reading    what the devices gave this cycle: the TCP pose, the wrist sensor's orientation, the
               newest raw FT-150 and FSE103 samples and how many of each have arrived
    estimate   Estimator.step (predicts every cycle, corrects when a sample's counter moved)
    command    HandGuidingController.step
    verdict    the supervisor: send the command, send zero, or end the session with the cause
    events     the probe check ending, the probe sensor drifting away from the wrist or back, the
               controller's mode changing (the robot taking the probe over and giving it back, a
               lost contact recovered; `MODE_GAP_S` apart at most one line), the robot following
               the breath or no longer (at most one line a breath, `FOLLOW_GAP_S`)

The caller does the I/O around it: the runner reads the robot and the mailboxes and writes speedL and
the log, replay reads a session log. The packet periods and whether there is a probe sensor are
facts of the rig, given once as a `SensorSetup` and passed to both blocks.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from hoh_cosim.control.controller import ControllerParams, HandGuidingController
from hoh_cosim.control.estimator import Estimator, EstimatorParams
from hoh_cosim.control.guidance.modes import GUIDING, HOLD_MODES, Mode
from hoh_cosim.control.hold import HoldEnd
from hoh_cosim.control.sensors import PROBE_SENSORS
from hoh_cosim.control.supervisor import SessionPolicy, Status, Verdict, supervise
from hoh_cosim.control.vectors import Rot3, Vec, Vec3, as_scalar
from hoh_cosim.errors import ConfigError

__all__ = [
    "FOLLOW_GAP_S",
    "MODE_GAP_S",
    "PROBE_SENSORS",
    "ControlBlocks",
    "Cycle",
    "Event",
    "Reading",
    "SensorSetup",
    "control_cycle",
]

MODE_GAP_S = 0.5
"""[s] The mode's announcements are at least this far apart: changes within it are told as one,
the mode it ended in (a contact's edge that flickers, a stale stream's gaps)."""
FOLLOW_GAP_S = 4.0
"""[s] The follow's announcements are at least this far apart: about a breath (the follow's own
`level_s`), which it may begin and end with."""


@dataclass(frozen=True)
class SensorSetup:
    """The rig's sensors as the estimator and the controller must both see them."""

    ft_period_s: float = 0.005  # [s] expected FT-150 packet period (seed: 5 ms)
    probe_period_s: float = 0.02  # [s] expected FSE103 packet period (50 Hz)
    use_probe: bool = True  # False: no probe sensor

    def __post_init__(self) -> None:
        for name in ("ft_period_s", "probe_period_s"):
            object.__setattr__(
                self, name, as_scalar(getattr(self, name), name, low=0.0, low_open=True)
            )

    @classmethod
    def of(cls, estimator: EstimatorParams) -> SensorSetup:
        """The setup an estimator's parameters describe."""
        return cls(
            estimator.ft_packet_period_s, estimator.probe_packet_period_s, estimator.use_probe
        )

    @classmethod
    def shared(
        cls,
        estimator: EstimatorParams,
        controller: ControllerParams,
        names: tuple[str, str] = ("estimator", "controller"),
    ) -> SensorSetup:
        """The setup of an estimator that feeds `controller`: the estimator's. A controller value
        other than its default must agree with it (`names` name the two blocks in the error)."""
        sensors = cls.of(estimator)
        default = ControllerParams()
        for name, estimator_name in _CONTROLLER_NAMES.items():
            mine, theirs = getattr(controller, name), getattr(sensors, name)
            if mine != theirs and mine != getattr(default, name):
                raise ConfigError(
                    f"{names[1]}.{name}: {mine} contradicts {names[0]}.{estimator_name}: {theirs} "
                    f"(the sensors are given once, in the estimator's parameters)"
                )
        return sensors

    def apply(
        self, estimator: EstimatorParams, controller: ControllerParams
    ) -> tuple[EstimatorParams, ControllerParams]:
        """Both blocks' parameters with this setup."""
        return (
            dataclasses.replace(
                estimator,
                ft_packet_period_s=self.ft_period_s,
                probe_packet_period_s=self.probe_period_s,
                use_probe=self.use_probe,
            ),
            dataclasses.replace(
                controller,
                ft_period_s=self.ft_period_s,
                probe_period_s=self.probe_period_s,
                use_probe=self.use_probe,
            ),
        )


# the controller's name of each sensor fact, and the estimator's
_CONTROLLER_NAMES = {
    "ft_period_s": "ft_packet_period_s",
    "probe_period_s": "probe_packet_period_s",
    "use_probe": "use_probe",
}


@dataclass
class Reading:
    """One cycle's raw inputs, as the devices gave them."""

    p_BT_B: Vec3  # [m] the TCP's position
    R_BS: Rot3  # the wrist sensor's orientation: the robot's R_BT times the mounting R_TS
    ft: Vec | None  # the newest raw FT-150 wrench in S [N, N·m] (None: none yet)
    ft_count: int  # FT-150 samples so far
    probe: Vec | None = None  # the newest raw FSE103 force in P [N] (None: none yet, or no probe)
    probe_count: int = 0


@dataclass(frozen=True)
class Event:
    """Something the session log records and the operator is told."""

    name: str  # the log's event name
    detail: str
    announcement: str


@dataclass
class Cycle:
    """What one cycle read, estimated, commanded and decided."""

    reading: Reading
    estimate: dict[str, Vec]
    command: dict[str, Vec]  # the controller's outputs
    verdict: Verdict
    events: list[Event] = field(default_factory=list)

    @property
    def status(self) -> Status:
        return self.verdict.status


class ControlBlocks:
    """The estimator, the controller and the supervisor's policy of one session, with the
    session's own state: whether the probe check is still running, whether the probe drifted."""

    def __init__(
        self, estimator: Estimator, controller: HandGuidingController, policy: SessionPolicy
    ) -> None:
        self.estimator = estimator
        self.controller = controller
        self.policy = policy
        # the probe check, if any, runs from the first cycle on (the rebias is over by then)
        self.checking = estimator.checking and policy.probe is not None
        self.drifted = False
        self.mode = Mode.STOPPED  # the controller's mode, as last announced
        self.modes = _Limited(MODE_GAP_S)
        self.following = False  # the breath is followed (as last announced)
        self.follows = _Limited(FOLLOW_GAP_S)
        # reused every cycle: the estimator reads them during its step only
        self._ft_counter = np.zeros(1)
        self._probe_counter = np.zeros(1)
        self._no_wrench = np.zeros(6)
        self._no_force = np.zeros(3)


def control_cycle(
    blocks: ControlBlocks,
    reading: Reading,
    t: float,
    dt: float,
    *,
    ft_error: str | None = None,
    probe_error: str | None = None,
    overload: str | None = None,
    starved: Mapping[Status, float] | None = None,
    quiet: Mapping[Status, str] | None = None,
) -> Cycle:
    """Estimator, controller and supervisor on one cycle's reading (the block contract's time:
    `t` is the cycle number times `dt`). `ft_error` and `probe_error` are what the streams'
    readers last reported, `overload` how starved the CPU was while a stream was stale, for the
    supervisor's message, `starved` how long ordinary tasks were starved since each stale stream
    turned stale, and `quiet` what each stale stream's reader got since its last sample
    (`supervise`)."""
    estimator, controller = blocks.estimator, blocks.controller
    blocks._ft_counter[0] = reading.ft_count
    blocks._probe_counter[0] = reading.probe_count
    estimate = estimator.step(
        t,
        dt,
        {
            "wrench_S": blocks._no_wrench if reading.ft is None else reading.ft,
            "ft_counter": blocks._ft_counter,
            "force_P": blocks._no_force if reading.probe is None else reading.probe,
            "probe_counter": blocks._probe_counter,
            "R_BS": reading.R_BS.reshape(9),
        },
    )
    command = controller.step(t, dt, {**estimate, "p_BT_B": reading.p_BT_B})
    events = _session_events(blocks, estimate)
    for event in (_mode_event(blocks, t), _follow_event(blocks, t)):
        if event is not None:
            events.append(event)
    verdict = supervise(
        blocks.policy,
        Status(int(command["status"][0])),
        estimate,
        command["twist_B"],
        ft=reading.ft,
        probe=reading.probe,
        checking=blocks.checking,
        ft_error=ft_error,
        probe_error=probe_error,
        overload=overload,
        starved=starved,
        quiet=quiet,
    )
    return Cycle(reading, estimate, command, verdict, events)


def _session_events(blocks: ControlBlocks, estimate: dict[str, Vec]) -> list[Event]:
    events = []
    if blocks.checking and not blocks.estimator.checking:
        blocks.checking = False
        text = _check_text(blocks.estimator)
        events.append(Event("probe check", text, f"probe check done: {text}"))
    if (estimate["probe_drift"][0] > 0.5) != blocks.drifted:
        blocks.drifted = not blocks.drifted
        mismatch = float(estimate["probe_mismatch"][0])
        if blocks.drifted:
            text = (
                f"the probe sensor disagrees with the wrist sensor by {mismatch:.1f} N across "
                "the probe: recheck it"
            )
            events.append(Event("probe drift", text, f"warning: {text}"))
        else:
            text = f"the two sensors agree again ({mismatch:.1f} N)"
            events.append(Event("probe drift", text, text))
    return events


class _Limited:
    """Announcements at least `gap_s` apart: a change within the gap waits for its end, and is
    told then if the state it settled in is not the one last told."""

    def __init__(self, gap_s: float) -> None:
        self.gap_s = gap_s
        self.told = -float("inf")  # when the last announcement was made

    def due(self, t: float, changed: bool) -> bool:
        """Whether to announce now: the state differs from the one told (`changed`) and the gap
        since the last announcement is over."""
        if not changed or t - self.told < self.gap_s - 1e-9:
            return False
        self.told = t
        return True


def _mode_event(blocks: ControlBlocks, t: float) -> Event | None:
    """The controller's mode changed since it was last told, `MODE_GAP_S` after that at the
    earliest: one line for the operator, and the log's "mode" event (with what the robot does,
    the hold's level, why a hold ended)."""
    controller = blocks.controller
    mode, before = controller.mode, blocks.mode
    if not blocks.modes.due(t, mode != before):
        return None
    blocks.mode = mode
    detail = f"{before.name.lower()} -> {mode.name.lower()}: {mode.label}"
    hold = controller.hold
    if mode == Mode.HOLDING:
        text = (
            f"holding the probe's contact force at {hold.target_N:.1f} N along the probe "
            f"(hold {hold.holds})"
        )
        announcement = f"ROBOT HOLDS: {text}; touch the handle to take the probe back"
        if before == Mode.RECOVERING:
            announcement = f"CONTACT BACK: {announcement}"
    elif mode in GUIDING and before in HOLD_MODES:
        text = "handed back to the hand"
        announcement = "HAND HAS THE PROBE: the robot handed back"
    elif mode == Mode.RECOVERING:
        p = controller.recovery.params
        text = (
            f"bringing the probe back along the surface's normal at {1e3 * p.speed_m_s:g} mm/s "
            f"(at most {1e3 * p.max_travel_m:g} mm, {p.max_s:g} s)"
        )
        announcement = f"CONTACT LOST: {text}"
    elif mode == Mode.BRAKING and before in HOLD_MODES:
        why = _HOLD_ENDS.get(hold.ended, hold.ended.name.lower())
        text = f"hold ended: {why}; at rest until the hand pushes"
        announcement = f"ROBOT STOPS HOLDING: {why}; at rest until the hand pushes"
    elif mode == Mode.BRAKING and before == Mode.RECOVERING:
        text = "no contact within the recovery's travel and time; at rest until the hand pushes"
        announcement = f"CONTACT NOT FOUND: {text}"
    else:
        text = mode.label
        announcement = f"robot: {text}"
    return Event("mode", f"{detail}; {text}", announcement)


def _follow_event(blocks: ControlBlocks, t: float) -> Event | None:
    """The robot began following the patient's breath along the probe, or stopped, since it was
    last told, `FOLLOW_GAP_S` after that at the earliest: one line for the operator, and the log's
    "follow" event."""
    follow = blocks.controller.follow
    if not blocks.follows.due(t, follow.active != blocks.following):
        return None
    blocks.following = follow.active
    if follow.active:
        text = f"following the breath along the probe about {follow.level_N:.1f} N"
        return Event("follow", text, f"ROBOT FOLLOWS THE BREATH: {text}")
    text = "no longer following the breath"
    return Event("follow", text, f"robot: {text}")


_HOLD_ENDS = {
    HoldEnd.CONTACT_LOST: "the contact was lost",
    HoldEnd.TRAVEL: "the tip moved too far",
    HoldEnd.STOPPED: "the controller stopped the robot",
}


def _check_text(estimator: Estimator) -> str:
    online = estimator.correction.online
    if online is None:
        return f"{estimator.params.probe_correction.kind} correction: nothing to identify"
    return f"online map identified from {online.updates} probe samples"
