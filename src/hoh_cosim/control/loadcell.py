"""The Honeywell Model 31 load cell's chain, bridge to ADC count: its constants and counts <-> newtons.

Seed 000, section 3.B.2 and Fig. 8: a 1-axis Honeywell Model 31 (mid range) load cell, an INA125P
instrumentation amplifier, and an Arduino Uno whose 10-bit ADC at 5 V turns the amplifier's output
into a count sent as a serial line. The chain, one reading:

    compression F [N] ──▶ bridge  v_b = S_b · V_exc · F / F_FS          (Model 31 data sheet)
                     ──▶ INA125P  v_o = V_zero + G · v_b,  G = 4 + 60 kΩ / R_G   (INA125 data sheet)
                     ──▶ ADC      n = clip(floor(1024 · v_o / V_ref), 0, 1023)   (ATmega328P data sheet)

Figures, and where they come from:
- Model 31 data sheet (mid range): a compression-only button cell, 2 mV/V nominal full-scale output,
  5 V excitation. The seed names no capacity; 10 lb (44.48 N) is assumed, the smallest of the mid
  range and one that carries the ~35 N of an abdominal scan (notes/hardware.md). The cell's own
  calibration certificate gives its exact mV/V: put it in `LoadCellChain(sensitivity_V_per_V=...)`.
- INA125 data sheet: G = 4 + 60 kΩ / R_G; R_G = 180 Ω (ours, E12) gives G = 337.3, so the 10 mV of
  full scale becomes 3.37 V. The amplifier's reference pin sits at V_zero = 0.5 V (a divider on the
  shield, ours): the unloaded cell reads about 102 counts, above the amplifier's lower swing limit,
  so that a tension (which a healthy button cell never feels) or a zero that drifts down stays
  visible instead of hiding at 0.
- ATmega328P data sheet (section 24, ADC): 10 bits, the conversion result n = V_in · 1024 / V_ref,
  V_ref = AVcc = 5 V: one count is 4.88 mV, the seed's "≈ 0.0049 V/bit".

So a count is 1 / COUNTS_PER_N ≈ 0.064 N and full scale (44.48 N) is about 793 counts.

Sign: the cell reports, as every probe sensor here (`hoh_cosim.control.estimator`), the force the
tool side puts on it in its own frame L, whose z points along the probe from handle to tip (eq. 3:
z against the base's z with the probe pointing down). A contact pushes the probe back into the
cell, a compression, which is a force along -z_L: F_L = (0, 0, -compression_N).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from hoh_cosim.control.frames import R_BL_EQ3, R_BS_EQ1
from hoh_cosim.control.vectors import Rot3, Vec, as_scalar, frozen

__all__ = [
    "ACROSS_FROM_WRIST",
    "ADC_BITS",
    "ADC_COUNTS",
    "ADC_REF_V",
    "BAUDRATE",
    "CAPACITY_N",
    "COUNTS_PER_N",
    "EXCITATION_V",
    "FULL_SCALE_COUNT",
    "INA125_GAIN",
    "INA125_RG_OHM",
    "LINE_RATE_HZ",
    "R_SL_SEED",
    "SEED_CHAIN",
    "SENSITIVITY_V_PER_V",
    "ZERO_COUNT",
    "ZERO_V",
    "LoadCellChain",
    "estimator_defaults",
    "force_L",
    "ina125_gain",
]

CAPACITY_N = 10.0 * 4.4482216152605
"""[N] Full-scale load: 10 lb (assumed; the seed names no capacity)."""
SENSITIVITY_V_PER_V = 2.0e-3
"""[V/V] Full-scale bridge output per volt of excitation: 2 mV/V (Model 31 data sheet, nominal)."""
EXCITATION_V = 5.0
"""[V] Bridge excitation: the Uno's 5 V (Model 31 data sheet: 5 V recommended)."""
INA125_RG_OHM = 180.0
"""[Ω] The gain resistor on the shield (ours)."""
ZERO_V = 0.5
"""[V] The INA125P's reference pin: its output with the cell unloaded (ours)."""
ADC_BITS = 10
ADC_COUNTS = 2**ADC_BITS
"""The ADC's levels (ATmega328P: 10 bits, 0 to 1023)."""
ADC_REF_V = 5.0
"""[V] The ADC's reference, AVcc (the Uno's default)."""
BAUDRATE = 115200
"""[bit/s] The Arduino's serial line (hoh_cosim.hardware.loadcell documents the line format)."""
LINE_RATE_HZ = 200.0
"""[Hz] Lines a second (hoh_cosim.hardware.loadcell says why)."""

