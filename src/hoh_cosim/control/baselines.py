"""Baseline filters the seed and the older work compared against: Butterworth, 1€, and no filter.

All share the interface of `ForceKalman`: `reset()`, and `step(dt, z) -> estimate` called every tick
with `z` the new packet or None. They are streaming filters with explicit state, so a run can stop,
reset or be checkpointed at any tick.

- `ButterworthFilter`: the seed's frequency-domain comparison (section 4.C, Fig. 19): a 5th-order,
  5 Hz low-pass, as scipy second-order sections, run every tick on the last packet held (zero-order
  hold) at the tick rate, with its state kept between calls.
- `OneEuroFilter`: the 1€ filter (Casiez, Roussel, Vogel, CHI 2012) that Finocchi used on F/T readings
  (seed section 1.B). It is event-driven by design, so it runs once per packet, with the time since the
  previous packet as its sampling period, and holds its output in between. We implement it from the
  paper rather than use the `OneEuroFilter` package: the package filters one scalar per object, keeps its
  state in name-mangled attributes that its `reset()` clears only in part, and treats a timestamp of 0
  as "no timestamp". The tests check our filter against the package on the same data.
- `ZeroOrderHold`: no filtering, the last packet held: what the seed calls "unfiltered" (Fig. 20).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from hoh_cosim.control.vectors import Vec, Vec3, as_scalar
from hoh_cosim.errors import ConfigError

__all__ = [
    "ButterworthFilter",
    "ButterworthParams",
    "OneEuroFilter",
    "OneEuroParams",
    "ZeroOrderHold",
    "one_euro_alpha",
]


class ZeroOrderHold:
    """Holds the last packet; zero before the first."""

    def __init__(self, size: int = 3) -> None:
        self.size = size
        self.reset()

    def reset(self) -> None:
        self.value = np.zeros(self.size)

    def step(self, dt: float, z: Vec | None) -> Vec:
        if z is not None:
            self.value = np.array(z, dtype=np.float64)
        return self.value.copy()


@dataclass(frozen=True)
class ButterworthParams:
    UNITS: ClassVar[dict[str, Any]] = {"order": "1", "cutoff_hz": "Hz"}

    order: int = 5  # seed Fig. 19
    cutoff_hz: float = 5.0  # seed Fig. 19

    def __post_init__(self) -> None:
        if not isinstance(self.order, int) or isinstance(self.order, bool) or self.order < 1:
            raise ConfigError(f"order must be an integer >= 1, got {self.order!r}")
        object.__setattr__(
            self, "cutoff_hz", as_scalar(self.cutoff_hz, "cutoff_hz", low=0.0, low_open=True)
        )


class ButterworthFilter:
    """Streaming low-pass Butterworth on the zero-order-held packets, designed for the tick rate.

    The design happens at the first step, for fs = 1/dt; a later step with another dt is refused. The
    state starts at the steady state for the first packet (no start-up transient from zero).
    """

    def __init__(self, params: ButterworthParams, size: int = 3) -> None:
        # scipy.signal takes most of a second to import and only this filter needs it: imported
        # when a filter is built, never on a tick
        from scipy.signal import butter, sosfilt_zi

        self._butter, self._sosfilt_zi = butter, sosfilt_zi
        self.params = params
        self.size = size
        self._dt = math.nan
        self.reset()

    def reset(self) -> None:
        self._held: list[float] | None = None  # the last packet
        self._zi: list[list[list[float]]] | None = None  # per axis, per section: (s0, s1)

    def _design(self, dt: float) -> None:
        nyquist = 0.5 / dt
        if not self.params.cutoff_hz < nyquist:
            raise ConfigError(
                f"cutoff_hz: must be below the Nyquist frequency {nyquist:g} Hz of dt = {dt} s, "
                f"got {self.params.cutoff_hz}"
            )
        sos = self._butter(self.params.order, self.params.cutoff_hz, fs=1.0 / dt, output="sos")
        # (b0, b1, b2, a1, a2) per second-order section; butter's sections have a0 = 1
        self._sections = [(b0, b1, b2, a1, a2) for b0, b1, b2, _, a1, a2 in sos.tolist()]
        self._zi_unit = self._sosfilt_zi(sos).tolist()  # (sections, 2) for a unit step
        self._dt = dt

    def step(self, dt: float, z: Vec | None) -> Vec:
        """One sample per axis through the sections in transposed direct form II, as scipy's
        `sosfilt` computes it (the same operations in the same order, in floats: a call of
        `sosfilt` per sample costs about 100 µs):

            y = b0 x + s0 ;  s0 ← b1 x - a1 y + s1 ;  s1 ← b2 x - a2 y ;  x ← y   (each section)
        """
        if dt != self._dt:
            if not math.isnan(self._dt):
                raise ConfigError(f"dt: the filter was designed for {self._dt} s, got {dt} s")
            self._design(dt)
        if z is not None:
            self._held = np.asarray(z, dtype=np.float64).tolist()
            if self._zi is None:  # the steady state for the first packet, per axis and section
                self._zi = [[[s0 * x, s1 * x] for s0, s1 in self._zi_unit] for x in self._held]
        if self._held is None:
            return np.zeros(self.size)
        out = []
        for x, states in zip(self._held, self._zi, strict=True):
            for (b0, b1, b2, a1, a2), s in zip(self._sections, states, strict=True):
                y = b0 * x + s[0]
                s[0] = b1 * x - a1 * y + s[1]
                s[1] = b2 * x - a2 * y
                x = y
            out.append(x)
        return np.array(out)


@dataclass(frozen=True)
class OneEuroParams:
    """1€ tuning (Casiez et al. 2012): `min_cutoff_hz` sets the smoothing at rest, `beta` how fast the
    cutoff rises with speed, `d_cutoff_hz` the smoothing of the speed estimate."""

    UNITS: ClassVar[dict[str, Any]] = {"min_cutoff_hz": "Hz", "beta": "1/N", "d_cutoff_hz": "Hz"}

    min_cutoff_hz: float = 1.0
    beta: float = 0.05
    d_cutoff_hz: float = 1.0

    def __post_init__(self) -> None:
        for name in ("min_cutoff_hz", "d_cutoff_hz"):
            object.__setattr__(
                self, name, as_scalar(getattr(self, name), name, low=0.0, low_open=True)
            )
        object.__setattr__(self, "beta", as_scalar(self.beta, "beta", low=0.0))


def one_euro_alpha(rate_hz: float, cutoff_hz: Vec | float) -> Vec | float:
    """Smoothing factor of the 1€ filter's exponential stage: α = 1 / (1 + τ·rate), τ = 1/(2π fc)."""
    tau = 1.0 / (2.0 * math.pi * cutoff_hz)
    return 1.0 / (1.0 + tau * rate_hz)


