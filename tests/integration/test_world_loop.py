"""The simulated world closed around the real estimator and controller, wired by hand."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from hoh_cosim.control.admittance import TRANSLATION_GAINS
from hoh_cosim.control.controller import ControllerParams, HandGuidingController
from hoh_cosim.control.estimator import Estimator, EstimatorParams
from hoh_cosim.control.gravity import ToolParams
from hoh_cosim.control.supervisor import Status
from plant_models.operator import Operator, OperatorParams
from plant_models.plant import Plant, PlantParams
from plant_models.sensors import FSE103Params, FSE103Sensor, FT150Sensor
from plant_models.tissue import PhantomParams

DT = 1e-3


def run_loop(
    operator: OperatorParams,
    seconds: float,
    controller=None,
    plant=None,
    probe_sensor: FSE103Params | None = None,
):
    plant = Plant(plant)
    tool = plant.params.tool
    op = Operator(operator)
    ft = FT150Sensor(rng=np.random.default_rng(1))
    probe = FSE103Sensor(probe_sensor, rng=np.random.default_rng(2))
    est = Estimator(
        EstimatorParams(
            tool=ToolParams(tool.mass_kg, tool.p_SC_S),
            ft_rebias_packets=400,
            probe_rebias_packets=100,
        )
    )
    ctl = HandGuidingController(controller)
    world, command, rows = plant.outputs_now, np.zeros(6), []
    for k in range(round(seconds / DT)):
        t = k * DT
        hand = op.step(t, DT, world)
        world = plant.step(
            t,
            DT,
            {
                "twist_cmd_B": command,
                "F_hand_B": hand["F_hand_B"],
                "tau_hand_B": hand["tau_hand_B"],
                "F_tip_B": hand["F_tip_B"],
            },
        )
        ft_out = ft.step(t, DT, {"wrench_S_true": world["wrench_S"]})
        probe_out = probe.step(t, DT, {"force_P_true": world["force_P"]})
        estimate = est.step(
            t,
            DT,
            {
                "wrench_S": ft_out["wrench_S"],
                "ft_counter": ft_out["counter"],
                "force_P": probe_out["force_P"],
                "probe_counter": probe_out["counter"],
                "R_BS": world["R_BS"],
            },
        )
        out = ctl.step(t, DT, {**estimate, "p_BT_B": world["p_BT_B"]})
        command = out["twist_B"]
        rows.append(
            (
                t + DT,
                world["p_BT_B"].copy(),
                hand["p_ref_B"].copy(),
                hand["F_hand_B"].copy(),
                estimate["F_hand_B"].copy(),
                int(out["status"][0]),
                world["F_contact_B"].copy(),
            )
        )
    t = np.array([r[0] for r in rows])
    return t, *(np.array([r[i] for r in rows]) for i in range(1, 7))


CIRCLE = OperatorParams(task="circle", start_s=3.0, radius_m=0.04, period_s=4.0)


def test_operator_draws_circles_through_the_whole_loop():
    t, p, ref, F_hand, F_est, status, _ = run_loop(CIRCLE, 13.0)
    drawing = t > 5.0
    path_err = np.linalg.norm(p[drawing] - ref[drawing], axis=1)
    assert np.sqrt(np.mean(path_err**2)) < 0.02
    assert np.sqrt(np.mean(np.sum(F_hand[drawing] ** 2, axis=1))) < 9.0
    # the estimate follows the true hand force to within the sensor's noise
    assert np.sqrt(np.mean(np.sum((F_est[drawing] - F_hand[drawing]) ** 2, axis=1))) < 0.5
    assert all(Status(int(s)).ok for s in status[t > 3.0])


def test_a_sluggish_robot_makes_the_operator_work_harder():
    _, _, _, F_fast, _, _, _ = run_loop(CIRCLE, 13.0)
    slow_gains = dataclasses.replace(TRANSLATION_GAINS, slope=TRANSLATION_GAINS.slope / 10)
    t, _, _, F_slow, _, _, _ = run_loop(CIRCLE, 13.0, ControllerParams(translation=slow_gains))
    drawing = t > 5.0
    rms = lambda F: np.sqrt(np.mean(np.sum(F[drawing] ** 2, axis=1)))  # noqa: E731
    assert rms(F_slow) > 2.0 * rms(F_fast)


PRESS = OperatorParams(task="press", start_s=3.0, target_force_N=8.0)
PHANTOM_BELOW = PlantParams(phantom=PhantomParams(plane_point_B=[0.0, 0.0, 0.22]))  # 3 cm down


def press_and_hold(compensation: bool, probe: FSE103Params):
    t, _, _, F_hand, _, _status, F_contact = run_loop(
        PRESS, 22.0, ControllerParams(contact_compensation=compensation), PHANTOM_BELOW, probe
    )
    held = t > 18.0
    return np.mean(F_contact[held, 2]), -np.mean(F_hand[held, 2])


def test_with_contact_compensation_the_robot_carries_the_contact_force():
    contact, hand_push = press_and_hold(True, FSE103Params(ideal=True))
    assert contact == pytest.approx(8.0, rel=0.05)
    assert abs(hand_push) < 0.5  # eq. 12: the hand only steers


def test_without_it_the_operator_holds_the_contact_force():
    # seed 3.F.2: the wrist reads hand + contact, so the robot stands still only while the hand
    # pushes as hard as the phantom pushes back; the operator gets there slowly
    contact, hand_push = press_and_hold(False, FSE103Params(ideal=True))
    assert contact > 6.0
    assert hand_push == pytest.approx(contact, abs=0.5)


def test_the_housing_errors_leave_the_hand_pushing_part_of_the_contact_force():
    # seed 3.B.2: the FSE103's housing misreads the contact force, so eq. 12 subtracts too little
    contact, hand_push = press_and_hold(True, FSE103Params())
    assert contact == pytest.approx(8.0, rel=0.05)
    assert 0.5 < hand_push < 6.5