ACROSS_FROM_WRIST = {
    "across_from_wrist_s": 0.3,
    "across_within_N": 5.0,
    "mismatch_threshold_N": 5.0,
}
"""The estimator's contact across the probe's axis, from the wrist (`probe_correction`), with a
load cell: the cell feels only the load along the axis, so the scan's friction across it (1.5-2 N in
contact_scan) reads on the wrist alone, and its moment about the wrist as the hand's torque: with
the FSE103's defaults (none taken from the wrist) the probe tilted 131° in contact_scan_loadcell's
30 s. Low-passed over 0.3 s and followed up to 5 N (the whole friction, not the FSE103's 1.2 N
mismatch): 2.4° and the contact held as the FSE103 holds it (docs/decisions/0070). The
consistency check's warning waits for the same 5 N: across the axis the cell reads nothing, so
the whole friction is its "mismatch"."""

R_SL_SEED: Rot3 = frozen(R_BS_EQ1.T @ R_BL_EQ3)
"""The load cell L in the wrist sensor S implied by eq. 1 and eq. 3: R_SL = R_BSᵀ R_BL (z_L along
-z_S, the probe's axis from handle to tip)."""


def ina125_gain(rg_ohm: float) -> float:
    """INA125 data sheet: G = 4 + 60 kΩ / R_G."""
    return 4.0 + 60e3 / rg_ohm


INA125_GAIN = ina125_gain(INA125_RG_OHM)


@dataclass(frozen=True)
class LoadCellChain:
    """The chain's figures (defaults: the seed's rig as above) and its transfer, both ways."""

    capacity_N: float = CAPACITY_N
    sensitivity_V_per_V: float = SENSITIVITY_V_PER_V
    excitation_V: float = EXCITATION_V
    gain: float = INA125_GAIN
    zero_V: float = ZERO_V
    adc_ref_V: float = ADC_REF_V

    def __post_init__(self) -> None:
        for name in ("capacity_N", "sensitivity_V_per_V", "excitation_V", "gain", "adc_ref_V"):
            object.__setattr__(
                self, name, as_scalar(getattr(self, name), name, low=0.0, low_open=True)
            )
        object.__setattr__(
            self, "zero_V", as_scalar(self.zero_V, "zero_V", low=0.0, high=self.adc_ref_V)
        )

    @property
    def volts_per_N(self) -> float:
        """[V/N] At the amplifier's output: G · S_b · V_exc / F_FS."""
        return self.gain * self.sensitivity_V_per_V * self.excitation_V / self.capacity_N

    @property
    def counts_per_V(self) -> float:
        return ADC_COUNTS / self.adc_ref_V

    @property
    def counts_per_N(self) -> float:
        return self.volts_per_N * self.counts_per_V

    @property
    def zero_count(self) -> float:
        """The unloaded cell's reading in counts (not rounded)."""
        return self.zero_V * self.counts_per_V

    def volts(self, compression_N: float | Vec) -> float | Vec:
        """The amplifier's output [V] for a compression (negative: a tension), unclipped."""
        return self.zero_V + self.volts_per_N * np.asarray(compression_N)

    def count(self, volts: float) -> int:
        """The ADC's reading of `volts`: floor(1024 v / V_ref), clipped to 0..1023."""
        return int(min(max(math.floor(volts * self.counts_per_V), 0), ADC_COUNTS - 1))

    def newtons(self, count: float) -> float:
        """The compression [N] a count stands for: the middle of the count's voltage interval,
        (n + 1/2) / (counts/V), less the zero, over V/N. A rebias takes the zero off in any case."""
        return ((count + 0.5) / self.counts_per_V - self.zero_V) / self.volts_per_N

    def counts(self, compression_N: float) -> int:
        """The count an ideal chain reads for `compression_N` (no noise)."""
        return self.count(float(self.volts(compression_N)))


SEED_CHAIN = LoadCellChain()
COUNTS_PER_N = SEED_CHAIN.counts_per_N
"""[1/N] About 15.5 counts a newton: one count is about 0.064 N."""
ZERO_COUNT = SEED_CHAIN.count(ZERO_V)
"""The unloaded cell's count (102)."""
FULL_SCALE_COUNT = SEED_CHAIN.counts(CAPACITY_N)
"""The count at full scale (793)."""


def estimator_defaults(estimator: Mapping[str, Any]) -> dict[str, Any]:
    """An estimator's parameters as a mapping (a scenario's or a rig file's) with what a load cell
    needs where the mapping gives none: its mounting (`R_SP` = `R_SL_SEED`, eq. 3), its line
    period and the contact across the axis from the wrist (`ACROSS_FROM_WRIST`)."""
    out = dict(estimator)
    out.setdefault("R_SP", R_SL_SEED.tolist())
    out.setdefault("probe_packet_period_s", 1.0 / LINE_RATE_HZ)
    out["probe_correction"] = {**ACROSS_FROM_WRIST, **dict(out.get("probe_correction") or {})}
    return out


def force_L(compression_N: float) -> Vec:
    """The cell's reading as a probe force in its frame L: (0, 0, -compression) [N]."""
    return np.array([0.0, 0.0, -compression_N])
