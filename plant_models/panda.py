"""A torque-controlled Franka Emika Panda holding the probe over the phantom (seed 001, sections 3, 6).

Figures:
- kinematics: Franka's modified Denavit–Hartenberg table (Craig's convention, the one Franka
  publishes for the Panda): a_{i-1}, d_i, α_{i-1} below, a flange 0.107 m beyond joint 7;
  joint position, speed and torque limits from Franka's datasheet;
- dynamics: the link masses, centres of mass and inertia tensors that Gaz, Cognetti, Oliva, Robuffo
  Giordano and De Luca identified ("Dynamic identification of the Franka Emika Panda robot with
  retrieval of feasible parameters using penalty-based optimization", IEEE RA-L 4(4), 2019), which
  the seed cites, each in its link's modified-DH frame, inertia about the centre of mass;
- friction: their sigmoid joint friction τ_f,i = φ1/(1 + exp(-φ2 (q̇ + φ3))) - φ1/(1 + exp(-φ2 φ3)).

The probe (ours, with the UR5 tool's figures): a 0.48 kg cylinder of 3 cm radius and 0.2 m along the
flange's z axis, its tip the TCP, with the flange's orientation.

The plant integrates the forward dynamics (pinocchio's ABA) with semi-implicit Euler, `substeps`
per millisecond whatever the master's step (default 2 x 0.5 ms; the seed simulated with 3 ms steps):

    B(q) q̈ + C(q, q̇) q̇ + τ_f(q̇) + g(q) = τ_cmd + g(q) + Jᵀ(q) F_contact

The robot compensates gravity itself, tool included, as Franka's controller does (the `+ g(q)` on
the right, seed 6.2); the commanded torque is clamped to the joint torque limits. Like libfranka's
model library, the robot reports its mass matrix, Coriolis vector, friction torque and TCP Jacobian
for the controller (seed 6.2: "robot inertia matrix B, Coriolis term C, friction term F, Jacobian").
"""

from __future__ import annotations

import functools
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from hoh_cosim.control.block import TWIST_UNITS, Port
from hoh_cosim.control.vectors import GRAVITY_B, Vec, Vec3, as_scalar, as_vector, frozen
from hoh_cosim.errors import ConfigError
from plant_models.tissue import PhantomParams, contact_force

__all__ = [
    "FRICTION",
    "INERTIAL",
    "MDH",
    "PANDA_READY_Q",
    "PandaParams",
    "PandaPlant",
    "friction_torque",
    "panda_urdf",
]

# (a_{i-1} [m], d_i [m], α_{i-1} [rad]) per joint, modified DH; then the flange
MDH: tuple[tuple[float, float, float], ...] = (
    (0.0, 0.333, 0.0),
    (0.0, 0.0, -math.pi / 2),
    (0.0, 0.316, math.pi / 2),
    (0.0825, 0.0, math.pi / 2),
    (-0.0825, 0.384, -math.pi / 2),
    (0.0, 0.0, math.pi / 2),
    (0.088, 0.0, math.pi / 2),
)
FLANGE_D = 0.107  # [m] along joint 7's axis
Q_MIN = (-2.8973, -1.7628, -2.8973, -3.0718, -2.8973, -0.0175, -2.8973)  # [rad]
Q_MAX = (2.8973, 1.7628, 2.8973, -0.0698, 2.8973, 3.7525, 2.8973)  # [rad]
QD_MAX = (2.175, 2.175, 2.175, 2.175, 2.61, 2.61, 2.61)  # [rad/s]
TAU_MAX = (87.0, 87.0, 87.0, 87.0, 12.0, 12.0, 12.0)  # [N·m]

