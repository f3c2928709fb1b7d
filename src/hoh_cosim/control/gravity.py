"""Tool-weight compensation of the wrist F/T sensor and its identification (seed 000, section 3.D).

The sensor reports the wrench that the tool side puts on it, expressed in its frame S. Held still and
untouched, that is the tool's weight acting at its centre of mass C plus the sensor's own offset:

    f_S = m · R_BSᵀ g_B + b_f
    τ_S = p_SC_S × (m · R_BSᵀ g_B) + b_τ                                  (seed eq. 4–5, generalised)

The seed wrote this for gravity along -z of the base with the sensor rebiased at a vertical home pose
(the extra `[0 0 -mg]` of eq. 5 undoes that rebias). Here gravity may point anywhere, the rebias pose
is whatever pose the rebias happened at, and the offset b = [b_f, b_τ] is explicit.

Identification from static poses, two ways:
- `identify_seed_two_step`: the seed's procedure (eq. 6–8): first mg from the forces, then the x and
  y of the centre of mass from the torques, on readings rebiased at a known pose.
- `identify_gravity`: all ten unknowns (m, p_SC_S, b_f, b_τ) by linear least squares, with standard
  errors, the condition number and plausibility checks. The products c = m·p_SC_S make the torque
  equations linear: τ_S = c × u + b_τ = -[u]× c + b_τ, with u = R_BSᵀ g_B.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np
import numpy.typing as npt

from hoh_cosim.control.frames import skew
from hoh_cosim.control.vectors import (
    GRAVITY_B,
    STANDARD_GRAVITY,
    Rot3,
    Vec,
    Vec3,
    Wrench,
    as_scalar,
    as_vector,
    cross3,
    frozen,
)
from hoh_cosim.errors import ConfigError, IdentificationError

__all__ = [
    "MAX_CONDITION_NUMBER",
    "SEED_TOOL",
    "GravityCalibration",
    "GravityModel",
    "SeedTwoStepResult",
    "ToolParams",
    "compensate_gravity",
    "identify_gravity",
    "identify_seed_two_step",
    "rebias",
    "tool_weight_wrench_S",
]

MAX_MASS_KG = 10.0
MAX_COM_M = 0.5
MAX_CONDITION_NUMBER = 1.0e3
"""Largest condition number (columns scaled to unit length) we accept: beyond it the poses are too
alike for the data to separate the parameters, whatever the standard errors claim."""


@dataclass(frozen=True)
class ToolParams:
    """What hangs below the wrist sensor: its mass and centre of mass."""

    UNITS: ClassVar[dict[str, Any]] = {"mass_kg": "kg", "p_SC_S": "m"}

    mass_kg: float  # [kg] probe + housing (+ probe sensor)
    p_SC_S: Vec3 = field(default_factory=lambda: frozen([0.0, 0.0, 0.0]))  # [m] from S, in S

    def __post_init__(self) -> None:
        object.__setattr__(self, "mass_kg", as_scalar(self.mass_kg, "mass_kg", low=0.0))
        object.__setattr__(self, "p_SC_S", as_vector(self.p_SC_S, 3, "p_SC_S"))


SEED_TOOL = ToolParams(mass_kg=4.7631 / STANDARD_GRAVITY, p_SC_S=frozen([-0.01250, -0.00033, 0.0]))
"""The seed's identified tool (section 4.B): mg = 4.7631 N, p_COM,xy = (-0.01250, -0.00033) m. The
seed did not identify the z of the centre of mass; 0 is its model's implicit value."""


def tool_weight_wrench_S(R_BS: Rot3, tool: ToolParams, g_B: Vec3 = GRAVITY_B) -> Wrench:
    """Wrench that the tool's weight puts on the wrist sensor, expressed in S.

    f_S = R_BSᵀ · m · g_B ;  τ_S = p_SC_S × f_S
    """
    f_S = R_BS.T @ (tool.mass_kg * g_B)
    return np.concatenate([f_S, cross3(tool.p_SC_S, f_S)])


