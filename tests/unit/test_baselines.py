"""Baseline filters: streaming Butterworth, 1€, zero-order hold."""

from __future__ import annotations

import numpy as np
import pytest
from OneEuroFilter import OneEuroFilter as PackageOneEuro
from scipy import signal

from hoh_cosim.control.baselines import (
    ButterworthFilter,
    ButterworthParams,
    OneEuroFilter,
    OneEuroParams,
    ZeroOrderHold,
)
from hoh_cosim.errors import ConfigError

DT = 1e-3


def _packets(rng, n=3000, every=5):
    """Packets every `every` ticks: (tick, value) with a moving signal and noise."""
    t = np.arange(n) * DT
    values = np.column_stack([np.sin(2 * t), 3 * np.cos(5 * t), t]) + rng.normal(0, 0.3, (n, 3))
    return [(k, values[k]) if k % every == 0 else (k, None) for k in range(n)]


@pytest.mark.parametrize(("order", "cutoff_hz"), [(5, 5.0), (1, 10.0), (2, 3.0), (8, 20.0)])
def test_butterworth_streaming_equals_scipy_batch(rng, order, cutoff_hz):
    params = ButterworthParams(order=order, cutoff_hz=cutoff_hz)
    stream = ButterworthFilter(params)
    packets = _packets(rng)
    out = np.array([stream.step(DT, z) for _, z in packets])

    held, last = [], None
    for _, z in packets:
        last = z if z is not None else last
        held.append(last)
    held = np.array(held)
    sos = signal.butter(order, cutoff_hz, fs=1 / DT, output="sos")
    zi = signal.sosfilt_zi(sos)[:, :, None] * held[0][None, None, :]
    batch, _ = signal.sosfilt(sos, held, axis=0, zi=zi)
    # the same operations in the same order as scipy's: the same bits
    np.testing.assert_array_equal(out, batch)


def test_butterworth_starts_without_a_transient():
    f = ButterworthFilter(ButterworthParams())
    z = np.array([1.0, -2.0, 3.0])
    np.testing.assert_allclose(f.step(DT, z), z, atol=1e-12)
    np.testing.assert_allclose(f.step(DT, None), z, atol=1e-12)


def test_butterworth_is_zero_before_the_first_packet():
    np.testing.assert_array_equal(ButterworthFilter(ButterworthParams()).step(DT, None), 0.0)


def test_butterworth_refuses_a_cutoff_above_nyquist():
    f = ButterworthFilter(ButterworthParams(cutoff_hz=600.0))
    with pytest.raises(ConfigError, match=r"cutoff_hz: must be below the Nyquist frequency 500 Hz"):
        f.step(DT, np.zeros(3))


def test_butterworth_refuses_a_changed_dt():
    f = ButterworthFilter(ButterworthParams())
    f.step(DT, np.zeros(3))
    with pytest.raises(ConfigError, match=r"dt: the filter was designed for 0.001 s, got 0.002 s"):
        f.step(2e-3, None)


def test_butterworth_params_are_checked():
    with pytest.raises(ConfigError, match=r"order must be an integer >= 1, got 0"):
        ButterworthParams(order=0)


def test_one_euro_equals_the_reference_package(rng):
    params = OneEuroParams(min_cutoff_hz=1.2, beta=0.3, d_cutoff_hz=1.5)
    ours = OneEuroFilter(params)
    refs = [
        PackageOneEuro(200.0, params.min_cutoff_hz, params.beta, params.d_cutoff_hz)
        for _ in range(3)
    ]
    t0 = 0.5  # the package reads a timestamp of exactly 0 as "none"
    for k, z in _packets(rng, every=7):
        out = ours.step(DT, z)
        if z is not None:
            expected = [refs[i](z[i], t0 + k * DT) for i in range(3)]
            np.testing.assert_allclose(out, expected, rtol=1e-12, atol=1e-12)


def test_one_euro_holds_between_packets():
    f = OneEuroFilter(OneEuroParams())
    first = f.step(DT, np.array([1.0, 2.0, 3.0]))
    np.testing.assert_array_equal(first, [1.0, 2.0, 3.0])
    np.testing.assert_array_equal(f.step(DT, None), first)


def test_one_euro_reset_forgets_everything():
    f = OneEuroFilter(OneEuroParams())
    f.step(DT, np.ones(3))
    f.step(DT, 2 * np.ones(3))
    f.reset()
    np.testing.assert_array_equal(f.step(DT, np.full(3, 7.0)), 7.0)


def test_one_euro_params_are_checked():
    with pytest.raises(ConfigError, match=r"min_cutoff_hz must be > 0.0, got 0.0"):
        OneEuroParams(min_cutoff_hz=0.0)


def test_zero_order_hold():
    f = ZeroOrderHold()
    np.testing.assert_array_equal(f.step(DT, None), 0.0)
    np.testing.assert_array_equal(f.step(DT, np.array([1.0, 2.0, 3.0])), [1.0, 2.0, 3.0])
    np.testing.assert_array_equal(f.step(DT, None), [1.0, 2.0, 3.0])
