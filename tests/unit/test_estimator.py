"""The Estimator block: rebias, gravity compensation, filtering, alignment, packet handling."""

from __future__ import annotations

import numpy as np
import pytest

from hoh_cosim.control.block import check_inputs, zero_inputs
from hoh_cosim.control.estimator import FILTER_KINDS, Estimator, EstimatorParams
from hoh_cosim.control.frames import R_BS_EQ1, R_SP_SEED, rotvec_to_matrix
from hoh_cosim.errors import ConfigError
from tests.streams import SensorStream

FAST_REBIAS = {"ft_rebias_packets": 20, "probe_rebias_packets": 10}
TILTED = rotvec_to_matrix([0.5, -0.3, 0.2]) @ R_BS_EQ1


def run(estimator: Estimator, stream: SensorStream, seconds: float):
    outputs = []
    for t, inputs in stream.ticks(round(seconds / stream.dt)):
        outputs.append((t, estimator.step(t, stream.dt, inputs)))
    return outputs


def test_outputs_match_the_declared_ports():
    est = Estimator()
    out = est.step(0.0, 1e-3, zero_inputs(est))
    assert set(out) == {p.name for p in est.outputs}
    for port in est.outputs:
        assert out[port.name].shape == (port.size,)


def test_not_ready_and_zero_until_both_sensors_are_rebiased():
    est = Estimator(EstimatorParams(**FAST_REBIAS))
    stream = SensorStream(hand_B=lambda t: np.array([5.0, 0.0, 0.0]))
    outs = run(est, stream, 0.3)
    # FT: 20 packets every 5 ms → 0.1 s; probe: 10 packets every 20 ms → 0.2 s (t = 0.18 s)
    for t, out in outs:
        if t < 0.18:
            assert out["ready"][0] == 0.0
            np.testing.assert_array_equal(out["F_hand_B"], 0.0)
    assert outs[-1][1]["ready"][0] == 1.0


def test_rebias_takes_the_seeds_500_packets_by_default():
    est = Estimator()
    outs = run(est, SensorStream(probe_every=5), 2.6)
    ready_at = next(t for t, out in outs if out["ready"][0] == 1.0)
    assert ready_at == pytest.approx(499 * 5e-3)


def test_untouched_tool_reads_zero_in_a_tilted_pose():
    est = Estimator(EstimatorParams(**FAST_REBIAS))
    outs = run(est, SensorStream(R_BS=lambda t: TILTED), 1.0)
    np.testing.assert_allclose(outs[-1][1]["F_hand_B"], 0.0, atol=1e-9)
    np.testing.assert_allclose(outs[-1][1]["tau_hand_B"], 0.0, atol=1e-9)


def test_gravity_is_compensated_while_the_sensor_turns():
    # rebias at home, then tilt the tool by 60°: without compensation the weight would show up
    turn = lambda t: rotvec_to_matrix([min(t, 1.0) * np.pi / 3, 0, 0]) @ R_BS_EQ1  # noqa: E731
    est = Estimator(EstimatorParams(**FAST_REBIAS))
    outs = run(est, SensorStream(R_BS=turn), 2.0)
    np.testing.assert_allclose(outs[-1][1]["F_hand_B"], 0.0, atol=1e-6)


def test_hand_force_comes_out_in_the_base_frame():
    hand = np.array([3.0, -2.0, 1.5])
    torque = np.array([0.2, 0.1, -0.3])
    # the stream's hand pushes at S: its torque about S (p_SR_S = 0) is the hand's twist alone
    est = Estimator(EstimatorParams(p_SR_S=[0.0, 0.0, 0.0], **FAST_REBIAS))
    stream = SensorStream(
        R_BS=lambda t: TILTED,
        hand_B=lambda t: hand * (t > 0.3),
        hand_torque_B=lambda t: torque * (t > 0.3),
    )
    out = run(est, stream, 2.0)[-1][1]
    # a step settles to 1e-4 of its size within 1.7 s (the filter's steady-state tail)
    np.testing.assert_allclose(out["F_hand_B"], hand, atol=1e-3)
    np.testing.assert_allclose(out["tau_hand_B"], torque, atol=1e-4)
    np.testing.assert_allclose(out["F_hand_meas_B"], hand, atol=1e-9)


