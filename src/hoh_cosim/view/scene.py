"""The view's geometry, pure numpy: the UR5's links, the tool, the phantom, the workspace box.

Everything is in the robot's base frame B. The arm is drawn from the UR5's DH table
(`plant_models.ur5.DH`): link i's frame is DH frame i-1 turned by q_i (as in the project's URDF),
and its shape is the DH link itself, a segment d_i along that frame's z (the joint's axis) and a
segment a_i along its x, with a joint housing around the z axis at its origin:

    L_i = T_B,i-1 · Rz(q_i)        T_B,i = L_i · Tz(d_i) · Tx(a_i) · Rx(α_i)

A co-simulation gives q; a robot session logs only the TCP pose, so there q comes from that pose by
damped least squares (`ArmTracker`), warm-started from the previous frame and first from the arm's
home pose (`plant_models.arm.HOME_Q`): the branch of the arm's eight solutions the robot starts on,
followed continuously.

The tool hangs below the flange along the TCP frame's z (`plant_models.tool.ToolModel`): the FT-150
from the flange to S, the housing from S to the probe sensor P, the probe from P to the tip T, the
handle H where the hand pushes.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from plant_models.ur5 import DH

__all__ = [
    "ArmTracker",
    "Scene",
    "ToolGeometry",
    "link_frames",
    "link_poses",
    "tcp_pose",
]


def _dh(theta: float, d: float, a: float, alpha: float) -> np.ndarray:
    ct, st, ca, sa = math.cos(theta), math.sin(theta), math.cos(alpha), math.sin(alpha)
    return np.array(
        [
            [ct, -st * ca, st * sa, a * ct],
            [st, ct * ca, -ct * sa, a * st],
            [0.0, sa, ca, d],
            [0.0, 0.0, 0.0, 1.0],
        ]
    )


def link_poses(q: np.ndarray) -> np.ndarray:
    """`link_frames` of many joint vectors at once: q (n, 6) -> L_1..L_6 (n, 6, 4, 4), in B."""
    q = np.asarray(q, dtype=float).reshape(-1, 6)
    n = len(q)
    T = np.tile(np.eye(4), (n, 1, 1))
    out = np.empty((n, 6, 4, 4))
    for i, (d, a, alpha) in enumerate(DH):
        c, s = np.cos(q[:, i]), np.sin(q[:, i])
        rz = np.zeros((n, 4, 4))
        rz[:, 0, 0], rz[:, 0, 1], rz[:, 1, 0], rz[:, 1, 1] = c, -s, s, c
        rz[:, 2, 2] = rz[:, 3, 3] = 1.0
        out[:, i] = T = T @ rz
        T = T @ _dh(0.0, d, a, alpha)  # the joint's fixed part: Tz(d) Tx(a) Rx(α)
    return out


def link_frames(q: Sequence[float]) -> tuple[list[np.ndarray], np.ndarray]:
    """The six link frames L_1..L_6 (4x4, in B) and the flange frame E (DH frame 6) at joints q."""
    T = np.eye(4)
    links = []
    for theta, (d, a, alpha) in zip(q, DH, strict=True):
        ct, st = math.cos(theta), math.sin(theta)
        rz = np.array([[ct, -st, 0.0, 0.0], [st, ct, 0.0, 0.0], [0, 0, 1.0, 0], [0, 0, 0, 1.0]])
        links.append(T @ rz)
        T = T @ _dh(theta, d, a, alpha)
    return links, T


@dataclass(frozen=True)
class ToolGeometry:
    """Where the tool's parts are along the TCP frame T (the probe's axis is T's z, the tip at 0),
    from the tool model's frames in the flange frame E."""

    T_ET: np.ndarray  # 4x4: the TCP in the flange frame
    p_TE_T: np.ndarray  # the flange, from the tip [m]
    p_TS_T: np.ndarray  # the wrist sensor S
    p_TP_T: np.ndarray  # the probe sensor P
    p_TH_T: np.ndarray  # the handle H

    @classmethod
    def of(cls, tool: object | None = None) -> ToolGeometry:
        """From a `plant_models.tool.ToolModel` (default: the project's tool)."""
        from plant_models.tool import ToolModel

        frames = (tool if tool is not None else ToolModel()).flange_frames()  # type: ignore[attr-defined]
        p_ET_E, R_ET = frames["tcp"]
        T_ET = np.eye(4)
        T_ET[:3, :3], T_ET[:3, 3] = R_ET, p_ET_E

        def from_tip(name: str) -> np.ndarray:
            return R_ET.T @ (np.asarray(frames[name][0]) - p_ET_E)

        return cls(
            T_ET=T_ET,
            p_TE_T=R_ET.T @ -np.asarray(p_ET_E),
            p_TS_T=from_tip("ft_sensor"),
            p_TP_T=from_tip("probe_sensor"),
            p_TH_T=from_tip("handle"),
        )


