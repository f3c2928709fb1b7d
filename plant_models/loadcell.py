"""The Honeywell Model 31 load cell on the probe, behind its INA125P and an Arduino Uno's 10-bit ADC.

Seed 000, section 3.B.2, Fig. 8 and 9; the chain's figures and data sheets are in
`hoh_cosim.control.loadcell`. Per reading (a line of the Arduino's, `LoadCellParams.rate_hz`):

    c = max(0, -F_z)                        compression only: a pull lifts the probe off the button
    v = V_zero + drift(t) + c · V/N + σ z   the amplifier's output, z standard normal
    n = clip(floor(1024 v / 5 V), 0, 1023)  the ADC's count (the quantisation)
    F_L = (0, 0, -newtons(n))               as the driver turns the count into a force

F is the true force on the cell in its frame L (eq. 3, z from handle to tip): only its axial part
loads a button cell. The packet timing (rate, latency, the counter) is the FSE103's and the
FT-150's (`plant_models.sensors.PacketClock`).

Faults, each a parameter (size 0 / False: off):
- `saturated`, the seed's cell (Fig. 9): crushed, perhaps by bad storage, it sits near the top
  rail (count 1022, noisy); a compression moves it by about one count (+5 mV), a tension by about
  -0.5 V. Both approach their figure as 1 - exp(-|F| / 2 N): the seed gives the deflections, not
  the loads that made them.
- `open_circuit`: a bridge lead open; the amplifier's input floats and its output goes to the
  rail: every reading is 1023, still and deaf to the load.
- `zero_drift_N_per_min`: the zero creeps by this much compression a minute (warming up, creep).

`ideal` switches off the noise (the quantisation stays: it is the interface, a count).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from hoh_cosim.control.block import Port
from hoh_cosim.control.loadcell import ADC_COUNTS, LINE_RATE_HZ, SEED_CHAIN, force_L
from hoh_cosim.control.vectors import Vec, as_scalar
from plant_models.sensors import _PacketSensor, _rate_and_latency

__all__ = [
    "OPEN_CIRCUIT_COUNT",
    "SATURATED_COUNT",
    "SATURATED_KNEE_N",
    "SATURATED_TENSION_V",
    "LoadCellParams",
    "LoadCellSensor",
]

SATURATED_COUNT = ADC_COUNTS - 2
"""The seed's crushed cell at rest: near the top rail (Fig. 9), one count below it."""
SATURATED_TENSION_V = 0.5
"""[V] How far a tension pulls the crushed cell's output down (seed 3.B.2: -0.5 V)."""
SATURATED_KNEE_N = 2.0
"""[N] The load at which the crushed cell's deflections reach 63 % of their figure (assumed)."""
OPEN_CIRCUIT_COUNT = ADC_COUNTS - 1
"""An open bridge: the amplifier at its rail, the ADC at full scale."""


@dataclass(frozen=True)
class LoadCellParams:
    rate_hz: float = LINE_RATE_HZ
    latency_s: float = 0.002  # a 20-byte line at 115200 baud is 1.7 ms on the wire
    noise_V: float = 0.002  # [V] σ at the amplifier's output (assumed: about half a count)
    offset_V: float = 0.03  # [V] the bridge's own zero imbalance after the amplifier (assumed)
    saturated: bool = False
    open_circuit: bool = False
    zero_drift_N_per_min: float = 0.0
    ideal: bool = False
    connected: bool = True  # False: every line is lost (a dropout)

    UNITS: ClassVar[dict[str, Any]] = {
        "rate_hz": "Hz",
        "latency_s": "s",
        "noise_V": "V",
        "offset_V": "V",
        "zero_drift_N_per_min": "N/min",
    }
    TUNABLE: ClassVar[frozenset[str]] = frozenset(
        {"connected", "saturated", "open_circuit", "zero_drift_N_per_min", "offset_V", "noise_V"}
    )

    def __post_init__(self) -> None:
        _rate_and_latency(self)
        object.__setattr__(self, "noise_V", as_scalar(self.noise_V, "noise_V", low=0.0))
        object.__setattr__(self, "offset_V", as_scalar(self.offset_V, "offset_V"))
        object.__setattr__(
            self,
            "zero_drift_N_per_min",
            as_scalar(self.zero_drift_N_per_min, "zero_drift_N_per_min"),
        )


class LoadCellSensor(_PacketSensor):
    """The load cell, its amplifier and its ADC under the block contract; noise from the injected
    generator. `count` is the ADC's raw reading of the last delivered line."""

    true_port, value_port, size = "force_P_true", "reading", 4  # the force's 3 and the count

    inputs: ClassVar[tuple[Port, ...]] = (
        Port("force_P_true", 3, "N", "true force of the probe on the load cell, in its frame L"),
    )
    outputs: ClassVar[tuple[Port, ...]] = (
        Port("force_P", 3, "N", "last delivered reading as a force in L, (0, 0, -compression)"),
        Port("count", 1, "1", "the ADC's count of the last delivered reading (0 to 1023)"),
        Port("counter", 1, "1", "readings delivered so far (0 before the first)"),
    )

    def __init__(
        self, params: LoadCellParams | None = None, rng: np.random.Generator | None = None
    ) -> None:
        super().__init__(params or LoadCellParams(), rng)

    def reset(self) -> None:
        self.clock.reset()
        self._hold_initial()
        self._raw: dict[str, Vec] | None = None
        self._out: dict[str, Vec] = {}

    def volts(self, true: Vec, t_s: float, z: float) -> float:
        """The amplifier's output [V] for the true force `true` (in L) at time `t_s`, noise z σ."""
        p, chain = self.params, SEED_CHAIN
        axial = -float(true[2])  # compression > 0, tension < 0
        if p.saturated:
            lsb = 1.0 / chain.counts_per_V
            rest = (SATURATED_COUNT + 0.5) * lsb
            bend = 1.0 - math.exp(-abs(axial) / SATURATED_KNEE_N)
            return rest + (lsb if axial > 0.0 else -SATURATED_TENSION_V) * bend + z * p.noise_V
        drift_N = p.zero_drift_N_per_min * t_s / 60.0
        compression = max(axial, 0.0)
        v = chain.zero_V + p.offset_V + chain.volts_per_N * (compression + drift_N)
        return v + z * p.noise_V

    def _measure(self, true: Vec) -> Vec:
        p = self.params
        z = 0.0 if p.ideal else float(self.rng.standard_normal())
        if p.open_circuit:
            count = OPEN_CIRCUIT_COUNT
        else:
            count = SEED_CHAIN.count(self.volts(true, self.clock.next_sample_s, z))
        return np.append(force_L(SEED_CHAIN.newtons(count)), float(count))

    def step(self, t: float, dt: float, inputs: Mapping[str, Vec]) -> dict[str, Vec]:
        raw = super().step(t, dt, inputs)
        if raw is not self._raw:  # a new line (or the first step): its force and count apart
            self._raw = raw
            reading = raw["reading"]
            self._out = {
                "force_P": reading[:3],
                "count": reading[3:],
                "counter": raw["counter"],
            }
        return self._out
