"""The filter without a gain peak (control/filters.py) against scipy's own bilinear transform."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import signal

from hoh_cosim.control.filters import LeadLowpassFilter, LeadLowpassParams, lead_lowpass_sections
from hoh_cosim.errors import ConfigError

T = 0.005


def _scipy_ba(params: LeadLowpassParams, period: float) -> tuple[np.ndarray, np.ndarray]:
    wz = 2 * math.pi * params.lead_zero_hz
    wc = 2 * math.pi * params.cutoff_hz
    num = np.polymul([1 / wz, 1], [wc])
    den = np.polymul([1 / (params.lead_ratio * wz), 1], [1, wc])
    return signal.bilinear(num, den, 1 / period)


@pytest.mark.parametrize("period", [0.005, 0.02])
def test_the_sections_are_scipys_bilinear_transform(period):
    params = LeadLowpassParams()
    (b0, b1, a1), (c0, c1, d1) = lead_lowpass_sections(params, period)
    b, a = _scipy_ba(params, period)
    np.testing.assert_allclose(np.polymul([b0, b1], [c0, c1]), b / a[0], rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(np.polymul([1.0, a1], [1.0, d1]), a / a[0], rtol=1e-12, atol=1e-15)


def test_the_filter_runs_scipys_filter_on_packets_and_holds_between(rng):
    params = LeadLowpassParams()
    f = LeadLowpassFilter(params, T)
    packets = rng.normal(size=(400, 3))
    b, a = _scipy_ba(params, T)
    zi = signal.lfilter_zi(b, a)
    expected = np.stack(
        [signal.lfilter(b, a, packets[:, i], zi=zi * packets[0, i])[0] for i in range(3)], axis=1
    )
    out = []
    for k in range(400 * 5):
        y = f.step(0.001, packets[k // 5] if k % 5 == 0 else None)
        if k % 5 == 4:
            out.append(y)
    np.testing.assert_allclose(np.array(out), expected, rtol=1e-9, atol=1e-12)


def test_a_constant_passes_from_the_first_packet_and_a_reset_forgets():
    f = LeadLowpassFilter(LeadLowpassParams(), T)
    for _ in range(3):
        np.testing.assert_allclose(f.step(0.001, np.array([1.0, -2.0, 3.0])), [1.0, -2.0, 3.0])
    f.reset()
    np.testing.assert_array_equal(f.step(0.001, None), 0.0)


def test_no_overshoot_on_a_step_beyond_the_lead():
    """A gain below 1.1 everywhere: a step overshoots by less than the lead's 15 %."""
    f = LeadLowpassFilter(LeadLowpassParams(), T)
    f.step(0.001, np.zeros(3))
    ys = [f.step(0.001, np.ones(3))[0] for _ in range(2000)]
    assert max(ys) <= 1.15
    assert ys[-1] == pytest.approx(1.0, abs=0.01)


def test_parameters_are_checked():
    with pytest.raises(ConfigError, match=r"lead_ratio must be >= 1.0, got 0.9"):
        LeadLowpassParams(lead_ratio=0.9)
    with pytest.raises(ConfigError, match=r"cutoff_hz: must be below the packet rate's Nyquist"):
        LeadLowpassFilter(LeadLowpassParams(cutoff_hz=30.0), 0.02)
