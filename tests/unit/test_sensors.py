"""The FT-150 and FSE103 sensor models: packets, noise, drift, quantisation, the housing."""

from __future__ import annotations

import numpy as np
import pytest

from hoh_cosim.errors import ConfigError
from plant_models.sensors import (
    FSE103Params,
    FSE103Sensor,
    FT150Params,
    FT150Sensor,
    HousingParams,
    housing_characterisation,
)

DT = 1e-3
QUIET_FT = dict(
    offset=np.zeros(6),
    drift_per_sqrt_s=np.zeros(6),
    quantisation=np.zeros(6),
    noise_sigma=np.zeros(6),
)


def run_ft(params: FT150Params, true, seconds: float, seed: int = 0):
    sensor = FT150Sensor(params, np.random.default_rng(seed))
    out = []
    for k in range(round(seconds / DT)):
        t = k * DT
        o = sensor.step(t, DT, {"wrench_S_true": np.asarray(true(t), float)})
        out.append((t + DT, o["wrench_S"], o["counter"][0]))
    return out


@pytest.mark.parametrize(("rate", "every"), [(200.0, 5), (100.0, 10), (62.5, 16)])
def test_packet_rate_is_exact(rate, every):
    out = run_ft(FT150Params(rate_hz=rate, latency_s=0.0, **QUIET_FT), lambda t: np.zeros(6), 2.0)
    counters = np.array([c for _, _, c in out])
    assert counters[-1] == rate * 2.0
    new = np.flatnonzero(np.diff(np.concatenate([[0.0], counters])))
    np.testing.assert_array_equal(np.diff(new), every)


def test_latency_and_zero_order_hold():
    # the true wrench steps at 0.1003 s; the packet sampled at 0.105 s carries it, 2 ms later
    step = lambda t: np.full(6, 1.0 if t >= 0.1003 else 0.0)  # noqa: E731
    out = run_ft(FT150Params(latency_s=0.002, **QUIET_FT), step, 0.2)
    seen = next(t for t, w, _ in out if w[0] == 1.0)
    assert seen == pytest.approx(0.107)
    values = [w[0] for t, w, _ in out if 0.107 <= t < 0.112]
    assert values == [1.0] * len(values)  # held between packets


def test_ideal_sensor_reads_the_truth():
    truth = np.array([1.234567, -2.0, 3.5, 0.01, -0.02, 0.03])
    out = run_ft(FT150Params(ideal=True), lambda t: truth, 0.1)
    np.testing.assert_array_equal(out[-1][1], truth)


def test_noise_statistics_match_their_parameters():
    sigma = np.array([0.33, 0.30, 0.09, 0.016, 0.015, 0.004])
    params = FT150Params(**{**QUIET_FT, "noise_sigma": sigma, "offset": np.arange(6.0)})
    out = run_ft(params, lambda t: np.zeros(6), 100.0, seed=4)
    packets = np.array([w for t, w, c in out[9::5]])  # one per packet, from the first delivered
    assert len(packets) == 19_999
    np.testing.assert_allclose(packets.std(axis=0), sigma, rtol=0.03)
    assert np.all(np.abs(packets.mean(axis=0) - np.arange(6.0)) < 4 * sigma / np.sqrt(20_000))


def test_default_noise_is_the_seeds_static_noise():
    out = run_ft(
        FT150Params(**{**QUIET_FT, "noise_sigma": FT150Params().noise_sigma}),
        lambda t: np.zeros(6),
        10.0,
        seed=5,
    )
    packets = np.array([w for t, w, c in out[4::5]])
    # seed 4.C: max |noise| about 1.15, 1.06, 0.31 N over a static record
    np.testing.assert_allclose(np.abs(packets[:, :3]).max(axis=0), [1.15, 1.06, 0.31], rtol=0.2)


def test_drift_is_a_random_walk_of_the_given_rate():
    rate = np.full(6, 0.01)
    params = FT150Params(**{**QUIET_FT, "drift_per_sqrt_s": rate})
    out = run_ft(params, lambda t: np.zeros(6), 100.0, seed=6)
    packets = np.array([w for t, w, c in out[9::5]])
    steps = np.diff(packets, axis=0)
    np.testing.assert_allclose(steps.std(axis=0), rate * np.sqrt(0.005), rtol=0.03)


def test_quantisation():
    params = FT150Params(**{**QUIET_FT, "quantisation": np.array([0.01] * 3 + [0.0005] * 3)})
    out = run_ft(params, lambda t: np.array([0.123456, -1.0049, 2.0, 0.01234, 0.0, -0.0003]), 0.01)
    np.testing.assert_allclose(out[-1][1], [0.12, -1.0, 2.0, 0.0125, 0.0, -0.0005], atol=1e-12)


