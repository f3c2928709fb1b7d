"""The plant block: the UR5 under speedL, the probe and its housing, and the phantom.

Inputs: the speedL twist command, the operator's wrench on the handle and a push directly on the
probe tip (how the seed collected its probe-sensor data, Fig. 6 and 14), and the phantom surface's
displacement along its normal and its rate (breathing, `plant_models.breathing`; optional: a caller
that does not give them, as every scenario without breathing, has a still surface). Outputs: what the robot
reports (TCP pose and twist, joint positions), the wrist sensor's pose, and the ideal readings of both
force sensors plus the contact force itself (the sensor blocks add their imperfections).

The UR5 is position controlled and stiff: the hand and the phantom do not move it, they only load the
sensors. A step advances from t to t + dt with the inputs held, and returns the outputs at t + dt.
The outputs are a function of the arm's state and the loads: an arm holding still under the same
loads gets the same arrays again, and the same kinematics under other loads.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from hoh_cosim.control.block import TWIST_UNITS, WRENCH_UNITS, Port
from hoh_cosim.control.vectors import GRAVITY_B, Vec, Vec3, as_vector, frozen
from plant_models.arm import ArmParams, SpeedLArm
from plant_models.kernels import (
    KernelUR5,
    contact_loads,
    kernels_enabled,
    loads_constants,
    phantom_constants,
)
from plant_models.tissue import PhantomParams, contact_force
from plant_models.tool import ToolLoads, ToolModel
from plant_models.ur5 import FramePlacement, UR5Model

__all__ = ["Plant", "PlantParams"]

# entries of a raveled 4x4 [[R_BX, p_BX_B], [0, 1]]: p_BX_B, then R_BX row by row
_POSE_ENTRIES = np.array([3, 7, 11, 0, 1, 2, 4, 5, 6, 8, 9, 10])
_STILL = frozen([0.0])  # the surface's offset and rate when no breathing is connected


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
        Port(
            "brake_accel",
            1,
            "m/s2",
            "speedL's acceleration for a command to rest, if above the arm's own (0: the arm's)",
        ),
        Port("F_hand_B", 3, "N", "force of the hand on the handle, in B"),
        Port("tau_hand_B", 3, "N.m", "torque of the hand on the handle (about the handle), in B"),
        Port(
            "F_tip_B", 3, "N", "force of a hand directly on the probe tip (below its sensor), in B"
        ),
        Port(
            "surface_offset_m",
            1,
            "m",
            "displacement of the phantom's surface along its outward normal (breathing), 0 at rest",
        ),
        Port("surface_rate_m_s", 1, "m/s", "rate of the surface's displacement"),
    )
    OPTIONAL_INPUTS: ClassVar[frozenset[str]] = frozenset(
        {"brake_accel", "surface_offset_m", "surface_rate_m_s"}
    )
    """Inputs that may be left unconnected: 0 then (no braking command: speedL's own acceleration;
    a phantom that does not breathe)."""
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
        # the kinematics compiled (plant_models.kernels), from the pinocchio model's placements;
        # pinocchio stays the reference they are checked against. Where it is not installed (an
        # FMU's host), the kernels' own geometry of the same chain (`ur5.chain_geometry`), compiled
        # where numba is installed, else plain Python
        try:
            self.model: UR5Model | None = UR5Model(frames)
        except ImportError:
            self.model = None
        if self.model is None:
            self._kernel: KernelUR5 | None = KernelUR5(None, frames)
        else:
            self._kernel = KernelUR5(self.model) if kernels_enabled() else None
        if self._kernel is not None and kernels_enabled():
            self._kernel.warm_up()
        self.arm = SpeedLArm(p.arm, self._kernel or self.model)  # type: ignore[arg-type]
        self._loads = ToolLoads(p.tool, p.g_B)
        self._loads_constants = loads_constants(p.tool, p.g_B)
        self.reset()

    def reset(self) -> None:
        self.arm.reset()
        self._cycle = -1
        self._params_changed()
        self._evaluate(np.zeros(3), np.zeros(3), np.zeros(3), _STILL, _STILL)

    def _params_changed(self) -> None:
        """Take what the evaluation needs from the parameters, and forget the last evaluation."""
        tool = self.params.tool
        self._p_SK_S = tool.cable.p_SK_S if tool.cable.enabled else None
        self._probe_mass = tool.probe_mass_kg > 0.0
        self._phantom = phantom_constants(self.params.phantom)
        # what the last evaluation was of: the arm's state (bytes of `arm.state`) and the loads
        self._kinematics_at: tuple[bytes, tuple[Any, ...]] | None = None
        self._evaluated_at: tuple[bytes, ...] | None = None

    def retune(self, params: PlantParams) -> None:
        """New parameters while running (only the phantom may change)."""
        self.params = params
        self._params_changed()

    def initial_outputs(self) -> dict[str, Vec]:
        """The outputs at t = 0, before any step: the arm at rest at q0."""
        return self._outputs

    def step(self, t: float, dt: float, inputs: Mapping[str, Vec]) -> dict[str, Vec]:
        # every robot cycle that starts within the step, with the command held over the step: a
        # step of any length gives what steps of 1 ms give
        arm, left = self.arm, dt
        period = arm.period
        while True:
            cycle = math.floor(t / period + 1e-9)
            if cycle != self._cycle:
                self._cycle = cycle
                brake = inputs.get("brake_accel")
                arm.cycle(inputs["twist_cmd_B"], 0.0 if brake is None else float(brake[0]))
            boundary = (cycle + 1) * period
            if boundary >= t + left - 1e-9 * period:  # the same tolerance as the floor's
                arm.advance(left)
                break
            arm.advance(boundary - t)
            left, t = t + left - boundary, boundary
        return self._evaluate(
            inputs["F_hand_B"],
            inputs["tau_hand_B"],
            inputs["F_tip_B"],
            inputs.get("surface_offset_m", _STILL),
            inputs.get("surface_rate_m_s", _STILL),
        )

    @property
    def outputs_now(self) -> dict[str, Vec]:
        """The outputs at the current time (after reset: at t = 0), without stepping."""
        return self._outputs

    def _kinematics(self, state: bytes) -> tuple[Any, ...]:
        """What the tool's frames do at the arm's state `state` (the bytes of `arm.state`):
        (p_BT_B, R_BT row by row, twist_B, p_BS_B, R_BS row by row, R_BS, [a_C; α] of the tool's
        centre of mass, ω, p_BK_B or None, a_P_B or None), in B. Computed once per state: an arm at
        rest keeps its arrays (the block contract lets a block return the same arrays again)."""
        at = self._kinematics_at
        if at is not None and at[0] == state:
            return at[1]
        arm = self.arm
        m = self.model
        if self._kernel is not None:  # the same quantities in one compiled call
            k = self._k = self._kernel.tool_kinematics_at(arm.state)
            pose_T, pose_S, twist = k[:12], k[12:24], k[24:30]
            a_C = k[30:36].tolist()
            a_P = k[36:39]
        else:
            m.update(arm.q, arm.qd, arm.qdd_mean)
            pose_T = m.homogeneous("tcp").take(_POSE_ENTRIES)  # [p_BT_B; R_BT]
            pose_S = m.homogeneous("ft_sensor").take(_POSE_ENTRIES)
            twist = m.twist("tcp")
            a_C = m.acceleration("tool_com").tolist()  # [a_C; α]
            a_P = m.acceleration("probe_sensor")[:3] if self._probe_mass else None
        p_BS, R_BS_rows = pose_S[:3], pose_S[3:]
        R_BS = R_BS_rows.reshape(3, 3)
        kinematics = (
            pose_T[:3],
            pose_T[3:],
            twist,
            p_BS,
            R_BS_rows,
            R_BS,
            a_C,
            twist[3:].tolist(),  # ω
            None if self._p_SK_S is None else p_BS + R_BS @ self._p_SK_S,  # p_BK
            a_P if self._probe_mass else None,
        )
        self._kinematics_at = (state, kinematics)
        return kinematics

    def _evaluate(
        self, F_hand_B: Vec3, tau_hand_B: Vec3, F_tip_B: Vec3, offset: Vec, offset_rate: Vec
    ) -> dict[str, Vec]:
        """The outputs at the arm's state under these loads, kept in `_outputs`; the same state and
        loads as the last evaluation give the same arrays again, in a new dict."""
        key = (
            self.arm.state.tobytes(),
            F_hand_B.tobytes(),
            tau_hand_B.tobytes(),
            F_tip_B.tobytes(),
            offset.tobytes(),
            offset_rate.tobytes(),
        )
        if key == self._evaluated_at:
            return dict(self._outputs)
        kinematics = self._kinematics(key[0])
        p_BT, R_BT, twist, p_BS, R_BS_rows, R_BS, a_C, omega, p_BK, a_P = kinematics
        # a push on the tip loads both sensors as a contact does
        if self._kernel is not None:  # the contact and ToolLoads.readings, compiled
            loads = contact_loads(
                self._loads_constants,
                self._k,
                self._phantom,
                F_hand_B,
                tau_hand_B,
                F_tip_B,
                offset,
                offset_rate,
            )
            wrench_S, force_P, F_contact, penetration = (
                loads[:6],
                loads[6:9],
                loads[9:12],
                loads[12:],
            )
        else:
            contact = contact_force(
                self.params.phantom, p_BT, twist[:3], float(offset[0]), float(offset_rate[0])
            )
            c0, c1, c2 = contact.force_B.tolist()
            t0, t1, t2 = F_tip_B.tolist()
            wrench_S, force_P = self._loads.readings(
                R_BS,
                a_C[:3],
                omega,
                a_C[3:],
                F_hand_B.tolist(),
                tau_hand_B.tolist(),
                [c0 + t0, c1 + t1, c2 + t2],
                p_BK,
                a_P,
            )
            F_contact = contact.force_B
            depth = contact.depth
            penetration = np.array([depth if math.isfinite(depth) else -1.0])
        self._evaluated_at = key
        self._outputs = {
            "p_BT_B": p_BT,
            "R_BT": R_BT,
            "twist_B": twist,
            "q": self.arm.q,
            "qd": self.arm.qd,
            "p_BS_B": p_BS,
            "R_BS": R_BS_rows,
            "wrench_S": wrench_S,
            "force_P": force_P,
            "F_contact_B": F_contact,
            "penetration": penetration,
        }
        return self._outputs
