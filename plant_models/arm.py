"""The UR5 following speedL commands, as the UR controller applies them.

Each robot cycle (125 Hz on a CB3, 500 Hz on an e-series):
1. latency: the command received during the previous cycle becomes the active one (one robot cycle
   of command latency on top of whatever the sender adds);
2. acceleration: the robot's own TCP twist moves towards the active command by at most a·T (linear)
   and a_rot·T (angular), speedL's `a` argument;
3. joint velocities from the TCP twist by damped least squares, q̇ = Jᵀ(J Jᵀ + λ² I)⁻¹ ξ, with λ
   growing from 0 as the smallest singular value of J falls below a threshold (Nakamura and Hanafusa's
   damping): exact away from singularities, bounded near them;
4. limits: every joint's speed within its limit (the whole vector scaled, so the TCP keeps its
   direction), and no joint driven past its position limit.
Within a cycle the joint velocities ramp linearly to the new values (the controller interpolates), so
positions, velocities and accelerations are continuous; the tool feels the acceleration.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from hoh_cosim.control.vectors import Vec, as_scalar, as_vector, frozen
from hoh_cosim.errors import ConfigError
from plant_models.ur5 import JOINT_POSITION_LIMIT, JOINT_SPEED_LIMIT, UR5Model

__all__ = ["HOME_Q", "ArmParams", "SpeedLArm", "damped_least_squares"]

HOME_Q = frozen(
    [
        1.113077538931708,
        -1.652905289036009,
        1.506885745714064,
        -1.424776783472951,
        -1.570796326794897,
        -2.028515114658085,
    ]
)
"""Probe pointing straight down, tip at (-0.10, -0.45, 0.25) m in the base frame, R_BS = eq. 1 with
the default tool. Smallest singular value of the TCP Jacobian 0.21: far from singularities."""


@dataclass(frozen=True)
class ArmParams:
    UNITS: ClassVar[dict[str, Any]] = {
        "rate_hz": "Hz",
        "latency_cycles": "1",
        "acceleration": "m/s2",
        "angular_acceleration": "rad/s2",
        "q0": "rad",
        "dls_threshold": "1",
        "dls_max_damping": "1",
        "joint_speed_limit": "rad/s",
        "joint_position_limit": "rad",
    }

    rate_hz: float = 125.0  # the seed's UR5 is a CB3; 500 for an e-series
    latency_cycles: int = 1
    acceleration: float = 1.5  # [m/s²] speedL `a`: above the controller's own 1 m/s² clamp
    angular_acceleration: float = 6.0  # [rad/s²] speedL `aRot`
    q0: Vec = field(default_factory=lambda: HOME_Q.copy())  # [rad]
    dls_threshold: float = 0.05  # σ_min below which damping starts
    dls_max_damping: float = 0.05  # λ at σ_min = 0
    joint_speed_limit: float = JOINT_SPEED_LIMIT  # [rad/s]
    joint_position_limit: float = JOINT_POSITION_LIMIT  # [rad], ±

    def __post_init__(self) -> None:
        for name in (
            "rate_hz",
            "acceleration",
            "angular_acceleration",
            "dls_threshold",
            "joint_speed_limit",
            "joint_position_limit",
        ):
            object.__setattr__(
                self, name, as_scalar(getattr(self, name), name, low=0.0, low_open=True)
            )
        object.__setattr__(
            self, "dls_max_damping", as_scalar(self.dls_max_damping, "dls_max_damping", low=0.0)
        )
        object.__setattr__(self, "q0", as_vector(self.q0, 6, "q0"))
        if not isinstance(self.latency_cycles, int) or self.latency_cycles < 0:
            raise ConfigError(
                f"latency_cycles must be an integer >= 0, got {self.latency_cycles!r}"
            )
        if np.any(np.abs(self.q0) > self.joint_position_limit):
            raise ConfigError(
                f"q0: outside the joint limits ±{self.joint_position_limit:.4g} rad: "
                f"{self.q0.tolist()}"
            )


def damped_least_squares(J: Vec, twist: Vec, threshold: float, max_damping: float) -> Vec:
    """q̇ = Jᵀ(J Jᵀ + λ² I)⁻¹ ξ with λ² = (1 - (σ_min/ε)²) λ_max² below σ_min = ε, else 0
    (then it is the plain solution J⁻¹ξ of a square J)."""
    sigma_min = float(np.linalg.svd(J, compute_uv=False)[-1])
    if sigma_min >= threshold and J.shape[0] == J.shape[1]:
        return np.linalg.solve(J, twist)
    lam2 = 0.0
    if sigma_min < threshold:
        lam2 = (1.0 - (sigma_min / threshold) ** 2) * max_damping**2
    return J.T @ np.linalg.solve(J @ J.T + lam2 * np.eye(J.shape[0]), twist)


def _step_towards(current: Vec, target: Vec, max_step: float) -> Vec:
    delta = target - current
    n = math.sqrt(float(delta @ delta))
    return target if n <= max_step else current + delta * (max_step / n)


class SpeedLArm:
    """Joint state of the UR5 under speedL; `cycle(command)` at each robot cycle, `advance(dt)`
    every tick in between."""

    def __init__(self, params: ArmParams, model: UR5Model, tcp: str = "tcp") -> None:
        self.params = params
        self.model = model
        self.tcp = tcp
        self.period = 1.0 / params.rate_hz
        self.reset()

    def reset(self) -> None:
        self.q = self.params.q0.copy()
        self.qd = np.zeros(6)
        self.qdd = np.zeros(6)
        self.robot_twist = np.zeros(6)  # the twist the robot is tracking, after the ramp
        self._queue = [np.zeros(6) for _ in range(self.params.latency_cycles)]
        self.active = np.zeros(6)
        self._ramp_left = 0.0
        self.qdd_mean = np.zeros(6)

    def cycle(self, command: Vec) -> None:
        """A robot cycle starts: take the (delayed) command, ramp, solve for joint velocities."""
        p = self.params
        self._queue.append(np.array(command, dtype=np.float64))
        self.active = self._queue.pop(0)
        T = self.period
        v = _step_towards(self.robot_twist[:3], self.active[:3], p.acceleration * T)
        w = _step_towards(self.robot_twist[3:], self.active[3:], p.angular_acceleration * T)
        self.robot_twist = np.concatenate([v, w])
        J = self.model.jacobian(self.q, self.tcp)
        qd = damped_least_squares(J, self.robot_twist, p.dls_threshold, p.dls_max_damping)
        peak = float(np.max(np.abs(qd)))
        if peak > p.joint_speed_limit:
            qd = qd * (p.joint_speed_limit / peak)
        # no joint past its limit by the end of the cycle (mean velocity over the ramp)
        q_end = self.q + 0.5 * (self.qd + qd) * T
        lim = p.joint_position_limit
        over = (q_end > lim) & (qd > 0.0) | (q_end < -lim) & (qd < 0.0)
        if over.any():
            qd = np.where(over, 0.0, qd)
        self.qdd = (qd - self.qd) / T
        self._ramp_left = T

    def advance(self, dt: float) -> None:
        """Integrate over dt: the cycle's constant joint acceleration until its ramp ends, then
        constant velocity (exact either way)."""
        ramp = min(dt, self._ramp_left)
        self.q = self.q + self.qd * dt + self.qdd * (0.5 * ramp * ramp + ramp * (dt - ramp))
        self.qd = self.qd + self.qdd * ramp
        self.qdd_mean = self.qdd * (ramp / dt)  # the mean over this step: what the tool felt
        self._ramp_left -= ramp
        if self._ramp_left <= 0.0:
            self.qdd = np.zeros(6)
