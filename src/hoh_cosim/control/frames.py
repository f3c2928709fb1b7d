"""Rotations, wrench re-expression and the seed's sensor alignment rotations (seed 000, section 3.C).

Conventions (see DESIGN.md §5): `R_AB` rotates vectors from frame B into frame A, so `v_A = R_AB v_B`;
`p_AB_A` is the position of B's origin from A's origin, expressed in A. A wrench is the 6-vector
`[f, τ]`: force [N] then torque [N·m], the torque taken about the origin of the frame it is
expressed in unless a function says otherwise.

Orientation formats: UR's RTDE reports a rotation vector (axis times angle, radians); the seed states
its alignments as ZYX Euler angles (yaw about z, then pitch about the new y, then roll about the new
x: `R = Rz(z) · Ry(y) · Rx(x)`).
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt
from scipy.spatial.transform import Rotation

from hoh_cosim.control.vectors import Rot3, Vec3, Wrench, cross3, frozen

__all__ = [
    "R_BL_EQ3",
    "R_BP_EQ2",
    "R_BS_EQ1",
    "R_SP_SEED",
    "SEED_EULER_ZYX",
    "euler_zyx_to_matrix",
    "matrix_to_euler_zyx",
    "matrix_to_rotvec",
    "rotate_wrench",
    "rotvec_to_matrix",
    "shift_wrench",
    "skew",
    "transform_wrench",
]


def skew(v: npt.ArrayLike) -> Rot3:
    """The matrix [v]× with [v]× w = v × w (the seed's sk(·) in eq. 5)."""
    x, y, z = (float(c) for c in np.asarray(v, dtype=np.float64).reshape(3))
    return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])


def rotvec_to_matrix(r: npt.ArrayLike) -> Rot3:
    """Rotation matrix of the rotation vector `r` (axis · angle [rad]), as RTDE's TCP pose gives it."""
    return Rotation.from_rotvec(np.asarray(r, dtype=np.float64).reshape(3)).as_matrix()


def matrix_to_rotvec(R: npt.ArrayLike) -> Vec3:
    """Rotation vector (axis · angle, angle in [0, π]) of the rotation matrix `R`.

    scipy's `Rotation.from_matrix(R).as_rotvec()` written out in floats for a rotation (rows
    orthonormal as scipy checks them, det > 0), the case of every control loop here: that call
    costs 100-150 µs, this one a few. The quaternion comes from the largest of R₀₀, R₁₁, R₂₂ and
    tr R (Shepperd's choice, as scipy makes it), is normalised and put in the half with w >= 0;
    then angle = 2 atan2(|q_xyz|, w) and r = q_xyz · angle / sin(angle/2), or the series
    2 + angle²/12 + 7 angle⁴/2880 for that factor below 1 mrad. Anything else (a matrix scipy would
    orthogonalise, or refuse) goes to scipy itself.
    """
    R = np.asarray(R, dtype=np.float64).reshape(3, 3)
    (r00, r01, r02), (r10, r11, r12), (r20, r21, r22) = R.tolist()
    if not _is_rotation(r00, r01, r02, r10, r11, r12, r20, r21, r22):
        return Rotation.from_matrix(R).as_rotvec()
    trace = r00 + r11 + r22
    best = max(r00, r11, r22, trace)  # the first of equals, as argmax picks it
    if best == r00:
        q = (1.0 - trace + 2.0 * r00, r10 + r01, r20 + r02, r21 - r12)
    elif best == r11:
        q = (r10 + r01, 1.0 - trace + 2.0 * r11, r21 + r12, r02 - r20)
    elif best == r22:
        q = (r20 + r02, r21 + r12, 1.0 - trace + 2.0 * r22, r10 - r01)
    else:
        q = (r21 - r12, r02 - r20, r10 - r01, 1.0 + trace)
    norm = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    x, y, z, w = (c / norm for c in q)
    if w < 0.0 or (w == 0.0 and (x < 0.0 or (x == 0.0 and (y < 0.0 or (y == 0.0 and z < 0.0))))):
        x, y, z, w = -x, -y, -z, -w
    angle = 2.0 * math.atan2(math.sqrt(x * x + y * y + z * z), w)
    if angle <= 1e-3:
        angle2 = angle * angle
        scale = 2.0 + angle2 / 12.0 + 7.0 * angle2 * angle2 / 2880.0
    else:
        scale = angle / math.sin(angle / 2.0)
    return np.array([scale * x, scale * y, scale * z])


