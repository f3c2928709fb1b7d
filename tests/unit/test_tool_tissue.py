"""The tool's loads on the sensors (Newton–Euler, cable drag) and the phantom's contact force."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from hoh_cosim.control.frames import R_BS_EQ1, rotvec_to_matrix
from hoh_cosim.control.gravity import ToolParams, identify_gravity, tool_weight_wrench_S
from hoh_cosim.control.vectors import GRAVITY_B
from hoh_cosim.errors import ConfigError
from plant_models.arm import HOME_Q, ArmParams
from plant_models.plant import Plant, PlantParams
from plant_models.tissue import PhantomParams, contact_force, surface_depth
from plant_models.tool import CableDrag, ToolLoads, ToolModel
from tests.poses import seed_like_poses

Z3 = np.zeros(3)
TOOL = ToolModel()
AS_ESTIMATOR_SEES_IT = ToolParams(TOOL.mass_kg, TOOL.p_SC_S)


@pytest.mark.parametrize("tilt", [[0, 0, 0], [0.4, 0, 0], [0, -0.7, 0.2], [1.2, 0.3, -0.5]])
def test_plant_at_rest_reads_the_estimators_weight_model(tilt):
    q0 = HOME_Q + np.array([0, 0, 0, *tilt])
    out = Plant(PlantParams(arm=ArmParams(q0=q0))).outputs_now
    R_BS = out["R_BS"].reshape(3, 3)
    np.testing.assert_allclose(
        out["wrench_S"], tool_weight_wrench_S(R_BS, AS_ESTIMATOR_SEES_IT), atol=1e-12
    )


def test_hand_force_reaches_the_wrist_with_its_moment_arm():
    loads = ToolLoads(TOOL, GRAVITY_B)
    F_hand = np.array([3.0, -1.0, 2.0])
    w, f_P = loads.readings(R_BS_EQ1, Z3, Z3, Z3, F_hand, Z3, Z3)
    weight = tool_weight_wrench_S(R_BS_EQ1, AS_ESTIMATOR_SEES_IT)
    F_S = R_BS_EQ1.T @ F_hand
    np.testing.assert_allclose(
        w - weight, np.concatenate([F_S, np.cross(TOOL.p_SH_S, F_S)]), atol=1e-12
    )
    np.testing.assert_array_equal(f_P, 0.0)  # the hand is above the probe sensor


def test_contact_reaches_both_sensors():
    loads = ToolLoads(TOOL, GRAVITY_B)
    F_c = np.array([0.5, -0.2, 9.0])
    w, f_P = loads.readings(R_BS_EQ1, Z3, Z3, Z3, Z3, Z3, F_c)
    F_S = R_BS_EQ1.T @ F_c
    weight = tool_weight_wrench_S(R_BS_EQ1, AS_ESTIMATOR_SEES_IT)
    np.testing.assert_allclose(
        w - weight, np.concatenate([F_S, np.cross(TOOL.p_ST_S, F_S)]), atol=1e-12
    )
    np.testing.assert_allclose(f_P, (R_BS_EQ1 @ TOOL.R_SP).T @ F_c, atol=1e-12)


def test_acceleration_loads_the_wrist_like_extra_gravity():
    # accelerating up at a feels like gravity g + a: the tool's inertia
    loads = ToolLoads(TOOL, GRAVITY_B)
    a = np.array([0.3, -0.2, 1.0])
    w, _ = loads.readings(R_BS_EQ1, a, Z3, Z3, Z3, Z3, Z3)
    heavier = ToolLoads(TOOL, GRAVITY_B - a).readings(R_BS_EQ1, Z3, Z3, Z3, Z3, Z3, Z3)[0]
    np.testing.assert_allclose(w, heavier, atol=1e-12)


def test_angular_acceleration_takes_inertia_torque():
    loads = ToolLoads(TOOL, GRAVITY_B)
    alpha_S = np.array([0.0, 0.0, 10.0])
    w, _ = loads.readings(R_BS_EQ1, Z3, Z3, R_BS_EQ1 @ alpha_S, Z3, Z3, Z3)
    w0, _ = loads.readings(R_BS_EQ1, Z3, Z3, Z3, Z3, Z3, Z3)
    np.testing.assert_allclose(w[3:] - w0[3:], -TOOL.inertia_C_S * alpha_S, atol=1e-15)


def test_the_wrist_feels_the_arm_accelerate():
    plant = Plant(PlantParams(arm=ArmParams(rate_hz=500.0, acceleration=1.0)))
    still = plant.outputs_now["wrench_S"]
    out = None
    for k in range(20):  # speeding up along x at 1 m/s²
        out = plant.step(
            k * 1e-3,
            1e-3,
            {
                "twist_cmd_B": np.array([0.1, 0, 0, 0, 0, 0]),
                "F_hand_B": Z3,
                "tau_hand_B": Z3,
                "F_tip_B": Z3,
            },
        )
    felt_B = R_BS_EQ1 @ (out["wrench_S"][:3] - still[:3])
    np.testing.assert_allclose(felt_B, [-TOOL.mass_kg * 1.0, 0, 0], atol=0.01)


def _tilt_y_axis(elevation_deg: float, azimuth_deg: float) -> np.ndarray:
    """R_BS with the sensor's y axis `elevation_deg` above the horizontal, turned about vertical."""
    R = rotvec_to_matrix([0.0, -math.radians(elevation_deg), 0.0]) @ R_BS_EQ1  # y_S up
    return rotvec_to_matrix([0.0, 0.0, math.radians(azimuth_deg)]) @ R