# Gaz et al. 2019: mass [kg], centre of mass [m], inertia about it (Ixx, Iyy, Izz, Ixy, Iyz, Ixz)
INERTIAL: tuple[tuple[float, tuple[float, ...], tuple[float, ...]], ...] = (
    (4.970684, (3.875e-03, 2.081e-03, 0.0), (0.70337, 0.70661, 0.009117, -1.39e-04, 0.019169, 0.006772)),
    (0.646926, (-3.141e-03, -2.872e-02, 3.495e-03), (0.007962, 0.02811, 0.025995, -0.003925, 0.000704, 0.010254)),
    (3.228604, (2.7518e-02, 3.9252e-02, -6.6502e-02), (0.037242, 0.036155, 0.01083, -0.004761, -0.012805, -0.011396)),
    (3.587895, (-5.317e-02, 1.04419e-01, 2.7454e-02), (0.025853, 0.019552, 0.028323, 0.007796, 0.008641, -0.001332)),
    (1.225946, (-1.1953e-02, 4.1065e-02, -3.8437e-02), (0.035549, 0.029474, 0.008627, -0.002117, 0.000229, -0.004037)),
    (1.666555, (6.0149e-02, -1.4117e-02, -1.0517e-02), (0.001964, 0.004354, 0.005433, 0.000109, 0.000341, -0.001158)),
    (0.735522, (1.0517e-02, -4.252e-03, 6.1597e-02), (0.012516, 0.010027, 0.004815, -0.000428, -0.000741, -0.001196)),
)  # fmt: skip
# Gaz et al. 2019, sigmoid friction: φ1 [N·m], φ2 [s/rad], φ3 [rad/s] per joint
FRICTION = (
    (0.54615, 0.87224, 0.64068, 1.2794, 0.83904, 0.30301, 0.56489),
    (5.1181, 9.0657, 10.136, 5.5903, 8.3469, 17.133, 10.336),
    (0.039533, 0.025882, -0.04607, 0.036194, 0.026226, -0.021047, 0.0035526),
)
_PHI = np.array(FRICTION)
_FRICTION_OFFSET = _PHI[0] / (1.0 + np.exp(-_PHI[1] * _PHI[2]))

PANDA_READY_Q = frozen([0.0, -math.pi / 4, 0.0, -3 * math.pi / 4, 0.0, math.pi / 2, math.pi / 4])
"""Franka's "ready" pose: the flange points straight down, the arm well inside its limits."""

JOINT_NAMES = tuple(f"panda_joint{i}" for i in range(1, 8))


def friction_torque(qd: Vec) -> Vec:
    """The joint friction torques of Gaz et al. at joint speeds q̇ (zero at rest)."""
    return _PHI[0] / (1.0 + np.exp(-_PHI[1] * (qd + _PHI[2]))) - _FRICTION_OFFSET


def _xyz(values: Any) -> str:
    return " ".join(f"{float(v):.9g}" for v in values)


@functools.cache
def panda_urdf(tool_mass_kg: float, tool_com_m: float, tool_length_m: float) -> str:
    """The Panda as URDF from the tables above, with the probe fixed to the flange."""
    lines = ['<?xml version="1.0"?>', '<robot name="panda">', '  <link name="panda_link0"/>']
    parent = "panda_link0"
    for i, ((a, d, alpha), (mass, com, inertia)) in enumerate(zip(MDH, INERTIAL, strict=True)):
        link = f"panda_link{i + 1}"
        ixx, iyy, izz, ixy, iyz, ixz = inertia
        lines += [
            f'  <link name="{link}">',
            "    <inertial>",
            f'      <origin xyz="{_xyz(com)}" rpy="0 0 0"/>',
            f'      <mass value="{mass}"/>',
            f'      <inertia ixx="{ixx}" ixy="{ixy}" ixz="{ixz}" iyy="{iyy}" iyz="{iyz}" izz="{izz}"/>',
            "    </inertial>",
            "  </link>",
            f'  <joint name="{JOINT_NAMES[i]}" type="revolute">',
            f'    <parent link="{parent}"/>',
            f'    <child link="{link}"/>',
            # modified DH: Rx(α) Tx(a) Tz(d), then the joint turns about the new z
            f'    <origin xyz="{_xyz((a, -math.sin(alpha) * d, math.cos(alpha) * d))}" '
            f'rpy="{alpha:.17g} 0 0"/>',
            '    <axis xyz="0 0 1"/>',
            f'    <limit lower="{Q_MIN[i]}" upper="{Q_MAX[i]}" effort="{TAU_MAX[i]}" '
            f'velocity="{QD_MAX[i]}"/>',
            "  </joint>",
        ]
        parent = link
    r = 0.03
    i_t = tool_mass_kg * (3 * r * r + tool_length_m**2) / 12.0
    i_a = tool_mass_kg * r * r / 2.0
    lines += [
        '  <link name="probe">',
        "    <inertial>",
        f'      <origin xyz="0 0 {tool_com_m:.9g}" rpy="0 0 0"/>',
        f'      <mass value="{tool_mass_kg}"/>',
        f'      <inertia ixx="{i_t:.9g}" ixy="0" ixz="0" iyy="{i_t:.9g}" iyz="0" izz="{i_a:.9g}"/>',
        "    </inertial>",
        "  </link>",
        '  <joint name="panda_flange" type="fixed">',
        f'    <parent link="{parent}"/>',
        '    <child link="probe"/>',
        f'    <origin xyz="0 0 {FLANGE_D}" rpy="0 0 0"/>',
        "  </joint>",
        "</robot>",
    ]
    return "\n".join(lines) + "\n"