def tcp_pose(q: Sequence[float], tool: ToolGeometry) -> np.ndarray:
    """The TCP's pose T_BT (4x4) at joints q."""
    return link_frames(q)[1] @ tool.T_ET


def _jacobian(q: np.ndarray, tool: ToolGeometry) -> tuple[np.ndarray, np.ndarray]:
    """The TCP's geometric Jacobian (6x6, [v; ω] in B) and its pose at q:
    J_i = [z_i-1 × (p_T - o_i-1); z_i-1], with z_i-1 and o_i-1 link i's joint axis and origin."""
    links, flange = link_frames(q)
    T = flange @ tool.T_ET
    p = T[:3, 3]
    J = np.empty((6, 6))
    for i, L in enumerate(links):
        z, o = L[:3, 2], L[:3, 3]
        J[:3, i] = np.cross(z, p - o)
        J[3:, i] = z
    return J, T


def _rotation_error(R_target: np.ndarray, R: np.ndarray) -> np.ndarray:
    """The rotation vector that turns R into R_target, in B (small angles: the skew part's
    axial vector, exact in direction, close in size below a few degrees)."""
    E = R_target @ R.T
    return 0.5 * np.array([E[2, 1] - E[1, 2], E[0, 2] - E[2, 0], E[1, 0] - E[0, 1]])


@dataclass
class ArmTracker:
    """Joint positions from TCP poses, frame after frame, by damped least squares:

        Δq = Jᵀ (J Jᵀ + λ² I)⁻¹ [p* - p; r(R* Rᵀ)]      until |Δp| < tol and |r| < tol

    warm-started from the last frame's q (first: `q0`). A pose the iterations cannot reach keeps
    the nearest q found, so the drawn arm lags rather than jumps."""

    tool: ToolGeometry
    q0: np.ndarray = field(default_factory=lambda: _home_q())
    damping: float = 1e-3
    tol: float = 1e-6  # [m] and [rad]
    max_iterations: int = 30

    def __post_init__(self) -> None:
        self.q = np.array(self.q0, dtype=float)

    def reset(self) -> None:
        self.q = np.array(self.q0, dtype=float)

    def solve(self, T_BT: np.ndarray) -> np.ndarray:
        """q for the TCP pose T_BT (4x4), from the last solution; the solution kept for the next."""
        q = self.q.copy()
        lam2 = self.damping**2
        for _ in range(self.max_iterations):
            J, T = _jacobian(q, self.tool)
            error = np.concatenate(
                [T_BT[:3, 3] - T[:3, 3], _rotation_error(T_BT[:3, :3], T[:3, :3])]
            )
            if np.max(np.abs(error)) < self.tol:
                break
            q = q + J.T @ np.linalg.solve(J @ J.T + lam2 * np.eye(6), error)
        if np.all(np.isfinite(q)):
            self.q = q
        return self.q.copy()

    def track(self, T_BT: np.ndarray) -> np.ndarray:
        """q (n, 6) for TCP poses T_BT (n, 4, 4) in order."""
        return np.array([self.solve(T) for T in T_BT]).reshape(len(T_BT), 6)


def _home_q() -> np.ndarray:
    from plant_models.arm import HOME_Q

    return np.array(HOME_Q, dtype=float)


