"""Rotations, wrench algebra and the seed's alignment rotations (seed 000, section 3.C)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from hoh_cosim.control.frames import (
    R_BL_EQ3,
    R_BP_EQ2,
    R_BS_EQ1,
    R_SP_SEED,
    SEED_EULER_ZYX,
    euler_zyx_to_matrix,
    matrix_to_euler_zyx,
    matrix_to_rotvec,
    rotate_wrench,
    rotvec_to_matrix,
    shift_wrench,
    skew,
    transform_wrench,
)
from hoh_cosim.control.vectors import cross3


def Rx(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def Ry(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def Rz(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


SEED_MATRICES = {"R_BS_EQ1": R_BS_EQ1, "R_BP_EQ2": R_BP_EQ2, "R_BL_EQ3": R_BL_EQ3}


@pytest.mark.parametrize("name", sorted(SEED_MATRICES))
def test_seed_rotation_equals_its_stated_zyx_euler_angles(name):
    z, y, x = SEED_EULER_ZYX[name]
    np.testing.assert_allclose(SEED_MATRICES[name], euler_zyx_to_matrix(z, y, x), atol=1e-12)
    # and the same product of elementary rotations, written out independently of scipy
    np.testing.assert_allclose(SEED_MATRICES[name], Rz(z) @ Ry(y) @ Rx(x), atol=1e-12)


def test_seed_rotations_are_printed_as_in_the_seed():
    np.testing.assert_array_equal(R_BS_EQ1, [[0, 1, 0], [-1, 0, 0], [0, 0, 1]])  # eq. 1
    np.testing.assert_array_equal(R_BP_EQ2, [[0, -1, 0], [0, 0, -1], [1, 0, 0]])  # eq. 2
    np.testing.assert_array_equal(R_BL_EQ3, [[-1, 0, 0], [0, 1, 0], [0, 0, -1]])  # eq. 3


@pytest.mark.parametrize("R", [R_BS_EQ1, R_BP_EQ2, R_BL_EQ3, R_SP_SEED])
def test_seed_rotations_are_proper_rotations(R):
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-15)
    assert np.linalg.det(R) == pytest.approx(1.0)


def test_seed_constants_cannot_be_modified():
    with pytest.raises(ValueError, match="read-only"):
        R_BS_EQ1[0, 0] = 5.0


def test_probe_mounting_maps_probe_readings_like_eq2():
    # a probe reading turned into S by R_SP, then into B by eq. 1, equals eq. 2 applied directly
    f_P = np.array([1.0, -2.0, 3.0])
    np.testing.assert_allclose(R_BS_EQ1 @ (R_SP_SEED @ f_P), R_BP_EQ2 @ f_P, atol=1e-15)


def test_eq1_turns_sensor_x_into_minus_base_y():
    # "x/y axes rotated -π/2 about the z-axis": a push along the sensor's x is along -y of the base
    np.testing.assert_allclose(R_BS_EQ1 @ [1.0, 0.0, 0.0], [0.0, -1.0, 0.0])


def test_rotvec_quarter_turn_about_x():
    R = rotvec_to_matrix([math.pi / 2, 0.0, 0.0])
    np.testing.assert_allclose(R, Rx(math.pi / 2), atol=1e-15)
    np.testing.assert_allclose(matrix_to_rotvec(R), [math.pi / 2, 0, 0], atol=1e-15)


def test_rotvec_zero_is_identity():
    np.testing.assert_array_equal(rotvec_to_matrix([0.0, 0.0, 0.0]), np.eye(3))


def test_rotvec_of_a_half_turn_has_angle_pi():
    R = Rz(math.pi)
    assert np.linalg.norm(matrix_to_rotvec(R)) == pytest.approx(math.pi)


def test_rotvec_matches_rodrigues(rng):
    for _ in range(50):
        r = rng.uniform(-3.0, 3.0, 3)
        theta = np.linalg.norm(r)
        K = skew(r / theta)
        rodrigues = np.eye(3) + math.sin(theta) * K + (1 - math.cos(theta)) * K @ K
        np.testing.assert_allclose(rotvec_to_matrix(r), rodrigues, atol=1e-13)


def test_rotvec_of_a_matrix_equals_scipys_to_the_bit(rng):
    # random rotations, products like the servo loops form, and the edge cases of the
    # quaternion's four branches and of the small-angle series (1 mrad)
    matrices = list(Rotation.random(2000, random_state=7).as_matrix())
    for angle in (0.0, 1e-12, 1e-6, 0.999e-3, 1e-3, 1.001e-3, 0.5, math.pi / 2, math.pi - 1e-8):
        for _ in range(20):
            axis = rng.normal(size=3)
            matrices.append(rotvec_to_matrix(angle * axis / np.linalg.norm(axis)))
    for _ in range(200):
        A, B = Rotation.random(2, random_state=int(rng.integers(1 << 30))).as_matrix()
        matrices.append(A @ B.T)
    matrices += [np.eye(3), Rx(math.pi), Ry(math.pi), Rz(math.pi)]
    for R in matrices:
        np.testing.assert_array_equal(matrix_to_rotvec(R), Rotation.from_matrix(R).as_rotvec())


def test_rotvec_of_a_matrix_that_is_no_rotation_is_scipys_too():
    almost = Rz(0.3) + 1e-9  # scipy orthogonalises it first
    np.testing.assert_array_equal(
        matrix_to_rotvec(almost), Rotation.from_matrix(almost).as_rotvec()
    )
    with pytest.raises(ValueError, match="determinant"):
        matrix_to_rotvec(np.diag([1.0, 1.0, -1.0]))


angles = st.floats(-math.pi, math.pi, allow_nan=False)


@given(angles, st.floats(-1.5, 1.5), angles)
def test_euler_zyx_round_trip(z, y, x):
    R = euler_zyx_to_matrix(z, y, x)
    np.testing.assert_allclose(euler_zyx_to_matrix(*matrix_to_euler_zyx(R)), R, atol=1e-12)


def test_euler_at_gimbal_lock_still_round_trips():
    R = euler_zyx_to_matrix(0.3, math.pi / 2, -0.2)
    np.testing.assert_allclose(euler_zyx_to_matrix(*matrix_to_euler_zyx(R)), R, atol=1e-12)


@given(st.lists(st.floats(-1e3, 1e3), min_size=6, max_size=6))
def test_skew_and_cross3_agree_with_numpy_cross(values):
    a, b = np.array(values[:3]), np.array(values[3:])
    np.testing.assert_allclose(skew(a) @ b, np.cross(a, b), rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(cross3(a, b), np.cross(a, b), rtol=1e-12, atol=1e-9)


def test_rotate_wrench_turns_force_and_torque_alike():
    w = np.array([1.0, 2.0, 3.0, 0.1, 0.2, 0.3])
    out = rotate_wrench(R_BS_EQ1, w)
    np.testing.assert_allclose(out, [2.0, -1.0, 3.0, 0.2, -0.1, 0.3])


def test_shift_wrench_moment_about_new_point():
    # a 10 N force along x through O; about Q = (0, 0.1, 0) it has a moment of -p × f = +1 N·m along z
    w = np.array([10.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    np.testing.assert_allclose(shift_wrench(w, [0.0, 0.1, 0.0]), [10, 0, 0, 0, 0, 1.0])


def test_transform_wrench_equals_rotate_then_shift(rng):
    for _ in range(20):
        R_AB = rotvec_to_matrix(rng.normal(size=3))
        p_AB_A = rng.normal(size=3)
        w_B = rng.normal(size=6)
        expected = shift_wrench(rotate_wrench(R_AB, w_B), -p_AB_A)
        np.testing.assert_allclose(transform_wrench(R_AB, p_AB_A, w_B), expected, atol=1e-12)


def test_transform_wrench_preserves_the_moment_about_any_point(rng):
    R_AB = rotvec_to_matrix(rng.normal(size=3))
    p_AB_A = rng.normal(size=3)
    w_B = rng.normal(size=6)
    w_A = transform_wrench(R_AB, p_AB_A, w_B)
    q_A = rng.normal(size=3)  # any point, in A
    q_B = R_AB.T @ (q_A - p_AB_A)  # the same point, in B
    moment_A = w_A[3:] - np.cross(q_A, w_A[:3])
    moment_B = R_AB @ (w_B[3:] - np.cross(q_B, w_B[:3]))
    np.testing.assert_allclose(moment_A, moment_B, atol=1e-12)
