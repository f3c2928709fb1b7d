"""Tool-weight model, rebias and identification (seed 000, sections 3.B.1, 3.D and 4.B)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hoh_cosim.control.frames import R_BS_EQ1, rotvec_to_matrix
from hoh_cosim.control.gravity import (
    SEED_TOOL,
    GravityModel,
    ToolParams,
    compensate_gravity,
    identify_gravity,
    identify_seed_two_step,
    rebias,
    tool_weight_wrench_S,
)
from hoh_cosim.control.vectors import GRAVITY_B
from hoh_cosim.errors import ConfigError, IdentificationError
from tests.poses import SEED_NOISE_SIGMA, TRUE_BIAS, seed_like_poses, synthetic_readings

SEED_MG = 4.7631  # [N] seed 4.B
SEED_COM_XY = (-0.01250, -0.00033)  # [m] seed 4.B


def test_weight_at_identity_is_mg_down_with_moment_p_cross_f():
    tool = ToolParams(0.5, [0.01, -0.02, 0.1])
    w = tool_weight_wrench_S(np.eye(3), tool)
    np.testing.assert_allclose(w[:3], [0, 0, -0.5 * 9.81])
    np.testing.assert_allclose(w[3:], np.cross(tool.p_SC_S, w[:3]))


def test_weight_in_sensor_frame_at_seed_home():
    # at the seed's home (eq. 1) gravity is along -z of S too, and the seed's p_COM,xy gives
    # τ = p × f = (p_y·(-mg), -p_x·(-mg), 0)
    w = tool_weight_wrench_S(R_BS_EQ1, SEED_TOOL)
    mg = SEED_MG
    np.testing.assert_allclose(
        w, [0, 0, -mg, SEED_COM_XY[1] * -mg, -SEED_COM_XY[0] * -mg, 0], atol=1e-12
    )


def test_weight_for_any_gravity_direction(rng):
    # turning the whole world (gravity and the sensor) by Q leaves the sensor's reading unchanged
    tool = ToolParams(0.7, [0.02, 0.01, 0.08])
    for _ in range(20):
        R_BS = rotvec_to_matrix(rng.normal(size=3))
        Q = rotvec_to_matrix(rng.normal(size=3))
        np.testing.assert_allclose(
            tool_weight_wrench_S(Q @ R_BS, tool, Q @ GRAVITY_B),
            tool_weight_wrench_S(R_BS, tool, GRAVITY_B),
            atol=1e-12,
        )


def test_gravity_model_equals_the_pure_function(rng):
    tool = ToolParams(0.48, [-0.0125, -0.0003, 0.06])
    g = np.array([0.3, -0.2, -9.8])
    model = GravityModel(tool, g)
    for _ in range(20):
        R = rotvec_to_matrix(rng.normal(size=3))
        np.testing.assert_allclose(model.weight_S(R), tool_weight_wrench_S(R, tool, g), atol=1e-14)


def test_compensation_returns_the_hand_wrench(rng):
    R = rotvec_to_matrix([0.4, -0.3, 0.2])
    hand = np.array([2.0, -1.0, 0.5, 0.05, 0.0, -0.02])
    reading = hand + TRUE_BIAS + tool_weight_wrench_S(R, SEED_TOOL)
    np.testing.assert_allclose(
        compensate_gravity(reading, R, SEED_TOOL, TRUE_BIAS), hand, atol=1e-12
    )


def test_rebias_with_tool_model_gives_the_sensor_offset(rng):
    R = rotvec_to_matrix([0.5, 0.2, -1.0])
    samples = (
        tool_weight_wrench_S(R, SEED_TOOL) + TRUE_BIAS + rng.normal(0, SEED_NOISE_SIGMA, (500, 6))
    )
    bias = rebias(samples, R, SEED_TOOL)
    assert np.all(np.abs(bias - TRUE_BIAS) < 4 * SEED_NOISE_SIGMA / math.sqrt(500))


def test_rebias_without_tool_is_the_plain_average_of_the_seed(rng):
    samples = rng.normal(size=(500, 6))
    np.testing.assert_array_equal(rebias(samples), samples.mean(axis=0))


def test_rebias_rejects_no_samples():
    with pytest.raises(ConfigError, match=r"rebias: expected samples as an \(N, k\) array"):
        rebias(np.zeros((0, 6)))


def test_tool_params_reject_negative_mass():
    with pytest.raises(ConfigError, match=r"mass_kg must be >= 0.0, got -1.0"):
        ToolParams(-1.0)


def test_tool_params_reject_wrong_com_size():
    with pytest.raises(ConfigError, match=r"p_SC_S: expected 3 values, got 2"):
        ToolParams(0.5, [0.0, 0.1])


# --- identification ------------------------------------------------------------------------


def test_full_identification_recovers_the_seed_tool(rng):
    # the seed's procedure: 32 poses, 1000 averaged samples each, seed-sized noise
    tool = ToolParams(0.48, [-0.0125, -0.00033, 0.065])
    R = seed_like_poses()
    cal = identify_gravity(R, synthetic_readings(R, tool, rng))
    assert abs(cal.mass_kg - 0.48) / 0.48 < 0.005
    assert np.linalg.norm(cal.com_m - tool.p_SC_S) < 0.002
    np.testing.assert_allclose(cal.force_bias_N, TRUE_BIAS[:3], atol=0.01)
    np.testing.assert_allclose(cal.torque_bias_Nm, TRUE_BIAS[3:], atol=0.001)
    assert cal.n_poses == 32
    assert 1.0 <= cal.condition_number < 10.0


def test_full_identification_is_exact_without_noise():
    tool = ToolParams(0.48, [-0.0125, -0.00033, 0.065])
    R = seed_like_poses()
    cal = identify_gravity(R, synthetic_readings(R, tool, np.random.default_rng(0), sigma=0.0))
    assert cal.mass_kg == pytest.approx(0.48, rel=1e-12)
    np.testing.assert_allclose(cal.com_m, tool.p_SC_S, atol=1e-12)
    np.testing.assert_allclose(cal.bias, TRUE_BIAS, atol=1e-12)
    np.testing.assert_allclose(cal.residual_rms_after, 0.0, atol=1e-12)


def test_residuals_before_are_the_tool_weight_and_after_are_the_noise(rng):
    R = seed_like_poses()
    cal = identify_gravity(R, synthetic_readings(R, SEED_TOOL, rng))
    weight = np.array([tool_weight_wrench_S(Ri, SEED_TOOL) for Ri in R])
    np.testing.assert_allclose(
        cal.residual_max_before, np.abs(weight).max(axis=0), rtol=0.01, atol=0.002
    )
    assert np.all(cal.residual_rms_after < 4 * SEED_NOISE_SIGMA / math.sqrt(1000))


def test_standard_errors_are_honest():
    # over many noisy identifications, the error should exceed 2 SE about 5 % of the time
    rng = np.random.default_rng(7)
    tool = ToolParams(0.48, [-0.0125, -0.00033, 0.065])
    R = seed_like_poses()
    inside_mass = inside_com = 0
    runs = 200
    for _ in range(runs):
        cal = identify_gravity(R, synthetic_readings(R, tool, rng, samples_per_pose=1))
        inside_mass += abs(cal.mass_kg - tool.mass_kg) < 2 * cal.mass_se_kg
        inside_com += np.all(np.abs(cal.com_m - tool.p_SC_S) < 2 * cal.com_se_m)
    assert 0.90 <= inside_mass / runs <= 0.99
    assert 0.80 <= inside_com / runs <= 0.97  # three coordinates inside at once: 0.95³ ≈ 0.86


def test_seed_two_step_round_trips_the_seed_figures():
    # the seed's data were rebiased at the probe-down home pose (3.B.1)
    R = seed_like_poses()
    readings = synthetic_readings(
        R, SEED_TOOL, np.random.default_rng(0), bias=np.zeros(6), sigma=0.0
    )
    readings -= tool_weight_wrench_S(R_BS_EQ1, SEED_TOOL)  # rebiased at home
    result = identify_seed_two_step(R, readings, R_BS_EQ1)
    assert result.mg_N == pytest.approx(SEED_MG, abs=1e-9)
    np.testing.assert_allclose(result.com_xy_m, SEED_COM_XY, atol=1e-12)
    assert result.tool.mass_kg == pytest.approx(SEED_TOOL.mass_kg)


def test_seed_two_step_with_seed_noise_is_within_a_milligram_and_a_tenth_mm(rng):
    R = seed_like_poses()
    readings = synthetic_readings(R, SEED_TOOL, rng, bias=np.zeros(6))
    readings -= tool_weight_wrench_S(R_BS_EQ1, SEED_TOOL)
    result = identify_seed_two_step(R, readings, R_BS_EQ1)
    assert result.mg_N == pytest.approx(SEED_MG, abs=0.005)
    np.testing.assert_allclose(result.com_xy_m, SEED_COM_XY, atol=1e-4)


def test_full_identification_of_seed_tool_gives_seed_mg(rng):
    R = seed_like_poses()
    cal = identify_gravity(R, synthetic_readings(R, SEED_TOOL, rng))
    assert cal.mass_kg * 9.81 == pytest.approx(SEED_MG, abs=0.005)
    np.testing.assert_allclose(cal.com_m[:2], SEED_COM_XY, atol=2e-4)


def test_too_few_poses_is_refused(rng):
    R = seed_like_poses()[:4]
    with pytest.raises(
        IdentificationError, match=r"need at least 10 poses for the 10 unknowns .* got 4"
    ):
        identify_gravity(R, synthetic_readings(R, SEED_TOOL, rng))


def test_identical_orientations_are_refused(rng):
    R = np.repeat(R_BS_EQ1[np.newaxis], 12, axis=0)
    with pytest.raises(
        IdentificationError, match=r"too alike to separate the mass from the force bias"
    ):
        identify_gravity(R, synthetic_readings(R, SEED_TOOL, rng))


def test_orientations_turned_only_about_gravity_are_refused(rng):
    # spinning the tool about the vertical never changes gravity in S: mass and bias inseparable
    R = np.array([rotvec_to_matrix([0, 0, a]) @ R_BS_EQ1 for a in np.linspace(0, 3, 12)])
    with pytest.raises(IdentificationError, match=r"too alike to separate the mass"):
        identify_gravity(R, synthetic_readings(R, SEED_TOOL, rng))


def test_two_orientations_cannot_give_the_centre_of_mass(rng):
    # two distinct gravity directions separate mass from bias but not the centre of mass
    R = np.array([R_BS_EQ1, rotvec_to_matrix([0.6, 0, 0]) @ R_BS_EQ1] * 6)
    with pytest.raises(
        IdentificationError, match=r"too alike to separate the centre of mass from the torque bias"
    ):
        identify_gravity(R, synthetic_readings(R, SEED_TOOL, rng))


def test_flipped_sensor_sign_gives_an_implausible_mass(rng):
    R = seed_like_poses()
    with pytest.raises(IdentificationError, match=r"implausible mass -0.48\d* kg"):
        identify_gravity(R, -synthetic_readings(R, SEED_TOOL, rng))


def test_a_far_centre_of_mass_is_implausible(rng):
    R = seed_like_poses()
    tool = ToolParams(0.48, [0.6, 0.0, 0.0])
    with pytest.raises(IdentificationError, match=r"implausible centre of mass \[0.6"):
        identify_gravity(R, synthetic_readings(R, tool, rng))


def test_pose_set_shapes_are_checked():
    with pytest.raises(ConfigError, match=r"got 3 orientations but 2 wrenches"):
        identify_gravity(np.tile(np.eye(3), (3, 1, 1)), np.zeros((2, 6)))