@dataclass(frozen=True)
class Surface:
    """The phantom's or the abdomen's surface at rest: a plane (point, outward normal) or an
    ellipsoid (centre, semi-axes); breathing moves it along its normal (an ellipsoid: grows)."""

    shape: str  # "plane" or "ellipsoid"
    point_B: np.ndarray  # plane: a point on it; ellipsoid: its centre [m]
    normal_B: np.ndarray  # plane: its outward normal
    axes: np.ndarray  # ellipsoid: semi-axes [m]

    @classmethod
    def of(cls, phantom: object | None) -> Surface | None:
        """From a `plant_models.tissue.PhantomParams` (None, or shape "none": no surface)."""
        shape = getattr(phantom, "shape", "none")
        if phantom is None or shape == "none":
            return None
        return cls(
            shape,
            np.array(
                phantom.plane_point_B if shape == "plane" else phantom.ellipsoid_center_B,  # type: ignore[attr-defined]
                dtype=float,
            ),
            np.array(phantom.plane_normal_B, dtype=float),  # type: ignore[attr-defined]
            np.array(phantom.ellipsoid_axes, dtype=float),  # type: ignore[attr-defined]
        )


@dataclass(frozen=True)
class Scene:
    """What the view draws that does not move with the data: the tool's geometry, the workspace
    box, the surface (if any), the force limits and the virtual fixture's direction."""

    tool: ToolGeometry = field(default_factory=ToolGeometry.of)
    workspace_min_B: np.ndarray = field(default_factory=lambda: np.array([-0.70, -0.70, 0.0]))
    workspace_max_B: np.ndarray = field(default_factory=lambda: np.array([0.70, 0.70, 0.80]))
    soft_cap_N: float = 20.0
    stop_N: float = 25.0
    surface: Surface | None = None
    fixture_up_B: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.0, 1.0]))
    fixture_follows_contact: bool = False  # the fixture's normal is the contact force's direction
    ur5: bool = True  # draw the UR5's links (False: another arm, or none)
    note: str = ""  # what the view leaves out, said once in its text log

    @classmethod
    def of(
        cls,
        controller: object | None = None,
        tool: object | None = None,
        phantom: object | None = None,
        *,
        ur5: bool = True,
        note: str = "",
    ) -> Scene:
        """From a `ControllerParams` (its limits and fixture), a `ToolModel` and a
        `PhantomParams`; defaults where one is None."""
        scene = cls(tool=ToolGeometry.of(tool), surface=Surface.of(phantom), ur5=ur5, note=note)
        limits = getattr(controller, "limits", None)
        if limits is None:
            return scene
        return cls(
            tool=scene.tool,
            workspace_min_B=np.array(limits.workspace_min_B, dtype=float),
            workspace_max_B=np.array(limits.workspace_max_B, dtype=float),
            soft_cap_N=float(limits.probe_force_soft_cap),
            stop_N=float(limits.probe_force_stop),
            surface=scene.surface,
            fixture_up_B=np.array(controller.fixture_up_B, dtype=float),  # type: ignore[attr-defined]
            fixture_follows_contact=controller.fixture_normal == "contact",  # type: ignore[attr-defined]
            ur5=ur5,
            note=note,
        )


def rotation_z_to(direction: np.ndarray) -> np.ndarray:
    """The quaternion [x, y, z, w] that turns +z onto `direction` (a unit vector)."""
    z = np.array([0.0, 0.0, 1.0])
    d = np.asarray(direction, dtype=float)
    d = d / np.linalg.norm(d)
    c = float(z @ d)
    if c < -1.0 + 1e-12:
        return np.array([1.0, 0.0, 0.0, 0.0])  # half a turn about x
    axis = np.cross(z, d)
    w = math.sqrt(0.5 * (1.0 + c))
    return np.array([*(axis / (2.0 * w)), w])


def quaternions(R: np.ndarray) -> np.ndarray:
    """Unit quaternions [x, y, z, w] of rotation matrices R (n, 3, 3)."""
    from scipy.spatial.transform import Rotation

    return Rotation.from_matrix(np.asarray(R, dtype=float).reshape(-1, 3, 3)).as_quat()
