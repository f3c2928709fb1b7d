"""The supervisor: the one safety policy that the controller, the runner and replay obey (DESIGN.md §7).

Every safety decision lives here, as pure functions over what the loop knows:

    check_inputs    the estimate of one tick: non-finite (latched) · estimator not ready · stale
                    FT-150 or probe data (older than `stale_periods` packet periods) · probe force
                    at the stop limit (latched)                     → stop flags: the twist is zero
    limit_command   the law's twist: speed clamp · acceleration clamp · probe-force soft cap ·
                    workspace box (in that order: the hard limits last)  → clamp flags
    supervise       one cycle of a session on the robot: the robot's own stop, a device that sent a
                    non-finite value, a stop flag (a stale stream is a gap that zeroes the command
                    for up to `stale_stop_s`, then the end), a command outside the limits
                                                                    → send, or end with the cause
    starved_cause   a cycle that reads or commands the robot later after the last command than
                    the robot's watchdog allows: the loop itself was starved, whatever the robot
                    says now
                                                                    → end with that cause

A stream's age counts the loop's cycles, not the wall clock: a loop held up for 100 ms runs one
late cycle, not fifty, so its own stall never makes a stream stale; a stall past the watchdog is
named as the loop's. The device's silence is counted only while ordinary tasks could run: on Linux
the bytes of a serial port (and of a pseudo-terminal) reach the reader through a kernel worker at
ordinary priority, which the loop's own real-time threads and a loaded machine can starve for
longer than `stale_stop_s`, with a perfectly healthy device. The runner measures that starvation
with a canary process of ordinary priority (`hoh_cosim.hardware.pressure.Canary`) from the cycle a
stream turns stale on; the session ends once the stream's age less that starved time reaches
`stale_stop_s`, or its age alone reaches `stale_stop_max_s`, whatever the machine does. The
command is zero all the while, so the arm stands still. A stop names the starved time it
discounted, and the CPU pressure when the machine was overloaded.

Two kinds of outcome, one `Status` flag set:
- clamps that change the command and let it through (speed, acceleration, workspace, soft force
  cap, fixture), reported so a run can count them;
- stops, after which only a zero twist may be sent (`Status.ok` is False).

Defaults (DESIGN.md §7): TCP speed <= 0.10 m/s, probe contact force soft cap 20 N and a latched stop
at 25 N (ISO/TS 15066 puts the abdomen's quasi-static limit at 110 N; robotic ultrasound commonly caps
near 20–25 N), stale sensor data (older than 3 expected packet periods) stops the motion, a stream
silent for 0.25 s ends a session on the robot.

A new safety check is a flag, its description, its test in `check_inputs` or `supervise` and, if it
takes a parameter, a field of `LimitParams`: all in this file.
"""

from __future__ import annotations

import enum
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from hoh_cosim.control.limits import (
    clamp_acceleration,
    clamp_speed,
    is_stale,
    probe_force_limit,
    workspace_limit,
)
from hoh_cosim.control.vectors import Vec, Vec3, as_scalar, as_vector, frozen
from hoh_cosim.errors import ConfigError

__all__ = [
    "LATCHED_FLAGS",
    "STARVED_TEXT",
    "STOP_FLAGS",
    "LimitParams",
    "SessionPolicy",
    "Status",
    "Verdict",
    "check_inputs",
    "limit_command",
    "robot_cause",
    "starved_cause",
    "supervise",
]