class GravityModel:
    """`tool_weight_wrench_S` with its constants precomputed, for the estimator's hot path."""

    def __init__(self, tool: ToolParams, g_B: Vec3 = GRAVITY_B) -> None:
        self.tool = tool
        self.g_B = as_vector(g_B, 3, "g_B")
        self._mg_B = tool.mass_kg * self.g_B
        self._skew_p = skew(tool.p_SC_S)

    def weight_S(self, R_BS: Rot3) -> Wrench:
        """f_S = R_BSᵀ · m · g_B ;  τ_S = [p_SC_S]× f_S (`ndarray.dot`: the BLAS routine of `@`,
        without its overhead on 3x3 arrays)."""
        w_S = np.empty(6)
        f_S = R_BS.T.dot(self._mg_B, out=w_S[:3])
        self._skew_p.dot(f_S, out=w_S[3:])
        return w_S


def compensate_gravity(
    w_S: Wrench, R_BS: Rot3, tool: ToolParams, bias: Wrench, g_B: Vec3 = GRAVITY_B
) -> Wrench:
    """The external (hand and contact) wrench at the sensor, in S (seed eq. 4):

    w_ext = w_S - b - w_weight(R_BS)
    """
    return w_S - bias - tool_weight_wrench_S(R_BS, tool, g_B)


def rebias(
    samples_S: npt.ArrayLike,
    R_BS: npt.ArrayLike | None = None,
    tool: ToolParams | None = None,
    g_B: Vec3 = GRAVITY_B,
) -> Wrench:
    """Sensor offset from N readings taken while nobody touches the tool (seed 3.B.1: N = 500).

    With a tool model, b = mean_k(w_k - w_weight(R_BS,k)): the offset such that the compensated
    wrench is zero there, whatever the pose. Without one, b = mean_k(w_k): the seed's plain average,
    right only for the pose it was taken at. `R_BS` is one 3x3 pose or one per sample.
    """
    w = np.asarray(samples_S, dtype=np.float64)
    if w.ndim != 2 or w.shape[0] == 0:
        raise ConfigError(f"rebias: expected samples as an (N, k) array with N >= 1, got {w.shape}")
    mean = w.mean(axis=0)
    if tool is None:
        return mean
    if w.shape[1] != 6:
        raise ConfigError(f"rebias: a tool model needs 6-axis samples, got {w.shape[1]}")
    if R_BS is None:
        raise ConfigError("rebias: a tool model needs the sensor orientation R_BS")
    R = np.asarray(R_BS, dtype=np.float64).reshape(-1, 3, 3)
    if R.shape[0] not in (1, w.shape[0]):
        raise ConfigError(f"rebias: expected 1 or {w.shape[0]} orientations, got {R.shape[0]}")
    weights = np.array([tool_weight_wrench_S(Rk, tool, g_B) for Rk in R])
    return mean - weights.mean(axis=0)


# --- identification --------------------------------------------------------------------------


@dataclass(frozen=True)
class SeedTwoStepResult:
    """The seed's eq. 6–8 result: mg [N] and the x, y of the centre of mass [m]."""

    mg_N: float
    com_xy_m: Vec
    gravity_m_s2: float = STANDARD_GRAVITY

    @property
    def tool(self) -> ToolParams:
        p = frozen([self.com_xy_m[0], self.com_xy_m[1], 0.0])
        return ToolParams(self.mg_N / self.gravity_m_s2, p)


@dataclass(frozen=True)
class GravityCalibration:
    """All ten parameters of the tool-weight model with their standard errors and residuals."""

    mass_kg: float
    com_m: Vec3  # p_SC_S
    force_bias_N: Vec3
    torque_bias_Nm: Vec3
    mass_se_kg: float
    com_se_m: Vec3
    force_bias_se_N: Vec3
    torque_bias_se_Nm: Vec3
    condition_number: float
    n_poses: int
    gravity_B: Vec3
    residual_rms_before: Vec  # 6: per component, readings minus the bias only
    residual_max_before: Vec  # 6: max |.|
    residual_rms_after: Vec  # 6: readings minus the bias and the weight model
    residual_max_after: Vec

    @property
    def tool(self) -> ToolParams:
        return ToolParams(self.mass_kg, self.com_m)

    @property
    def bias(self) -> Wrench:
        return np.concatenate([self.force_bias_N, self.torque_bias_Nm])