def test_same_seed_same_readings():
    a = run_ft(FT150Params(), lambda t: np.zeros(6), 0.5, seed=9)
    b = run_ft(FT150Params(), lambda t: np.zeros(6), 0.5, seed=9)
    c = run_ft(FT150Params(), lambda t: np.zeros(6), 0.5, seed=10)
    np.testing.assert_array_equal([w for _, w, _ in a], [w for _, w, _ in b])
    assert not np.array_equal([w for _, w, _ in a], [w for _, w, _ in c])


# --- FSE103 ------------------------------------------------------------------------------


def run_fse(params: FSE103Params, force, seconds: float):
    sensor = FSE103Sensor(params, np.random.default_rng(0))
    out = []
    for k in range(round(seconds / DT)):
        t = k * DT
        o = sensor.step(t, DT, {"force_P_true": np.asarray(force(t), float)})
        out.append((t + DT, force(t), o["force_P"], o["counter"][0]))
    return out


def triangle(t):  # 0 → 10 N → 0 on z over 4 s, twice
    phase = (t % 4.0) / 4.0
    return np.array([0.0, 0.0, 20.0 * (phase if phase < 0.5 else 1.0 - phase)])


def loop_area(out, rate=50.0, axis=2):
    """Area between the loading and unloading branches of the readings against the true force,
    each packet paired with the force it sampled (packet k: the input of the step ending at k/rate)."""
    f, m, up = [], [], []
    previous = 0.0
    for _, _, reading, counter in out:
        if counter != previous and counter > 200:  # a new packet, after the first cycle
            t_sample = counter / rate - DT
            f.append(triangle(t_sample)[2])
            m.append(reading[axis])
            up.append(triangle(t_sample + DT)[2] > triangle(t_sample)[2])
        previous = counter
    f, m, up = np.array(f), np.array(m), np.array(up)
    grid = np.linspace(1.0, 9.0, 40)
    order_up, order_down = np.argsort(f[up]), np.argsort(f[~up])
    m_up = np.interp(grid, f[up][order_up], m[up][order_up])
    m_down = np.interp(grid, f[~up][order_down], m[~up][order_down])
    return float(np.trapezoid(np.abs(m_down - m_up), grid))


NO_NOISE = dict(noise_sigma=np.zeros(3), offset=np.zeros(3))


def test_rate_is_50_hz():
    out = run_fse(FSE103Params(**NO_NOISE, latency_s=0.0), triangle, 2.0)
    assert out[-1][3] == 100
    new = np.flatnonzero(np.diff([0.0] + [c for *_, c in out]))
    np.testing.assert_array_equal(np.diff(new), 20)


def test_hysteresis_loop_is_there_when_on_and_gone_when_off():
    on = run_fse(FSE103Params(**NO_NOISE, redirection=False), triangle, 12.0)
    off = run_fse(FSE103Params(**NO_NOISE, redirection=False, hysteresis=False), triangle, 12.0)
    play = housing_characterisation(HousingParams()).play[2]
    assert loop_area(on) > 0.5 * 2 * play * 8.0  # about 2w wide over the 8 N of the grid
    assert loop_area(off) < 1e-9


def test_housing_redirects_force_between_axes():
    # a pure z push shows up on x and y too, as in the seed's Fig. 6
    out = run_fse(FSE103Params(**NO_NOISE, hysteresis=False), lambda t: [0.0, 0.0, 10.0], 0.1)
    C = housing_characterisation(HousingParams()).C
    kappa = housing_characterisation(HousingParams()).kappa
    y = np.array([0.0, 0.0, 10.0])
    np.testing.assert_allclose(out[-1][2], C @ y + kappa * y * np.abs(y), atol=1e-12)
    assert np.all(np.abs(out[-1][2][:2]) > 0.1)


def test_every_session_has_its_own_housing_and_a_session_repeats():
    day1 = housing_characterisation(HousingParams(session=1))
    day1_again = housing_characterisation(HousingParams(session=1))
    day2 = housing_characterisation(HousingParams(session=2))
    np.testing.assert_array_equal(day1.C, day1_again.C)
    assert np.max(np.abs(day1.C - day2.C)) > 0.1


def test_ideal_probe_sensor_reads_the_truth():
    out = run_fse(FSE103Params(ideal=True), triangle, 1.0)
    _t, _, reading, _ = out[-1]
    # the packet sampled at 0.98 s, in the step from 0.979 s that holds the input of 0.979 s
    np.testing.assert_array_equal(reading, triangle(0.979))


def test_sensor_params_are_checked():
    with pytest.raises(ConfigError, match=r"rate_hz must be > 0.0, got 0.0"):
        FT150Params(rate_hz=0.0)
    with pytest.raises(ConfigError, match=r"noise_sigma must be >= 0 on every axis"):
        FSE103Params(noise_sigma=[-1.0, 0.0, 0.0])
    with pytest.raises(ConfigError, match=r"play_N: expected \(low, high\) with low <= high"):
        HousingParams(play_N=(1.0, 0.5))