@dataclass(frozen=True)
class PandaParams:
    UNITS: ClassVar[dict[str, Any]] = {
        "q0": "rad",
        "qd0": "rad/s",
        "tool_mass_kg": "kg",
        "tool_com_m": "m",
        "tool_length_m": "m",
        "g_B": "m/s2",
        "substeps": "1",
    }
    TUNABLE: ClassVar[frozenset[str]] = frozenset({"phantom"})

    q0: Vec = field(default_factory=lambda: PANDA_READY_Q.copy())  # [rad]
    qd0: Vec = field(default_factory=lambda: frozen(np.zeros(7)))  # [rad/s] e.g. a self-motion
    tool_mass_kg: float = 0.48
    tool_com_m: float = 0.08  # [m] along the flange's z
    tool_length_m: float = 0.20  # [m] flange to tip
    friction: bool = True  # Gaz et al.'s joint friction
    gravity_compensation: bool = True  # the robot adds g(q) to the command, as Franka's does
    substeps: int = 2  # integration steps per millisecond (per 1 ms master step)
    phantom: PhantomParams = field(default_factory=PhantomParams)
    g_B: Vec3 = field(default_factory=lambda: GRAVITY_B.copy())  # [m/s²]

    def __post_init__(self) -> None:
        object.__setattr__(self, "q0", as_vector(self.q0, 7, "q0"))
        object.__setattr__(self, "qd0", as_vector(self.qd0, 7, "qd0"))
        object.__setattr__(self, "g_B", as_vector(self.g_B, 3, "g_B"))
        object.__setattr__(
            self, "tool_mass_kg", as_scalar(self.tool_mass_kg, "tool_mass_kg", low=0.0)
        )
        object.__setattr__(self, "tool_com_m", as_scalar(self.tool_com_m, "tool_com_m"))
        object.__setattr__(
            self,
            "tool_length_m",
            as_scalar(self.tool_length_m, "tool_length_m", low=0.0, low_open=True),
        )
        if not isinstance(self.substeps, int) or self.substeps < 1:
            raise ConfigError(f"substeps: expected an integer >= 1, got {self.substeps!r}")
        outside = [j for j, q in enumerate(self.q0) if not Q_MIN[j] <= q <= Q_MAX[j]]
        if outside:
            j = outside[0]
            raise ConfigError(
                f"q0: joint {j + 1} at {self.q0[j]:.4g} rad is outside [{Q_MIN[j]}, {Q_MAX[j]}]"
            )


