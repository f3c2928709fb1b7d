"""The constant-acceleration Kalman filter (seed 000, eq. 9 and section 4.C)."""

from __future__ import annotations

import numpy as np
import pytest
from filterpy.common import Q_discrete_white_noise
from filterpy.kalman import KalmanFilter

from hoh_cosim.control.estimator import (
    FSE103_NOISE_MAX,
    FT150_NOISE_MAX,
    FT150_NOISE_MAX_S,
    NOISE_MAX_PER_SIGMA,
    default_kalman,
)
from hoh_cosim.control.kalman import (
    H_FORCE,
    ForceKalman,
    KalmanBank,
    KalmanParams,
    SteadyStateForceKalman,
    axis_transition,
    predict,
    process_noise,
    steady_state_gain,
    to_seed_covariance,
    to_seed_state,
    transition_matrix,
    update,
)
from hoh_cosim.cosim.metrics import lag_at_frequency, max_abs, sinusoid_phase
from hoh_cosim.errors import ConfigError

DT = 1e-3  # tick: the seed predicted every 1 ms (4.C)
PACKET_TICKS = 5  # a packet every 5 ms (4.C)


def test_transition_matrix_is_eq9_as_printed():
    dt = 0.01  # the seed's value
    h = 0.5 * dt**2
    eq9 = np.array(
        [
            [1, 0, 0, dt, 0, 0, h, 0, 0],
            [0, 1, 0, 0, dt, 0, 0, h, 0],
            [0, 0, 1, 0, 0, dt, 0, 0, h],
            [0, 0, 0, 1, 0, 0, dt, 0, 0],
            [0, 0, 0, 0, 1, 0, 0, dt, 0],
            [0, 0, 0, 0, 0, 1, 0, 0, dt],
            [0, 0, 0, 0, 0, 0, 1, 0, 0],
            [0, 0, 0, 0, 0, 0, 0, 1, 0],
            [0, 0, 0, 0, 0, 0, 0, 0, 1],
        ]
    )
    np.testing.assert_array_equal(transition_matrix(dt), eq9)


def test_measurement_selects_the_forces_only():
    np.testing.assert_array_equal(H_FORCE @ np.arange(9.0), [0.0, 1.0, 2.0])


def test_process_noise_is_filterpys_discrete_white_noise():
    q, dt = 3.0, 2e-3
    expected = Q_discrete_white_noise(3, dt=dt, var=q * dt, block_size=3, order_by_dim=False)
    np.testing.assert_allclose(
        to_seed_covariance(process_noise(dt, np.full(3, q))), expected, rtol=1e-14, atol=0
    )


def _filterpy_reference(params: KalmanParams, dt: float) -> KalmanFilter:
    kf = KalmanFilter(dim_x=9, dim_z=3)
    kf.F = transition_matrix(dt)
    kf.H = H_FORCE.copy()
    kf.Q = to_seed_covariance(process_noise(dt, params.q))
    kf.R = np.diag(params.r)
    kf.P = np.diag(np.repeat(params.p0, 3))
    return kf


