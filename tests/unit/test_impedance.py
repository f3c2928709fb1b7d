"""Seed 001's Cartesian impedance and the UR5's position-based impedance, block by block."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hoh_cosim.control.frames import rotvec_to_matrix
from hoh_cosim.control.impedance import (
    CartesianImpedance,
    ImpedanceParams,
    PositionImpedance,
    PositionImpedanceParams,
    SlideTask,
    rpy_angles,
    rpy_rate_matrix,
)
from hoh_cosim.errors import ConfigError
from plant_models.panda import PandaParams, PandaPlant
from plant_models.tissue import PhantomParams

FREE = PhantomParams(shape="none")
PORTS = ("qd", "B", "C", "F", "J", "p_BT_B", "R_BT")


def run(plant: PandaPlant, ctl: CartesianImpedance, seconds: float, dt: float = 1e-3):
    out = plant.initial_outputs()
    rows = []
    for k in range(round(seconds / dt)):
        command = ctl.step(k * dt, dt, {n: out[n] for n in PORTS})
        out = plant.step(k * dt, dt, {"tau_cmd": command["tau_cmd"]})
        rows.append((out, command))
    return rows


def euler_rpy(phi, theta, psi):
    return (
        rotvec_to_matrix([0, 0, psi])
        @ rotvec_to_matrix([0, theta, 0])
        @ rotvec_to_matrix([phi, 0, 0])
    )


@pytest.mark.parametrize("angles", [(0.1, -0.2, 0.3), (-1.0, 1.2, 2.5), (0.0, 0.0, 0.0)])
def test_rpy_angles_invert_rz_ry_rx(angles):
    np.testing.assert_allclose(rpy_angles(euler_rpy(*angles)), angles, atol=1e-12)


def test_rpy_rate_matrix_maps_angle_rates_to_angular_velocity():
    rng = np.random.default_rng(4)
    angles, rates = rng.uniform(-1.0, 1.0, 3), rng.normal(size=3)
    h = 1e-6
    R0, R1 = euler_rpy(*(angles - h * rates)), euler_rpy(*(angles + h * rates))
    skew = (R1 - R0) / (2 * h) @ euler_rpy(*angles).T  # Ṙ Rᵀ = [ω]×
    omega = np.array([skew[2, 1], skew[0, 2], skew[1, 0]])
    np.testing.assert_allclose(rpy_rate_matrix(angles) @ rates, omega, atol=1e-8)


def test_the_task_presses_then_slides():
    task = SlideTask(approach_start_s=1.0, slide_start_s=2.0)
    start = np.array([0.3, 0.0, 0.4])
    np.testing.assert_array_equal(task.reference(0.5, start)[0], start)
    p, v, _ = task.reference(1.5, start)
    np.testing.assert_allclose(p, [0.3, 0.0, 0.4 - 0.0754])
    np.testing.assert_array_equal(v, 0.0)
    p, v, a = task.reference(2.0 + 1 / (4 * 0.3), start)  # a quarter period into the slide
    np.testing.assert_allclose(p, [0.3, 0.05, 0.4 - 0.0754], atol=1e-12)
    np.testing.assert_allclose(v, 0.0, atol=1e-12)
    np.testing.assert_allclose(a, [0.0, -0.05 * (2 * math.pi * 0.3) ** 2, 0.0], atol=1e-12)
    with pytest.raises(ConfigError, match="slide_start_s"):
        SlideTask(approach_start_s=2.0, slide_start_s=1.0)


def test_regulation_in_free_space_converges():
    plant = PandaPlant(PandaParams(phantom=FREE))
    start = plant.initial_outputs()["p_BT_B"].copy()
    task = SlideTask(approach_start_s=0.2, slide_start_s=100.0, depth_m=0.05)
    rows = run(plant, CartesianImpedance(ImpedanceParams(task=task)), 8.0)
    out, command = rows[-1]
    # z is the soft axis (K = 100, D = 100: a 1 s time constant): 8 s is 7.8 of them
    np.testing.assert_allclose(out["p_BT_B"], start - [0.0, 0.0, 0.05], atol=1e-4)
    assert command["pose_error_norm"][1] < 1e-4
    assert np.linalg.norm(out["qd"]) < 1e-3
    # and nothing moved before the start: the robot held itself with zero command
    assert np.all(rows[150][1]["tau_cmd"] == 0.0)
    assert rows[150][0]["p_BT_B"] == pytest.approx(start, abs=1e-12)


def null_space_direction(plant: PandaPlant) -> np.ndarray:
    J = plant.initial_outputs()["J"].reshape(6, 7)
    return np.linalg.svd(J)[2][-1]  # the right singular vector J leaves out


@pytest.mark.parametrize("damping", [100.0, 0.0])
def test_null_space_damping_removes_self_motion(damping):
    plant = PandaPlant(PandaParams(phantom=FREE))
    n = null_space_direction(plant)
    plant = PandaPlant(PandaParams(phantom=FREE, qd0=0.3 * n))
    assert np.linalg.norm(plant.initial_outputs()["twist_B"]) < 1e-12  # a pure self-motion
    task = SlideTask(approach_start_s=0.0, slide_start_s=100.0, depth_m=0.0)
    rows = run(plant, CartesianImpedance(ImpedanceParams(task=task, null_damping=damping)), 1.0)
    speed = np.linalg.norm(rows[-1][0]["qd"])
    if damping > 0.0:
        assert speed < 1e-3 * 0.3  # e^(-100 t): gone within a second
    else:
        assert speed > 0.5 * 0.3  # undamped, the elbow keeps swinging
    # the tip stayed put either way: the motion was in the null space of the task
    assert max(r[1]["pose_error_norm"][0] for r in rows) < 1e-3


def test_the_start_up_blend_starts_from_zero_torque():
    plant = PandaPlant(PandaParams(phantom=FREE))
    task = SlideTask(approach_start_s=0.1, slide_start_s=0.1)
    rows = run(plant, CartesianImpedance(ImpedanceParams(task=task)), 0.2)
    # before the start the command is zero; at the start τ_d - τ_d0 is the step of the reference
    assert np.all(rows[99][1]["tau_cmd"] == 0.0)
    assert np.linalg.norm(rows[100][1]["tau_cmd"]) > 1.0


def test_position_impedance_renders_the_spring_against_a_steady_force():
    params = PositionImpedanceParams(task=SlideTask(approach_start_s=0.0, slide_start_s=100.0))
    ctl = PositionImpedance(params)
    p, R = np.array([0.0, 0.0, 0.3]), np.eye(3)
    F = np.array([5.0, 0.0, 2.0])
    dt = 2e-3
    for k in range(5000):  # the compliant frame alone, the tip following it perfectly
        out = ctl.step(
            k * dt, dt, {"p_BT_B": p, "R_BT": R.reshape(9), "F_ext_B": F, "ready": [1.0]}
        )
        p = p + dt * out["twist_B"][:3]
    # x_c - x_d = F / K: 2 mm in x (K = 2500 N/m), 20 mm in z (K = 100 N/m)
    np.testing.assert_allclose(p - [0.0, 0.0, 0.3 - 0.0754], [0.002, 0.0, 0.02], atol=1e-5)


def test_position_impedance_waits_for_a_valid_force_and_clamps_its_speed():
    params = PositionImpedanceParams(
        max_speed=0.05, task=SlideTask(approach_start_s=0.0, slide_start_s=100.0)
    )
    ctl = PositionImpedance(params)
    inputs = {"p_BT_B": np.zeros(3), "R_BT": np.eye(3).reshape(9), "F_ext_B": np.full(3, 1e3)}
    out = ctl.step(0.0, 2e-3, {**inputs, "ready": [0.0]})
    np.testing.assert_array_equal(out["twist_B"], 0.0)  # holds the start
    for k in range(1, 200):
        out = ctl.step(k * 2e-3, 2e-3, {**inputs, "ready": [1.0]})
        assert np.linalg.norm(out["twist_B"][:3]) <= 0.05 + 1e-12
