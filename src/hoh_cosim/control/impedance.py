"""Tele-echography: Cartesian impedance on a torque-controlled arm, and its position-based twin.

`CartesianImpedance` is seed 001's controller (sections 3 and 6.2) for a 7-joint torque-controlled arm:
the inverse-dynamics law u = B(q) y + n(q, q̇) (eq. 3) with

    y = J_A⁺ (ẍ̃_d + D x̃̇ + K x̃ - J̇_A q̇)                                     (eq. 5, M_d = I)

where the pose error is taken in the desired frame d (eq. 10-12): R_e^d = R_dᵀ R_e, o_{d,e}^d =
R_dᵀ (o_e - o_d), x̃ = -[o_{d,e}^d; φ_{d,e}] with φ the roll-pitch-yaw angles of R_e^d (R = Rz(ψ)
Ry(θ) Rx(φ), regular at R = I where the probe works; ZYZ angles would be singular there), and the
analytic Jacobian of eq. 13-14, J_A = T_A⁻¹(φ) diag(R_dᵀ, R_dᵀ) J(q). J̇_A is the difference of
successive J_A over the step, as the seed's code does. The robot compensates gravity itself; the law
adds the Coriolis and friction torques the robot's model reports, and damps the redundant joint's
self-motion in the null space of the task (eq. 15):

    τ_r = -(I - J_Aᵀ J̄ᵀ) B D_n q̇,   J̄ᵀ = (J_A B⁻¹ J_Aᵀ)⁻¹ J_A B⁻¹   (dynamically consistent)

Start-up (6.2): until the task starts the command is zero (the robot holds itself against gravity)
while τ_d0 follows τ_d; from then on τ_cmd = τ_d - τ_d0 exp(-μ (t - t_start)), μ = 4 s⁻¹ as in the
code the seed built on.

`PositionImpedance` renders the translational impedance M ẍ_c + D (ẋ_c - ẋ_d) + K (x_c - x_d) =
F_ext on a velocity-commanded arm (the UR5 under speedL): it integrates the compliant frame x_c from
the measured contact force and servoes the tip to it, holding the start orientation.

Both follow `SlideTask`, the seed's reference: from `approach_start_s` the z reference drops by
`depth_m` (0.0754 m in the seed's code), from `slide_start_s` y follows `amplitude_m` sin(2π f t)
(0.05 m, 0.3 Hz). The seed started both at once; a later slide lets the approach settle first.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from hoh_cosim.control.block import TWIST_UNITS, Port
from hoh_cosim.control.frames import matrix_to_rotvec
from hoh_cosim.control.vectors import (
    Rot3,
    Vec,
    Vec3,
    as_nonnegative_vector,
    as_positive_vector,
    as_scalar,
    as_unit_vector,
    frozen,
)

__all__ = [
    "CartesianImpedance",
    "ImpedanceParams",
    "PositionImpedance",
    "PositionImpedanceParams",
    "SlideTask",
    "rpy_angles",
    "rpy_rate_matrix",
]

_POSE_UNITS = ("m",) * 3 + ("rad",) * 3


@dataclass(frozen=True)
class SlideTask:
    """The reference: press `depth_m` below the start, then slide sinusoidally along `axis_B`."""

    UNITS: ClassVar[dict[str, Any]] = {
        "approach_start_s": "s",
        "slide_start_s": "s",
        "depth_m": "m",
        "amplitude_m": "m",
        "frequency_hz": "Hz",
        "axis_B": "1",
    }

    approach_start_s: float = 0.5  # [s] the seed's delay before the trajectory
    slide_start_s: float = 0.5  # [s] the seed slid from the same instant
    depth_m: float = 0.0754  # [m] z reference below the start (seed 6.2: 7.5446e-02)
    amplitude_m: float = 0.05  # [m]
    frequency_hz: float = 0.3  # [Hz]
    axis_B: Vec3 = field(default_factory=lambda: frozen([0.0, 1.0, 0.0]))  # the slide's direction

    def __post_init__(self) -> None:
        for name in ("approach_start_s", "depth_m", "amplitude_m", "frequency_hz"):
            object.__setattr__(self, name, as_scalar(getattr(self, name), name, low=0.0))
        object.__setattr__(
            self,
            "slide_start_s",
            as_scalar(self.slide_start_s, "slide_start_s", low=self.approach_start_s),
        )
        object.__setattr__(self, "axis_B", as_unit_vector(self.axis_B, "axis_B"))

    def reference(self, t: float, p_start: Vec3) -> tuple[Vec3, Vec3, Vec3]:
        """Desired tip position, velocity and acceleration at t, in B."""
        p = p_start.copy()
        v, a = np.zeros(3), np.zeros(3)
        if t >= self.approach_start_s:
            p[2] -= self.depth_m
        if t >= self.slide_start_s:
            w = 2.0 * math.pi * self.frequency_hz
            s = t - self.slide_start_s
            p += self.axis_B * (self.amplitude_m * math.sin(w * s))
            v += self.axis_B * (self.amplitude_m * w * math.cos(w * s))
            a -= self.axis_B * (self.amplitude_m * w * w * math.sin(w * s))
        return p, v, a


def rpy_angles(R: Rot3) -> Vec3:
    """(φ, θ, ψ) with R = Rz(ψ) Ry(θ) Rx(φ)."""
    return np.array(
        [
            math.atan2(R[2, 1], R[2, 2]),
            math.atan2(-R[2, 0], math.hypot(R[0, 0], R[1, 0])),
            math.atan2(R[1, 0], R[0, 0]),
        ]
    )


def rpy_rate_matrix(rpy: Vec3) -> np.ndarray:
    """T(φ) with ω = T(φ) φ̇ for roll-pitch-yaw angles, ω in the fixed frame (singular at θ = ±π/2)."""
    _, theta, psi = rpy
    ct, st, cp, sp = math.cos(theta), math.sin(theta), math.cos(psi), math.sin(psi)
    return np.array([[cp * ct, -sp, 0.0], [sp * ct, cp, 0.0], [-st, 0.0, 1.0]])


@dataclass(frozen=True)
class ImpedanceParams:
    UNITS: ClassVar[dict[str, Any]] = {
        "K": ("1/s2",) * 6,
        "D": ("1/s",) * 6,
        "null_damping": "1/s",
        "mu": "1/s",
    }
    TUNABLE: ClassVar[frozenset[str]] = frozenset({"K", "D", "null_damping"})

    # seed 001, 6.2: K = diag(50², 50², 10², 50², 20², 20²), D = diag(2·50, 2·50, 2·50, 2·20, ...)
    K: Vec = field(default_factory=lambda: frozen([2500.0, 2500.0, 100.0, 2500.0, 400.0, 400.0]))
    D: Vec = field(default_factory=lambda: frozen([100.0, 100.0, 100.0, 40.0, 40.0, 40.0]))
    null_damping: float = 100.0  # D_n of eq. 15
    mu: float = 4.0  # start-up blend rate
    task: SlideTask = field(default_factory=SlideTask)

    def __post_init__(self) -> None:
        object.__setattr__(self, "K", as_nonnegative_vector(self.K, 6, "K"))
        object.__setattr__(self, "D", as_nonnegative_vector(self.D, 6, "D"))
        object.__setattr__(
            self, "null_damping", as_scalar(self.null_damping, "null_damping", low=0.0)
        )
        object.__setattr__(self, "mu", as_scalar(self.mu, "mu", low=0.0))


def _pose_error(p: Vec3, R: Rot3, p_d: Vec3, R_d: Rot3) -> tuple[Vec, Vec3]:
    """x_e = [o_{d,e}^d; φ_{d,e}] (eq. 11-12; x̃ = -x_e) and the roll-pitch-yaw angles."""
    rpy = rpy_angles(R_d.T @ R)
    return np.concatenate([R_d.T @ (p - p_d), rpy]), rpy


def _error_outputs(x_e: Vec, p_d: Vec3) -> dict[str, Vec]:
    return {
        "pose_error": x_e,
        "pose_error_norm": np.array([np.linalg.norm(x_e[:3]), np.linalg.norm(x_e[3:])]),
        "p_ref_B": p_d,
    }


_ERROR_PORTS = (
    Port("pose_error", 6, _POSE_UNITS, "tip pose in the desired frame: position, roll-pitch-yaw"),
    Port("pose_error_norm", 2, ("m", "rad"), "norms of the position and orientation errors"),
    Port("p_ref_B", 3, "m", "desired tip position in the base frame"),
)


class CartesianImpedance:
    """Seed 001's impedance controller for a 7-joint torque-controlled arm (module docstring)."""

    inputs: ClassVar[tuple[Port, ...]] = (
        Port("qd", 7, "rad/s", "joint velocities"),
        Port("B", 49, "1", "joint-space mass matrix, row by row"),
        Port("C", 7, "N.m", "Coriolis and centrifugal torques C(q, q̇) q̇"),
        Port("F", 7, "N.m", "friction torques"),
        Port("J", 42, "1", "TCP Jacobian of [v; ω] in the base frame, row by row"),
        Port("p_BT_B", 3, "m", "TCP position in the base frame"),
        Port("R_BT", 9, "1", "TCP orientation in the base frame, row by row"),
    )
    outputs: ClassVar[tuple[Port, ...]] = (
        Port("tau_cmd", 7, "N.m", "commanded joint torques (the robot adds gravity)"),
        *_ERROR_PORTS,
    )

    def __init__(self, params: ImpedanceParams | None = None) -> None:
        self.params = params or ImpedanceParams()
        self.reset()

    def reset(self) -> None:
        self._start: tuple[Vec3, Rot3] | None = None
        self._Ja_old: np.ndarray | None = None
        self._t_old = 0.0
        self._tau_d0 = np.zeros(7)

    def retune(self, params: ImpedanceParams) -> None:
        self.params = params

    def step(self, t: float, dt: float, inputs: Mapping[str, Vec]) -> dict[str, Vec]:
        p = self.params
        qd = inputs["qd"]
        B = inputs["B"].reshape(7, 7)
        J = inputs["J"].reshape(6, 7)
        p_e, R_e = inputs["p_BT_B"], inputs["R_BT"].reshape(3, 3)
        if self._start is None:  # the desired frame starts where the robot is (fMed0 = fMe)
            self._start = (p_e.copy(), R_e.copy())
        p_start, R_d = self._start
        p_d, v_d, a_d = p.task.reference(t, p_start)

        x_e, rpy = _pose_error(p_e, R_e, p_d, R_d)
        T_inv = np.linalg.inv(rpy_rate_matrix(rpy))
        to_d = np.zeros((6, 6))
        to_d[:3, :3] = R_d.T
        to_d[3:, 3:] = T_inv @ R_d.T  # T_A⁻¹ diag(R_dᵀ, R_dᵀ)
        Ja = to_d @ J  # eq. 14
        xd_tilde = to_d @ (np.concatenate([v_d, np.zeros(3)]) - J @ qd)  # eq. 13
        dJa = np.zeros((6, 7))
        if self._Ja_old is not None and t > self._t_old:
            dJa = (Ja - self._Ja_old) / (t - self._t_old)
        self._Ja_old, self._t_old = Ja, t
        acc_d = to_d @ np.concatenate([a_d, np.zeros(3)])

        y = np.linalg.pinv(Ja) @ (acc_d + p.D * xd_tilde - p.K * x_e - dJa @ qd)  # eq. 5
        L = np.linalg.cholesky(B)
        B_inv_JaT = np.linalg.solve(L.T, np.linalg.solve(L, Ja.T))
        Jbar_T = np.linalg.solve(Ja @ B_inv_JaT, B_inv_JaT.T)  # (J_A B⁻¹ J_Aᵀ)⁻¹ J_A B⁻¹
        tau_r = -(np.eye(7) - Ja.T @ Jbar_T) @ (B @ qd) * p.null_damping  # eq. 15
        tau_d = B @ y + inputs["C"] + inputs["F"] + tau_r  # eq. 3, gravity in the robot

        if t < p.task.approach_start_s:  # wait: the robot holds itself; remember τ_d
            self._tau_d0 = tau_d
            tau_cmd = np.zeros(7)
        else:
            tau_cmd = tau_d - self._tau_d0 * math.exp(-p.mu * (t - p.task.approach_start_s))
        return {"tau_cmd": tau_cmd, **_error_outputs(x_e, p_d)}


