"""What the controller's detectors and stages share on one tick: the tick's inputs, read once
(`Tick`), and the command the stages pass along and refine (`Command`), with the one interface of a
stage (`Stage`)."""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Protocol

import numpy as np

from hoh_cosim.control.admittance import contact_compensated
from hoh_cosim.control.vectors import Vec, Vec3, frozen

__all__ = ["ZERO3", "Command", "Stage", "Tick"]

ZERO3 = frozen(np.zeros(3))


class Tick:
    """One tick's inputs as the controller reads them; the detectors and the stages only read it.
    On a tick with a stop flag only the time, the flags and the last command are read.

    F, tau        F̃ and τ̃: the estimated hand force and torque, in B, with the contact's force
                  and moment taken out (eq. 11-12) where contact compensation is on (in the
                  air, beyond the play only, with an onset)
    F_raw         the newest unfiltered wrist packet, compensated the same way (None: not wired,
                  or nothing reads it)
    F_meas        ... as it came (hand and contact), or None
    F_probe       the contact force's estimate in B; `probe` the same, or None without a probe
                  sensor (no compensation, fixture, force limits or hold then)
    F_probe_meas  the probe sensor's newest corrected packet in B, or None
    axis          the probe's axis in B (handle to tip), or None
    p_BT          the measured tip position in B
    ft_age, probe_age   [s] since each sensor's newest packet
    probe_sq      |F_probe|² [N²] (0 without a probe sensor)
    (F_probe_meas, axis and the ages are read only where a stage or a detector reads them: None,
    None and 0 otherwise)
    status        the supervisor's stop flags of this tick (`hoh_cosim.control.supervisor`)
    v_last, w_last      the twist the controller commanded on its last tick
    request       the hand's request: the law's twist [v; ω] (set once the law has run)
    """

    __slots__ = (
        "F",
        "F_meas",
        "F_probe",
        "F_probe_meas",
        "F_raw",
        "axis",
        "dt",
        "ft_age",
        "p_BT",
        "probe",
        "probe_age",
        "probe_sq",
        "request",
        "status",
        "t",
        "tau",
        "v_last",
        "w_last",
    )

    def __init__(self) -> None:
        self.start(0.0, 0.0, 1, (ZERO3, ZERO3), {}, (False, False, False, False, 0.0, False, 0.0))

    def start(
        self,
        t: float,
        dt: float,
        status: int,
        last: tuple[Vec3, Vec3],
        inputs: Mapping[str, Vec],
        reading: tuple[bool, bool, bool, bool, float, bool, float],
        air: bool | None = True,
    ) -> None:
        """A new tick (one object serves every tick of a controller). Its forces only without a
        stop flag (a stop's inputs may be non-finite); `reading`: contact compensation, the
        contact's torque, a probe sensor, the compensated raw packet (which only the release
        detector and the hold read), the compensation's onset in the air (`ControllerParams`),
        whether anything reads the probe's packet, axis and the ages, and the lift-off's size
        squared; `air`: the probe was off the patient on the last tick, or None (braking): off it
        if the probe force is under the lift-off."""
        self.t, self.dt, self.status = t, dt, status
        self.v_last, self.w_last = last
        self.request = _ZERO6
        if status:
            return
        compensated, contact_torque, use_probe, raw, onset, extra, lift_sq = reading
        F_probe = inputs["F_probe_B"]
        F, tau = inputs["F_hand_B"], inputs["tau_hand_B"]
        F_meas = inputs.get("F_hand_meas_B") if raw or extra else None
        F_raw = F_meas if raw else None
        self.probe_sq = probe_sq = float(F_probe.dot(F_probe)) if use_probe else 0.0
        if compensated:
            tau_probe = inputs.get("tau_probe_B")
            F_c = F_probe
            if air is None:
                air = probe_sq < lift_sq
            if onset > 0.0 and air:  # in the air: none under onset / 2, all from onset on
                w = min(max(2.0 * math.sqrt(probe_sq) / onset - 1.0, 0.0), 1.0)
                F_c = w * F_probe
                tau_probe = None if tau_probe is None else w * tau_probe
            F = contact_compensated(F, F_c)
            if contact_torque and tau_probe is not None:
                # τ̃ = τ_hand - p_RT × F_probe: the contact's moment is not the hand's
                tau = tau - tau_probe
            if F_raw is not None:
                F_raw = contact_compensated(F_raw, F_c)
        self.F, self.tau, self.F_raw, self.F_meas = F, tau, F_raw, F_meas
        self.F_probe = F_probe
        self.probe = F_probe if use_probe else None
        self.p_BT = inputs["p_BT_B"]
        if extra:
            self.F_probe_meas = inputs.get("F_probe_meas_B")
            self.axis = inputs.get("probe_axis_B")
            self.ft_age = float(inputs["ft_age"][0])
            self.probe_age = float(inputs["probe_age"][0])
        else:
            self.F_probe_meas = self.axis = None
            self.ft_age = self.probe_age = 0.0


_ZERO6 = frozen(np.zeros(6))


class Command:
    """The command the stages pass along and refine: the linear and angular velocity [m/s, rad/s]
    in B, the law's own twist (`twist_law_B`), the status flags so far, whether it is the hand's
    request (`steering`: the mode steers by it) and whether the robot brakes to rest after a
    release (speedL's deceleration, the supervisor's braking clamp)."""

    __slots__ = ("braking", "law", "status", "steering", "v", "w")

    def __init__(self) -> None:
        self.start(0)

    def start(self, status: int) -> None:
        """Rest, with the tick's stop flags (one object serves every tick of a controller)."""
        self.v = self.w = ZERO3
        self.law = _ZERO6
        self.status = status
        self.steering = self.braking = False


class Stage(Protocol):
    """One feature of the controller: it knows nothing of the others.

    `step` refines the command of this tick (it may return the same object); `reset` forgets
    everything (a stop, the controller's reset); `rest` is called on a tick whose mode does not
    run it, for a stage that keeps state it must not carry over (glide's, the follow's)."""

    def reset(self) -> None: ...

    def step(self, tick: Tick, command: Command) -> Command: ...
