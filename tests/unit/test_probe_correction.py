"""The probe-force correction: the seed's network, the online map, the consistency check, and the
estimator's probe check."""

from __future__ import annotations

import numpy as np
import pytest

from hoh_cosim.control.estimator import Estimator, EstimatorParams
from hoh_cosim.control.frames import skew
from hoh_cosim.control.probe_correction import (
    NETWORK_SIZE,
    ContactConsistency,
    OnlineProbeMap,
    ProbeCorrectionParams,
    contact_across_axis,
    features,
    network_forward,
    pack_network,
)
from hoh_cosim.errors import ConfigError
from plant_models.operator import Operator, OperatorParams
from plant_models.sensors import FSE103Params, FSE103Sensor, HousingParams


def test_network_forward_is_scikit_learns_prediction():
    from sklearn.neural_network import MLPRegressor

    rng = np.random.default_rng(3)
    x = rng.normal(0.0, 5.0, (300, 3))
    y = np.column_stack([np.tanh(x[:, 0] / 4) + 0.1 * x[:, 1], x[:, 2] ** 2 / 10, x.sum(axis=1)])
    x_mean, x_scale = x.mean(axis=0), x.std(axis=0)
    y_mean, y_scale = y.mean(axis=0), y.std(axis=0)
    nets, layers = [], []
    for j in range(3):
        net = MLPRegressor(
            hidden_layer_sizes=(20,),
            activation="logistic",
            solver="lbfgs",
            max_iter=200,
            random_state=j,
        )
        net.fit((x - x_mean) / x_scale, (y[:, j] - y_mean[j]) / y_scale[j])
        nets.append(net)
        layers.append(
            (net.coefs_[0].T, net.intercepts_[0], net.coefs_[1][:, 0], net.intercepts_[1][0])
        )
    weights = pack_network(x_mean, x_scale, y_mean, y_scale, layers)
    assert weights.shape == (NETWORK_SIZE,)
    probe = rng.normal(0.0, 6.0, (20, 3))
    expected = np.column_stack(
        [nets[j].predict((probe - x_mean) / x_scale) * y_scale[j] + y_mean[j] for j in range(3)]
    )
    got = np.array([network_forward(weights, m) for m in probe])
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-10)


def test_map_with_no_random_walk_is_the_regularised_least_squares_fit():
    """Without process noise the Kalman filter over Θ is ridge regression with the prior: per output
    i, θᵢ = (P₀ᵢ⁻¹ + ΦᵀΦ/r)⁻¹ (P₀ᵢ⁻¹ θ₀ᵢ + Φᵀ fᵢ / r)."""
    params = ProbeCorrectionParams(kind="online", tracking_per_sqrt_s=0.0)
    online = OnlineProbeMap(params)
    rng = np.random.default_rng(11)
    m = rng.normal(0.0, 6.0, (200, 3))
    f = m @ np.array([[1.1, 0.2, -0.1], [0.0, 0.9, 0.3], [0.2, 0.0, 1.2]]) + rng.normal(
        0, 0.3, (200, 3)
    )
    for k in range(len(m)):
        online.update(0.02 * k, m[k], f[k])
    Phi = np.array([features(row) for row in m])
    r = params.reference_sigma_N**2
    theta0 = np.vstack([np.eye(3), np.zeros((4, 3))])
    for i in range(3):
        P0_inv = np.linalg.inv(online._P0[i])
        A = P0_inv + Phi.T @ Phi / r
        b = P0_inv @ theta0[:, i] + Phi.T @ f[:, i] / r
        np.testing.assert_allclose(online.theta[:, i], np.linalg.solve(A, b), rtol=0, atol=1e-9)
        np.testing.assert_allclose(online.P[i], np.linalg.inv(A), rtol=1e-7, atol=1e-12)


def _pushes(seed: int, seconds: float, session: int, hysteresis: bool):
    """(reading m, true force f) at 50 Hz while a hand pushes the tip, in P (taken equal to B)."""
    op = Operator(OperatorParams(task="probe_push", start_s=0.0), rng=np.random.default_rng(seed))
    sensor = FSE103Sensor(
        FSE103Params(housing=HousingParams(session=session), hysteresis=hysteresis),
        rng=np.random.default_rng(seed),
    )
    f = np.array([op.tip_push(0.02 * k) for k in range(round(seconds / 0.02))])
    m = np.array([sensor.housing_output(row) for row in f])
    return m, f


