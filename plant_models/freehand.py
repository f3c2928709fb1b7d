"""Freehand: the probe held by the hand alone, no robot, on the same phantom and the same tasks.

What the hand does on the robot, it does here on the probe itself: the operator block's force
`F_hand_B` acts at the handle H. The hand carries everything the robot carried there: the probe's
weight (the operator's feed-forward of a known weight, `OperatorParams.feedforward_B`), its
inertia, and the contact force and friction of the phantom at the tip T. So the effort metrics of
the two (the operator's `F_hand_B`, the force the hand puts on the probe) compare the very same
task and hand.

The probe is one rigid body, the tool of `plant_models.tool` (mass m, inertia I about its centre of
mass C, the frames S, H, T), free in six degrees of freedom. Newton–Euler about C, in B:

    m v̇  = F_hand + F_T + m g
    I ω̇  = τ_hand + τ_grip + r_CH × F_hand + r_CT × F_T - ω × I ω
    F_T  = F_contact(p_T, v_T, h, ḣ) + F_tip,   v_T = v + ω × r_CT

The operator block gives a force only (it steers by force, as on the robot); the grip's rotational
impedance is here, since it is the mechanical joint between hand and probe, and acts while the hand
holds the probe (the operator's `hand_on`):

    τ_grip = -K_r θ - D_r ω + r_CH × m g

θ the rotation vector from the start orientation to the current one, K_r and D_r the grip's
rotational stiffness and damping (the population draws them, `plant_models.population`), and the
last term the hand holding the weight's moment about the handle (the same feed-forward as the
force's). With the feed-forward the probe held still in the air is in equilibrium at the start pose,
and the hand's force is exactly -m g.

Integration: linearly implicit Euler in `substep_s` steps (within a communication step, the inputs
held): with M the mass matrix, C and K the Jacobians of the forces with respect to velocity and
position (the contact's normal stiffness and damping and its friction, the grip), u = [v; ω],

    (M + h C + h² K) u₁ = (M + h C) u₀ + h f(x₀, u₀),    x₁ = x₀ + h u₁  (R through exp)

which stays stable with the stiff smoothed Coulomb friction of the phantom (μ F_n / v_s ≈ 1600
N·s/m at 8 N) that an explicit step would need 0.1 ms for. The block is sampled: it refuses a step
other than its first, as a controller does (its result depends on the step, as any integrator's).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from hoh_cosim.control.block import TWIST_UNITS, Port
from hoh_cosim.control.frames import skew
from hoh_cosim.control.vectors import (
    GRAVITY_B,
    Rot3,
    Vec,
    Vec3,
    as_rotation,
    as_scalar,
    as_vector,
    cross3,
    frozen,
)
from plant_models.kernels import freehand_constants, freehand_step, kernels_enabled
from plant_models.tissue import PhantomParams, contact_force, surface_depth
from plant_models.tool import ToolModel

__all__ = ["HOME_R_BT", "HOME_TIP_B", "FreehandParams", "FreehandProbe"]

HOME_TIP_B = frozen([-0.10, -0.45, 0.25])
"""[m] The UR5 plant's tip at its home pose (`plant_models.arm.HOME_Q`): the same start."""
HOME_R_BT = frozen([[0.0, -1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
"""The UR5 plant's tip orientation at home: the probe pointing down."""
_STILL = frozen([0.0])
_OUTPUTS = (
    ("p_BT_B", slice(0, 3)),
    ("R_BT", slice(3, 12)),
    ("twist_B", slice(12, 18)),
    ("F_contact_B", slice(18, 21)),
    ("penetration", slice(21, 22)),
    ("tau_grip_B", slice(22, 25)),
)
"""Where each output sits in the compiled step's array (`plant_models.kernels.freehand_step`)."""


class _StatePart:
    """A part of `FreehandProbe._x` as an attribute: reading gives a view (in `shape`), assigning
    writes the values into the state."""

    def __init__(self, start: int, stop: int, shape: tuple[int, ...] | None = None) -> None:
        self.at = slice(start, stop)
        self.shape = shape

    def __get__(self, probe: Any, owner: type | None = None) -> Vec:
        part = probe._x[self.at]
        return part if self.shape is None else part.reshape(self.shape)

    def __set__(self, probe: Any, value: Vec) -> None:
        probe._x[self.at] = np.reshape(value, -1)


@dataclass(frozen=True)
class FreehandParams:
    UNITS: ClassVar[dict[str, Any]] = {
        "g_B": "m/s2",
        "p_BT0_B": "m",
        "R_BT0": "1",
        "grip_stiffness": "N.m/rad",
        "grip_damping": "N.m.s/rad",
        "substep_s": "s",
    }
    TUNABLE: ClassVar[frozenset[str]] = frozenset({"phantom"})

    tool: ToolModel = field(default_factory=ToolModel)
    phantom: PhantomParams = field(default_factory=PhantomParams)
    g_B: Vec3 = field(default_factory=lambda: GRAVITY_B.copy())  # [m/s²]
    p_BT0_B: Vec3 = field(default_factory=lambda: HOME_TIP_B.copy())  # [m] tip at the start
    R_BT0: Rot3 = field(default_factory=lambda: HOME_R_BT.copy())  # tip orientation at the start
    grip_stiffness: float = 3.0  # K_r [N·m/rad]
    grip_damping: float = 0.05  # D_r [N·m·s/rad]
    substep_s: float = 1e-3  # [s] the integrator's longest step

    def __post_init__(self) -> None:
        object.__setattr__(self, "g_B", as_vector(self.g_B, 3, "g_B"))
        object.__setattr__(self, "p_BT0_B", as_vector(self.p_BT0_B, 3, "p_BT0_B"))
        object.__setattr__(self, "R_BT0", as_rotation(self.R_BT0, "R_BT0"))
        object.__setattr__(
            self, "grip_stiffness", as_scalar(self.grip_stiffness, "grip_stiffness", low=0.0)
        )
        object.__setattr__(
            self, "grip_damping", as_scalar(self.grip_damping, "grip_damping", low=0.0)
        )
        object.__setattr__(
            self,
            "substep_s",
            as_scalar(self.substep_s, "substep_s", low=0.0, low_open=True, high=0.01),
        )


class FreehandProbe:
    """The probe in the hand, on the phantom, under the block contract."""

    inputs: ClassVar[tuple[Port, ...]] = (
        Port("F_hand_B", 3, "N", "force of the hand on the handle, in B"),
        Port("tau_hand_B", 3, "N.m", "torque of the hand on the handle (about the handle), in B"),
        Port("F_tip_B", 3, "N", "force of a hand directly on the probe tip, in B"),
        Port(
            "surface_offset_m",
            1,
            "m",
            "displacement of the phantom's surface along its outward normal (breathing), 0 at rest",
        ),
        Port("surface_rate_m_s", 1, "m/s", "rate of the surface's displacement"),
        Port("hand_on", 1, "1", "1 while the hand holds the probe (the grip acts), else 0"),
    )
    OPTIONAL_INPUTS: ClassVar[frozenset[str]] = frozenset(
        {"surface_offset_m", "surface_rate_m_s", "hand_on"}
    )
    """Inputs that may be left unconnected: 0 then (a phantom that does not breathe, no grip)."""
    outputs: ClassVar[tuple[Port, ...]] = (
        Port("p_BT_B", 3, "m", "probe tip position in the base frame"),
        Port("R_BT", 9, "1", "probe tip orientation in the base frame, row by row"),
        Port("twist_B", 6, TWIST_UNITS, "probe tip twist [v; ω] in the base frame"),
        Port("F_contact_B", 3, "N", "force of the phantom on the probe tip, in B"),
        Port("penetration", 1, "m", "depth of the tip in the phantom, > 0 in contact"),
        Port("tau_grip_B", 3, "N.m", "torque of the grip on the probe, in B"),
    )

    def __init__(self, params: FreehandParams | None = None) -> None:
        self.params = params or FreehandParams()
        # the substeps compiled (plant_models.kernels.freehand_step), or this class's pure ones,
        # which stay the reference (tests compare the two to 1e-12)
        self._compiled = kernels_enabled()
        self._x = np.zeros(18)  # the state: [p_C; R row by row; v_C; ω], in B
        self._derive()
        self.reset()

    # the pure path's views of the state (each assignment writes into it)
    _p_C = _StatePart(0, 3)  # [m] the centre of mass, in B
    _R = _StatePart(3, 12, (3, 3))  # R_BS
    _u = _StatePart(12, 18)  # [v_C; ω], in B

    def _derive(self) -> None:
        p = self.params
        tool = p.tool
        self._m = tool.mass_kg
        self._I_S = np.diag(tool.inertia_C_S)
        self._R_ST = tool.R_ES.T.copy()  # the tip frame has the flange's orientation
        # the handle and the tip from the centre of mass, in S
        self._r_CH_S = tool.p_SH_S - tool.p_SC_S
        self._r_CT_S = tool.p_ST_S - tool.p_SC_S
        self._R_BS0 = p.R_BT0 @ self._R_ST.T
        self._weight = self._m * p.g_B
        self._grip_C = p.grip_damping * np.eye(3)
        self._grip_K = p.grip_stiffness * np.eye(3)
        # work arrays of every substep (no result refers to them)
        self._M = np.zeros((6, 6))
        self._M[:3, :3] = self._m * np.eye(3)
        self._J = np.hstack([np.eye(3), np.zeros((3, 3))])
        self._C = np.zeros((6, 6))
        self._K = np.zeros((6, 6))
        self._constants = freehand_constants(p, self) if self._compiled else None

    def retune(self, params: FreehandParams) -> None:
        """New parameters while running (only the phantom may change)."""
        self.params = params
        self._derive()

    def reset(self) -> None:
        p = self.params
        self._R = self._R_BS0.copy()
        self._p_C = p.p_BT0_B - self._R @ self._r_CT_S
        self._u = np.zeros(6)  # [v_C; ω] in B
        self._gripped = False
        if self._constants is not None:
            self._outputs = self._unpack(
                freehand_step(self._constants, self._x, np.zeros(12), 0, 0.0)
            )
        else:
            self._outputs = self._evaluate(
                np.zeros(3), np.zeros(3), np.zeros(3), 0.0, 0.0, jacobians=False
            )[0]

    @staticmethod
    def _unpack(out: Vec) -> dict[str, Vec]:
        return {name: out[at] for name, at in _OUTPUTS}

    def initial_outputs(self) -> dict[str, Vec]:
        return self._outputs

    @property
    def outputs_now(self) -> dict[str, Vec]:
        return self._outputs

    def _evaluate(
        self,
        F_hand: Vec3,
        tau_hand: Vec3,
        F_tip: Vec3,
        offset: float,
        offset_rate: float,
        *,
        jacobians: bool,
    ) -> tuple[dict[str, Vec], Vec, np.ndarray | None, np.ndarray | None]:
        """The outputs, the generalised force f = [force; torque about C] and (with `jacobians`)
        its Jacobians C = -∂f/∂u and K = -∂f/∂x at the current state."""
        p = self.params
        R = self._R
        v, w = self._u[:3], self._u[3:]
        r_CT = R @ self._r_CT_S
        r_CH = R @ self._r_CH_S
        p_T = self._p_C + r_CT
        v_T = v + cross3(w, r_CT)
        contact = contact_force(p.phantom, p_T, v_T, offset, offset_rate)
        F_T = contact.force_B + F_tip
        if self._gripped:
            theta = _log(R @ self._R_BS0.T)
            tau_grip = -p.grip_stiffness * theta - p.grip_damping * w + cross3(r_CH, self._weight)
        else:
            tau_grip = np.zeros(3)
        I_B = R @ self._I_S @ R.T
        f = np.empty(6)
        f[:3] = F_hand + F_T + self._weight
        f[3:] = tau_hand + tau_grip + cross3(r_CH, F_hand) + cross3(r_CT, F_T) - cross3(w, I_B @ w)
        depth = contact.depth
        outputs = {
            "p_BT_B": p_T,
            "R_BT": (R @ self._R_ST).reshape(9),
            "twist_B": np.concatenate([v_T, w]),
            "F_contact_B": contact.force_B,
            "penetration": np.array([depth if math.isfinite(depth) else -1.0]),
            "tau_grip_B": tau_grip,
        }
        if not jacobians:
            return outputs, f, None, None
        self._M[3:, 3:] = I_B
        C_T, K_T = _contact_jacobians(p.phantom, p_T, v_T, offset_rate, depth)
        C = self._C
        K = self._K
        if C_T is None:
            C.fill(0.0)
            K.fill(0.0)
        else:
            J = self._J  # v_T = J u = v - [r_CT]× ω
            J[:, 3:] = -skew(r_CT)
            C[...] = J.T @ C_T @ J
            K[...] = J.T @ K_T @ J
        if self._gripped:
            C[3:, 3:] += self._grip_C
            K[3:, 3:] += self._grip_K
        return outputs, f, C, K

    def step(self, t: float, dt: float, inputs: Mapping[str, Vec]) -> dict[str, Vec]:
        F_hand = np.asarray(inputs["F_hand_B"], dtype=np.float64)
        tau_hand = np.asarray(inputs["tau_hand_B"], dtype=np.float64)
        F_tip = np.asarray(inputs["F_tip_B"], dtype=np.float64)
        offset = float(inputs.get("surface_offset_m", _STILL)[0])
        offset_rate = float(inputs.get("surface_rate_m_s", _STILL)[0])
        self._gripped = float(inputs.get("hand_on", _STILL)[0]) > 0.5
        n = max(1, math.ceil(dt / self.params.substep_s - 1e-9))
        h = dt / n
        if self._constants is not None:
            packed = np.empty(12)
            packed[0:3] = F_hand
            packed[3:6] = tau_hand
            packed[6:9] = F_tip
            packed[9:] = offset, offset_rate, 1.0 if self._gripped else 0.0
            self._outputs = self._unpack(freehand_step(self._constants, self._x, packed, n, h))
            return self._outputs
        M = self._M
        for _ in range(n):
            _, f, C, K = self._evaluate(
                F_hand, tau_hand, F_tip, offset, offset_rate, jacobians=True
            )
            assert C is not None
            assert K is not None
            MC = M + h * C
            # (M + h C + h² K) u₁ = (M + h C) u₀ + h f
            self._u = np.linalg.solve(MC + (h * h) * K, MC @ self._u + h * f)
            self._p_C = self._p_C + h * self._u[:3]
            self._R = _orthonormal(_exp(h * self._u[3:]) @ self._R)
        self._outputs = self._evaluate(
            F_hand, tau_hand, F_tip, offset, offset_rate, jacobians=False
        )[0]
        return self._outputs


def _exp(r: Vec3) -> Rot3:
    """exp([r]×): Rodrigues' formula, I + sin θ/θ [r]× + (1 - cos θ)/θ² [r]×², θ = |r|."""
    x, y, z = r.tolist()
    theta2 = x * x + y * y + z * z
    if theta2 < 1e-12:  # the series to the term in θ²
        a, b = 1.0 - theta2 / 6.0, 0.5 - theta2 / 24.0
    else:
        theta = math.sqrt(theta2)
        a, b = math.sin(theta) / theta, (1.0 - math.cos(theta)) / theta2
    K = np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])
    return np.eye(3) + a * K + b * (K @ K)


def _log(R: Rot3) -> Vec3:
    """The rotation vector of R, for the grip's small angles (well below π): the axis from R's
    skew part, sin θ · axis = vee(R - Rᵀ)/2, and θ = atan2(sin θ, (tr R - 1)/2)."""
    (r00, r01, r02), (r10, r11, r12), (r20, r21, r22) = R.tolist()
    x, y, z = 0.5 * (r21 - r12), 0.5 * (r02 - r20), 0.5 * (r10 - r01)
    s = math.sqrt(x * x + y * y + z * z)
    if s < 1e-12:
        return np.array([x, y, z])
    scale = math.atan2(s, 0.5 * (r00 + r11 + r22 - 1.0)) / s
    return np.array([scale * x, scale * y, scale * z])


def _orthonormal(R: Rot3) -> Rot3:
    """R with the rounding of many products taken out: R (3 I - Rᵀ R) / 2, one Newton step
    towards the nearest rotation (enough for the 1e-16 a step adds)."""
    return R @ (1.5 * np.eye(3) - 0.5 * (R.T @ R))


def _contact_jacobians(
    phantom: PhantomParams, p_T: Vec3, v_T: Vec3, offset_rate: float, depth: float
) -> tuple[np.ndarray, np.ndarray] | tuple[None, None]:
    """(-∂F/∂v_T, -∂F/∂p_T) of the contact force at the tip (`plant_models.tissue`): the normal
    spring-damper along n, the friction's linearisation across it; (None, None) out of contact."""
    if depth <= 0.0:
        return None, None
    _, n = surface_depth(phantom, p_T)
    k, e, c = phantom.stiffness, phantom.exponent, phantom.damping
    depth_rate = -float(v_T @ n) + offset_rate
    spring = k * depth**e
    F_n = spring * (1.0 + 1.5 * c * depth_rate)
    if F_n <= 0.0:
        return None, None
    nn = np.outer(n, n)
    # F_n = k δᵉ (1 + 3/2 c δ̇),  δ̇ = -v·n + ḣ,  δ = δ₀(p) + h with ∂δ₀/∂p ≈ -n
    C_T = 1.5 * c * spring * nn
    K_T = e * k * depth ** (e - 1.0) * (1.0 + 1.5 * c * depth_rate) * nn
    # friction -g(s) v_t, g(s) = μ F_n tanh(s/v_s)/s + b, s = |v_t|:
    # -∂/∂v_t = g I_t + s g'(s) t tᵀ
    v_t = v_T - float(v_T @ n) * n
    s = math.sqrt(float(v_t @ v_t))
    P = np.eye(3) - nn
    mu_F, v_s = phantom.friction * F_n, phantom.stiction_velocity
    if s > 1e-9 * v_s:
        th = math.tanh(s / v_s)
        g = mu_F * th / s + phantom.viscous_friction
        s_g_prime = mu_F * ((1.0 - th * th) / v_s - th / s)
        t = v_t / s
        C_T = C_T + g * P + s_g_prime * np.outer(t, t)
    else:
        C_T = C_T + (mu_F / v_s + phantom.viscous_friction) * P
    return C_T, K_T
