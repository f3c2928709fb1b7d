"""Force-to-velocity laws, contact compensation and the virtual fixture (seed 000, section 3.F).

Every law maps a 3-vector (force [N] or torque [N·m]) to a 3-vector velocity [m/s or rad/s] and is
odd, zero at zero and monotone along any axis:

- `deadband_linear` (eq. 10), per axis: zero inside the deadband η, then slope α.
- `isotropic_deadband`: the same law with a deadband on the (η-scaled) vector norm, so that pushing
  along a diagonal feels like pushing along an axis: along any single axis it equals eq. 10, in
  between it has none of eq. 10's per-axis "corners". With η equal on every axis the feel does not
  depend on direction at all.
- `variable` (`hoh_cosim.control.variable_admittance`): eq. 10 whose slope follows the hand's
  intent, stateful, so the controller steps it; `apply_law` gives its special case, eq. 10.
- `sigmoid`: the older work's sigmoidal gains (Finocchi, seed refs. 3–4) as a baseline.
  The seed does not give that law's formula; ours is a logistic curve shifted to pass through zero:
      v = sgn(F) · v_max · (σ(k(|F| - F_c)) - σ(-k F_c)) / (1 - σ(-k F_c)),  σ(s) = 1/(1 + e⁻ˢ)
  zero at zero, flat near zero (a soft deadband), steepest at the midpoint F_c, saturating at v_max.
  Its defaults undershoot eq. 10 over the working range, as the seed's Fig. 21 shows.

Contact compensation (eq. 11–12) subtracts the probe's contact force from the wrist reading before the
law; the virtual fixture (3.F.3) blocks upward motion while the probe feels contact.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, ClassVar, Literal

import numpy as np

from hoh_cosim.control.vectors import (
    Vec3,
    as_nonnegative_vector,
    as_positive_vector,
    frozen,
)
from hoh_cosim.errors import ConfigError

__all__ = [
    "LAWS",
    "AdmittanceGains",
    "apply_law",
    "contact_compensated",
    "deadband_linear",
    "horizontal_fixture",
    "isotropic_deadband",
    "sigmoid",
]

LawName = Literal["deadband_linear", "isotropic", "sigmoid", "variable"]
LAWS: tuple[str, ...] = ("deadband_linear", "isotropic", "sigmoid", "variable")


def deadband_linear(F: Vec3, slope: Vec3, deadband: Vec3) -> Vec3:
    """Seed eq. 10, per axis:  ẋ = 0 if |F| ≤ η, else sgn(F) · α · (|F| - η)."""
    return np.sign(F) * slope * np.maximum(np.abs(F) - deadband, 0.0)


def isotropic_deadband(F: Vec3, slope: Vec3, deadband: Vec3) -> Vec3:
    """Deadband on the norm: s = ‖F ⊘ η‖;  ẋ = 0 if s ≤ 1, else α ⊙ F · (1 - 1/s).

    Along one axis this is eq. 10 exactly; the deadband is the ellipsoid ‖F ⊘ η‖ ≤ 1 (a sphere when η is
    equal on every axis). An axis with η = 0 is left out of the norm and responds linearly.
    """
    scaled = np.divide(F, deadband, out=np.zeros_like(F, dtype=np.float64), where=deadband > 0)
    s = math.sqrt(float(scaled @ scaled))
    if s <= 1.0:
        return np.where(deadband > 0, 0.0, slope * F)
    return slope * F * np.where(deadband > 0, 1.0 - 1.0 / s, 1.0)


def sigmoid(F: Vec3, max_speed: Vec3, midpoint: Vec3, steepness: Vec3) -> Vec3:
    """The older work's sigmoidal law, our parametrisation (see the module docstring)."""
    base = 1.0 / (1.0 + np.exp(steepness * midpoint))  # σ(-k F_c)
    rise = 1.0 / (1.0 + np.exp(-steepness * (np.abs(F) - midpoint)))  # σ(k(|F| - F_c))
    return np.sign(F) * max_speed * (rise - base) / (1.0 - base)