@pytest.mark.parametrize("session", [1, 2])
def test_online_map_identifies_a_housing_from_a_probe_check(session):
    m, f = _pushes(seed=5, seconds=20.0, session=session, hysteresis=False)
    rng = np.random.default_rng(session)
    online = OnlineProbeMap(ProbeCorrectionParams(kind="online"))
    for k in range(len(m)):  # the wrist's noise on the reference
        online.update(0.02 * k, m[k], f[k] + rng.normal(0.0, 0.3, 3))
    m_new, f_new = _pushes(seed=6, seconds=20.0, session=session, hysteresis=False)
    corrected = np.array([online.correct(row) for row in m_new])
    rms_raw = np.sqrt(np.mean((m_new - f_new) ** 2))
    rms = np.sqrt(np.mean((corrected - f_new) ** 2))
    assert rms_raw > 0.6  # the housing is far from the identity...
    assert rms < 0.15  # ...and the check's map is close to its inverse on other pushes


def test_a_day_one_map_fails_on_day_two_and_the_check_repairs_it():
    online = OnlineProbeMap(ProbeCorrectionParams(kind="online"))
    m1, f1 = _pushes(seed=5, seconds=20.0, session=1, hysteresis=False)
    for k in range(len(m1)):
        online.update(0.02 * k, m1[k], f1[k])
    m2, f2 = _pushes(seed=6, seconds=20.0, session=2, hysteresis=False)
    day_two = np.sqrt(np.mean((np.array([online.correct(r) for r in m2]) - f2) ** 2))
    assert day_two > 1.0
    t0 = 20.0 + 12 * 3600.0  # the next morning: the random walk has loosened the map
    for k in range(len(m2)):
        online.update(t0 + 0.02 * k, m2[k], f2[k])
    m3, f3 = _pushes(seed=7, seconds=20.0, session=2, hysteresis=False)
    repaired = np.sqrt(np.mean((np.array([online.correct(r) for r in m3]) - f3) ** 2))
    assert repaired < 0.2


def test_contact_across_axis_ignores_the_hand():
    rng = np.random.default_rng(2)
    p_RH, p_RT = np.array([0.0, 0.0, -0.09]), np.array([0.0, 0.0, -0.2])
    for _ in range(20):
        F_hand, F_contact = rng.normal(0, 5, 3), rng.normal(0, 8, 3)
        F = F_hand + F_contact
        tau = skew(p_RH) @ F_hand + skew(p_RT) @ F_contact
        got = contact_across_axis(F, tau, p_RH, p_RT)
        across = F_contact.copy()
        across[2] = 0.0  # the axis is z here
        np.testing.assert_allclose(got, across, rtol=0, atol=1e-12)


def test_consistency_flags_a_probe_that_disagrees_and_not_one_that_agrees():
    params = ProbeCorrectionParams()
    p_RH, p_RT = params.handle_S, params.tip_S
    for offset, flagged in ((0.5, False), (3.0, True)):
        check = ContactConsistency(params, np.zeros(3))
        F_hand, F_contact = np.array([2.0, -1.0, -6.0]), np.array([1.5, 0.5, 8.0])
        F = F_hand + F_contact
        tau = skew(p_RH) @ F_hand + skew(p_RT) @ F_contact
        probe = F_contact + np.array([offset, 0.0, 4.0])  # the axial error is not seen
        for k in range(401):  # 2 s at 200 Hz: four time constants
            check.step(0.005 * k, F, tau, probe)
        assert check.mismatch == pytest.approx(offset * (1 - np.exp(-4.0)), rel=0.01)
        assert check.drifted is flagged


def test_correction_parameters_refuse_what_cannot_work():
    with pytest.raises(ConfigError, match=r"kind: expected one of none, network, online, got 'nn'"):
        ProbeCorrectionParams(kind="nn")
    with pytest.raises(
        ConfigError, match=r"network: expected trained weights .* 'hoh-cosim probe-correction'"
    ):
        ProbeCorrectionParams(kind="network")
    with pytest.raises(ConfigError, match=r"network: expected 315 numbers|network"):
        ProbeCorrectionParams(network=[1.0, 2.0])
    with pytest.raises(ConfigError, match=r"at least 1 mm apart"):
        ProbeCorrectionParams(tip_S=[0, 0, -0.1], handle_S=[0, 0, -0.1])
    with pytest.raises(ConfigError, match=r"across_from_wrist_s must be >= 0.0, got -1.0"):
        ProbeCorrectionParams(across_from_wrist_s=-1.0)
    with pytest.raises(ConfigError, match=r"across_within_N must be > 0.0, got 0.0"):
        ProbeCorrectionParams(across_within_N=0.0)


