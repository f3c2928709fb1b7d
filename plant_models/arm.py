"""The UR5 following speedL commands, as the UR controller applies them.

Each robot cycle (125 Hz on a CB3, 500 Hz on an e-series):
1. latency: the command received during the previous cycle becomes the active one (one robot cycle
   of command latency on top of whatever the sender adds);
2. acceleration: the robot's own TCP twist moves towards the active command by at most a·T (linear)
   and a_rot·T (angular), speedL's `a` argument; a command to rest may carry its own, larger `a`
   (the controller's braking after a release), which travels with it through the latency;
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
from plant_models.kernels import KernelUR5, arm_advance, arm_cycle
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


def damped_least_squares(
    J: Vec, twist: Vec, threshold: float, max_damping: float, sigma_min: float | None = None
) -> Vec:
    """q̇ = Jᵀ(J Jᵀ + λ² I)⁻¹ ξ with λ² = (1 - (σ_min/ε)²) λ_max² below σ_min = ε, else 0
    (then it is the plain solution J⁻¹ξ of a square J).

    `sigma_min`: σ_min(J) when the caller has it, or any lower bound of it that is >= ε (then only
    the comparison with ε uses it); computed by SVD when None.
    """
    if sigma_min is None:
        sigma_min = float(np.linalg.svd(J, compute_uv=False)[-1])
    if sigma_min >= threshold and J.shape[0] == J.shape[1]:
        return np.linalg.solve(J, twist)
    lam2 = 0.0
    if sigma_min < threshold:
        lam2 = (1.0 - (sigma_min / threshold) ** 2) * max_damping**2
    return J.T @ np.linalg.solve(J @ J.T + lam2 * np.eye(J.shape[0]), twist)


def _step_towards(current: Vec, target: Vec, max_step_v: float, max_step_w: float) -> Vec:
    """The twist `target` if within reach of `current`, else `current` moved towards it by at most
    `max_step_v` in v and `max_step_w` in ω: current + δ · max_step/|δ| with δ = target - current."""
    delta = target - current
    d_v, d_w = delta[:3], delta[3:]
    n_v, n_w = math.sqrt(d_v.dot(d_v)), math.sqrt(d_w.dot(d_w))
    if n_v <= max_step_v and n_w <= max_step_w:
        return target
    c, d = current.tolist(), delta.tolist()
    v = target[:3] if n_v <= max_step_v else [c[i] + d[i] * (max_step_v / n_v) for i in range(3)]
    w = target[3:] if n_w <= max_step_w else [c[i] + d[i] * (max_step_w / n_w) for i in range(3, 6)]
    return np.concatenate((v, w))


_JOINTS = range(6)


class SpeedLArm:
    """Joint state of the UR5 under speedL; `cycle(command)` at each robot cycle, `advance(dt)`
    every tick in between.

    The joint state is kept in floats and published after every change as one new array `state`,
    [q; q̇; q̈_mean], of which `q`, `qd` and `qdd_mean` are views; a published array is never written.
    """

    # Headroom of the SVD-free test σ_min >= ε in `_joint_velocities`: far above the error of
    # LAPACK's singular values (a few ulp of σ_max) and of the distance's rounding
    _WEYL_MARGIN = 1e-9

    def __init__(self, params: ArmParams, model: UR5Model | KernelUR5, tcp: str = "tcp") -> None:
        self.params = params
        self.model = model
        self.tcp = tcp
        self.period = 1.0 / params.rate_hz
        # with compiled kinematics the cycle's arithmetic is compiled too (plant_models.kernels)
        self._compiled: Vec | None = None
        if isinstance(model, KernelUR5):
            T = self.period
            self._compiled = np.array(
                [
                    *(params.acceleration * T, params.angular_acceleration * T),
                    *(params.dls_threshold, params.dls_max_damping),
                    *(params.joint_speed_limit, params.joint_position_limit),
                    *(T, self._WEYL_MARGIN),
                ]
            )
        self.reset()

    def reset(self) -> None:
        self._q = self.params.q0.tolist()
        self._qd = [0.0] * 6
        self._qdd = [0.0] * 6  # the cycle's constant joint acceleration while its ramp lasts
        self._publish(self._qdd)
        self.qdd = np.zeros(6)
        self.robot_twist = np.zeros(6)  # the twist the robot is tracking, after the ramp
        self._queue = [(np.zeros(6), 0.0) for _ in range(self.params.latency_cycles)]
        self.active = np.zeros(6)
        self.active_brake = 0.0
        self._ramp_left = 0.0
        self._svd_at: tuple[Vec, float, float] | None = None  # (J, σ_min, σ_max) of the last SVD
        self._svd = np.zeros(39)  # the same for the compiled cycle: J (36), σ_min, σ_max, taken
        # (what the last computed cycle depended on, what it set)
        self._cycled: tuple[tuple[Any, ...], tuple[Any, ...]] | None = None

    def _publish(self, qdd_mean: list[float]) -> None:
        """New arrays for the joint state: those handed out before keep their values."""
        self.state = np.array(self._q + self._qd + qdd_mean)
        self.q, self.qd, self.qdd_mean = self.state[:6], self.state[6:12], self.state[12:]

    def cycle(self, command: Vec, brake_accel: float = 0.0) -> None:
        """A robot cycle starts: take the (delayed) command, ramp, solve for joint velocities.

        `brake_accel` [m/s²]: speedL's `a` for a command to rest (zero linear velocity), when it
        exceeds the arm's own `acceleration`; it never applies to a command away from rest."""
        p = self.params
        self._queue.append((np.array(command, dtype=np.float64), float(brake_accel)))
        active, brake = self._queue.pop(0)
        self.active, self.active_brake = active, brake
        T = self.period
        a = p.acceleration
        if brake > a and not active[:3].any():
            a = brake
        self._ramp_left = T
        # all the cycle depends on: the command, the twist tracked, q and q̇ (an arm holding still
        # gets the same cycle again)
        key = (active.tobytes(), self.robot_twist.tobytes(), self.state[:12].tobytes(), a)
        if self._cycled is not None and self._cycled[0] == key:
            self.robot_twist, self._qdd, self.qdd = self._cycled[1]
            return
        if self._compiled is not None:  # what follows, in one compiled call
            constants = self._compiled
            if a != p.acceleration:  # a brake to rest: its own a·T
                constants = constants.copy()
                constants[0] = a * T
            out = arm_cycle(
                self.model,
                self.tcp,
                self.state,
                active,
                self.robot_twist,
                self._svd,
                constants,
            )
            self.robot_twist, self.qdd = out[:6], out[6:]
            self._qdd = self.qdd.tolist()
            self._cycled = (key, (self.robot_twist, self._qdd, self.qdd))
            return
        self.robot_twist = _step_towards(
            self.robot_twist, active, a * T, p.angular_acceleration * T
        )
        J = self.model.jacobian(self.q, self.tcp)
        qd = self._joint_velocities(J, self.robot_twist).tolist()
        peak = max(map(abs, qd))
        if math.isnan(sum(qd)) and any(math.isnan(x) for x in qd):
            peak = math.nan  # as numpy's max (the builtin passes over a NaN after the first entry)
        if peak > p.joint_speed_limit:
            s = p.joint_speed_limit / peak
            qd = [x * s for x in qd]
        # no joint past its limit by the end of the cycle (mean velocity over the ramp)
        q, qd0, lim = self._q, self._qd, p.joint_position_limit
        q_end = [q[i] + 0.5 * (qd0[i] + qd[i]) * T for i in _JOINTS]
        qd = [
            0.0 if (q_end[i] > lim and qd[i] > 0.0) or (q_end[i] < -lim and qd[i] < 0.0) else qd[i]
            for i in _JOINTS
        ]
        self._qdd = [(qd[i] - qd0[i]) / T for i in _JOINTS]
        self.qdd = np.array(self._qdd)
        self._cycled = (key, (self.robot_twist, self._qdd, self.qdd))

    def _joint_velocities(self, J: Vec, twist: Vec) -> Vec:
        """`damped_least_squares`, without the SVD when Weyl's inequality already shows σ_min >= ε
        from the last SVD's J₀: σ_min(J) >= σ_min(J₀) - ‖J - J₀‖₂ >= σ_min(J₀) - ‖J - J₀‖_F (the same
        decision, so the same q̇)."""
        p = self.params
        if self._svd_at is not None and J.shape[0] == J.shape[1]:
            J0, sigma_min0, sigma_max0 = self._svd_at
            dJ = (J - J0).ravel()
            bound = sigma_min0 - math.sqrt(dJ.dot(dJ))
            if bound >= p.dls_threshold + self._WEYL_MARGIN * sigma_max0:
                return damped_least_squares(J, twist, p.dls_threshold, p.dls_max_damping, bound)
        sigma = np.linalg.svd(J, compute_uv=False)
        self._svd_at = (J, float(sigma[-1]), float(sigma[0]))
        return damped_least_squares(J, twist, p.dls_threshold, p.dls_max_damping, float(sigma[-1]))

    def advance(self, dt: float) -> None:
        """Integrate over dt: the cycle's constant joint acceleration until its ramp ends, then
        constant velocity (exact either way)."""
        ramp = min(dt, self._ramp_left)
        if self._compiled is not None:  # the same, on the state array (the lists are not kept)
            self.state = state = arm_advance(self.state, self.qdd, ramp, dt)
            self.q, self.qd, self.qdd_mean = state[:6], state[6:12], state[12:]
            self._ramp_left -= ramp
            if self._ramp_left <= 0.0:
                self._qdd = [0.0] * 6
                self.qdd = np.zeros(6)
            return
        c = 0.5 * ramp * ramp + ramp * (dt - ramp)
        q, qd, qdd = self._q, self._qd, self._qdd
        self._q = [q[i] + qd[i] * dt + qdd[i] * c for i in _JOINTS]
        self._qd = [qd[i] + qdd[i] * ramp for i in _JOINTS]
        # the mean over this step, what the tool felt: q̈ ramp/dt (q̈ itself when the ramp lasts)
        k = ramp / dt
        self._publish(qdd if ramp == dt else [a * k for a in qdd])
        self._ramp_left -= ramp
        if self._ramp_left <= 0.0:
            self._qdd = [0.0] * 6
            self.qdd = np.zeros(6)