class Status(enum.IntFlag):
    """What the supervisor decided on one cycle. Zero is a clean cycle."""

    SPEED_CLAMPED = 1 << 0
    ACCEL_CLAMPED = 1 << 1
    WORKSPACE = 1 << 2
    FORCE_SOFT_CAP = 1 << 3
    FIXTURE = 1 << 4
    RELEASED = 1 << 5  # the hand let go: the controller holds the robot at rest
    BRAKING = 1 << 6  # braking to rest at the braking deceleration
    PASSIVITY = 1 << 7  # the passivity controller removed motion that would have made energy
    FORCE_STOP = 1 << 8  # latched
    NONFINITE = 1 << 9  # latched
    STALE_FT = 1 << 10
    STALE_PROBE = 1 << 11
    NOT_READY = 1 << 12
    HOLDING = 1 << 13  # hold-on-release: the robot holds the probe's contact force
    HANDING_BACK = 1 << 14  # a touch of the handle: the law's command blended in
    FOLLOWING = 1 << 15  # in contact, the hand steering: the breath followed along the probe
    RECOVERING = 1 << 16  # the contact was lost: the probe brought back along the last normal

    @property
    def ok(self) -> bool:
        """True when the command may be sent; False means send zero (or stop the robot)."""
        return not (self & STOP_FLAGS)

    def describe(self) -> str:
        """Human-readable names of the set flags, stops first: 'stale FT-150 data, speed clamped'."""
        if not self:
            return "ok"
        ordered = sorted(Status, key=lambda f: (not f & STOP_FLAGS, f.value))
        return ", ".join(_DESCRIPTIONS[f] for f in ordered if f & self)


STOP_FLAGS = (
    Status.FORCE_STOP | Status.NONFINITE | Status.STALE_FT | Status.STALE_PROBE | Status.NOT_READY
)
LATCHED_FLAGS = Status.FORCE_STOP | Status.NONFINITE  # cleared only by a reset

_DESCRIPTIONS = {
    Status.SPEED_CLAMPED: "speed clamped",
    Status.ACCEL_CLAMPED: "acceleration clamped",
    Status.WORKSPACE: "at the workspace boundary",
    Status.FORCE_SOFT_CAP: "probe force above the soft cap",
    Status.FIXTURE: "virtual fixture engaged",
    Status.RELEASED: "hand released: holding at rest",
    Status.HOLDING: "hand released in contact: holding the contact force",
    Status.HANDING_BACK: "handing back to the hand",
    Status.FOLLOWING: "following the breath",
    Status.RECOVERING: "recovering the contact",
    Status.BRAKING: "braking to rest",
    Status.PASSIVITY: "passivity controller acting",
    Status.FORCE_STOP: "probe force above the stop limit (latched)",
    Status.NONFINITE: "non-finite input (latched)",
    Status.STALE_FT: "stale FT-150 data",
    Status.STALE_PROBE: "stale probe-sensor data",
    Status.NOT_READY: "estimator not ready (rebiasing)",
}

# Status bits as plain ints in the hot path: IntFlag arithmetic costs a microsecond a time.
_NONFINITE = int(Status.NONFINITE)
_NOT_READY = int(Status.NOT_READY)
_STALE_FT = int(Status.STALE_FT)
_STALE_PROBE = int(Status.STALE_PROBE)
_FORCE_STOP = int(Status.FORCE_STOP)
_SPEED_CLAMPED = int(Status.SPEED_CLAMPED)
_ACCEL_CLAMPED = int(Status.ACCEL_CLAMPED)
_FORCE_SOFT_CAP = int(Status.FORCE_SOFT_CAP)
_WORKSPACE = int(Status.WORKSPACE)
_BRAKING = int(Status.BRAKING)