class OneEuroFilter:
    """The 1€ filter on every axis, one step per packet, output held between packets.

    On a packet after an interval T (rate = 1/T):
        dx   = (z - x̂) · rate
        dx̂  ← dx̂ + α(rate, d_cutoff) (dx - dx̂)
        fc   = min_cutoff + β |dx̂|
        x̂   ← x̂ + α(rate, fc) (z - x̂)
    The first packet initialises x̂ = z, dx̂ = 0.
    """

    def __init__(self, params: OneEuroParams, size: int = 3) -> None:
        self.params = params
        self.size = size
        self.reset()

    def reset(self) -> None:
        self.x_hat = np.zeros(self.size)
        self.dx_hat = np.zeros(self.size)
        self._since_packet = 0.0
        self._started = False

    def step(self, dt: float, z: Vec3 | None) -> Vec3:
        self._since_packet += dt
        if z is not None:
            z = np.asarray(z, dtype=np.float64)
            if not self._started:
                self.x_hat = z.copy()
                self._started = True
            else:
                p = self.params
                rate = 1.0 / self._since_packet
                dx = (z - self.x_hat) * rate
                self.dx_hat = self.dx_hat + one_euro_alpha(rate, p.d_cutoff_hz) * (dx - self.dx_hat)
                cutoff = p.min_cutoff_hz + p.beta * np.abs(self.dx_hat)
                self.x_hat = self.x_hat + one_euro_alpha(rate, cutoff) * (z - self.x_hat)
            self._since_packet = 0.0
        return self.x_hat.copy()
