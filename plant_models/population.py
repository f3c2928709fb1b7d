"""A population of sonographers, and the patients they scan: seeded draws from documented ranges.

Each operator i of a study seeded S is drawn from its own generator (seeded with [S, i]): operator 3
is the same person in a study of 5 operators and in one of 50, and the same in every mode and task
of a study, so that comparisons between modes are paired. Each operator scans a patient of their
own (drawn from the same generator, after the operator), whose breathing every mode sees.

What is drawn, and from where (ranges as the literature gives them, a uniform draw within unless
said otherwise):

Hand (`plant_models.operator`):
- stiffness 200-600 N/m and damping 10-30 N·s/m: hand stiffness in maintained arm postures is a
  few hundred N/m, up to about a thousand along the stiffest direction (Mussa-Ivaldi, Hogan and
  Bizzi 1985, "Neural, mechanical, and geometric factors subserving arm posture in humans",
  J. Neurosci. 5(10):2732-2743), and hand viscosity of the order of ten to a few tens of N·s/m
  (Tsuji, Morasso, Goto and Ito 1995, "Human hand impedance characteristics during maintained
  posture", Biol. Cybern. 72:475-485). We take the relaxed to moderately co-contracted part;
- reaction delay 100-200 ms: voluntary corrections to what is felt or seen come after about
  100-200 ms (long-latency stretch reflexes at 50-100 ms are faster, visual reaction times of
  about 200 ms slower); the press loop on the felt contact force waits this long;
- physiological tremor: frequency 8-12 Hz (Elble 2003, "Physiologic and enhanced physiologic
  tremor", Handbook of Clinical Neurophysiology vol. 1, ch. 22) and a force of 0.011-0.14 N RMS,
  log-uniform. Calibrated on the hand holding the probe freehand in the air: the smallest force on
  the stiffest, most damped hand and the largest on the softest, least damped one move the 0.48 kg
  probe with 0.0015 and 0.035 g peak, the range of normal postural hand tremor (0.0015 to 0.035 g
  peak at the dominant frequency, modal 0.01 g: Wade, Gresty and Findley 1982, "A normative study
  of postural tremor of the hand", Arch. Neurol. 39(6):358-362; tests/unit/test_population.py
  checks it);
- grip strength (maximal voluntary contraction): normal, 530 ± 95 N for men and 320 ± 60 N for
  women, sex drawn with probability `female_fraction` (Mathiowetz et al. 1985, "Grip and pinch
  strength: normative data for adults", Arch. Phys. Med. Rehabil. 66(2):69-74: right-hand means of
  about 117-122 lb for men and 70-79 lb for women aged 20-44, standard deviations of about 20 and
  13 lb), clipped to ±2.5 standard deviations;
- strength, the most the hand pushes on the probe (`max_force_N`): `push_fraction` (10 %) of the
  grip strength, no less than 20 N. A force held for minutes stays below about 15 % of the maximal
  one before fatigue sets the limit (Rohmert 1960, "Ermittlung von Erholungspausen für statische
  Arbeit des Menschen", Int. Z. angew. Physiol. 18:123-164);
- the grip's rotational stiffness 2-8 N·m/rad and damping 0.02-0.08 N·m·s/rad (the freehand
  probe's tilt, `plant_models.freehand`): the relaxed wrist is of the order of 1 N·m/rad (Formica,
  Charles, Zollo, Guglielmelli, Hogan and Krebs 2012, "The passive stiffness of the wrist and
  forearm", J. Neurophysiol. 108(4):1158-1166), and a grip several times stiffer ("Evaluating
  viscoelastic properties of the wrist joint during external perturbations: influence of velocity,
  grip, and handedness", Front. Hum. Neurosci. 15:726841, 2021).

Patient (`plant_models.breathing`): rate 12-20 breaths per minute, peak-to-peak excursion 5-15 mm,
irregularity 0.05-0.15 (the sources are in that module).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from hoh_cosim.control.vectors import as_scalar
from hoh_cosim.errors import ConfigError

__all__ = ["RANGES", "Operator", "Patient", "PopulationParams", "draw_operator", "draw_patient"]


_CLIP_SD = 2.5  # grip strength draws stay within this many standard deviations


def _range(value: Any, name: str, low: float = 0.0) -> tuple[float, float]:
    try:
        a, b = (float(v) for v in value)
    except (TypeError, ValueError):
        raise ConfigError(f"{name}: expected [low, high], got {value!r}") from None
    if not (math.isfinite(a) and math.isfinite(b)) or a < low or b < a:
        raise ConfigError(f"{name}: expected {low} <= low <= high, got [{a}, {b}]")
    return a, b


@dataclass(frozen=True)
class PopulationParams:
    """The ranges (module docstring); each a (low, high) pair, SI units."""

    UNITS: ClassVar[dict[str, Any]] = {
        "stiffness": "N/m",
        "damping": "N.s/m",
        "reaction_delay_s": "s",
        "tremor_hz": "Hz",
        "tremor_rms_N": "N",
        "grip_strength_male_N": "N",
        "grip_strength_female_N": "N",
        "grip_stiffness": "N.m/rad",
        "grip_damping": "N.m.s/rad",
        "breathing_rate_per_min": "1/min",
        "breathing_amplitude_m": "m",
    }

    stiffness: tuple[float, float] = (200.0, 600.0)
    damping: tuple[float, float] = (10.0, 30.0)
    reaction_delay_s: tuple[float, float] = (0.10, 0.20)
    tremor_hz: tuple[float, float] = (8.0, 12.0)
    tremor_rms_N: tuple[float, float] = (0.011, 0.14)  # log-uniform
    female_fraction: float = 0.5
    grip_strength_male_N: tuple[float, float] = (530.0, 95.0)  # mean, standard deviation
    grip_strength_female_N: tuple[float, float] = (320.0, 60.0)
    push_fraction: float = 0.10
    min_force_N: float = 20.0
    grip_stiffness: tuple[float, float] = (2.0, 8.0)
    grip_damping: tuple[float, float] = (0.02, 0.08)
    breathing_rate_per_min: tuple[float, float] = (12.0, 20.0)
    breathing_amplitude_m: tuple[float, float] = (0.005, 0.015)
    breathing_irregularity: tuple[float, float] = (0.05, 0.15)
    tremor_bandwidth_hz: float = 2.0

    def __post_init__(self) -> None:
        for f in (
            "stiffness",
            "damping",
            "reaction_delay_s",
            "tremor_hz",
            "tremor_rms_N",
            "grip_stiffness",
            "grip_damping",
            "breathing_rate_per_min",
            "breathing_amplitude_m",
            "breathing_irregularity",
        ):
            object.__setattr__(self, f, _range(getattr(self, f), f))
        for f in ("grip_strength_male_N", "grip_strength_female_N"):
            try:
                mean, sd = (float(v) for v in getattr(self, f))
            except (TypeError, ValueError):
                raise ConfigError(f"{f}: expected [mean, sd], got {getattr(self, f)!r}") from None
            if not (mean > _CLIP_SD * sd >= 0.0):
                raise ConfigError(
                    f"{f}: expected a mean above {_CLIP_SD} standard deviations >= 0, "
                    f"got [{mean}, {sd}]"
                )
            object.__setattr__(self, f, (mean, sd))
        if self.tremor_rms_N[0] <= 0.0:
            raise ConfigError(
                f"tremor_rms_N: expected low > 0 (log-uniform), got {self.tremor_rms_N}"
            )
        for f in ("female_fraction", "push_fraction"):
            object.__setattr__(self, f, as_scalar(getattr(self, f), f, low=0.0, high=1.0))
        object.__setattr__(self, "min_force_N", as_scalar(self.min_force_N, "min_force_N", low=0.0))
        object.__setattr__(
            self,
            "tremor_bandwidth_hz",
            as_scalar(self.tremor_bandwidth_hz, "tremor_bandwidth_hz", low=0.0),
        )


RANGES = PopulationParams()
"""The documented ranges (module docstring)."""


@dataclass(frozen=True)
class Operator:
    """One sonographer: what the operator block and the freehand grip take from the draw."""

    index: int
    female: bool
    stiffness: float  # [N/m]
    damping: float  # [N·s/m]
    reaction_delay_s: float
    tremor_hz: float
    tremor_rms_N: float
    tremor_bandwidth_hz: float
    grip_strength_N: float  # maximal voluntary contraction
    max_force_N: float  # the most the hand pushes
    grip_stiffness: float  # [N·m/rad]
    grip_damping: float  # [N·m·s/rad]

    def operator_values(self) -> dict[str, float]:
        """`OperatorParams` fields and their values for this hand."""
        return {
            "stiffness": self.stiffness,
            "damping": self.damping,
            "reaction_delay_s": self.reaction_delay_s,
            "tremor_hz": self.tremor_hz,
            "tremor_rms_N": self.tremor_rms_N,
            "tremor_bandwidth_hz": self.tremor_bandwidth_hz,
            "max_force_N": self.max_force_N,
        }

    def grip_values(self) -> dict[str, float]:
        """`FreehandParams` fields and their values for this hand's grip."""
        return {"grip_stiffness": self.grip_stiffness, "grip_damping": self.grip_damping}