@dataclass(frozen=True)
class LimitParams:
    UNITS: ClassVar[dict[str, Any]] = {
        "max_linear_speed": "m/s",
        "max_angular_speed": "rad/s",
        "max_linear_accel": "m/s2",
        "max_angular_accel": "rad/s2",
        "max_brake_accel": "m/s2",
        "workspace_min_B": "m",
        "workspace_max_B": "m",
        "probe_force_soft_cap": "N",
        "probe_force_stop": "N",
        "stale_periods": "1",
    }

    max_linear_speed: float = 0.10  # [m/s] DESIGN.md §7
    max_angular_speed: float = 0.5  # [rad/s] ~29°/s, a brisk wrist turn
    max_linear_accel: float = 1.0  # [m/s²] 0.1 m/s reached or shed in 0.1 s
    max_angular_accel: float = 5.0  # [rad/s²]
    # [m/s²] shedding speed towards rest after a release (never speeding up): ur-rtde's speedStop
    # default; 0.05 m/s is shed in 5 ms over 0.125 mm
    max_brake_accel: float = 10.0
    workspace_min_B: Vec3 = field(default_factory=lambda: frozen([-0.70, -0.70, 0.0]))  # [m]
    workspace_max_B: Vec3 = field(default_factory=lambda: frozen([0.70, 0.70, 0.80]))  # [m]
    probe_force_soft_cap: float = 20.0  # [N]
    probe_force_stop: float = 25.0  # [N] latched
    stale_periods: float = 3.0  # expected packet periods before the data count as stale

    def __post_init__(self) -> None:
        for name in (
            "max_linear_speed",
            "max_angular_speed",
            "max_linear_accel",
            "max_angular_accel",
            "max_brake_accel",
            "probe_force_soft_cap",
            "probe_force_stop",
            "stale_periods",
        ):
            object.__setattr__(
                self, name, as_scalar(getattr(self, name), name, low=0.0, low_open=True)
            )
        lo = as_vector(self.workspace_min_B, 3, "workspace_min_B")
        hi = as_vector(self.workspace_max_B, 3, "workspace_max_B")
        if np.any(lo >= hi):
            raise ConfigError(
                f"workspace_min_B must be below workspace_max_B on every axis, got "
                f"{lo.tolist()} and {hi.tolist()}"
            )
        object.__setattr__(self, "workspace_min_B", lo)
        object.__setattr__(self, "workspace_max_B", hi)
        if self.probe_force_soft_cap > self.probe_force_stop:
            raise ConfigError(
                f"probe_force_soft_cap ({self.probe_force_soft_cap} N) must not exceed "
                f"probe_force_stop ({self.probe_force_stop} N)"
            )


# --- one tick of the controller ----------------------------------------------------------------


def check_inputs(
    inputs: Mapping[str, Vec],
    limits: LimitParams,
    *,
    ft_period_s: float,
    probe_period_s: float,
    use_probe: bool,
) -> int:
    """The stop flags of one tick's estimate (the controller's inputs), as an int.

    Any flag in `STOP_FLAGS` means a zero twist; `LATCHED_FLAGS` stay until a reset."""
    F, tau, F_probe, p_BT = (
        inputs["F_hand_B"],
        inputs["tau_hand_B"],
        inputs["F_probe_B"],
        inputs["p_BT_B"],
    )
    ft_age, probe_age = float(inputs["ft_age"][0]), float(inputs["probe_age"][0])
    ready = float(inputs["ready"][0])
    probe_sq = float(F_probe @ F_probe)
    # a NaN or an infinity anywhere makes this sum non-finite (so does an overflow: also a fault)
    total = float(F @ F) + float(tau @ tau) + probe_sq + float(p_BT @ p_BT)
    if not math.isfinite(total + ft_age + probe_age + ready):
        return _NONFINITE
    status = 0
    if ready < 0.5:
        status |= _NOT_READY
    if is_stale(ft_age, ft_period_s, limits.stale_periods):
        status |= _STALE_FT
    if use_probe:
        if is_stale(probe_age, probe_period_s, limits.stale_periods):
            status |= _STALE_PROBE
        if math.sqrt(probe_sq) >= limits.probe_force_stop:
            status |= _FORCE_STOP
    return status