def test_probe_contact_force_comes_out_in_the_base_frame():
    contact = np.array([0.5, -0.3, 6.0])
    est = Estimator(EstimatorParams(**FAST_REBIAS))
    stream = SensorStream(R_BS=lambda t: TILTED, contact_B=lambda t: contact * (t > 0.3))
    out = run(est, stream, 3.0)[-1][1]
    np.testing.assert_allclose(out["F_probe_B"], contact, atol=1e-3)
    # the wrist feels the contact too: eq. 12's F_hand - F_probe is the hand's own force, zero here
    np.testing.assert_allclose(out["F_hand_B"] - out["F_probe_B"], 0.0, atol=2e-3)


def test_probe_alignment_uses_the_mounting_rotation():
    est = Estimator(EstimatorParams(ft_rebias_packets=0, probe_rebias_packets=0))
    inputs = zero_inputs(est)
    inputs["R_BS"] = TILTED.reshape(9)
    inputs["force_P"] = np.array([1.0, 2.0, 3.0])
    inputs["probe_counter"] = np.array([1.0])
    est.step(0.0, 1e-3, inputs)
    est_out = est.step(0.001, 1e-3, inputs)
    expected = TILTED @ R_SP_SEED @ np.array([1.0, 2.0, 3.0])
    # one packet: the filter has moved most of the way there, in the right direction
    direction = est_out["F_probe_B"] / np.linalg.norm(est_out["F_probe_B"])
    np.testing.assert_allclose(direction, expected / np.linalg.norm(expected), atol=1e-6)


def test_same_counter_means_no_new_packet():
    est = Estimator(EstimatorParams(ft_rebias_packets=0, probe_rebias_packets=0, filter="none"))
    inputs = zero_inputs(est)
    inputs["R_BS"] = R_BS_EQ1.reshape(9)
    inputs["wrench_S"] = est._weight.weight_S(R_BS_EQ1) + np.array([4.0, 0, 0, 0, 0, 0])
    inputs["ft_counter"] = np.array([1.0])
    first = est.step(0.0, 1e-3, inputs)["F_hand_B"]
    inputs["wrench_S"] = inputs["wrench_S"] + 100.0  # changed values, same counter
    second = est.step(0.001, 1e-3, inputs)["F_hand_B"]
    np.testing.assert_array_equal(first, second)
    np.testing.assert_allclose(first, R_BS_EQ1 @ [4.0, 0, 0])


def test_a_nan_packet_is_rejected_and_counted():
    est = Estimator(EstimatorParams(**FAST_REBIAS))
    outs = run(est, SensorStream(), 0.5)
    t, inputs = 0.5, next(SensorStream().ticks(1))[1]
    inputs["wrench_S"][2] = np.nan
    inputs["ft_counter"] = np.array([1000.0])
    out = est.step(t, 1e-3, inputs)
    assert out["rejected_packets"][0] == 1.0
    assert np.all(np.isfinite(out["F_hand_B"]))
    assert out["ft_age"][0] == pytest.approx(t - outs[-5][0])  # the last good packet's age


def test_packet_age_grows_between_packets_and_resets_on_one():
    est = Estimator(EstimatorParams(**FAST_REBIAS))
    ages = [out["ft_age"][0] for _, out in run(est, SensorStream(), 0.02)]
    np.testing.assert_allclose(ages[:6], [0.0, 0.001, 0.002, 0.003, 0.004, 0.0], atol=1e-12)


def test_age_counts_from_the_start_when_no_packet_arrives():
    est = Estimator()
    inputs = zero_inputs(est)
    inputs["R_BS"] = np.eye(3).reshape(9)
    est.step(2.0, 1e-3, inputs)
    out = est.step(2.5, 1e-3, inputs)
    assert out["ft_age"][0] == pytest.approx(0.5)
    assert out["probe_age"][0] == pytest.approx(0.5)