def _inputs(k: int, f_P: np.ndarray, R_SP: np.ndarray, rng) -> dict:
    """Sensor packets for tick k (1 ms): FT-150 every 5 ms, FSE103 every 20 ms, tool weightless."""
    f_S = R_SP @ f_P
    return {
        "wrench_S": np.concatenate([f_S + rng.normal(0, 0.05, 3), np.zeros(3)]),
        "ft_counter": np.array([float(k // 5)]),
        "force_P": f_P + rng.normal(0, 0.02, 3),
        "probe_counter": np.array([float(k // 20)]),
        "R_BS": np.eye(3).reshape(9),
    }


def test_estimator_holds_not_ready_through_the_probe_check_and_learns_in_it():
    from hoh_cosim.control.gravity import ToolParams

    params = EstimatorParams(
        tool=ToolParams(mass_kg=0.0),
        ft_rebias_packets=10,
        probe_rebias_packets=5,
        probe_correction=ProbeCorrectionParams(kind="online", check_s=2.0),
    )
    est = Estimator(params)
    op = Operator(
        OperatorParams(task="probe_push", start_s=0.2, push_s=0.5), rng=np.random.default_rng(1)
    )
    gain = np.diag([1.3, 0.8, 1.1])  # a housing that is off by 30 %
    rng = np.random.default_rng(4)
    ready, checking = [], []
    for k in range(1, 4000):
        f = op.tip_push(max(0.0, k * 1e-3 - 0.2)) if k * 1e-3 < 2.3 else np.array([0.0, 0.0, 5.0])
        inputs = _inputs(k, f, params.R_SP, rng)
        inputs["force_P"] = gain @ f + rng.normal(0, 0.02, 3)
        out = est.step(k * 1e-3, 1e-3, inputs)
        ready.append(out["ready"][0])
        checking.append(out["probe_check"][0])
    ready, checking = np.array(ready), np.array(checking)
    first_check = int(np.argmax(checking > 0.5))
    first_ready = int(np.argmax(ready > 0.5))
    assert 90 <= first_check <= 110  # the rebias: 5 probe packets of 20 ms
    assert first_ready - first_check == 2000  # then exactly check_s
    assert not np.any((ready > 0.5) & (checking > 0.5))
    # after the check a steady 5 N along z reads as 5 N, not the housing's 5.5 N
    assert out["F_probe_corr_P"][2] == pytest.approx(5.0, abs=0.15)
    assert out["F_probe_meas_P"][2] == pytest.approx(5.5, abs=0.1)
    assert est.correction.online is not None
    assert est.correction.online.updates == 99  # packets 6 to 104: k = 120, 140, ..., 2080


def _contact_across_from_wrist(T: float, grip_N_m: float, seconds: float) -> dict:
    """An estimator at `across_from_wrist_s` T after `seconds` of a hand pushing the handle (and
    gripping it with a torque about x_S) while the tip presses a contact that the probe sensor
    reads 0.8 N off across the axis (a play's frozen error); its last outputs."""
    from hoh_cosim.control.gravity import ToolParams

    params = EstimatorParams(
        tool=ToolParams(mass_kg=0.0),
        ft_rebias_packets=10,
        probe_rebias_packets=5,
        probe_correction=ProbeCorrectionParams(across_from_wrist_s=T),
    )
    est = Estimator(params)
    pc = params.probe_correction
    F_hand, F_contact = np.array([0.4, -0.3, -6.0]), np.array([1.0, -0.5, 8.0])
    wrench = np.concatenate(
        [
            F_hand + F_contact,
            skew(pc.handle_S) @ F_hand + skew(pc.tip_S) @ F_contact + [grip_N_m, 0.0, 0.0],
        ]
    )
    probe_P = params.R_SP.T @ (F_contact + np.array([0.8, 0.0, 0.0]))
    rng = np.random.default_rng(7)
    ready_at = None
    for k in range(1, round((0.2 + seconds) * 1000)):
        loaded = k >= 200  # nothing on the tool for the rebias (0.1 s)
        inputs = {
            "wrench_S": (wrench if loaded else np.zeros(6))
            + np.r_[rng.normal(0, 0.02, 3), rng.normal(0, 0.0005, 3)],
            "ft_counter": np.array([float(k // 5)]),
            "force_P": (probe_P if loaded else np.zeros(3)) + rng.normal(0, 0.02, 3),
            "probe_counter": np.array([float(k // 20)]),
            "R_BS": np.eye(3).reshape(9),
        }
        out = est.step(k * 1e-3, 1e-3, inputs)
        if ready_at is None and out["ready"][0] > 0.5:
            ready_at = k * 1e-3
    assert ready_at is not None
    assert ready_at < 0.2
    return out


@pytest.mark.parametrize("T", [2.0, 5.0])
def test_the_probe_force_across_the_axis_takes_its_slow_part_from_the_wrist(T):
    # the probe's 0.8 N across the axis goes as the mismatch's 0.5 s and then T's low-passes say
    # (the estimator is ready before the loads come, 0.2 s in; they last T)
    out = _contact_across_from_wrist(T, 0.0, T)
    taken = 1.0 - (T * np.exp(-1.0) - 0.5 * np.exp(-T / 0.5)) / (T - 0.5)
    error = out["F_probe_B"][0] - 1.0
    assert error == pytest.approx(0.8 * (1.0 - taken), abs=0.04)
    # long after: the contact across the axis is the wrist's, the probe's error gone ...
    out = _contact_across_from_wrist(T, 0.0, 12.0 * T)
    np.testing.assert_allclose(out["F_probe_B"], [1.0, -0.5, 8.0], atol=0.03)
    # ... and its moment about R with it (eq. 12 takes that out of the torque)
    p_RT = np.asarray(ProbeCorrectionParams().tip_S) - np.asarray(EstimatorParams().p_SR_S)
    np.testing.assert_allclose(out["tau_probe_B"], skew(p_RT) @ out["F_probe_B"], atol=1e-9)


def test_the_wrist_part_reads_a_grip_as_contact_but_not_a_twist_and_is_off_when_zero():
    # without it the probe's error stays whole
    out = _contact_across_from_wrist(0.0, 0.0, 10.0)
    assert out["F_probe_B"][0] - 1.0 == pytest.approx(0.8, abs=0.03)
    # a grip's 0.02 N·m about x reads as the contact across the axis, τ_g × d / |d|²: 0.18 N
    # along +y for d along -z, 0.11 m long (the handle to the tip)
    out = _contact_across_from_wrist(2.0, 0.02, 30.0)
    np.testing.assert_allclose(out["F_probe_B"][:2], [1.0, -0.5 + 0.02 / 0.11], atol=0.03)
    # a hand twisting the handle to tilt the probe (0.35 N·m: 3.2 N across, with the play's 0.8
    # N a mismatch beyond across_within_N) is not followed: the probe's reading stays, play and all
    # (but for what the part took while the mismatch rose through 1.2 N), where following it would
    # read +2.68 N along y
    out = _contact_across_from_wrist(2.0, 0.35, 30.0)
    np.testing.assert_allclose(out["F_probe_B"][:2], [1.8, -0.5], atol=0.08)
    assert out["probe_mismatch"][0] > 1.2


def test_probe_pushes_are_seeded_bounded_and_do_not_depend_on_the_step():
    params = OperatorParams(
        task="probe_push", start_s=1.0, push_min_N=3.0, push_max_N=12.0, push_cone_deg=45.0
    )
    a = Operator(params, rng=np.random.default_rng(8))
    b = Operator(params, rng=np.random.default_rng(8))
    c = Operator(params, rng=np.random.default_rng(9))
    coarse = [a.tip_push(t) for t in np.arange(0.0, 20.0, 0.25)]
    fine = [b.tip_push(t) for t in np.arange(0.0, 20.0, 0.001)][::250]
    np.testing.assert_array_equal(coarse, fine)
    assert not np.allclose(coarse, [c.tip_push(t) for t in np.arange(0.0, 20.0, 0.25)])
    peaks = [a.tip_push(k * params.push_s + params.push_s / 2) for k in range(10)]
    up = -params.press_direction_B
    for F in peaks:
        n = np.linalg.norm(F)
        assert 3.0 - 1e-9 <= n <= 12.0 + 1e-9
        assert F @ up / n >= np.cos(np.radians(45.0)) - 1e-12
    out = a.step(
        2.0, 0.002, {"p_BT_B": np.zeros(3), "twist_B": np.zeros(6), "F_contact_B": np.zeros(3)}
    )
    assert out["hand_on"][0] == 0.0
    assert not out["F_hand_B"].any()
    assert out["F_tip_B"].any()