def _as_pose_set(R_BS: npt.ArrayLike, wrench_S: npt.ArrayLike) -> tuple[Vec, Vec]:
    R = np.asarray(R_BS, dtype=np.float64)
    w = np.asarray(wrench_S, dtype=np.float64)
    if R.ndim != 3 or R.shape[1:] != (3, 3):
        raise ConfigError(f"R_BS: expected an (n, 3, 3) array of rotations, got shape {R.shape}")
    if w.ndim != 2 or w.shape[1] != 6:
        raise ConfigError(f"wrench_S: expected an (n, 6) array, got shape {w.shape}")
    if R.shape[0] != w.shape[0]:
        raise ConfigError(f"got {R.shape[0]} orientations but {w.shape[0]} wrenches")
    if not (np.all(np.isfinite(R)) and np.all(np.isfinite(w))):
        raise ConfigError("the pose set contains non-finite numbers")
    return R, w


def _scaled_condition(A: Vec) -> float:
    """2-norm condition number of A with every column scaled to unit length (scale-free)."""
    norms = np.linalg.norm(A, axis=0)
    if np.any(norms == 0.0):
        return math.inf
    s = np.linalg.svd(A / norms, compute_uv=False)
    return math.inf if s[-1] <= s[0] * 1e-15 else float(s[0] / s[-1])


def _least_squares(A: Vec, b: Vec) -> tuple[Vec, Vec, Vec]:
    """x, its covariance (σ² (AᵀA)⁻¹ with σ² from the residuals) and the residuals."""
    x, *_ = np.linalg.lstsq(A, b, rcond=None)
    residual = b - A @ x
    dof = A.shape[0] - A.shape[1]
    sigma2 = float(residual @ residual) / dof
    cov = sigma2 * np.linalg.inv(A.T @ A)
    return x, cov, residual


def identify_gravity(
    R_BS: npt.ArrayLike,
    wrench_S: npt.ArrayLike,
    g_B: npt.ArrayLike = GRAVITY_B,
    *,
    max_condition: float = MAX_CONDITION_NUMBER,
) -> GravityCalibration:
    """Identify mass, centre of mass, force and torque offsets from static, untouched poses.

    R_BS: (n, 3, 3) orientations of the wrist sensor in the base frame.
    wrench_S: (n, 6) raw averaged readings [N, N·m] in S.

    Forces and torques are separate least-squares problems (they share no unknown once c = m·p is
    used), each with its own residual variance, so a force error in N and a torque error in N·m are
    never mixed. Standard errors assume independent, equal-variance errors per group; the error of
    p = c / m follows by first-order propagation.

    Raises IdentificationError when there are fewer poses than the ten unknowns, when the poses are too
    alike (condition number above `max_condition`), or when the result is implausible
    (mass outside (0, 10) kg, |p_SC_S| >= 0.5 m).
    """
    R, w = _as_pose_set(R_BS, wrench_S)
    g = as_vector(g_B, 3, "g_B")
    n = R.shape[0]
    if n < 10:
        raise IdentificationError(
            f"need at least 10 poses for the 10 unknowns (mass, centre of mass, force and torque "
            f"bias), got {n}"
        )
    u = np.einsum("nji,j->ni", R, g)  # gravity in S per pose: R_BSᵀ g_B
    eye = np.tile(np.eye(3), (n, 1))
    A_f = np.hstack([u.reshape(-1, 1), eye])  # unknowns [m, b_f]
    A_t = np.hstack([-np.array([skew(uk) for uk in u]).reshape(-1, 3), eye])  # [c, b_τ]

    cond_f, cond_t = _scaled_condition(A_f), _scaled_condition(A_t)
    if cond_f > max_condition:
        raise IdentificationError(
            f"the orientations are too alike to separate the mass from the force bias "
            f"(condition number {cond_f:.3g} > {max_condition:.3g}): tilt the tool further"
        )
    if cond_t > max_condition:
        raise IdentificationError(
            f"the orientations are too alike to separate the centre of mass from the torque bias "
            f"(condition number {cond_t:.3g} > {max_condition:.3g}): tilt the tool about more axes"
        )

    x_f, cov_f, res_f = _least_squares(A_f, w[:, :3].reshape(-1))
    x_t, cov_t, res_t = _least_squares(A_t, w[:, 3:].reshape(-1))
    mass, b_f = float(x_f[0]), x_f[1:]
    c, b_t = x_t[:3], x_t[3:]

    if not 0.0 < mass < MAX_MASS_KG:
        raise IdentificationError(
            f"implausible mass {mass:.4g} kg (expected 0 < mass < {MAX_MASS_KG:g} kg): check the "
            f"gravity vector, the orientations and the sensor's sign convention"
        )
    p = c / mass
    if float(np.linalg.norm(p)) >= MAX_COM_M:
        raise IdentificationError(
            f"implausible centre of mass {np.round(p, 4).tolist()} m (expected |p| < {MAX_COM_M} m)"
        )
    var_m = float(cov_f[0, 0])
    var_p = np.diag(cov_t)[:3] / mass**2 + c**2 * var_m / mass**4

    before = w - np.concatenate([b_f, b_t])
    after = np.hstack([res_f.reshape(n, 3), res_t.reshape(n, 3)])
    return GravityCalibration(
        mass_kg=mass,
        com_m=frozen(p),
        force_bias_N=frozen(b_f),
        torque_bias_Nm=frozen(b_t),
        mass_se_kg=math.sqrt(var_m),
        com_se_m=frozen(np.sqrt(var_p)),
        force_bias_se_N=frozen(np.sqrt(np.diag(cov_f)[1:])),
        torque_bias_se_Nm=frozen(np.sqrt(np.diag(cov_t)[3:])),
        condition_number=max(cond_f, cond_t),
        n_poses=n,
        gravity_B=g,
        residual_rms_before=frozen(np.sqrt(np.mean(before**2, axis=0))),
        residual_max_before=frozen(np.max(np.abs(before), axis=0)),
        residual_rms_after=frozen(np.sqrt(np.mean(after**2, axis=0))),
        residual_max_after=frozen(np.max(np.abs(after), axis=0)),
    )


