"""Safety limits as pure functions over plain arrays: each returns what it did, and the caller obeys.

The supervisor (`hoh_cosim.control.supervisor`) decides which apply, in which order and what a
cycle's status is; these are its arithmetic, also used by the pose sequencer.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from hoh_cosim.control.vectors import Vec, Vec3

__all__ = [
    "clamp_acceleration",
    "clamp_speed",
    "is_stale",
    "probe_force_limit",
    "workspace_limit",
]


def _norm(v: Vec) -> float:
    return math.sqrt(v.dot(v))


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
    into = float(v_B.dot(out_of_patient))
    if into < 0.0:
        return v_B - into * out_of_patient, True
    return v_B, True


def is_stale(age_s: float, period_s: float, periods: float) -> bool:
    """True when the newest packet is older than `periods` expected packet periods."""
    return age_s > periods * period_s
