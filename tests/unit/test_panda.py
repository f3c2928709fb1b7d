"""The Panda plant: its URDF against the modified-DH table, its dynamics, friction and contact."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hoh_cosim.errors import ConfigError
from plant_models.panda import (
    FLANGE_D,
    MDH,
    PANDA_READY_Q,
    PandaParams,
    PandaPlant,
    friction_torque,
)
from plant_models.tissue import PhantomParams

FREE = PhantomParams(shape="none")


def mdh_tip(q: np.ndarray, tool_length: float) -> np.ndarray:
    """The tip's pose by multiplying Craig's transforms Rx(α) Tx(a) Rz(θ) Tz(d) by hand."""

    def rx(a):
        c, s = math.cos(a), math.sin(a)
        return np.array([[1, 0, 0, 0], [0, c, -s, 0], [0, s, c, 0], [0, 0, 0, 1.0]])

    def rz(a):
        c, s = math.cos(a), math.sin(a)
        return np.array([[c, -s, 0, 0], [s, c, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1.0]])

    def tx(x):
        T = np.eye(4)
        T[0, 3] = x
        return T

    def tz(z):
        T = np.eye(4)
        T[2, 3] = z
        return T

    T = np.eye(4)
    for (a, d, alpha), theta in zip(MDH, q, strict=True):
        T = T @ rx(alpha) @ tx(a) @ rz(theta) @ tz(d)
    return T @ tz(FLANGE_D + tool_length)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_urdf_has_the_modified_dh_kinematics(seed):
    rng = np.random.default_rng(seed)
    q = PANDA_READY_Q + rng.uniform(-0.5, 0.5, 7)
    plant = PandaPlant(PandaParams(q0=q, phantom=FREE))
    out = plant.initial_outputs()
    T = mdh_tip(q, plant.params.tool_length_m)
    np.testing.assert_allclose(out["p_BT_B"], T[:3, 3], atol=1e-12)
    np.testing.assert_allclose(out["R_BT"].reshape(3, 3), T[:3, :3], atol=1e-12)


def test_the_ready_pose_points_the_probe_down():
    out = PandaPlant(PandaParams(phantom=FREE)).initial_outputs()
    np.testing.assert_allclose(out["R_BT"].reshape(3, 3)[:, 2], [0.0, 0.0, -1.0], atol=1e-12)
    # Franka's ready pose puts the flange 0.307 m out and 0.590 m up; the probe adds 0.2 m down
    np.testing.assert_allclose(out["p_BT_B"], [0.30689, 0.0, 0.59028 - 0.2], atol=1e-4)


def test_mass_matrix_is_symmetric_positive_definite_and_the_jacobian_matches_the_twist():
    rng = np.random.default_rng(3)
    plant = PandaPlant(PandaParams(qd0=rng.normal(0.0, 0.3, 7), phantom=FREE))
    out = plant.initial_outputs()
    B = out["B"].reshape(7, 7)
    np.testing.assert_allclose(B, B.T, atol=1e-12)
    assert np.linalg.eigvalsh(B).min() > 1e-3
    np.testing.assert_allclose(out["J"].reshape(6, 7) @ out["qd"], out["twist_B"], atol=1e-12)


def test_gravity_compensation_holds_the_arm_and_without_it_the_arm_falls():
    held = PandaPlant(PandaParams(phantom=FREE))
    falling = PandaPlant(PandaParams(phantom=FREE, gravity_compensation=False))
    zero = {"tau_cmd": np.zeros(7)}
    for k in range(200):
        a = held.step(k * 1e-3, 1e-3, zero)
        b = falling.step(k * 1e-3, 1e-3, zero)
    np.testing.assert_allclose(a["q"], PANDA_READY_Q, atol=1e-12)
    assert b["p_BT_B"][2] < a["p_BT_B"][2] - 0.01  # 0.2 s of free fall bends it down


def test_without_friction_and_gravity_energy_is_kept():
    plant = PandaPlant(
        PandaParams(qd0=np.full(7, 0.5), friction=False, substeps=4, phantom=FREE, g_B=[0, 0, 0])
    )

    def energy(out):
        return 0.5 * out["qd"] @ out["B"].reshape(7, 7) @ out["qd"]

    e0 = energy(plant.initial_outputs())
    for k in range(500):
        out = plant.step(k * 1e-3, 1e-3, {"tau_cmd": np.zeros(7)})
    assert energy(out) == pytest.approx(e0, rel=0.02)


def test_friction_is_zero_at_rest_and_opposes_motion():
    np.testing.assert_allclose(friction_torque(np.zeros(7)), 0.0, atol=1e-15)
    assert np.all(friction_torque(np.full(7, 0.5)) > 0.0)
    assert np.all(friction_torque(np.full(7, -0.5)) < 0.0)
    # saturates at φ1 minus the offset: joint 4's φ1 is 1.2794 N·m
    assert friction_torque(np.full(7, 50.0))[3] == pytest.approx(
        1.2794 - 1.2794 / (1 + math.exp(-5.5903 * 0.036194)), rel=1e-9
    )


def test_the_phantom_pushes_back_through_the_jacobian():
    below = PandaPlant(PandaParams(phantom=FREE)).initial_outputs()["p_BT_B"][2]
    plant = PandaPlant(PandaParams(phantom=PhantomParams(plane_point_B=[0, 0, below + 0.01])))
    out = plant.initial_outputs()
    assert out["penetration"][0] == pytest.approx(0.01)
    assert out["F_contact_B"][2] == pytest.approx(7.5e3 * 0.01**1.5)
    for k in range(20):
        out = plant.step(k * 1e-3, 1e-3, {"tau_cmd": np.zeros(7)})
    assert out["twist_B"][2] > 0.0  # pushed up


def test_torque_commands_are_clamped_to_the_joint_limits():
    plant = PandaPlant(PandaParams(phantom=FREE))
    out = plant.step(0.0, 1e-3, {"tau_cmd": np.full(7, 1e3)})
    gravity = plant.pin.computeGeneralizedGravity(plant.model, plant.data, out["q"])
    np.testing.assert_allclose(out["tau_J"] - gravity, [87] * 4 + [12] * 3, atol=1e-9)


def test_bad_parameters_are_named():
    with pytest.raises(ConfigError, match=r"q0: joint 4 at 0 rad is outside \[-3.0718, -0.0698\]"):
        PandaParams(q0=[0.0] * 7)
    with pytest.raises(ConfigError, match="substeps"):
        PandaParams(substeps=0)