def test_matches_filterpys_nine_state_filter_step_by_step(rng):
    params = KalmanParams(q=[900.0, 400.0, 2500.0], r=[0.1, 0.08, 0.01], p0=[10.0, 1e3, 1e5])
    ours = ForceKalman(params)
    ref = _filterpy_reference(params, DT)
    for _k in range(2000):
        z = rng.normal(size=3) * 2 if rng.random() < 0.2 else None  # irregular packets
        estimate = ours.step(DT, z)
        ref.predict()
        if z is not None:
            ref.update(z)
        np.testing.assert_allclose(estimate, ref.x[:3, 0], rtol=1e-10, atol=1e-10)
    np.testing.assert_allclose(to_seed_state(ours.x), ref.x[:, 0], rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(to_seed_covariance(ours.P), ref.P, rtol=1e-9, atol=1e-12)


def test_no_packet_means_prediction_only():
    kf = ForceKalman(KalmanParams(q=[1.0] * 3, r=[0.01] * 3))
    for k in range(100):  # learn a ramp of 10 N/s
        kf.step(DT, np.full(3, 10.0 * k * DT) if k % 5 == 0 else None)
    x, P = kf.x.copy(), kf.P.copy()
    kf.step(DT, None)
    np.testing.assert_allclose(kf.x[:, 0], x[:, 0] + DT * x[:, 1] + 0.5 * DT**2 * x[:, 2])
    assert np.all(kf.P[:, 0, 0] > P[:, 0, 0])  # uncertainty grows without a measurement


def test_upsamples_a_ramp_between_packets():
    # Fig. 11: between packets the filter extrapolates, a held sample would not
    kf = ForceKalman(default_kalman(FT150_NOISE_MAX))
    for k in range(3000):
        t = k * DT
        out = kf.step(DT, np.full(3, 4.0 * t) if k % PACKET_TICKS == 0 else None)
    np.testing.assert_allclose(out, 4.0 * t, atol=1e-3)


def _run(params, signal, sigma, seed, seconds=10.0):
    rng = np.random.default_rng(seed)
    kf = ForceKalman(params)
    n = round(seconds / DT)
    t = np.arange(n) * DT
    out, held, truth = np.zeros((n, 3)), np.zeros((n, 3)), signal(t)
    last = np.zeros(3)
    for k in range(n):
        z = None
        if k % PACKET_TICKS == 0:
            z = last = truth[k] + rng.normal(0.0, sigma)
        out[k] = kf.step(DT, z)
        held[k] = last
    return t, out, held, truth


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_halves_the_seeds_static_noise_per_axis(seed):
    # seed 4.C: max |noise| 1.15, 1.06, 0.31 N cut to 0.58, 0.48, 0.12 N: "a factor of about 2"
    sigma = FT150_NOISE_MAX / NOISE_MAX_PER_SIGMA
    t, out, held, _ = _run(
        default_kalman(FT150_NOISE_MAX), lambda t: np.zeros((t.size, 3)), sigma, seed
    )
    settled = t >= 1.0
    raw, filtered = max_abs(held[settled]), max_abs(out[settled])
    np.testing.assert_allclose(raw, FT150_NOISE_MAX, rtol=0.25)  # the seed's noise level
    assert np.all(raw / filtered >= 2.0), raw / filtered


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_lag_on_a_half_hertz_sinusoid_is_at_most_10_ms(seed):
    sigma = FT150_NOISE_MAX / NOISE_MAX_PER_SIGMA
    t, out, _, truth = _run(
        default_kalman(FT150_NOISE_MAX),
        lambda t: 5.0 * np.sin(np.pi * t)[:, None] * np.ones(3),
        sigma,
        seed,
        seconds=12.0,
    )
    settled = t >= 2.0
    for axis in range(3):
        lag = lag_at_frequency(t[settled], truth[settled, axis], out[settled, axis], 0.5)
        assert abs(lag) <= 0.010, (axis, lag)
        gain = sinusoid_phase(t[settled], out[settled, axis], 0.5)[0] / 5.0
        assert gain == pytest.approx(1.0, abs=0.05)


def test_steady_state_filter_converges_to_the_full_filter(rng):
    params = default_kalman(FT150_NOISE_MAX)
    full = ForceKalman(params)
    steady = SteadyStateForceKalman(params, DT, PACKET_TICKS)
    for k in range(8000):
        z = rng.normal(0.0, 0.3, 3) + np.sin(k * DT) if k % PACKET_TICKS == 0 else None
        a, b = full.step(DT, z), steady.step(DT, z)
        if k * DT >= 5.0:
            np.testing.assert_allclose(a, b, atol=1e-6)


def test_steady_state_covariance_is_the_full_filters_prior():
    params = KalmanParams(q=[200.0, 300.0, 400.0], r=[0.1, 0.1, 0.01])
    _, P_steady = steady_state_gain(params, DT, PACKET_TICKS)
    full = ForceKalman(params)
    for k in range(10_000):  # ends on k ≡ 4 (mod 5): the next tick brings a packet
        full.step(DT, np.zeros(3) if k % PACKET_TICKS == 0 else None)
    _, prior = predict(full.x, full.P, axis_transition(DT), process_noise(DT, params.q))
    np.testing.assert_allclose(to_seed_covariance(prior), P_steady, rtol=1e-6, atol=1e-12)


def test_steady_state_filter_refuses_another_dt():
    f = SteadyStateForceKalman(KalmanParams(q=[1.0] * 3, r=[1.0] * 3), DT, 5)
    with pytest.raises(ConfigError, match=r"dt: the steady-state gain was designed for 0.001 s"):
        f.step(2e-3, None)


def test_params_reject_wrong_sizes_and_signs():
    with pytest.raises(ConfigError, match=r"q: expected 3 values, got 2"):
        KalmanParams(q=[1.0, 1.0], r=[1.0] * 3)
    with pytest.raises(ConfigError, match=r"r must be > 0 on every axis, got \[1.0, 0.0, 1.0\]"):
        KalmanParams(q=[1.0] * 3, r=[1.0, 0.0, 1.0])


def test_flattened_prediction_equals_the_matrix_form(rng):
    F = axis_transition(3e-3)
    x, P = rng.normal(size=(9, 3)), rng.normal(size=(9, 3, 3))
    Q = process_noise(3e-3, rng.uniform(1, 10, 9))
    x1, P1 = predict(x, P, F, Q)
    x2, P2 = predict(x, P, F, Q, np.kron(F, F))
    np.testing.assert_array_equal(x1, x2)
    np.testing.assert_allclose(P1, P2, rtol=1e-13, atol=1e-15)


def test_bank_with_any_channels_read_equals_the_plain_update(rng):
    # The bank corrects only the rows of the channels with a reading when they are one run of
    # channels, and masks the gain otherwise: both must give the masked `update`'s bits. Against
    # a plain filter that predicts P every tick (the bank applies its owed predictions at once,
    # which rounds differently: 1.5e-8 of the force here) it agrees to 1e-6. Every pattern of
    # readings, none and the non-contiguous one included, at random ticks.
    channels = [
        KalmanParams(q=[2.0e3, 1.0e3, 5.0e2], r=[0.1, 0.2, 0.05]),
        KalmanParams(q=[10.0, 20.0, 5.0], r=[1e-3, 2e-3, 5e-4]),
        KalmanParams(q=[4.0e2, 4.0e2, 1.0e2], r=[0.02, 0.02, 0.03]),
    ]
    rows, masked = KalmanBank(channels), KalmanBank(channels)
    masked._block = lambda pattern: np.repeat(np.array(pattern, dtype=float), 3)
    F, Q = axis_transition(DT), process_noise(DT, np.concatenate([c.q for c in channels]))
    r = np.concatenate([c.r for c in channels])
    x, P = np.zeros((9, 3)), rows.P.copy()
    seen = set()
    for k in range(3000):
        pattern = tuple(bool(b) for b in rng.integers(0, 2, 3)) if k % 3 == 0 else (False,) * 3
        seen.add(pattern)
        readings = [rng.normal(0.0, 5.0, 3) if on else None for on in pattern]
        got = rows.step_bank(DT, readings).copy()
        np.testing.assert_array_equal(got, masked.step_bank(DT, readings))
        x, P = predict(x, P, F, Q)
        if any(pattern):
            z = np.concatenate([np.zeros(3) if z is None else z for z in readings])
            x, P = update(x, P, z, r, np.repeat(np.array(pattern, dtype=float), 3))
        np.testing.assert_allclose(got, x[:, 0], rtol=1e-6, atol=1e-6)
    np.testing.assert_array_equal(rows.P, masked.P)
    assert len(seen) == 8


def test_the_banks_covariance_stays_symmetric_to_the_bit(rng):
    # Rounding set P and Pᵀ apart by 5e-10 in 20 s of 1 kHz ticks, and the gap kept growing (4e-4
    # of P after 3 h): a session on the robot lasts hours. Every correction now averages P with
    # its transpose; every reading pattern, the masked one included.
    channels = [default_kalman(FT150_NOISE_MAX_S), KalmanParams(q=[10.0] * 3, r=[1e-3] * 3)]
    channels.append(default_kalman(FSE103_NOISE_MAX))
    bank = KalmanBank(channels)
    for k in range(20000):
        pattern = (k % 5 == 0, k % 5 == 0, k % 20 == 0) if k % 7 else (True, False, True)
        bank.step_bank(DT, [rng.normal(0.0, 0.3, 3) if on else None for on in pattern])
    P = bank.P
    np.testing.assert_array_equal(P, P.transpose(0, 2, 1))
    assert np.all(np.linalg.eigvalsh(P) > 0.0)
