"""The detectors that tell the controller's events, and the machine that turns them into its mode.

Each tick the machine asks the detectors, in this order, each in the modes it listens in, and moves
the mode by `hoh_cosim.control.guidance.modes.TRANSITIONS` after each answer, so that one tick may
pass through several modes (a release in contact and the hold taking the probe; a hold's lost
contact and the recovery):

    supervisor   STOP on any stop flag (`hoh_cosim.control.supervisor.check_inputs`), GO once none
    release      RELEASED: the hand let go (`hoh_cosim.control.release`); PUSHED: after a
                 release, the hand pushes again
    hold watch   HOLD_READY: hands off in contact, settled (`ContactHold.watch`)
    hold guard   CONTACT_LOST, TRAVEL_LIMIT: a hold's contact lost, or its tip too far
    touch        TOUCHED: a touch of the handle while holding; HANDED_BACK: the blend is over
    recovery     RECOVERED, CONTACT_BACK: the contact is back (hands off, under the hand);
                 RECOVERY_FAILED: none within the search's travel and time (or no recovery);
                 PUSHED: the hand pulls the probe out
    contact      TOUCH_DOWN, LIFT_OFF: the probe on or off the patient; CONTACT_LOST: under the
                 hand, the patient left the probe (with the recovery on)

After every transition each detector's `enter` sees it: the release detector rests after a hold or
a recovery that ended without the hand and resumes guiding after a hand-back, the hold engages, the
recovery starts. The detectors adapt the features' own blocks, which the stages own
(`hoh_cosim.control.guidance.stages`).
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Sequence
from typing import Protocol

from hoh_cosim.control.guidance.modes import GUIDING, HOLD_MODES, Event, Mode, next_mode
from hoh_cosim.control.guidance.tick import Tick
from hoh_cosim.control.hold import ContactHold, HoldEnd, HoldPhase
from hoh_cosim.control.recovery import ContactRecovery
from hoh_cosim.control.release import ReleaseDetector
from hoh_cosim.control.vectors import Vec3

__all__ = [
    "ContactWatch",
    "Detector",
    "HoldGuard",
    "HoldWatch",
    "ModeMachine",
    "RecoveryWatch",
    "ReleaseWatch",
    "SupervisorWatch",
    "TouchWatch",
]

_ALL = frozenset(Mode)
_RUNNING = _ALL - {Mode.STOPPED}


class Detector(Protocol):
    """Tells an event of this tick in the modes it listens in (`modes`), and sees every
    transition (`enter`)."""

    modes: frozenset[Mode]

    def event(self, mode: Mode, tick: Tick) -> Event | None: ...

    def enter(self, mode: Mode, previous: Mode, tick: Tick) -> None: ...

    def reset(self) -> None: ...


class ModeMachine:
    """The detectors in order, and the mode they move (module docstring)."""

    def __init__(self, detectors: Sequence[Detector]) -> None:
        self.detectors = tuple(detectors)
        # per mode, the detectors that watch it, with their places in the order
        self._watching = {
            mode: tuple((i, d) for i, d in enumerate(self.detectors) if mode in d.modes)
            for mode in Mode
        }

    def advance(self, mode: Mode, tick: Tick) -> Mode:
        """The mode at the end of this tick, from `mode` at its start: the detectors in their
        order, each from the mode the ones before it left."""
        for i, detector in self._watching[mode]:
            event = detector.event(mode, tick)
            if event is not None:
                new = next_mode(mode, event)
                if new != mode:
                    return self._moved(new, mode, i + 1, tick)
        return mode

    def _moved(self, mode: Mode, before: Mode, start: int, tick: Tick) -> Mode:
        """A transition to `mode`: the detectors' hooks, then the rest of the order from it."""
        for each in self.detectors:
            each.enter(mode, before, tick)
        for i, detector in self._watching[mode]:
            if i < start:
                continue
            event = detector.event(mode, tick)
            if event is not None:
                new = next_mode(mode, event)
                if new != mode:
                    return self._moved(new, mode, i + 1, tick)
        return mode

    def reset(self) -> None:
        for detector in self.detectors:
            detector.reset()


class _Quiet:
    """A detector that needs no hook on transitions or resets."""

    def enter(self, mode: Mode, previous: Mode, tick: Tick) -> None:
        pass

    def reset(self) -> None:
        pass


class SupervisorWatch(_Quiet):
    """STOP on any stop flag; GO in the first tick without."""

    modes = _ALL

    def event(self, mode: Mode, tick: Tick) -> Event | None:
        if tick.status:
            return Event.STOP
        return Event.GO if mode == Mode.STOPPED else None


