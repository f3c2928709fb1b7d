"""A force filter without a gain peak: an exponential smoother whose lag is bought back by a lead.

Why not another Kalman model. The constant-acceleration filter of the seed (eq. 9) and a
constant-velocity one both follow a ramp without error, and a filter that does must overshoot: in
their steady state the gain against the held reading peaks at 1.58 (eq. 9) and 1.27 (constant
velocity) whatever Q and R, near the frequency where the hand-robot loop crosses -180°, which is
what costs that loop its gain margin (`hoh_cosim.study.linear`). A Singer model (the rate a
first-order Gauss-Markov process) has no peak, but no lead either: 3x less noise costs it 20 ms of
lag at the circles' 0.25 Hz. Bode's gain-phase relation says why: for a minimum-phase filter with
unit gain at rest the low-frequency delay is τ = (2/π) ∫₀^∞ -ln|G(iω)| / ω² dω, so every
attenuation of the noise adds delay and only gain above 1 takes delay away, weighted by 1/ω².
A gain a little above 1 at low frequency buys back much delay; a peak is not needed.

The filter, per axis, at the packet rate (the analog prototype through the bilinear transform with
the packet period T, run once per packet, the output held between packets):

    G(s) = (1 + s/ω_z) / (1 + s/(r ω_z)) · ω_c / (s + ω_c)

a lead-lag (gain 1 at rest rising to r = 1.15 from f_z = 0.32 Hz on) and a first-order low-pass
at f_c = 3.4 Hz. At the FT-150's 200 Hz its gain never exceeds 1.096, it cuts white noise's
standard deviation 3.9x, and against the held reading it lags 4.4 ms at 0.25 Hz (the circles'
frequency) and about 39 ms at 1-2 Hz: it trades the Kalman filters' lead at the loop's -180°
crossover for the absence of their peak, which gives the default hand-robot loop a gain margin of
2.2 instead of 1.52 (`hoh_cosim.study.linear`;
`docs/decisions/0036-transparency-pieces-off-by-default.md`).

Bilinear transform, s = K (1 - z⁻¹)/(1 + z⁻¹), K = 2/T, per first-order section:
    (1 + s/ω₁)/(1 + s/ω₂) → ((1 + K/ω₁) + (1 - K/ω₁) z⁻¹) / ((1 + K/ω₂) + (1 - K/ω₂) z⁻¹)
    ω_c/(s + ω_c)          → (ω_c + ω_c z⁻¹) / ((ω_c + K) + (ω_c - K) z⁻¹)
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from hoh_cosim.control.vectors import Vec, as_scalar
from hoh_cosim.errors import ConfigError

__all__ = ["LeadLowpassFilter", "LeadLowpassParams", "lead_lowpass_sections"]


@dataclass(frozen=True)
class LeadLowpassParams:
    """lead_zero_hz: f_z; lead_ratio: r, the gain the lead-lag rises to (>= 1; 1: no lead);
    cutoff_hz: f_c of the first-order low-pass."""

    UNITS: ClassVar[dict[str, Any]] = {
        "lead_zero_hz": "Hz",
        "lead_ratio": "1",
        "cutoff_hz": "Hz",
    }

    lead_zero_hz: float = 0.32
    lead_ratio: float = 1.15
    cutoff_hz: float = 3.4

    def __post_init__(self) -> None:
        for name in ("lead_zero_hz", "cutoff_hz"):
            object.__setattr__(
                self, name, as_scalar(getattr(self, name), name, low=0.0, low_open=True)
            )
        object.__setattr__(
            self, "lead_ratio", as_scalar(self.lead_ratio, "lead_ratio", low=1.0, high=2.0)
        )


def lead_lowpass_sections(
    params: LeadLowpassParams, period_s: float
) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
    """The two first-order sections (b0, b1, a1), a0 = 1, of the filter at packet period T (the
    module docstring's bilinear transform). Each has unit gain at rest."""
    nyquist = 0.5 / period_s
    if not params.cutoff_hz < nyquist:
        raise ConfigError(
            f"cutoff_hz: must be below the packet rate's Nyquist frequency {nyquist:g} Hz, "
            f"got {params.cutoff_hz}"
        )
    K = 2.0 / period_s
    w1 = 2.0 * math.pi * params.lead_zero_hz
    w2 = params.lead_ratio * w1
    wc = 2.0 * math.pi * params.cutoff_hz
    a0 = 1.0 + K / w2
    lead = ((1.0 + K / w1) / a0, (1.0 - K / w1) / a0, (1.0 - K / w2) / a0)
    a0 = wc + K
    low = (wc / a0, wc / a0, (wc - K) / a0)
    return lead, low


class LeadLowpassFilter:
    """The filter of the module docstring on three axes: one step per packet, held in between.

    Designed for the expected packet period (the rig's, measured at the rebias); the state starts
    at the steady state of the first packet, so there is no start-up transient from zero.
    """

    def __init__(self, params: LeadLowpassParams, period_s: float, size: int = 3) -> None:
        self.params = params
        self.period_s = float(period_s)
        self.size = size
        (self._b0, self._b1, self._a1), (self._c0, self._c1, self._d1) = lead_lowpass_sections(
            params, self.period_s
        )
        self.reset()

    def reset(self) -> None:
        self._x: Vec | None = None  # the last packet
        self._u = np.zeros(self.size)  # the lead-lag's last output
        self.y = np.zeros(self.size)  # the filter's last output (held)

    def step(self, dt: float, z: Vec | None) -> Vec:
        """u = b0 x + b1 x₋ - a1 u₋ ;  y = c0 u + c1 u₋ - d1 y₋   (on a packet; else y held)"""
        if z is not None:
            x = np.array(z, dtype=np.float64)
            if self._x is None:  # steady state of the first packet
                self._x, self._u, self.y = x, x.copy(), x.copy()
            u = self._b0 * x + self._b1 * self._x - self._a1 * self._u
            self.y = self._c0 * u + self._c1 * self._u - self._d1 * self.y
            self._x, self._u = x, u
        # a new array on every packet, never written to afterwards: handed out as it is
        return self.y