def _is_rotation(*m: float) -> bool:
    """Whether the row-major 3x3 `m` is what scipy takes as a rotation without change: det > 0 and
    R Rᵀ within 1e-12 + 1e-5·I of I elementwise (numpy's `isclose` with atol 1e-12)."""
    r0, r1, r2 = m[0:3], m[3:6], m[6:9]
    det = (
        r0[0] * (r1[1] * r2[2] - r1[2] * r2[1])
        - r0[1] * (r1[0] * r2[2] - r1[2] * r2[0])
        + r0[2] * (r1[0] * r2[1] - r1[1] * r2[0])
    )
    if not det > 0.0:
        return False
    rows = (r0, r1, r2)
    for i in range(3):
        for j in range(i, 3):
            a, b = rows[i], rows[j]
            gram = a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
            if i == j:
                if not abs(gram - 1.0) <= 1e-12 + 1e-5:
                    return False
            elif not abs(gram) <= 1e-12:
                return False
    return True


def euler_zyx_to_matrix(z: float, y: float, x: float) -> Rot3:
    """R = Rz(z) · Ry(y) · Rx(x): intrinsic ZYX Euler angles [rad], the seed's convention (3.C)."""
    return Rotation.from_euler("ZYX", [z, y, x]).as_matrix()


def matrix_to_euler_zyx(R: npt.ArrayLike) -> tuple[float, float, float]:
    """(z, y, x) with R = Rz(z) · Ry(y) · Rx(x); y in [-π/2, π/2]. At y = ±π/2 (gimbal lock) x is 0."""
    R = np.asarray(R, dtype=np.float64).reshape(3, 3)
    cos_y = math.hypot(R[0, 0], R[1, 0])
    y = math.atan2(-R[2, 0], cos_y)  # atan2 stays accurate near ±π/2, where asin does not
    if cos_y > 1e-9:
        z = math.atan2(R[1, 0], R[0, 0])
        x = math.atan2(R[2, 1], R[2, 2])
    else:  # gimbal lock: only z ± x is defined; put it all in z
        z = math.atan2(-R[0, 1], R[1, 1])
        x = 0.0
    return z, y, x


def rotate_wrench(R_AB: Rot3, w_B: Wrench) -> Wrench:
    """The same wrench, same reference point, re-expressed in A: f_A = R_AB f_B, τ_A = R_AB τ_B."""
    return np.concatenate([R_AB @ w_B[:3], R_AB @ w_B[3:]])


def shift_wrench(w: Wrench, p_OQ: Vec3) -> Wrench:
    """Move a wrench's reference point from O to Q (both vectors in the wrench's frame).

    τ_Q = τ_O - p_OQ × f ;  f unchanged.
    """
    return np.concatenate([w[:3], w[3:] - cross3(p_OQ, w[:3])])


def transform_wrench(R_AB: Rot3, p_AB_A: Vec3, w_B: Wrench) -> Wrench:
    """A wrench about B's origin, expressed in B, as the same wrench about A's origin, expressed in A.

    f_A = R_AB f_B ;  τ_A = R_AB τ_B + p_AB_A × f_A
    """
    f_A = R_AB @ w_B[:3]
    return np.concatenate([f_A, R_AB @ w_B[3:] + cross3(p_AB_A, f_A)])


# --- The seed's alignment rotations (section 3.C), as printed ----------------------------------
#
# Each maps a sensor's readings into the robot base frame B at the seed's home pose (probe pointing
# down), i.e. it is R_B<sensor> there. Our estimator takes the wrist sensor's orientation R_BS from the
# robot at every tick instead of a constant; these constants are its value at home, and R_SP_SEED is the
# fixed mounting of the probe sensor relative to the wrist sensor that eq. 1 and eq. 2 imply.

R_BS_EQ1: Rot3 = frozen([[0, 1, 0], [-1, 0, 0], [0, 0, 1]])
"""Eq. 1: Robotiq FT-150 (frame S): z along base z, x/y turned -π/2 about z; ZYX (-π/2, 0, 0)."""

R_BP_EQ2: Rot3 = frozen([[0, -1, 0], [0, 0, -1], [1, 0, 0]])
"""Eq. 2: Variense FSE103 (frame P), mounted sideways: x along base z; ZYX (π/2, -π/2, 0)."""

R_BL_EQ3: Rot3 = frozen([[-1, 0, 0], [0, 1, 0], [0, 0, -1]])
"""Eq. 3: Honeywell Model 31 load cell (frame L): z against base z; one of many; ZYX (0, π, 0)."""

SEED_EULER_ZYX: dict[str, tuple[float, float, float]] = {
    "R_BS_EQ1": (-math.pi / 2, 0.0, 0.0),
    "R_BP_EQ2": (math.pi / 2, -math.pi / 2, 0.0),
    "R_BL_EQ3": (0.0, math.pi, 0.0),
}
"""The ZYX Euler angles (z, y, x) the seed states beside each matrix."""

R_SP_SEED: Rot3 = frozen(R_BS_EQ1.T @ R_BP_EQ2)
"""Probe sensor P in wrist sensor S implied by eq. 1 and eq. 2: R_SP = R_BSᵀ R_BP."""