def test_torque_about_a_reference_point():
    # a 10 N push along base x through the sensor origin: about a point 0.1 m down the probe
    # (R = S + 0.1 m along -z of B) it has a moment of -p × f
    hand = np.array([10.0, 0.0, 0.0])
    p_SR_B = np.array([0.0, 0.0, -0.1])
    p_SR_S = R_BS_EQ1.T @ p_SR_B
    est = Estimator(EstimatorParams(p_SR_S=p_SR_S, **FAST_REBIAS))
    out = run(est, SensorStream(hand_B=lambda t: hand * (t > 0.3)), 2.0)[-1][1]
    np.testing.assert_allclose(out["tau_hand_B"], -np.cross(p_SR_B, hand), atol=1e-3)


@pytest.mark.parametrize("kind", FILTER_KINDS)
def test_every_filter_settles_on_a_steady_push(kind):
    hand = np.array([2.0, -1.0, 4.0])
    est = Estimator(EstimatorParams(filter=kind, **FAST_REBIAS))
    # 4 s: the lead-lag's slow pole (0.37 Hz) settles to 1e-3 of a 4 N step in about 3 s
    out = run(est, SensorStream(hand_B=lambda t: hand * (t > 0.3)), 4.0)[-1][1]
    np.testing.assert_allclose(out["F_hand_B"], hand, atol=1e-3)


def test_without_a_probe_sensor_the_probe_is_ignored():
    est = Estimator(EstimatorParams(use_probe=False, ft_rebias_packets=20))
    stream = SensorStream(probe_every=10**9)  # the probe never sends
    out = run(est, stream, 0.5)[-1][1]
    assert out["ready"][0] == 1.0
    np.testing.assert_array_equal(out["F_probe_B"], 0.0)
    assert out["probe_age"][0] == 0.0


def test_start_rebias_takes_a_new_offset():
    est = Estimator(EstimatorParams(**FAST_REBIAS))
    run(est, SensorStream(), 0.5)
    est.start_rebias()
    assert not est.ready
    drifted = SensorStream(ft_bias=np.array([3.0, 0, 0, 0, 0, 0]))
    out = run(est, drifted, 1.0)[-1][1]
    np.testing.assert_allclose(out["F_hand_B"], 0.0, atol=1e-9)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        (
            {"filter": "median"},
            r"filter: expected one of kalman, steady_kalman, lead_lowpass, butterworth, "
            r"one_euro, none, got 'median'",
        ),
        ({"ft_rebias_packets": -1}, r"ft_rebias_packets must be an integer >= 0, got -1"),
        ({"R_SP": np.diag([1.0, 1.0, -1.0])}, r"R_SP: not a rotation matrix"),
        ({"ft_bias": [0.0] * 5}, r"ft_bias: expected 6 values, got 5"),
    ],
)
def test_params_reject_bad_values(kwargs, message):
    with pytest.raises(ConfigError, match=message):
        EstimatorParams(**kwargs)


def test_steady_kalman_needs_a_whole_number_of_ticks_per_packet():
    est = Estimator(
        EstimatorParams(
            filter="steady_kalman",
            ft_packet_period_s=0.0055,
            ft_rebias_packets=0,
            probe_rebias_packets=0,
        )
    )
    with pytest.raises(ConfigError, match=r"packet period 0.0055 s is not a whole number of ticks"):
        est.step(0.0, 1e-3, {**zero_inputs(est), "R_BS": np.eye(3).reshape(9)})


def test_check_inputs_names_the_bad_port():
    est = Estimator()
    with pytest.raises(ConfigError, match=r"Estimator.wrench_S: expected 6 values, got 7"):
        check_inputs(est, {**zero_inputs(est), "wrench_S": np.zeros(7)})
    with pytest.raises(ConfigError, match=r"Estimator: unknown input port 'wrench_B'"):
        check_inputs(est, {**zero_inputs(est), "wrench_B": np.zeros(6)})
    inputs = zero_inputs(est)
    del inputs["R_BS"]
    with pytest.raises(ConfigError, match=r"Estimator: input port 'R_BS' is missing"):
        check_inputs(est, inputs)