class ReleaseWatch:
    """The release detector (`hoh_cosim.control.release`): while guiding (if on; in contact only
    with its `in_contact`) whether the hand let go; while braking whether it pushes again."""

    modes = frozenset({Mode.FREE, Mode.CONTACT, Mode.BRAKING})

    def __init__(self, detector: ReleaseDetector, deadband: Vec3, enabled: bool) -> None:
        self.detector, self.deadband, self.enabled = detector, deadband, enabled

    def event(self, mode: Mode, tick: Tick) -> Event | None:
        if mode != Mode.BRAKING and not self.enabled:
            return None
        if mode == Mode.CONTACT and not self.detector.params.in_contact:
            return None
        braking = self.detector.step(
            tick.t, tick.F, tick.F_raw, self.deadband, bool(tick.request.any()), tick.probe
        )
        if mode == Mode.BRAKING:
            return None if braking else Event.PUSHED
        return Event.RELEASED if braking else None

    def enter(self, mode: Mode, previous: Mode, tick: Tick) -> None:
        if mode == Mode.BRAKING and previous not in GUIDING:  # rest until the hand pushes
            self.detector.hold_at_rest(tick.t)
        elif mode in GUIDING and previous in _ROBOT_HAS_IT:  # the hand has the robot again
            self.detector.resume()

    def reset(self) -> None:
        """The brake stage owns the detector's state."""


_ROBOT_HAS_IT = frozenset({Mode.HOLDING, Mode.HANDING_BACK, Mode.RECOVERING})


class HoldWatch:
    """Hands off in contact (`ContactHold.watch`): a release in contact, or the hand quiet a while;
    engages the hold on entering HOLDING (at its last level after a recovery)."""

    modes = frozenset({Mode.FREE, Mode.CONTACT, Mode.BRAKING})

    def __init__(
        self, hold: ContactHold, deadband: Vec3, enabled: bool, contact_threshold_N: float
    ) -> None:
        self.hold, self.deadband, self.enabled = hold, deadband, enabled
        self.threshold_sq = contact_threshold_N * contact_threshold_N
        self.reset()

    def event(self, mode: Mode, tick: Tick) -> Event | None:
        axis = tick.axis
        if not self.enabled or axis is None:
            return None
        if mode == Mode.BRAKING and not self._released_in_contact:
            # a brake after a release in the air, or after a hold or a recovery that ended
            # without the hand: rest until the hand pushes, never a hold of the robot's own
            return None
        in_contact = mode == Mode.BRAKING
        moved = self._moved(tick, axis) if self.hold.params.engage_still_m > 0.0 else 0.0
        if self.hold.watch(tick.t, tick.F, self.deadband, axis, tick.F_probe, in_contact, moved):
            return Event.HOLD_READY
        return None

    def enter(self, mode: Mode, previous: Mode, tick: Tick) -> None:
        if mode == Mode.BRAKING:
            # the release detector's own test: let go with the probe on the patient
            F = tick.probe
            self._released_in_contact = (
                previous in GUIDING and F is not None and float(F.dot(F)) > self.threshold_sq
            )
        elif mode == Mode.HOLDING and previous != Mode.HANDING_BACK:
            assert tick.axis is not None
            self.hold.engage(
                tick.t,
                tick.F,
                tick.F_meas,
                tick.F_probe,
                tick.axis,
                tick.p_BT,
                tick.v_last,
                tick.F_probe_meas,
                keep_level=previous == Mode.RECOVERING,
            )

    def _moved(self, tick: Tick, axis: Vec3) -> float:
        """How far the tip moved across the probe's axis over the last `engage_s` [m]."""
        tips = self._tips
        tips.append((tick.t, tick.p_BT.copy()))
        while tick.t - tips[0][0] > self.hold.params.engage_s + 1e-9:
            tips.popleft()
        d = tips[-1][1] - tips[0][1]
        across = d - float(d.dot(axis)) * axis
        return math.sqrt(float(across.dot(across)))

    def reset(self) -> None:
        self._released_in_contact = False
        self._tips: deque[tuple[float, Vec3]] = deque()


class HoldGuard(_Quiet):
    """The hold's guards (`ContactHold.guard`): its contact lost, or its tip too far."""

    modes = HOLD_MODES

    def __init__(self, hold: ContactHold) -> None:
        self.hold = hold

    def event(self, mode: Mode, tick: Tick) -> Event | None:
        ended = self.hold.guard(tick.t, tick.p_BT, tick.F_probe)
        if ended is None:
            return None
        return Event.CONTACT_LOST if ended == HoldEnd.CONTACT_LOST else Event.TRAVEL_LIMIT


