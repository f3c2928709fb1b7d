"""The plant block: the UR5 under speedL, the probe and its housing, and the phantom.

Inputs: the speedL twist command, the operator's wrench on the handle and a push directly on the
probe tip (how the seed collected its probe-sensor data, Fig. 6 and 14). Outputs: what the robot
reports (TCP pose and twist, joint positions), the wrist sensor's pose, and the ideal readings of both
force sensors plus the contact force itself (the sensor blocks add their imperfections).

The UR5 is position controlled and stiff: the hand and the phantom do not move it, they only load the
sensors. A step advances from t to t + dt with the inputs held, and returns the outputs at t + dt.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from hoh_cosim.control.block import TWIST_UNITS, WRENCH_UNITS, Port
from hoh_cosim.control.vectors import GRAVITY_B, Vec, Vec3, as_vector
from plant_models.arm import ArmParams, SpeedLArm
from plant_models.tissue import PhantomParams, contact_force
from plant_models.tool import ToolLoads, ToolModel
from plant_models.ur5 import FramePlacement, UR5Model

__all__ = ["Plant", "PlantParams"]


@dataclass(frozen=True)
class PlantParams:
    UNITS: ClassVar[dict[str, Any]] = {"g_B": "m/s2"}
    TUNABLE: ClassVar[frozenset[str]] = frozenset({"phantom"})  # e.g. move the phantom

    arm: ArmParams = field(default_factory=ArmParams)
    tool: ToolModel = field(default_factory=ToolModel)
    phantom: PhantomParams = field(default_factory=PhantomParams)
    g_B: Vec3 = field(default_factory=lambda: GRAVITY_B.copy())  # [m/s²]

    def __post_init__(self) -> None:
        object.__setattr__(self, "g_B", as_vector(self.g_B, 3, "g_B"))


class Plant:
    """UR5 + tool + phantom under the block contract."""

    variable_step: ClassVar[bool] = True  # every robot cycle that starts within a step
    inputs: ClassVar[tuple[Port, ...]] = (
        Port("twist_cmd_B", 6, TWIST_UNITS, "speedL command: TCP twist [v; ω] in the base frame"),
        Port("F_hand_B", 3, "N", "force of the hand on the handle, in B"),
        Port("tau_hand_B", 3, "N.m", "torque of the hand on the handle (about the handle), in B"),
        Port(
            "F_tip_B", 3, "N", "force of a hand directly on the probe tip (below its sensor), in B"
        ),
    )
    outputs: ClassVar[tuple[Port, ...]] = (
        Port("p_BT_B", 3, "m", "TCP (probe tip) position in the base frame"),
        Port("R_BT", 9, "1", "TCP orientation in the base frame, row by row"),
        Port("twist_B", 6, TWIST_UNITS, "actual TCP twist [v; ω] in the base frame"),
        Port("q", 6, "rad", "joint positions"),
        Port("qd", 6, "rad/s", "joint velocities"),
        Port("p_BS_B", 3, "m", "wrist sensor position in the base frame"),
        Port("R_BS", 9, "1", "wrist sensor orientation in the base frame, row by row"),
        Port("wrench_S", 6, WRENCH_UNITS, "true wrench of the tool on the wrist sensor, in S"),
        Port("force_P", 3, "N", "true force of the probe on the probe sensor, in P"),
        Port("F_contact_B", 3, "N", "force of the phantom on the probe tip, in B"),
        Port("penetration", 1, "m", "depth of the tip in the phantom, > 0 in contact"),
    )

    def __init__(self, params: PlantParams | None = None) -> None:
        self.params = p = params or PlantParams()
        frames = tuple(
            FramePlacement(name, p_EX_E, R_EX)
            for name, (p_EX_E, R_EX) in p.tool.flange_frames().items()
        )
        self.model = UR5Model(frames)
        self.arm = SpeedLArm(p.arm, self.model)
        self._loads = ToolLoads(p.tool, p.g_B)
        self.reset()

    def reset(self) -> None:
        self.arm.reset()
        self._cycle = -1
        self._outputs = self._evaluate(np.zeros(3), np.zeros(3), np.zeros(3))

    def retune(self, params: PlantParams) -> None:
        """New parameters while running (only the phantom may change)."""
        self.params = params

    def initial_outputs(self) -> dict[str, Vec]:
        """The outputs at t = 0, before any step: the arm at rest at q0."""
        return self._outputs

    def step(self, t: float, dt: float, inputs: Mapping[str, Vec]) -> dict[str, Vec]:
        # every robot cycle that starts within the step, with the command held over the step: a
        # step of any length gives what steps of 1 ms give
        arm, left = self.arm, dt
        while True:
            cycle = math.floor(t / arm.period + 1e-9)
            if cycle != self._cycle:
                self._cycle = cycle
                arm.cycle(inputs["twist_cmd_B"])
            boundary = (cycle + 1) * arm.period
            if boundary >= t + left - 1e-9 * arm.period:  # the same tolerance as the floor's
                arm.advance(left)
                break
            arm.advance(boundary - t)
            left, t = t + left - boundary, boundary
        self._outputs = self._evaluate(inputs["F_hand_B"], inputs["tau_hand_B"], inputs["F_tip_B"])
        return self._outputs

    @property
    def outputs_now(self) -> dict[str, Vec]:
        """The outputs at the current time (after reset: at t = 0), without stepping."""
        return self._outputs

    def _evaluate(self, F_hand_B: Vec3, tau_hand_B: Vec3, F_tip_B: Vec3) -> dict[str, Vec]:
        p = self.params
        m = self.model
        arm = self.arm
        m.update(arm.q, arm.qd, arm.qdd_mean)
        p_BT, R_BT = m.placement("tcp")
        p_BS, R_BS = m.placement("ft_sensor")
        twist = m.twist("tcp")
        contact = contact_force(p.phantom, p_BT, twist[:3])
        acc_C = m.acceleration("tool_com")
        omega = twist[3:]
        p_BK = p_BS + R_BS @ p.tool.cable.p_SK_S if p.tool.cable.enabled else None
        a_P = m.acceleration("probe_sensor")[:3] if p.tool.probe_mass_kg > 0.0 else None
        # a push on the tip loads both sensors as a contact does
        wrench_S, force_P = self._loads.readings(
            R_BS,
            acc_C[:3],
            omega,
            acc_C[3:],
            F_hand_B,
            tau_hand_B,
            contact.force_B + F_tip_B,
            p_BK,
            a_P,
        )
        return {
            "p_BT_B": p_BT,
            "R_BT": R_BT.reshape(9),
            "twist_B": twist,
            "q": arm.q,
            "qd": arm.qd,
            "p_BS_B": p_BS,
            "R_BS": R_BS.reshape(9),
            "wrench_S": wrench_S,
            "force_P": force_P,
            "F_contact_B": contact.force_B,
            "penetration": np.array([contact.depth if math.isfinite(contact.depth) else -1.0]),
        }
