"""The operator: a delayed impedance that drives the probe through a task."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hoh_cosim.errors import ConfigError
from plant_models.operator import Operator, OperatorParams

DT = 1e-3
Z3 = np.zeros(3)


def inputs(p, v=Z3, F_contact=Z3):
    return {
        "p_BT_B": np.asarray(p, float),
        "twist_B": np.concatenate([v, Z3]),
        "F_contact_B": np.asarray(F_contact, float),
    }


def drive_admittance_robot(
    params: OperatorParams,
    damping: float,
    seconds: float,
    wall: float | None = None,
    wall_stiffness: float = 5000.0,
):
    """The operator pushing an ideal admittance robot (ẋ = F / damping), optionally against a wall
    at z = wall that pushes back linearly. Returns time, tip, reference and hand force."""
    op = Operator(params)
    p, v = np.array([0.0, 0.0, 0.1]), np.zeros(3)
    rows = []
    for k in range(round(seconds / DT)):
        F_c = np.zeros(3)
        if wall is not None and p[2] < wall:
            F_c[2] = wall_stiffness * (wall - p[2])
        out = op.step(k * DT, DT, inputs(p, v, F_c))
        # the hand's own force moves the robot (contact compensated, as eq. 12 does)
        v = out["F_hand_B"] / damping
        p = p + v * DT
        rows.append(
            (k * DT + DT, p.copy(), out["p_ref_B"].copy(), out["F_hand_B"].copy(), F_c.copy())
        )
    t = np.array([r[0] for r in rows])
    return (
        t,
        np.array([r[1] for r in rows]),
        np.array([r[2] for r in rows]),
        np.array([r[3] for r in rows]),
        np.array([r[4] for r in rows]),
    )


CIRCLE = OperatorParams(task="circle", radius_m=0.04, period_s=4.0)
ALPHA_SEED = 0.0125  # [m/(s·N)]: eq. 10's slope, a damping of 80 N·s/m


def test_circle_on_a_transparent_robot_needs_little_force_and_follows_the_path():
    t, p, ref, F, _ = drive_admittance_robot(CIRCLE, damping=1 / ALPHA_SEED, seconds=12.0)
    settled = t > 4.0
    force_rms = np.sqrt(np.mean(np.sum(F[settled] ** 2, axis=1)))
    path_err = np.linalg.norm(p[settled] - ref[settled], axis=1)
    assert force_rms < 8.0  # 0.063 m/s at 0.0125 m/(s·N) is 5 N
    assert np.max(path_err) < 0.02
    assert np.max(np.linalg.norm(F, axis=1)) < CIRCLE.max_force_N


def test_circle_on_a_ten_times_damped_robot_needs_clearly_more_force():
    t, _, _, F_ideal, _ = drive_admittance_robot(CIRCLE, damping=1 / ALPHA_SEED, seconds=12.0)
    t, p, ref, F_heavy, _ = drive_admittance_robot(CIRCLE, damping=10 / ALPHA_SEED, seconds=12.0)
    settled = t > 4.0
    rms = lambda F: np.sqrt(np.mean(np.sum(F[settled] ** 2, axis=1)))  # noqa: E731
    assert rms(F_heavy) > 2.0 * rms(F_ideal)  # measured: 12.0 N against 4.9 N
    assert np.max(np.linalg.norm(p[settled] - ref[settled], axis=1)) > 0.03  # and lags behind


def test_circle_reference_starts_at_rest_and_reaches_full_speed():
    op = Operator(CIRCLE)
    p0, v0 = op.reference(0.0)
    np.testing.assert_array_equal(p0, 0.0)
    np.testing.assert_array_equal(v0, 0.0)
    for tau in np.linspace(1.0, 9.0, 20):  # after the 1 s ramp: on the circle at full speed
        p, v = op.reference(tau)
        centre = np.array([-0.04, 0.0, 0.0])
        assert np.linalg.norm(p - centre) == pytest.approx(0.04)
        assert np.linalg.norm(v) == pytest.approx(2 * math.pi * 0.04 / 4.0)


def test_the_hand_reacts_a_reaction_delay_late():
    op = Operator(OperatorParams(task="hold", reaction_delay_s=0.15))
    forces = []
    for k in range(400):
        p = [0.0, 0.0, 0.1] if k < 100 else [0.01, 0.0, 0.1]  # the tip is moved at 0.1 s
        forces.append(op.step(k * DT, DT, inputs(p))["F_hand_B"][0])
    first_reaction = next(k for k, f in enumerate(forces) if abs(f) > 1e-9)
    assert first_reaction == 100 + 150
    assert forces[-1] == pytest.approx(-300.0 * 0.01)


def test_nobody_touches_before_the_start():
    op = Operator(OperatorParams(task="circle", start_s=2.0))
    for k in range(1999):
        out = op.step(k * DT, DT, inputs([0.3, 0.0, 0.2]))
        np.testing.assert_array_equal(out["F_hand_B"], 0.0)
        assert out["hand_on"][0] == 0.0


def test_push_then_release():
    op = Operator(
        OperatorParams(task="push_release", push_force_B=[5.0, 0, 0], start_s=1.0, release_s=3.0)
    )
    F = {k: op.step(k * DT, DT, inputs([0.0, 0.0, 0.1]))["F_hand_B"] for k in range(4000)}
    np.testing.assert_array_equal(F[500], 0.0)
    np.testing.assert_array_equal(F[2000], [5.0, 0, 0])
    np.testing.assert_array_equal(F[3500], 0.0)


def test_force_is_saturated():
    op = Operator(OperatorParams(task="hold", max_force_N=25.0, reaction_delay_s=0.0))
    op.step(0.0, DT, inputs([0, 0, 0]))
    out = op.step(DT, DT, inputs([1.0, 1.0, 0.0]))  # a metre away: 424 N unsaturated
    assert np.linalg.norm(out["F_hand_B"]) == pytest.approx(25.0)


@pytest.mark.parametrize("target", [3.0, 5.0, 10.0])
@pytest.mark.parametrize("wall_stiffness", [800.0, 3000.0])
def test_press_reaches_the_target_contact_force_and_relaxes(target, wall_stiffness):
    params = OperatorParams(task="press", target_force_N=target)
    t, _p, _, F, F_c = drive_admittance_robot(
        params, damping=1 / ALPHA_SEED, seconds=14.0, wall=0.05, wall_stiffness=wall_stiffness
    )
    settled = t > 10.0
    assert np.mean(F_c[settled, 2]) == pytest.approx(target, rel=0.01)
    assert np.ptp(F_c[settled, 2]) < 0.05 * target
    assert np.max(np.linalg.norm(F[settled], axis=1)) < 0.5  # the robot holds; the hand rests
    assert np.max(F_c[:, 2]) < 2.5 * target  # a human's first overshoot, bounded


def test_scan_slides_along_the_line_while_pressing():
    params = OperatorParams(
        task="scan", target_force_N=8.0, direction_B=[1, 0, 0], length_m=0.1, period_s=6.0
    )
    t, p, _ref, _, F_c = drive_admittance_robot(
        params, damping=1 / ALPHA_SEED, seconds=12.0, wall=0.05
    )
    pressing = t > 3.0
    assert np.ptp(p[pressing, 0]) > 0.07  # slid most of the 10 cm line
    assert np.mean(F_c[pressing, 2]) == pytest.approx(8.0, rel=0.15)


def test_operator_params_are_checked():
    with pytest.raises(ConfigError, match=r"task: expected one of off, hold, circle, line, press"):
        OperatorParams(task="dance")
    with pytest.raises(ConfigError, match=r"plane: expected one of xy, xz, yz, got 'ab'"):
        OperatorParams(plane="ab")
    with pytest.raises(ConfigError, match=r"direction_B: expected a non-zero vector"):
        OperatorParams(direction_B=[0, 0, 0])
    with pytest.raises(ConfigError, match=r"radius_m must be > 0.0, got -0.1"):
        OperatorParams(radius_m=-0.1)