def _compensation_residual(tool: ToolModel, poses, probe) -> np.ndarray:
    """Readings at `poses` with the tool's cable, compensated with a model identified from them."""
    loads = ToolLoads(tool, GRAVITY_B)
    p_BS = np.array([-0.10, -0.45, 0.4875])  # the sensor at home

    def reading(R):
        p_BK = p_BS + R @ tool.cable.p_SK_S
        return loads.readings(R, Z3, Z3, Z3, Z3, Z3, Z3, p_BK)[0]

    R_all = seed_like_poses()
    cal = identify_gravity(R_all, np.array([reading(R) for R in R_all]))
    return np.array([reading(R) - cal.bias - tool_weight_wrench_S(R, cal.tool) for R in probe])


def test_cable_drag_makes_45_and_135_degrees_differ_after_compensation():
    # seed 5.B: F_y compensated well except with the y axis 135° from the horizontal, not at 45°
    probe = [_tilt_y_axis(45.0, 0.0), _tilt_y_axis(45.0, 180.0)]  # 45° and 135°
    dragged = ToolModel(cable=CableDrag(enabled=True))
    with_cable = _compensation_residual(dragged, seed_like_poses(), probe)
    without = _compensation_residual(TOOL, seed_like_poses(), probe)
    assert abs(with_cable[0, 1] - with_cable[1, 1]) > 0.1  # N
    np.testing.assert_allclose(without, 0.0, atol=1e-9)  # the weight model alone is exact


def test_cable_drag_is_off_by_default():
    assert not ToolModel().cable.enabled


# --- the phantom ---------------------------------------------------------------------------

PLANE = PhantomParams()
SPHERE_ISH = PhantomParams(
    shape="ellipsoid", ellipsoid_center_B=[0, 0, 0], ellipsoid_axes=[0.2, 0.15, 0.25]
)


def test_hertz_figures_of_the_gel_phantom():
    f1 = contact_force(PLANE, np.array([0, 0, -0.01]), Z3).force_B
    f2 = contact_force(PLANE, np.array([0, 0, -0.02]), Z3).force_B
    np.testing.assert_allclose(f1, [0, 0, 7.5], atol=1e-9)
    np.testing.assert_allclose(f2, [0, 0, 7.5 * 2**1.5], atol=1e-9)


@pytest.mark.parametrize("phantom", [PLANE, SPHERE_ISH])
@given(height=st.floats(1e-6, 0.5), v=st.lists(st.floats(-1, 1), min_size=3, max_size=3))
def test_no_force_out_of_contact(phantom, height, v):
    _, n = surface_depth(phantom, np.array([0.0, 0.0, 0.25]))
    surface = np.array([0.0, 0.0, 0.0 if phantom is PLANE else 0.25])
    contact = contact_force(phantom, surface + height * n, np.array(v))
    np.testing.assert_array_equal(contact.force_B, 0.0)


@given(d1=st.floats(1e-5, 0.05), d2=st.floats(1e-5, 0.05))
def test_force_grows_with_depth(d1, d2):
    lo, hi = sorted((d1, d2))
    f_lo = contact_force(PLANE, np.array([0, 0, -lo]), Z3).force_B[2]
    f_hi = contact_force(PLANE, np.array([0, 0, -hi]), Z3).force_B[2]
    assert f_hi >= f_lo > 0.0
    if hi > lo * (1 + 1e-9):
        assert f_hi > f_lo


@given(depth=st.floats(1e-5, 0.05), v_out=st.floats(0.0, 5.0))
def test_never_pulls_even_when_leaving_fast(depth, v_out):
    force = contact_force(PLANE, np.array([0, 0, -depth]), np.array([0, 0, v_out])).force_B
    assert force[2] >= 0.0


@given(v=st.lists(st.floats(-0.5, 0.5), min_size=2, max_size=2))
def test_friction_opposes_sliding(v):
    v_t = np.array([v[0], v[1], 0.0])
    contact = contact_force(PLANE, np.array([0, 0, -0.01]), v_t)
    F_n = contact.force_B[2]
    F_t = contact.force_B[:2]
    speed = np.linalg.norm(v_t)
    if speed > 1e-9:
        assert float(F_t @ v_t[:2]) < 0.0
        assert np.linalg.norm(F_t) <= PLANE.friction * F_n + PLANE.viscous_friction * speed + 1e-12
        cross_z = F_t[0] * v_t[1] - F_t[1] * v_t[0]
        assert cross_z == pytest.approx(0.0, abs=1e-9)  # straight against it


def test_ellipsoid_depth_is_zero_on_its_surface_and_grows_inside():
    for point in ([0.2, 0, 0], [0, -0.15, 0], [0, 0, 0.25]):
        depth, n = surface_depth(SPHERE_ISH, np.array(point, dtype=float))
        assert depth == pytest.approx(0.0, abs=1e-12)
        np.testing.assert_allclose(n, np.array(point) / np.linalg.norm(point), atol=1e-12)
    assert surface_depth(SPHERE_ISH, np.array([0, 0, 0.23]))[0] == pytest.approx(0.02, rel=0.05)


def test_phantom_params_are_checked():
    with pytest.raises(ConfigError, match=r"shape: expected one of plane, ellipsoid, none"):
        PhantomParams(shape="cube")
    with pytest.raises(ConfigError, match=r"stiffness must be > 0.0, got 0.0"):
        PhantomParams(stiffness=0.0)