@dataclass(frozen=True)
class PositionImpedanceParams:
    UNITS: ClassVar[dict[str, Any]] = {
        "M": "kg",
        "K": "N/m",
        "D": "N.s/m",
        "tracking_gain": "1/s",
        "orientation_gain": "1/s",
        "max_speed": "m/s",
    }
    TUNABLE: ClassVar[frozenset[str]] = frozenset({"M", "K", "D"})

    # the translational part of the seed's gains, with the unit mass its law implies (M_d = I)
    M: Vec3 = field(default_factory=lambda: frozen([1.0, 1.0, 1.0]))  # [kg]
    K: Vec3 = field(default_factory=lambda: frozen([2500.0, 2500.0, 100.0]))  # [N/m]
    D: Vec3 = field(default_factory=lambda: frozen([100.0, 100.0, 100.0]))  # [N·s/m]
    tracking_gain: float = 20.0  # [1/s] tip towards the compliant frame
    orientation_gain: float = 5.0  # [1/s] tip orientation towards the start's
    max_speed: float = 0.25  # [m/s] the command's linear speed, clamped
    task: SlideTask = field(default_factory=SlideTask)

    def __post_init__(self) -> None:
        object.__setattr__(self, "M", as_positive_vector(self.M, 3, "M"))
        object.__setattr__(self, "K", as_nonnegative_vector(self.K, 3, "K"))
        object.__setattr__(self, "D", as_nonnegative_vector(self.D, 3, "D"))
        for name in ("tracking_gain", "orientation_gain", "max_speed"):
            object.__setattr__(
                self, name, as_scalar(getattr(self, name), name, low=0.0, low_open=True)
            )


