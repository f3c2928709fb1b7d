"""The UR5 model (kinematics from the published DH figures) and speedL as the UR controller applies it."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from hoh_cosim.control.frames import R_BS_EQ1
from hoh_cosim.errors import ConfigError
from plant_models.arm import HOME_Q, ArmParams, SpeedLArm, damped_least_squares
from plant_models.plant import Plant, PlantParams
from plant_models.ur5 import DH, UR5Model, ur5_urdf

ZERO = np.zeros(6)


def dh_forward(q):
    """Flange pose by the standard DH product, written out here independently of the URDF."""
    T = np.eye(4)
    for qi, (d, a, alpha) in zip(q, DH, strict=True):
        ct, st, ca, sa = math.cos(qi), math.sin(qi), math.cos(alpha), math.sin(alpha)
        T = T @ np.array(
            [
                [ct, -st * ca, st * sa, a * ct],
                [st, ct * ca, -ct * sa, a * st],
                [0, sa, ca, d],
                [0, 0, 0, 1],
            ]
        )
    return T


def test_flange_at_zero_is_urs_documented_pose():
    model = UR5Model()
    model.update(ZERO, ZERO, ZERO)
    p, R = model.placement("flange")
    # a2 + a3 along x, -(d4 + d6) along y, d1 - d5 along z
    np.testing.assert_allclose(p, [-0.81725, -0.19145, -0.005491], atol=1e-12)
    np.testing.assert_allclose(R, [[1, 0, 0], [0, 0, -1], [0, 1, 0]], atol=1e-12)


def test_urdf_kinematics_equal_the_dh_product(rng):
    model = UR5Model()
    for _ in range(50):
        q = rng.uniform(-2 * math.pi, 2 * math.pi, 6)
        model.update(q, ZERO, ZERO)
        p, R = model.placement("flange")
        T = dh_forward(q)
        np.testing.assert_allclose(p, T[:3, 3], atol=1e-12)
        np.testing.assert_allclose(R, T[:3, :3], atol=1e-12)


def test_committed_urdf_is_the_generated_one():
    committed = Path(__file__).resolve().parents[2] / "plant_models" / "ur5.urdf"
    assert committed.read_text() == ur5_urdf()


def test_home_points_the_probe_down_with_the_seeds_sensor_alignment():
    out = Plant().outputs_now
    np.testing.assert_allclose(out["R_BS"].reshape(3, 3), R_BS_EQ1, atol=1e-12)  # eq. 1
    np.testing.assert_allclose(out["p_BT_B"], [-0.10, -0.45, 0.25], atol=1e-12)
    np.testing.assert_allclose(out["R_BT"].reshape(3, 3) @ [0, 0, 1], [0, 0, -1], atol=1e-12)


def test_frame_twist_is_the_derivative_of_its_position(rng):
    plant = Plant()
    model, q, qd = plant.model, HOME_Q.copy(), rng.normal(0, 0.3, 6)
    h = 1e-6
    model.update(q, qd, ZERO)
    twist = model.twist("tcp")
    model.update(q + h * qd, ZERO, ZERO)
    p1, _ = model.placement("tcp")
    model.update(q - h * qd, ZERO, ZERO)
    p0, _ = model.placement("tcp")
    np.testing.assert_allclose(twist[:3], (p1 - p0) / (2 * h), atol=1e-8)
    np.testing.assert_allclose(model.jacobian(q, "tcp") @ qd, twist, atol=1e-12)


def run_arm(params: ArmParams, command, seconds: float, dt: float = 1e-3):
    plant = Plant(PlantParams(arm=params))
    inputs = {"F_hand_B": np.zeros(3), "tau_hand_B": np.zeros(3), "F_tip_B": np.zeros(3)}
    rows = []
    for k in range(round(seconds / dt)):
        t = k * dt
        out = plant.step(t, dt, {**inputs, "twist_cmd_B": np.asarray(command(t), float)})
        rows.append((t + dt, out))
    return plant, rows


@pytest.mark.parametrize("rate", [125.0, 500.0])
def test_tracks_a_constant_twist(rate):
    cmd = np.array([0.04, -0.03, 0.02, 0.0, 0.0, 0.1])
    _, rows = run_arm(ArmParams(rate_hz=rate), lambda t: cmd, 1.0)
    np.testing.assert_allclose(rows[-1][1]["twist_B"], cmd, atol=2e-4)


@pytest.mark.parametrize("rate", [125.0, 500.0])
def test_one_robot_cycle_of_latency(rate):
    period = 1.0 / rate
    _, rows = run_arm(ArmParams(rate_hz=rate), lambda t: [0.05, 0, 0, 0, 0, 0], 4 * period)
    moving = [t for t, out in rows if abs(out["twist_B"][0]) > 1e-12]
    # sent at t = 0, taken at the cycle at t = 0, applied from the next cycle
    assert moving[0] == pytest.approx(period + 1e-3)


@pytest.mark.parametrize("rate", [125.0, 500.0])
def test_commands_are_taken_only_at_the_robot_rate(rate):
    period = 1.0 / rate
    plant = Plant(PlantParams(arm=ArmParams(rate_hz=rate)))
    seen = []
    for k in range(round(0.1 / 1e-3)):
        cmd = np.array([0.001 * k, 0, 0, 0, 0, 0])  # a new command every tick
        plant.step(
            k * 1e-3,
            1e-3,
            {
                "twist_cmd_B": cmd,
                "F_hand_B": np.zeros(3),
                "tau_hand_B": np.zeros(3),
                "F_tip_B": np.zeros(3),
            },
        )
        seen.append(plant.arm.active[0])
    changes = [k for k in range(1, len(seen)) if seen[k] != seen[k - 1]]
    ticks_per_cycle = round(period / 1e-3)
    assert all(k % ticks_per_cycle == 0 for k in changes)
    assert len(changes) >= 0.1 / period - 2


def test_acceleration_is_limited_to_speedl_a():
    a = 1.5
    _, rows = run_arm(ArmParams(rate_hz=500.0, acceleration=a), lambda t: [0.1, 0, 0, 0, 0, 0], 0.2)
    speeds = np.array([out["twist_B"][0] for _, out in rows])
    assert np.max(np.diff(speeds)) <= a * 1e-3 * 1.01
    # 0.1 m/s at 1.5 m/s² takes 67 ms, after the 2 ms cycle of latency
    reached = next(t for t, out in rows if out["twist_B"][0] > 0.0999)
    assert reached == pytest.approx(0.002 + 0.1 / a, abs=0.003)


def test_joint_speed_limit_holds_and_keeps_the_direction():
    cmd = np.array([0.0, 0.0, 0.0, 0.0, 0.0, 6.0])  # 6 rad/s about z: wrist 3 past its limit
    params = ArmParams(rate_hz=500.0, angular_acceleration=100.0)
    _plant, rows = run_arm(params, lambda t: cmd, 0.5)
    qd = np.array([out["qd"] for _, out in rows])
    assert np.max(np.abs(qd)) <= math.pi + 1e-9
    twist = rows[-1][1]["twist_B"]
    np.testing.assert_allclose(twist[:5] / np.linalg.norm(twist), [0, 0, 0, 0, 0], atol=1e-3)


def test_joint_position_limit_holds():
    q0 = HOME_Q.copy()
    q0[5] = 2 * math.pi - 0.05
    params = ArmParams(rate_hz=500.0, q0=q0)
    _plant, rows = run_arm(params, lambda t: [0, 0, 0, 0, 0, -1.0], 1.0)  # turns wrist 3 forward
    q = np.array([out["q"] for _, out in rows])
    assert np.max(q[:, 5]) <= 2 * math.pi + 1e-9
    assert np.max(q[:, 5]) > 2 * math.pi - 0.01  # it did reach the limit


def test_damped_least_squares_is_exact_away_from_singularities(rng):
    model = UR5Model()
    J = model.jacobian(HOME_Q, "flange")
    twist = rng.normal(size=6)
    np.testing.assert_allclose(
        damped_least_squares(J, twist, 0.05, 0.05), np.linalg.solve(J, twist), atol=1e-12
    )


def test_damped_least_squares_stays_bounded_at_a_wrist_singularity():
    q = HOME_Q.copy()
    q[4] = 0.0  # wrist 2 at zero: wrist 1 and wrist 3 line up
    model = UR5Model()
    J = model.jacobian(q, "flange")
    assert np.linalg.svd(J, compute_uv=False)[-1] < 1e-9
    qd = damped_least_squares(J, np.array([0, 0, 0, 0.3, 0.2, 0.1]), 0.05, 0.05)
    assert np.all(np.isfinite(qd))
    assert np.max(np.abs(qd)) < 50.0


def test_arm_params_are_checked():
    with pytest.raises(ConfigError, match=r"rate_hz must be > 0.0, got 0.0"):
        ArmParams(rate_hz=0.0)
    with pytest.raises(ConfigError, match=r"latency_cycles must be an integer >= 0, got -1"):
        ArmParams(latency_cycles=-1)
    with pytest.raises(ConfigError, match=r"q0: outside the joint limits"):
        ArmParams(q0=[7.0, 0, 0, 0, 0, 0])


def test_speedl_arm_resets_to_q0():
    plant, _ = run_arm(ArmParams(), lambda t: [0.05, 0, 0, 0, 0, 0], 0.2)
    arm: SpeedLArm = plant.arm
    assert not np.allclose(arm.q, HOME_Q)
    plant.reset()
    np.testing.assert_array_equal(arm.q, HOME_Q)
    np.testing.assert_array_equal(arm.qd, 0.0)


def test_skipping_the_svd_changes_no_joint_velocity(rng):
    # The arm skips the SVD while Weyl's bound shows the Jacobian far from singular. Started near
    # the wrist singularity (wrist 2 at 0.12 rad) and turned through it, so that the damped branch,
    # the skip and the switches between them all happen, it must give what an SVD on every cycle
    # gives, bit for bit.
    q0 = HOME_Q.copy()
    q0[4] = 0.12
    params = ArmParams(rate_hz=500.0, q0=q0)
    fast, every = SpeedLArm(params, UR5Model(_frames())), SpeedLArm(params, UR5Model(_frames()))
    skipped = damped = 0
    for k in range(1500):
        v = 0.01 * rng.normal(size=3)
        command = np.concatenate([v, [0.2 * math.sin(k / 200), 0.2 * math.cos(k / 300), 0.0]])
        every._svd_at = None  # forces the SVD
        before = fast._svd_at
        for arm in (fast, every):
            arm.cycle(command)
            arm.advance(1.0 / params.rate_hz)
        skipped += fast._svd_at is before
        sigma = np.linalg.svd(fast.model.jacobian(fast.q, "tcp"), compute_uv=False)[-1]
        damped += sigma < params.dls_threshold
        np.testing.assert_array_equal(fast.state, every.state)
        np.testing.assert_array_equal(fast.qdd, every.qdd)
    assert skipped > 100, skipped
    assert damped > 100, damped


def _frames():
    from plant_models.tool import ToolModel
    from plant_models.ur5 import FramePlacement

    return tuple(FramePlacement(name, p, R) for name, (p, R) in ToolModel().flange_frames().items())
