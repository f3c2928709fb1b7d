"""The UR5 arm: its published kinematic and inertial figures, a URDF written from them, and a
pinocchio model with the tool's frames.

Figures (Universal Robots, "Parameters for calculations of kinematics and dynamics", UR5 / CB3):
standard Denavit–Hartenberg parameters d1 0.089159, a2 -0.425, a3 -0.39225, d4 0.10915, d5 0.09465,
d6 0.0823 m, α = (π/2, 0, 0, π/2, -π/2, 0); link masses 3.7, 8.393, 2.275, 1.219, 1.219, 0.1879 kg
and centres of mass in the DH frame of each link. Joint range ±2π, joint speed limit π rad/s
(180°/s) on every joint.

UR does not publish link inertia tensors. The URDF gives each link the inertia of a uniform rod of its
mass along its DH link: the speedL arm is velocity controlled and never uses them, and a dynamic model
would have to be identified anyway.

Frames follow the DH convention: link i's URDF frame is DH frame i-1 turned by q_i, the joint's origin
is the previous joint's fixed DH part Tz(d) Tx(a) Rx(α), and a fixed `flange` frame closes with joint
6's. The flange frame E is then exactly DH frame 6, as UR's controller reports it.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

__all__ = [
    "DH",
    "JOINT_SPEED_LIMIT",
    "LINK_COM",
    "LINK_MASS",
    "UR5Model",
    "chain_geometry",
    "dh_transform",
    "ur5_urdf",
]

# (d [m], a [m], α [rad]) per joint, standard DH
DH: tuple[tuple[float, float, float], ...] = (
    (0.089159, 0.0, math.pi / 2),
    (0.0, -0.425, 0.0),
    (0.0, -0.39225, 0.0),
    (0.10915, 0.0, math.pi / 2),
    (0.09465, 0.0, -math.pi / 2),
    (0.0823, 0.0, 0.0),
)
LINK_MASS = (3.7, 8.393, 2.275, 1.219, 1.219, 0.1879)  # [kg]
LINK_COM = (  # [m] in each link's DH frame
    (0.0, -0.02561, 0.00193),
    (0.2125, 0.0, 0.11336),
    (0.15, 0.0, 0.0265),
    (0.0, -0.0018, 0.01634),
    (0.0, 0.0018, 0.01634),
    (0.0, 0.0, -0.001159),
)
JOINT_POSITION_LIMIT = 2.0 * math.pi  # [rad], ±
JOINT_SPEED_LIMIT = math.pi  # [rad/s]
JOINT_NAMES = ("shoulder_pan", "shoulder_lift", "elbow", "wrist_1", "wrist_2", "wrist_3")


def dh_transform(theta: float, d: float, a: float, alpha: float) -> np.ndarray:
    """Standard DH: Rz(θ) Tz(d) Tx(a) Rx(α), as a 4x4 homogeneous transform."""
    ct, st, ca, sa = math.cos(theta), math.sin(theta), math.cos(alpha), math.sin(alpha)
    return np.array(
        [
            [ct, -st * ca, st * sa, a * ct],
            [st, ct * ca, -ct * sa, a * st],
            [0.0, sa, ca, d],
            [0.0, 0.0, 0.0, 1.0],
        ]
    )


def _fixed_part(d: float, a: float, alpha: float) -> np.ndarray:
    return dh_transform(0.0, d, a, alpha)


def _origin(T: np.ndarray) -> str:
    """URDF origin (xyz, rpy as fixed-axis roll-pitch-yaw) of a homogeneous transform."""
    R = T[:3, :3]
    pitch = math.atan2(-R[2, 0], math.hypot(R[0, 0], R[1, 0]))
    roll = math.atan2(R[2, 1], R[2, 2])
    yaw = math.atan2(R[1, 0], R[0, 0])
    xyz = " ".join(f"{v:.9g}" for v in T[:3, 3])
    return f'<origin xyz="{xyz}" rpy="{roll:.17g} {pitch:.17g} {yaw:.17g}"/>'


def _rod_inertia(mass: float, length: float) -> tuple[float, float, float]:
    """Diagonal inertia of a uniform rod of `length` along z (with a floor of 1 cm radius)."""
    transverse = mass * (length**2 / 12.0 + 0.01**2 / 4.0)
    return transverse, transverse, mass * 0.01**2 / 2.0


@functools.cache
def ur5_urdf() -> str:
    """The UR5 as URDF, written from the DH table, masses and centres of mass above."""
    lines = ['<?xml version="1.0"?>', '<robot name="ur5">', '  <link name="base_link"/>']
    parent = "base_link"
    previous_fixed = np.eye(4)
    for i, ((d, a, alpha), mass, com) in enumerate(zip(DH, LINK_MASS, LINK_COM, strict=True)):
        link = f"link{i + 1}"
        fixed = _fixed_part(d, a, alpha)
        # the link's frame is DH frame i-1 turned by q_i; its DH frame i is `fixed` further on
        com_link = fixed @ np.array([*com, 1.0])
        ixx, iyy, izz = _rod_inertia(mass, math.hypot(d, a))
        lines += [
            f'  <link name="{link}">',
            "    <inertial>",
            f'      <origin xyz="{" ".join(f"{v:.9g}" for v in com_link[:3])}" rpy="0 0 0"/>',
            f'      <mass value="{mass}"/>',
            f'      <inertia ixx="{ixx:.6g}" ixy="0" ixz="0" iyy="{iyy:.6g}" iyz="0" izz="{izz:.6g}"/>',
            "    </inertial>",
            "  </link>",
            f'  <joint name="{JOINT_NAMES[i]}" type="revolute">',
            f'    <parent link="{parent}"/>',
            f'    <child link="{link}"/>',
            f"    {_origin(previous_fixed)}",
            '    <axis xyz="0 0 1"/>',
            f'    <limit lower="{-JOINT_POSITION_LIMIT:.17g}" upper="{JOINT_POSITION_LIMIT:.17g}" '
            f'effort="150" velocity="{JOINT_SPEED_LIMIT:.17g}"/>',
            "  </joint>",
        ]
        parent, previous_fixed = link, fixed
    lines += [
        '  <link name="flange"/>',
        '  <joint name="flange_fixed" type="fixed">',
        f'    <parent link="{parent}"/>',
        '    <child link="flange"/>',
        f"    {_origin(previous_fixed)}",
        "  </joint>",
        "</robot>",
    ]
    return "\n".join(lines) + "\n"


@dataclass(frozen=True)
class FramePlacement:
    """A frame fixed to the flange: its position and orientation in the flange frame E."""

    name: str
    p_EX_E: np.ndarray
    R_EX: np.ndarray


def chain_geometry(
    tool_frames: tuple[FramePlacement, ...] = (),
) -> tuple[list[np.ndarray], dict[str, np.ndarray]]:
    """The chain `ur5_urdf` describes, without pinocchio: each joint's placement in its parent's
    frame (a 4x4 transform: the previous joint's fixed DH part), and the `flange` and the tool's
    frames in the last joint's frame (DH frame 6's fixed part, then each frame's placement in the
    flange frame E). `plant_models.kernels.KernelUR5` runs on it where pinocchio is not installed;
    the tests hold it to pinocchio's model of the URDF."""
    joints = [np.eye(4)] + [_fixed_part(*dh) for dh in DH[:-1]]
    flange = _fixed_part(*DH[-1])
    frames = {"flange": flange}
    for f in tool_frames:
        E_X = np.eye(4)
        E_X[:3, :3], E_X[:3, 3] = np.asarray(f.R_EX, float), np.asarray(f.p_EX_E, float)
        frames[f.name] = flange @ E_X
    return joints, frames