class PositionImpedance:
    """Impedance by admittance on a velocity-commanded arm (module docstring)."""

    inputs: ClassVar[tuple[Port, ...]] = (
        Port("p_BT_B", 3, "m", "TCP position in the base frame"),
        Port("R_BT", 9, "1", "TCP orientation in the base frame, row by row"),
        Port("F_ext_B", 3, "N", "measured force of the environment on the probe, in B"),
        Port("ready", 1, "1", "1 once the force measurement is valid"),
    )
    outputs: ClassVar[tuple[Port, ...]] = (
        Port("twist_B", 6, TWIST_UNITS, "speedL command [v; ω] in the base frame"),
        *_ERROR_PORTS,
    )

    def __init__(self, params: PositionImpedanceParams | None = None) -> None:
        self.params = params or PositionImpedanceParams()
        self.reset()

    def reset(self) -> None:
        self._start: tuple[Vec3, Rot3] | None = None
        self._x_c = np.zeros(3)
        self._v_c = np.zeros(3)
        self._active = False

    def retune(self, params: PositionImpedanceParams) -> None:
        self.params = params

    def step(self, t: float, dt: float, inputs: Mapping[str, Vec]) -> dict[str, Vec]:
        p = self.params
        p_e, R_e = inputs["p_BT_B"], inputs["R_BT"].reshape(3, 3)
        if self._start is None:
            self._start = (p_e.copy(), R_e.copy())
            self._x_c = p_e.copy()
        p_start, R_d = self._start
        p_d, v_d, a_d = p.task.reference(t, p_start)
        ready = inputs["ready"][0] > 0.5
        if not self._active and ready and t >= p.task.approach_start_s:
            self._active = True
        if self._active:  # M ẍ_c + D (ẋ_c - ẋ_d) + K (x_c - x_d) = F_ext, semi-implicit Euler
            F = inputs["F_ext_B"] if ready else np.zeros(3)
            acc = a_d + (F - p.D * (self._v_c - v_d) - p.K * (self._x_c - p_d)) / p.M
            self._v_c = self._v_c + dt * acc
            self._x_c = self._x_c + dt * self._v_c
        v = self._v_c + p.tracking_gain * (self._x_c - p_e)
        speed = float(np.linalg.norm(v))
        if speed > p.max_speed:
            v *= p.max_speed / speed
        w = p.orientation_gain * matrix_to_rotvec(R_d @ R_e.T)
        x_e, _ = _pose_error(p_e, R_e, p_d if self._active else p_start, R_d)
        return {
            "twist_B": np.concatenate([v, w]),
            **_error_outputs(x_e, p_d if self._active else p_start),
        }
