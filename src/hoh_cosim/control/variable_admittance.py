"""Variable admittance: the slope of eq. 10 follows the hand's intent (law name `variable`).

Lecours, Mayer-St-Onge and Gosselin (ICRA 2012, "Variable admittance control of a four-degree-of-
freedom intelligent assist device") vary the virtual damping c of the admittance ẋ = F / c with the
operator's intent: c falls when the operator accelerates (the motion should follow easily) and rises
when they decelerate (the motion should stop crisply). Dimeas and Aspragathos (seed ref. [7], IFAC
2015) learn the same kind of damping schedule. Our admittance is the seed's static law (eq. 10,
ẋ = α (|F| - η) sgn F per axis, α = 1/c), so the intent is read from the force itself: the excess
force beyond the deadband, e = ‖F ⊘ η‖ - 1 (in deadbands, 0 inside), grows while the hand
accelerates the probe and falls while it brakes.

    ė      = (e - e_prev) / Δt                          [deadbands per second]
    g      = clip(1 + k · tanh(ė / ė_ref), g_min, g_max)
    ẋ      = g · α (|F| - η) sgn F                      (eq. 10 with the slope g α)

k = 0 (or g_min = g_max = 1) is eq. 10 exactly: the seed's law is the special case. g changes the
slope only: the law stays odd, zero inside the deadband and passive (F · ẋ >= 0 for g > 0), and
g <= g_max bounds the loop gain the linear analysis must cover (`hoh_cosim.study.linear`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, ClassVar

from hoh_cosim.control.admittance import deadband_linear
from hoh_cosim.control.release import scaled_norm
from hoh_cosim.control.vectors import Vec3, as_scalar
from hoh_cosim.errors import ConfigError

__all__ = ["VariableAdmittance", "VariableAdmittanceParams"]


@dataclass(frozen=True)
class VariableAdmittanceParams:
    """intent_gain: k; intent_rate_per_s: ė_ref [1/s]; slope_min, slope_max: g_min, g_max."""

    UNITS: ClassVar[dict[str, Any]] = {
        "intent_gain": "1",
        "intent_rate_per_s": "1/s",
        "slope_min": "1",
        "slope_max": "1",
    }

    intent_gain: float = 0.3
    intent_rate_per_s: float = 10.0
    slope_min: float = 0.7
    slope_max: float = 1.3

    def __post_init__(self) -> None:
        object.__setattr__(self, "intent_gain", as_scalar(self.intent_gain, "intent_gain", low=0.0))
        object.__setattr__(
            self,
            "intent_rate_per_s",
            as_scalar(self.intent_rate_per_s, "intent_rate_per_s", low=0.0, low_open=True),
        )
        for name in ("slope_min", "slope_max"):
            object.__setattr__(
                self, name, as_scalar(getattr(self, name), name, low=0.0, low_open=True)
            )
        if not self.slope_min <= 1.0 <= self.slope_max:
            raise ConfigError(
                f"slope_min <= 1 <= slope_max expected, got {self.slope_min} and {self.slope_max}"
            )


class VariableAdmittance:
    """The variable law of the module docstring, with its one state: the last excess force."""

    def __init__(self, params: VariableAdmittanceParams | None = None) -> None:
        self.params = params or VariableAdmittanceParams()
        self.reset()

    def reset(self) -> None:
        self._t_prev: float | None = None
        self._e_prev = 0.0
        self.factor = 1.0  # g of the last step

    def step(self, t: float, F: Vec3, slope: Vec3, deadband: Vec3) -> Vec3:
        p = self.params
        e = max(0.0, scaled_norm(F, deadband) - 1.0)
        dt = None if self._t_prev is None else t - self._t_prev
        e_dot = (e - self._e_prev) / dt if dt is not None and dt > 0.0 else 0.0
        self._t_prev, self._e_prev = t, e
        # g = clip(1 + k tanh(ė/ė_ref), g_min, g_max)
        g = 1.0 + p.intent_gain * math.tanh(e_dot / p.intent_rate_per_s)
        self.factor = g = min(max(g, p.slope_min), p.slope_max)
        return deadband_linear(F, g * slope, deadband)