class UR5Model:
    """A pinocchio model of the UR5 with extra frames fixed to the flange (sensors, tool, tip).

    Per-call cost matters here: the plant calls `update` on every tick, then reads only the frames it
    needs (a frame's placement is computed when it is read).
    """

    def __init__(self, tool_frames: tuple[FramePlacement, ...] = ()) -> None:
        import pinocchio as pin  # imported here: plant-only dependency, slow-ish to import

        self.pin = pin
        self.model = pin.buildModelFromXML(ur5_urdf())
        flange = self.model.getFrameId("flange")
        parent_joint = self.model.frames[flange].parentJoint
        oMflange = self.model.frames[flange].placement
        self.frame_ids: dict[str, int] = {"flange": flange}
        for f in tool_frames:
            placement = oMflange * pin.SE3(np.asarray(f.R_EX, float), np.asarray(f.p_EX_E, float))
            frame = pin.Frame(f.name, parent_joint, flange, placement, pin.FrameType.OP_FRAME)
            self.frame_ids[f.name] = self.model.addFrame(frame)
        self.data = self.model.createData()
        self.nq = self.model.nq

    def update(self, q: np.ndarray, v: np.ndarray, a: np.ndarray) -> None:
        """Kinematics, velocities and accelerations of every joint at (q, q̇, q̈); the frames' are
        read from them by the methods below."""
        self.pin.forwardKinematics(self.model, self.data, q, v, a)

    def homogeneous(self, frame: str) -> np.ndarray:
        """[[R_BX, p_BX_B], [0, 1]] of a frame after `update`, as a fresh 4x4 array."""
        return self.pin.updateFramePlacement(
            self.model, self.data, self.frame_ids[frame]
        ).homogeneous

    def placement(self, frame: str) -> tuple[np.ndarray, np.ndarray]:
        """(p_BX_B, R_BX) of a frame after `update` (views of a fresh 4x4 array)."""
        H = self.homogeneous(frame)
        return H[:3, 3], H[:3, :3]

    def twist(self, frame: str) -> np.ndarray:
        """[v; ω] of a frame's origin in the base frame (speedL's convention), after `update`."""
        return self.pin.getFrameVelocity(
            self.model, self.data, self.frame_ids[frame], self.pin.LOCAL_WORLD_ALIGNED
        ).vector.copy()

    def acceleration(self, frame: str) -> np.ndarray:
        """[a; α]: classical acceleration of a frame's origin and angular acceleration, in B."""
        return self.pin.getFrameClassicalAcceleration(
            self.model, self.data, self.frame_ids[frame], self.pin.LOCAL_WORLD_ALIGNED
        ).vector.copy()

    def jacobian(self, q: np.ndarray, frame: str) -> np.ndarray:
        """6x6 Jacobian of [v; ω] of a frame's origin in the base frame with respect to q̇."""
        return self.pin.computeFrameJacobian(
            self.model, self.data, q, self.frame_ids[frame], self.pin.LOCAL_WORLD_ALIGNED
        )