class PandaPlant:
    """The Panda, the probe and the phantom under the block contract; torque in, state and model out.

    A step holds the commanded torque over [t, t + dt] and returns the state at t + dt.
    """

    variable_step: ClassVar[bool] = True  # `substeps` per millisecond whatever the step
    inputs: ClassVar[tuple[Port, ...]] = (
        Port("tau_cmd", 7, "N.m", "commanded joint torques, gravity excluded (the robot adds it)"),
    )
    outputs: ClassVar[tuple[Port, ...]] = (
        Port("q", 7, "rad", "joint positions"),
        Port("qd", 7, "rad/s", "joint velocities"),
        Port("tau_J", 7, "N.m", "joint torques applied: the clamped command plus gravity"),
        Port("p_BT_B", 3, "m", "TCP (probe tip) position in the base frame"),
        Port("R_BT", 9, "1", "TCP orientation in the base frame, row by row"),
        Port("twist_B", 6, TWIST_UNITS, "TCP twist [v; ω] in the base frame"),
        Port("B", 49, "1", "joint-space mass matrix B(q), row by row [kg·m², kg·m, kg]"),
        Port("C", 7, "N.m", "Coriolis and centrifugal torques C(q, q̇) q̇"),
        Port("F", 7, "N.m", "the friction model's torques at q̇"),
        Port("J", 42, "1", "TCP Jacobian of [v; ω] in the base frame, row by row [m, 1]"),
        Port("F_contact_B", 3, "N", "force of the phantom on the probe tip, in B"),
        Port("penetration", 1, "m", "depth of the tip in the phantom, > 0 in contact"),
    )

    def __init__(self, params: PandaParams | None = None) -> None:
        import pinocchio as pin  # a plant-only dependency, slow to import

        self.params = p = params or PandaParams()
        self.pin = pin
        self.model = pin.buildModelFromXML(
            panda_urdf(p.tool_mass_kg, p.tool_com_m, p.tool_length_m)
        )
        self.model.gravity.linear = np.asarray(p.g_B, dtype=float)
        probe = self.model.getFrameId("probe")
        frame = self.model.frames[probe]
        tip = pin.SE3(np.eye(3), np.array([0.0, 0.0, p.tool_length_m]))
        self.tcp = self.model.addFrame(
            pin.Frame(
                "tcp", frame.parentJoint, probe, frame.placement * tip, pin.FrameType.OP_FRAME
            )
        )
        self.data = self.model.createData()
        self._tau_max = np.array(TAU_MAX)
        self.reset()

    def reset(self) -> None:
        self.q = self.params.q0.copy()
        self.qd = self.params.qd0.copy()
        self._tau_cmd = np.zeros(7)  # the last command, clamped
        self._outputs = self._evaluate()

    def retune(self, params: PandaParams) -> None:
        """New parameters while running (only the phantom may change)."""
        self.params = params

    def initial_outputs(self) -> dict[str, Vec]:
        return self._outputs

    @property
    def outputs_now(self) -> dict[str, Vec]:
        return self._outputs

    def _contact(self) -> tuple[Vec3, float, Vec]:
        """The phantom's force on the tip, the depth, and the joint torques it makes (Jᵀ F)."""
        pin, m, d = self.pin, self.model, self.data
        pin.forwardKinematics(m, d, self.q, self.qd)
        pin.updateFramePlacements(m, d)
        p_tip = d.oMf[self.tcp].translation
        v_tip = pin.getFrameVelocity(m, d, self.tcp, pin.LOCAL_WORLD_ALIGNED).linear
        contact = contact_force(self.params.phantom, p_tip, v_tip)
        if contact.depth <= 0.0:
            return contact.force_B, contact.depth, np.zeros(7)
        J = pin.computeFrameJacobian(m, d, self.q, self.tcp, pin.LOCAL_WORLD_ALIGNED)
        return contact.force_B, contact.depth, J[:3].T @ contact.force_B

    def step(self, t: float, dt: float, inputs: Mapping[str, Vec]) -> dict[str, Vec]:
        p = self.params
        pin, m, d = self.pin, self.model, self.data
        tau_cmd = np.clip(inputs["tau_cmd"], -self._tau_max, self._tau_max)
        n = max(1, math.ceil(dt * 1e3 * p.substeps - 1e-9))  # a step of any length: the same h
        h = dt / n
        for _ in range(n):
            _, _, tau_contact = self._contact()
            tau = tau_cmd + tau_contact
            if p.gravity_compensation:
                tau = tau + pin.computeGeneralizedGravity(m, d, self.q)
            if p.friction:
                tau = tau - friction_torque(self.qd)
            qdd = pin.aba(m, d, self.q, self.qd, tau)
            self.qd = self.qd + h * qdd
            self.q = self.q + h * self.qd
        self._tau_cmd = tau_cmd
        self._outputs = self._evaluate()
        return self._outputs

    def _evaluate(self) -> dict[str, Vec]:
        pin, m, d = self.pin, self.model, self.data
        q, qd = self.q, self.qd
        force, depth, _ = self._contact()  # forward kinematics at (q, q̇) too
        H = d.oMf[self.tcp].homogeneous
        twist = pin.getFrameVelocity(m, d, self.tcp, pin.LOCAL_WORLD_ALIGNED).vector.copy()
        J = pin.computeFrameJacobian(m, d, q, self.tcp, pin.LOCAL_WORLD_ALIGNED)
        B = pin.crba(m, d, q)
        B = np.triu(B) + np.triu(B, 1).T  # crba fills the upper triangle
        gravity = pin.computeGeneralizedGravity(m, d, q)
        coriolis = pin.nonLinearEffects(m, d, q, qd) - gravity
        tau_J = self._tau_cmd + gravity if self.params.gravity_compensation else self._tau_cmd
        friction = friction_torque(qd) if self.params.friction else np.zeros(7)
        return {
            "q": q.copy(),
            "qd": qd.copy(),
            "tau_J": tau_J.copy(),
            "p_BT_B": H[:3, 3].copy(),
            "R_BT": H[:3, :3].reshape(9).copy(),
            "twist_B": twist,
            "B": B.reshape(49),
            "C": np.asarray(coriolis).copy(),
            "F": friction,
            "J": np.asarray(J).reshape(42).copy(),
            "F_contact_B": np.asarray(force, dtype=float).copy(),
            "penetration": np.array([depth if math.isfinite(depth) else -1.0]),
        }
