"""Breathing: the patient's abdominal wall rising and falling under the probe.

The block gives the phantom's surface displacement h(t) along its outward normal and its rate; the
plant (`plant_models.plant`, `plant_models.freehand`) adds h to the contact depth and ḣ to its rate
(`plant_models.tissue.contact_force`), on the plane and on the ellipsoid alike.

The shape is Lujan's breathing model (Lujan, Larsen, Balter and Ten Haken 1999, "A method for
incorporating organ motion due to breathing into 3D dose calculations", Med. Phys. 26(5):715-720),
written from end-expiration:

    h(t) = A_k sin²ⁿ(π φ),   φ = (t - t_k) / T_k  in breath k, which starts at t_k and lasts T_k
    ḣ(t) = A_k · 2n sin²ⁿ⁻¹(π φ) cos(π φ) · π / T_k

n = 1 is a raised cosine; a larger n rests longer at end-expiration and peaks more sharply at
inspiration, as Lujan et al. observed (they fitted n = 1 to 3). h and ḣ are zero at every breath's
start and end, so they stay continuous from breath to breath whatever its period and depth.

Irregularity (seeded): each breath's period and depth are drawn as T_k = T (1 + c ε) and
A_k = A (1 + c η), ε and η standard normal clipped to ±2.5, c the `irregularity`; the first breath
starts at a random phase. The draws come from the block's generator in breath order, so the signal
is a function of time alone: any step size gives the same values.

Figures (the ranges the population draws from, `plant_models.population`):
- rate 12-20 breaths per minute: the normal adult resting respiratory rate (e.g. Cretikos et al.
  2008, "Respiratory rate: the neglected vital sign", Med. J. Aust. 188(11):657-659);
- peak-to-peak excursion 5-15 mm: the abdominal wall moves almost only ventrally in tidal
  breathing (De Groote et al. 1997, J. Appl. Physiol. 83(5):1531-1537), by millimetres to about a
  centimetre in quiet breathing and more in deep breathing (Kaneko and Horie 2012, "Breathing
  movements of the chest and abdominal wall in healthy subjects", Respir. Care 57(9):1442-1451);
- irregularity 0.1: breath-to-breath variation of period and depth of the order of 10 %.

Moving away (the clinical study's planted contact loss, "the patient moves away 15 mm within
0.3 s"): a patient who shifts, coughs or pulls in the belly takes the skin away from the probe. From
t_a = `away_s` the surface moves D = `away_m` inward, away from the probe, over T_a = `away_time_s`,
and stays there:

    d(t) = D (1 - cos(π s)) / 2,   s = clip((t - t_a) / T_a, 0, 1)
    ḋ(t) = D π sin(π s) / (2 T_a)  while 0 < s < 1, else 0
    offset = h - d,   rate = ḣ - ḋ

a raised cosine, so the offset and its rate stay continuous; like the breaths, a function of time
alone, and independent of `start_s`. With `away_m` 0 (the default) the surface never moves away and
the outputs are the breaths' alone.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from hoh_cosim.control.block import Port
from hoh_cosim.control.vectors import Vec, as_scalar
from hoh_cosim.errors import ConfigError

__all__ = ["Breathing", "BreathingParams", "away_value", "breath_value"]

_CLIP = 2.5  # standard deviations: a breath's period stays positive up to irregularity 0.4


@dataclass(frozen=True)
class BreathingParams:
    UNITS: ClassVar[dict[str, Any]] = {
        "rate_per_min": "1/min",
        "amplitude_m": "m",
        "irregularity": "1",
        "shape_n": "1",
        "start_s": "s",
        "away_s": "s",
        "away_m": "m",
        "away_time_s": "s",
    }

    rate_per_min: float = 15.0  # mean breaths per minute
    amplitude_m: float = 0.010  # [m] mean peak-to-peak excursion along the surface's normal
    irregularity: float = 0.1  # c: relative standard deviation of each breath's period and depth
    shape_n: int = 2  # Lujan's exponent n
    start_s: float = 0.0  # [s] the surface rests (h = 0) before this
    away_s: float = 0.0  # [s] the patient begins to move away (with away_m 0: never)
    away_m: float = 0.0  # [m] how far the surface moves inward, away from the probe (0: never)
    away_time_s: float = 0.3  # [s] how long the move away takes

    def __post_init__(self) -> None:
        object.__setattr__(
            self,
            "rate_per_min",
            as_scalar(self.rate_per_min, "rate_per_min", low=0.0, low_open=True, high=120.0),
        )
        object.__setattr__(
            self, "amplitude_m", as_scalar(self.amplitude_m, "amplitude_m", low=0.0, high=0.1)
        )
        object.__setattr__(
            self, "irregularity", as_scalar(self.irregularity, "irregularity", low=0.0, high=0.4)
        )
        object.__setattr__(self, "start_s", as_scalar(self.start_s, "start_s", low=0.0))
        object.__setattr__(self, "away_s", as_scalar(self.away_s, "away_s", low=0.0))
        object.__setattr__(self, "away_m", as_scalar(self.away_m, "away_m", low=0.0, high=0.1))
        object.__setattr__(
            self, "away_time_s", as_scalar(self.away_time_s, "away_time_s", low=0.0, low_open=True)
        )
        n = self.shape_n
        if not isinstance(n, int | np.integer) or isinstance(n, bool) or not 1 <= n <= 5:
            raise ConfigError(f"shape_n: expected an integer from 1 to 5, got {n!r}")
        object.__setattr__(self, "shape_n", int(n))


def away_value(distance: float, duration: float, progress: float) -> tuple[float, float]:
    """(d, ḋ) of a move of `distance` [m] over `duration` [s] at `progress` (clipped to 0-1)."""
    if progress <= 0.0:
        return 0.0, 0.0
    if progress >= 1.0:
        return distance, 0.0
    return (
        distance * (1.0 - math.cos(math.pi * progress)) / 2.0,
        distance * math.pi * math.sin(math.pi * progress) / (2.0 * duration),
    )


def breath_value(amplitude: float, period: float, phase: float, n: int) -> tuple[float, float]:
    """(h, ḣ) at `phase` (0 to 1) of a breath of depth `amplitude` [m] lasting `period` [s]."""
    s, c = math.sin(math.pi * phase), math.cos(math.pi * phase)
    s_odd = s ** (2 * n - 1)
    return amplitude * s_odd * s, amplitude * 2.0 * n * s_odd * c * math.pi / period


class Breathing:
    """The surface's displacement along its normal under the block contract; no inputs."""

    variable_step: ClassVar[bool] = True  # a function of time alone
    inputs: ClassVar[tuple[Port, ...]] = ()
    outputs: ClassVar[tuple[Port, ...]] = (
        Port("offset_m", 1, "m", "displacement of the surface along its outward normal"),
        Port("rate_m_s", 1, "m/s", "rate of the displacement"),
        Port("phase", 1, "1", "fraction of the current breath, 0 at end-expiration"),
    )

    def __init__(
        self, params: BreathingParams | None = None, rng: np.random.Generator | None = None
    ) -> None:
        self.params = params or BreathingParams()
        rng = rng if rng is not None else np.random.default_rng(0)
        self._seed = int(rng.integers(2**63))
        self.reset()

    def retune(self, params: BreathingParams) -> None:
        self.params = params

    def reset(self) -> None:
        self._rng = np.random.default_rng(self._seed)
        self._first_phase = float(self._rng.uniform(0.0, 1.0))
        # breath k: (start relative to start_s in periods of the mean, relative period, depth)
        self._breaths: list[tuple[float, float, float]] = []
        self._k = 0

    def _draw(self) -> tuple[float, float]:
        eps, eta = np.clip(self._rng.standard_normal(2), -_CLIP, _CLIP).tolist()
        c = self.params.irregularity
        return 1.0 + c * eps, 1.0 + c * eta

    def _breath(self, k: int) -> tuple[float, float, float]:
        """Breath k, drawing the breaths up to it in order."""
        while len(self._breaths) <= k:
            period, depth = self._draw()
            if self._breaths:
                start, last, _ = self._breaths[-1]
                start += last
            else:
                start = -self._first_phase * period
            self._breaths.append((start, period, depth))
        return self._breaths[k]

    def value(self, t: float) -> tuple[float, float, float]:
        """(offset [m], rate [m/s], phase) at time t: the breath less the move away."""
        h, h_dot, phase = self._breath_value(t)
        p = self.params
        if p.away_m > 0.0:  # only then: without a move the breaths' arithmetic is untouched
            d, d_dot = away_value(p.away_m, p.away_time_s, (t - p.away_s) / p.away_time_s)
            h, h_dot = h - d, h_dot - d_dot
        return h, h_dot, phase

    def _breath_value(self, t: float) -> tuple[float, float, float]:
        """(h [m], ḣ [m/s], phase) of the breaths at time t."""
        p = self.params
        if t < p.start_s:
            return 0.0, 0.0, 0.0
        mean_period = 60.0 / p.rate_per_min
        u = (t - p.start_s) / mean_period  # in mean periods
        k = self._k
        start, period, depth = self._breath(k)
        while u < start and k > 0:  # time went back (a reset does not; a restored state may)
            k -= 1
            start, period, depth = self._breath(k)
        while u >= start + period:
            k += 1
            start, period, depth = self._breath(k)
        self._k = k
        phase = (u - start) / period
        h, h_dot = breath_value(p.amplitude_m * depth, mean_period * period, phase, p.shape_n)
        return h, h_dot, phase

    def _outputs(self, t: float) -> dict[str, Vec]:
        h, h_dot, phase = self.value(t)
        return {
            "offset_m": np.array([h]),
            "rate_m_s": np.array([h_dot]),
            "phase": np.array([phase]),
        }

    def initial_outputs(self) -> dict[str, Vec]:
        return self._outputs(0.0)

    def step(self, t: float, dt: float, inputs: Mapping[str, Vec]) -> dict[str, Vec]:
        return self._outputs(t + dt)