def limit_command(
    v: Vec3,
    w: Vec3,
    v_prev: Vec3,
    w_prev: Vec3,
    dt: float,
    F_probe_B: Vec3 | None,
    p_BT_B: Vec3,
    limits: LimitParams,
    box: tuple[list[float], list[float]],
    *,
    braking: bool = False,
) -> tuple[Vec3, Vec3, int]:
    """The law's twist within the limits, and the clamp flags, as an int.

    Speed, then acceleration (from the last command), then the probe-force soft cap (without a
    probe sensor `F_probe_B` is None) and the workspace box (`box`: its corners as lists): the hard
    limits last, so they override the acceleration clamp, never the other way round.

    `braking`: the hand let go and the command is rest (v = 0): the linear speed may be shed at
    `max_brake_accel` (flag BRAKING while it is). Only towards rest: any other command is clamped
    at `max_linear_accel`, so no rule lets the robot speed up faster."""
    status = 0
    v, hit_v = clamp_speed(v, limits.max_linear_speed)
    w, hit_w = clamp_speed(w, limits.max_angular_speed)
    if hit_v or hit_w:
        status |= _SPEED_CLAMPED
    if braking and not v.any():
        if v_prev.any():
            status |= _BRAKING
        v, hit_v = clamp_acceleration(v, v_prev, dt, limits.max_brake_accel)
    else:
        v, hit_v = clamp_acceleration(v, v_prev, dt, limits.max_linear_accel)
    w, hit_w = clamp_acceleration(w, w_prev, dt, limits.max_angular_accel)
    if hit_v or hit_w:
        status |= _ACCEL_CLAMPED
    if F_probe_B is not None:
        v, hit = probe_force_limit(v, F_probe_B, limits.probe_force_soft_cap)
        if hit:
            status |= _FORCE_SOFT_CAP
    v, hit = workspace_limit(v, p_BT_B, *box)
    if hit:
        status |= _WORKSPACE
    return v, w, status


# --- one cycle of a session on the robot ---------------------------------------------------------


@dataclass(frozen=True)
class SessionPolicy:
    """What the supervisor of a session on the robot needs to know besides the cycle itself."""

    limits: LimitParams
    stale_stop_s: float = 0.25  # a stream silent this long ends the session; shorter: zero twist
    stale_stop_max_s: float = 1.0  # ... however long ordinary tasks were starved meanwhile
    robot: str = "the robot"  # the devices' names, as the messages give them
    ft: str = "FT-150"
    probe: str | None = None  # None: no probe sensor
    watchdog_s: float = math.inf  # the robot's watchdog: it stops the arm after this silence


@dataclass(frozen=True)
class Verdict:
    """One cycle's decision: the flags as logged, the twist to send, and why the session ends."""

    status: Status
    twist_B: Vec  # what goes to the robot: the command, or zero
    cause: str | None  # None: go on


_ZERO_TWIST = frozen(np.zeros(6))

STARVED_TEXT = "ms of it with this machine's ordinary tasks starved"
"""How a stale stream's stop names the starved time it discounted (after the milliseconds)."""


def robot_cause(policy: SessionPolicy, problem: str) -> str:
    """Why a session ends when the robot stopped itself (protective or emergency stop, program not
    running): before the cycle's blocks are stepped."""
    return f"{policy.robot}: {problem}"


def starved_cause(policy: SessionPolicy, before: str, silent_s: float) -> str | None:
    """The cause to end with when the loop, about to read or command the robot (`before`: "cycle
    7"), finds `silent_s` passed since its last command: at or past the robot's watchdog the robot
    has stopped itself, and the loop's stall, not what the robot reports now ("program not
    running"), is why."""
    if math.isinf(policy.watchdog_s) or not silent_s >= policy.watchdog_s:
        return None
    return (
        f"the control loop was starved: no command for {1e3 * silent_s:.0f} ms before {before}, "
        f"past the robot's {1e3 * policy.watchdog_s:.0f} ms watchdog (this machine is "
        "overloaded, or the loop lacks its real-time priority)"
    )


