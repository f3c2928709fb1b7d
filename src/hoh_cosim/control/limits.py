"""Safety limits as pure functions that return what they did; the caller obeys (DESIGN.md §7).

Two kinds of outcome, one `Status` flag set:
- clamps that change the command and let it through (speed, acceleration, workspace, soft force
  cap), reported so a run can count them;
- stops, after which only a zero twist may be sent (`Status.ok` is False): stale or non-finite data,
  the estimator not ready, the latched contact-force stop.

Defaults (DESIGN.md §7): TCP speed <= 0.10 m/s, probe contact force soft cap 20 N and a latched stop
at 25 N (ISO/TS 15066 puts the abdomen's quasi-static limit at 110 N; robotic ultrasound commonly caps
near 20–25 N), stale sensor data (older than 3 expected packet periods) stops the motion.
"""

from __future__ import annotations

import enum
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from hoh_cosim.control.vectors import Vec, Vec3, as_scalar, as_vector, frozen
from hoh_cosim.errors import ConfigError

__all__ = [
    "STOP_FLAGS",
    "LimitParams",
    "Status",
    "clamp_acceleration",
    "clamp_speed",
    "is_stale",
    "probe_force_limit",
    "workspace_limit",
]


class Status(enum.IntFlag):
    """What the limits did on one cycle. Zero is a clean cycle."""

    SPEED_CLAMPED = 1 << 0
    ACCEL_CLAMPED = 1 << 1
    WORKSPACE = 1 << 2
    FORCE_SOFT_CAP = 1 << 3
    FIXTURE = 1 << 4
    FORCE_STOP = 1 << 8  # latched
    NONFINITE = 1 << 9  # latched
    STALE_FT = 1 << 10
    STALE_PROBE = 1 << 11
    NOT_READY = 1 << 12

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

_DESCRIPTIONS = {
    Status.SPEED_CLAMPED: "speed clamped",
    Status.ACCEL_CLAMPED: "acceleration clamped",
    Status.WORKSPACE: "at the workspace boundary",
    Status.FORCE_SOFT_CAP: "probe force above the soft cap",
    Status.FIXTURE: "virtual fixture engaged",
    Status.FORCE_STOP: "probe force above the stop limit (latched)",
    Status.NONFINITE: "non-finite input (latched)",
    Status.STALE_FT: "stale FT-150 data",
    Status.STALE_PROBE: "stale probe-sensor data",
    Status.NOT_READY: "estimator not ready (rebiasing)",
}


@dataclass(frozen=True)
class LimitParams:
    UNITS: ClassVar[dict[str, Any]] = {
        "max_linear_speed": "m/s",
        "max_angular_speed": "rad/s",
        "max_linear_accel": "m/s2",
        "max_angular_accel": "rad/s2",
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


def _norm(v: Vec) -> float:
    return math.sqrt(float(v @ v))


def clamp_speed(v: Vec3, max_speed: float) -> tuple[Vec3, bool]:
    """Scale `v` down to |v| <= max_speed, keeping its direction."""
    n = _norm(v)
    if n <= max_speed:
        return v, False
    return v * (max_speed / n), True


def clamp_acceleration(v: Vec3, v_prev: Vec3, dt: float, max_accel: float) -> tuple[Vec3, bool]:
    """Move from `v_prev` toward `v` by at most max_accel·dt (a vector rate limit)."""
    dv = v - v_prev
    n = _norm(dv)
    step = max_accel * dt
    if n <= step:
        return v, False
    return v_prev + dv * (step / n), True


def workspace_limit(
    v_B: Vec3, p_B: Vec3, box_min: Sequence[float], box_max: Sequence[float]
) -> tuple[Vec3, bool]:
    """Zero every velocity component that would take the TCP further out of the box.

    Inside the box nothing changes; at or beyond a face, motion back inside stays free.
    """
    # three scalars: plain floats are several times faster than numpy's small-array operations
    p0, p1, p2 = p_B.tolist()
    lo0, lo1, lo2 = box_min[0], box_min[1], box_min[2]
    hi0, hi1, hi2 = box_max[0], box_max[1], box_max[2]
    if lo0 < p0 < hi0 and lo1 < p1 < hi1 and lo2 < p2 < hi2:
        return v_B, False
    v = v_B.tolist()
    hit = False
    for i, (p, lo, hi) in enumerate(((p0, lo0, hi0), (p1, lo1, hi1), (p2, lo2, hi2))):
        if (p >= hi and v[i] > 0.0) or (p <= lo and v[i] < 0.0):
            v[i] = 0.0
            hit = True
    return (np.array(v), True) if hit else (v_B, False)


def probe_force_limit(v_B: Vec3, F_probe_B: Vec3, soft_cap: float) -> tuple[Vec3, bool]:
    """Above the soft cap, remove the velocity component that would press the probe harder.

    The contact force on the probe points out of the patient, so pressing harder is moving against it:
    the component of v along -F̂ is removed, moving away or sideways stays free.
    """
    n = _norm(F_probe_B)
    if n < soft_cap:
        return v_B, False
    out_of_patient = F_probe_B / n
    into = float(v_B @ out_of_patient)
    if into < 0.0:
        return v_B - into * out_of_patient, True
    return v_B, True


def is_stale(age_s: float, period_s: float, periods: float) -> bool:
    """True when the newest packet is older than `periods` expected packet periods."""
    return age_s > periods * period_s