@dataclass(frozen=True)
class AdmittanceGains:
    """One law and its gains for three axes. Units for the translational case; for rotation read
    N·m for N and rad for m.

    slope, deadband: α [m/(s·N)] and η [N] of eq. 10 (also used by the isotropic law).
    sigmoid_max_speed [m/s], sigmoid_midpoint [N], sigmoid_steepness [1/N]: the sigmoid law.
    """

    UNITS: ClassVar[dict[str, Any]] = {
        "slope": "m/(s.N)",
        "deadband": "N",
        "sigmoid_max_speed": "m/s",
        "sigmoid_midpoint": "N",
        "sigmoid_steepness": "1/N",
    }

    law: LawName = "deadband_linear"
    slope: Vec3 = field(default_factory=lambda: frozen([0.0125, 0.0125, 0.0125]))
    deadband: Vec3 = field(default_factory=lambda: frozen([0.95, 0.95, 0.25]))
    sigmoid_max_speed: Vec3 = field(default_factory=lambda: frozen([0.10, 0.10, 0.10]))
    sigmoid_midpoint: Vec3 = field(default_factory=lambda: frozen([6.0, 6.0, 6.0]))
    sigmoid_steepness: Vec3 = field(default_factory=lambda: frozen([0.6, 0.6, 0.6]))

    def __post_init__(self) -> None:
        if self.law not in LAWS:
            raise ConfigError(f"law: expected one of {', '.join(LAWS)}, got {self.law!r}")
        object.__setattr__(self, "slope", as_nonnegative_vector(self.slope, 3, "slope"))
        object.__setattr__(self, "deadband", as_nonnegative_vector(self.deadband, 3, "deadband"))
        for name in ("sigmoid_max_speed", "sigmoid_steepness"):
            object.__setattr__(self, name, as_positive_vector(getattr(self, name), 3, name))
        object.__setattr__(
            self,
            "sigmoid_midpoint",
            as_nonnegative_vector(self.sigmoid_midpoint, 3, "sigmoid_midpoint"),
        )


TRANSLATION_GAINS = AdmittanceGains()
"""The seed's gains (3.F.1): α = 0.0125 m/(s·N) on every axis, η = 0.95 N on x, y and 0.25 N on z."""

ROTATION_GAINS = AdmittanceGains(
    slope=frozen([0.4, 0.4, 0.4]),
    deadband=frozen([0.1, 0.1, 0.1]),
    sigmoid_max_speed=frozen([0.5, 0.5, 0.5]),
    sigmoid_midpoint=frozen([0.6, 0.6, 0.6]),
    sigmoid_steepness=frozen([6.0, 6.0, 6.0]),
)
"""Our rotational gains (the seed gives none): α = 0.4 rad/(s·N·m), η = 0.1 N·m. A twist of 0.5 N·m
(5 N on a 10 cm lever) turns the probe at 0.16 rad/s; the deadband sits above our assumed torque noise
(max about 0.06 N·m, see docs/decisions/0004-kalman-filter-bank.md)."""


def apply_law(F: Vec3, gains: AdmittanceGains) -> Vec3:
    """The velocity that `gains.law` gives for the force (or torque) `F`."""
    if gains.law in ("deadband_linear", "variable"):  # variable: its stateless special case
        return deadband_linear(F, gains.slope, gains.deadband)
    if gains.law == "isotropic":
        return isotropic_deadband(F, gains.slope, gains.deadband)
    return sigmoid(F, gains.sigmoid_max_speed, gains.sigmoid_midpoint, gains.sigmoid_steepness)


def contact_compensated(F_hand: Vec3, F_probe: Vec3) -> Vec3:
    """Seed eq. 11–12: the hand's own force F̃_hand = F_hand - F_probe.

    The wrist sensor feels the hand and the patient's reaction on the probe; without this the robot
    "bounces" off the patient (3.F.2). Both forces are on the tool, in the same frame.
    """
    return F_hand - F_probe


def horizontal_fixture(
    v_B: Vec3, F_probe_B: Vec3, threshold_N: float, up_B: Vec3
) -> tuple[Vec3, bool]:
    """Seed 3.F.3: while |F_probe| > threshold, the velocity along `up_B` is clipped to <= 0.

    Downward and sideways motion stay free; lifting the probe needs no contact force first. The seed's
    fixture is a horizontal plane (up = +z of the base); `up_B` is a unit vector.
    Returns the velocity and whether the fixture is engaged.
    """
    if float(F_probe_B.dot(F_probe_B)) <= threshold_N * threshold_N:
        return v_B, False
    upward = float(v_B.dot(up_B))
    if upward > 0.0:
        return v_B - upward * up_B, True
    return v_B, True