def supervise(
    policy: SessionPolicy,
    status: Status,
    estimate: Mapping[str, Vec],
    twist_B: Vec,
    *,
    ft: Vec | None,
    probe: Vec | None,
    checking: bool = False,
    ft_error: str | None = None,
    probe_error: str | None = None,
    overload: str | None = None,
    starved: Mapping[Status, float] | None = None,
    quiet: Mapping[Status, str] | None = None,
) -> Verdict:
    """Decide one cycle of a session: send the controller's twist, send zero, or end the session.

    `status` is the controller's, `estimate` the estimator's outputs (for the ages and the probe
    force), `ft` and `probe` the raw samples the cycle read (None: none yet), `checking` whether the
    probe check runs (the estimator is not ready by design then, and the robot holds still), the
    errors what the streams' readers last reported, for the message, and `overload` how starved the
    machine's CPU was while a stream was stale (None: not measured, or not starved), and
    `starved` for each stale stream's flag how long ordinary tasks were starved since it turned
    stale [s] (the module's docstring), and `quiet` for each stale stream's flag what its reader
    got since its last sample (bytes or none), which a stop's message carries where the reader
    gave no reason of its own."""
    if checking:
        status &= ~Status.NOT_READY
    cause = _stop_cause(
        policy,
        status,
        estimate,
        ft,
        probe,
        ft_error,
        probe_error,
        overload,
        starved or {},
        quiet or {},
    )
    if cause is None:
        cause = _command_cause(policy.limits, twist_B)
    return Verdict(status, _ZERO_TWIST if cause else twist_B, cause)


def _stop_cause(
    policy: SessionPolicy,
    status: Status,
    estimate: Mapping[str, Vec],
    ft: Vec | None,
    probe: Vec | None,
    ft_error: str | None,
    probe_error: str | None,
    overload: str | None,
    starved: Mapping[Status, float],
    quiet: Mapping[Status, str],
) -> str | None:
    for name, values in ((policy.ft, ft), (policy.probe, probe)):
        if values is not None and not np.all(np.isfinite(values)):
            return f"{name} sent a non-finite value {np.round(values, 3).tolist()}"
    if status.ok:
        return None
    if status & Status.FORCE_STOP:
        force = float(np.linalg.norm(estimate["F_probe_B"]))
        return (
            f"probe contact force {force:.1f} N reached the "
            f"{policy.limits.probe_force_stop:g} N stop"
        )
    gaps = Status(0)  # stale streams still inside their grace: the command is zero meanwhile
    for flag, name, age_port, error in (
        (Status.STALE_FT, policy.ft, "ft_age", ft_error),
        (Status.STALE_PROBE, policy.probe, "probe_age", probe_error),
    ):
        if status & flag and name is not None:
            age = float(estimate[age_port][0])
            discounted = min(age, max(0.0, starved.get(flag, 0.0)))
            if age - discounted >= policy.stale_stop_s or age >= policy.stale_stop_max_s:
                said = error  # the reader's own reason, which says more than its byte count
                if error is None and overload is not None:
                    error = f"{overload}: its delivery was starved, not necessarily the device"
                why = error or "the stream stalled"
                if said is None and flag in quiet:
                    why += f": {quiet[flag]}"
                if discounted >= 0.0005:
                    why += f"; {1e3 * discounted:.0f} {STARVED_TEXT}"
                return f"{name}: no new sample for {1e3 * age:.0f} ms ({why})"
            gaps |= flag
    if not (status & STOP_FLAGS) & ~gaps:
        return None
    return f"the controller stopped: {status.describe()}"


def _command_cause(limits: LimitParams, twist_B: Vec) -> str | None:
    """The command itself, checked again at the last gate before the robot."""
    if not np.all(np.isfinite(twist_B)):
        return f"non-finite command {twist_B.tolist()}"
    v, w = float(np.linalg.norm(twist_B[:3])), float(np.linalg.norm(twist_B[3:]))
    if v > limits.max_linear_speed * (1 + 1e-9) or w > limits.max_angular_speed * (1 + 1e-9):
        return f"command above the speed limits: {v:.4f} m/s, {w:.4f} rad/s"
    return None