@dataclass(frozen=True)
class Patient:
    """The breathing of the patient an operator scans."""

    rate_per_min: float
    amplitude_m: float  # peak-to-peak
    irregularity: float

    def breathing_values(self) -> dict[str, float]:
        """`BreathingParams` fields and their values."""
        return {
            "rate_per_min": self.rate_per_min,
            "amplitude_m": self.amplitude_m,
            "irregularity": self.irregularity,
        }


@dataclass(frozen=True)
class _Draw:
    operator: Operator
    patient: Patient


def _uniform(rng: np.random.Generator, bounds: tuple[float, float]) -> float:
    return float(rng.uniform(bounds[0], bounds[1]))


def _draws(params: PopulationParams, seed: int, index: int) -> _Draw:
    """Operator `index`'s hand and patient, in a fixed order from the generator [seed, index]."""
    if index < 0:
        raise ConfigError(f"operator index: expected >= 0, got {index}")
    rng = np.random.default_rng([seed, index])
    p = params
    female = bool(rng.uniform() < p.female_fraction)
    mean, sd = p.grip_strength_female_N if female else p.grip_strength_male_N
    grip = mean + sd * float(np.clip(rng.standard_normal(), -_CLIP_SD, _CLIP_SD))
    lo, hi = p.tremor_rms_N
    operator = Operator(
        index=index,
        female=female,
        stiffness=_uniform(rng, p.stiffness),
        damping=_uniform(rng, p.damping),
        reaction_delay_s=_uniform(rng, p.reaction_delay_s),
        tremor_hz=_uniform(rng, p.tremor_hz),
        tremor_rms_N=float(math.exp(rng.uniform(math.log(lo), math.log(hi)))),
        tremor_bandwidth_hz=p.tremor_bandwidth_hz,
        grip_strength_N=grip,
        max_force_N=max(p.min_force_N, p.push_fraction * grip),
        grip_stiffness=_uniform(rng, p.grip_stiffness),
        grip_damping=_uniform(rng, p.grip_damping),
    )
    patient = Patient(
        rate_per_min=_uniform(rng, p.breathing_rate_per_min),
        amplitude_m=_uniform(rng, p.breathing_amplitude_m),
        irregularity=_uniform(rng, p.breathing_irregularity),
    )
    return _Draw(operator, patient)


def draw_operator(params: PopulationParams, seed: int, index: int) -> Operator:
    """Operator `index` of the population seeded `seed`."""
    return _draws(params, seed, index).operator


def draw_patient(params: PopulationParams, seed: int, index: int) -> Patient:
    """The patient operator `index` of the population seeded `seed` scans."""
    return _draws(params, seed, index).patient