def identify_seed_two_step(
    R_BS: npt.ArrayLike,
    wrench_S: npt.ArrayLike,
    R_BS_rebias: npt.ArrayLike,
    g_B: npt.ArrayLike = GRAVITY_B,
) -> SeedTwoStepResult:
    """The seed's two-step least squares (eq. 6–8) on readings rebiased at the pose `R_BS_rebias`.

    Step 1 (eq. 6, force rows): f_k = m (u_k - u_0), u = R_BSᵀ g_B, solved for the scalar m, hence mg.
    Step 2 (eq. 7–8, torque rows): τ_k = p × m (u_k - u_0) with p_z = 0, solved for p_x, p_y.

    The seed's eq. 6 left the rebias out of the torque rows and its eq. 7 and 8 differ in sign; this
    is the same procedure with the rebias applied to forces and torques alike, which is what makes
    its figures round-trip.
    """
    R, w = _as_pose_set(R_BS, wrench_S)
    g = as_vector(g_B, 3, "g_B")
    R0 = np.asarray(R_BS_rebias, dtype=np.float64).reshape(3, 3)
    d = np.einsum("nji,j->ni", R, g) - R0.T @ g  # (u_k - u_0), per pose
    dd = float(np.sum(d * d))
    if R.shape[0] < 3 or dd < 1e-9:
        raise IdentificationError(
            f"the seed's two-step method needs at least 3 poses that differ from the rebias pose, "
            f"got {R.shape[0]} poses with a total tilt of {math.sqrt(dd):.2g} m/s² of gravity change"
        )
    mass = float(np.sum(d * w[:, :3])) / dd
    f = mass * d
    # τ = p × f = -[f]× p, only the x and y columns of -[f]× (p_z = 0)
    A = -np.array([skew(fk)[:, :2] for fk in f]).reshape(-1, 2)
    p_xy, *_ = np.linalg.lstsq(A, w[:, 3:].reshape(-1), rcond=None)
    g_norm = float(np.linalg.norm(g))
    return SeedTwoStepResult(mg_N=mass * g_norm, com_xy_m=frozen(p_xy), gravity_m_s2=g_norm)