class TouchWatch(_Quiet):
    """A touch of the handle while holding (`ContactHold.touched`), and the hand-back's blend
    (`ContactHold.blended`)."""

    modes = HOLD_MODES

    def __init__(self, hold: ContactHold, deadband: Vec3) -> None:
        self.hold, self.deadband = hold, deadband

    def event(self, mode: Mode, tick: Tick) -> Event | None:
        hold = self.hold
        if mode == Mode.HANDING_BACK:
            return Event.HANDED_BACK if hold.blended(tick.t) else None
        if not hold.touched(tick.t, tick.dt, tick.F, tick.F_raw, self.deadband, tick.F_probe):
            return None
        return Event.HANDED_BACK if hold.phase == HoldPhase.OFF else Event.TOUCHED


class RecoveryWatch:
    """The contact recovery (`hoh_cosim.control.recovery`): the normal while not recovering; while
    recovering, the contact back, the search given up, or the hand pulling the probe out. Without
    the recovery a lost contact gives up at once."""

    modes = _RUNNING

    def __init__(self, recovery: ContactRecovery, enabled: bool) -> None:
        self.recovery, self.enabled = recovery, enabled

    def event(self, mode: Mode, tick: Tick) -> Event | None:
        recovery = self.recovery
        if mode != Mode.RECOVERING:
            if self.enabled:
                recovery.observe(tick.dt, tick.probe, tick.axis)
            return None
        if not self.enabled:
            return Event.RECOVERY_FAILED
        if recovery.pulled(tick.t, tick.F):
            return Event.PUSHED
        if recovery.back(tick.t, tick.probe):
            return Event.RECOVERED if recovery.hands_off else Event.CONTACT_BACK
        if recovery.gave_up(tick.t, tick.p_BT):
            return Event.RECOVERY_FAILED
        return None

    def enter(self, mode: Mode, previous: Mode, tick: Tick) -> None:
        if mode == Mode.RECOVERING:
            if self.enabled:
                self.recovery.start(tick.t, tick.p_BT, tick.axis, previous in HOLD_MODES)
        elif previous == Mode.RECOVERING:
            self.recovery.stop()

    def reset(self) -> None:
        """The recovery stage owns the recovery's state."""


class ContactWatch:
    """The probe on or off the patient: TOUCH_DOWN above `touch_down_N`, LIFT_OFF under
    `lift_off_N`. With the recovery on, a contact of at least its `established_s` that ends under
    the hand is a loss (CONTACT_LOST) unless the hand lifted the probe: it pulled it out, or the tip
    moved out along the probe (`hoh_cosim.control.recovery`, module docstring)."""

    modes = GUIDING

    def __init__(
        self, touch_down_N: float, lift_off_N: float, recovery: ContactRecovery, enabled: bool
    ) -> None:
        self.touch_sq, self.lift_sq = touch_down_N * touch_down_N, lift_off_N * lift_off_N
        self.recovery, self.enabled = recovery, enabled
        self.reset()

    def event(self, mode: Mode, tick: Tick) -> Event | None:
        size_sq = tick.probe_sq
        if mode == Mode.FREE:
            return Event.TOUCH_DOWN if size_sq > self.touch_sq else None
        if size_sq >= self.lift_sq:
            self._lost_at = None
            return None
        axis = tick.axis
        p = self.recovery.params
        established = tick.t - self._since >= p.established_s - 1e-9
        if not (self.enabled and established) or axis is None or not axis.any():
            return Event.LIFT_OFF
        if self._lost_at is None:
            self._lost_at, self._lost_z = tick.t, float(tick.p_BT.dot(axis))
        pulled = float(tick.F.dot(axis)) < -p.pull_N
        out = self._lost_z - float(tick.p_BT.dot(axis)) >= p.loss_m
        if pulled or out:
            self._lost_at = None
            return Event.LIFT_OFF
        if tick.t - self._lost_at >= p.loss_s - 1e-9:
            self._lost_at = None
            return Event.CONTACT_LOST
        return None

    def enter(self, mode: Mode, previous: Mode, tick: Tick) -> None:
        if mode != Mode.CONTACT:
            self._lost_at = None
        elif previous == Mode.FREE:  # a new contact (not the hand taking over from the robot)
            self._since = tick.t

    def reset(self) -> None:
        self._lost_at: float | None = None
        self._lost_z = 0.0
        self._since = 0.0  # when the contact began
