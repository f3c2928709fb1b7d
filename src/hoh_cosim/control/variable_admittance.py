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
slope only: the law stays odd, zero inside the deadband and passive (F · ẋ >= 0 for g > 0).

Linearised about a steady push of e₀ deadbands (tanh' (0) = 1), the schedule adds a derivative
term: δẋ = α η (δe + (k e₀ / ė_ref) δė) along the push, a zero at ė_ref / (k e₀) in the loop
(`hoh_cosim.study.linear.variable_law_lead`). A little of it is a phase lead that the hand-robot
loop welcomes; much of it raises the gain at the loop's -180° crossover. On the default circles
(e₀ about 10 with the tuned gains) k = 0.05 gives the gain margin 2.07 where k = 0 gives 1.90 and
k = 0.2 gives 1.49 (`docs/decisions/0038-variable-admittance-and-oscillation-watch.md`): the
default is k = 0.05, a light touch.

Stability against a stiff hand. A hand that grips hard and reacts late (a delayed stiffness of
1000 N/m or more) makes the hand-robot loop oscillate at 1-3 Hz at the seed's slope, and no
passivity controller on the robot sees it: the robot only yields to the hand, the hand's own delay
drives the oscillation (`docs/decisions/0038-variable-admittance-and-oscillation-watch.md`). Dimeas
and Aspragathos (IEEE Trans. Haptics 9(2), 2016, "Online stability in human-robot cooperation with
admittance control") detect the onset from the interaction's high-frequency content and raise the
damping until it dies. Ours watches the tip's measured velocity (the controller has the TCP's
positions):

    u      = highpass_fo(highpass_fo(v))                    (second order, f_o = 1 Hz: the
                                                              circles' 0.25 Hz pass at 6 %)
    σ²    ← σ² + (Δt / T_w) (‖u‖² - σ²)                     (its mean power over T_w = 0.5 s)
    c     ← c e^(-Δt / T_r) + Σᵢ [sgn uᵢ ≠ sᵢ]              (swings: an axis of u beyond ±σ_o
                                                              with the other sign than the last
                                                              time it was, sᵢ; T_r = 2 s)
    oscillating  ⇔  σ > σ_o  and  c >= c_o
    on it:       h ← h/2, c ← 0                             (halve the slope, count afresh)
    quiet for T_q after the last halving:  h ← h/2 once     (the loop was still oscillating at
                                                              2h and is quiet at h: the critical
                                                              slope lies between, so h/2 keeps a
                                                              gain margin of at least 2)
    h     ← min(1, h e^(ρ Δt))                              (and comes back slowly, ρ = 0.01/s:
                                                              doubling in 70 s)
    ẋ      = h · g · α (|F| - η) sgn F

The swings tell an oscillation (two large reversals a second per axis at 1 Hz, so c settles near 4
or above) from the start of a firm push, whose high-passed velocity swings once (c <= 1) however
large it is; c_o = 2.5. Per axis, so that an oscillation around a circle, whose high-passed velocity
turns rather than passes through zero, counts too. σ_o = 12 mm/s sits above what a relaxed hand's
circles show (about 4 mm/s: the circle's 63 mm/s through the high-pass, and jitter) and below an
oscillation (30-60 mm/s). h = 1 while the loop is quiet, so it changes nothing for a relaxed
operator; `oscillation_watch` False switches it off. A hand that stays stiff meets the slope
coming back after a minute or two and is halved again.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from hoh_cosim.control.admittance import AdmittanceGains, apply_law, deadband_linear
from hoh_cosim.control.release import scaled_norm
from hoh_cosim.control.vectors import Vec, Vec3, as_scalar
from hoh_cosim.errors import ConfigError

__all__ = ["VariableAdmittance", "VariableAdmittanceParams"]

_SWING_WINDOW_S = 2.0  # T_r


@dataclass(frozen=True)
class VariableAdmittanceParams:
    """intent_gain: k; intent_rate_per_s: ė_ref [1/s]; slope_min, slope_max: g_min, g_max."""

    UNITS: ClassVar[dict[str, Any]] = {
        "intent_gain": "1",
        "intent_rate_per_s": "1/s",
        "slope_min": "1",
        "slope_max": "1",
        "oscillation_cutoff_hz": "Hz",
        "oscillation_window_s": "s",
        "oscillation_threshold_m_s": "m/s",
        "oscillation_quiet_s": "s",
        "oscillation_recover_per_s": "1/s",
        "oscillation_min": "1",
        "oscillation_swings": "1",
    }

    intent_gain: float = 0.05
    intent_rate_per_s: float = 20.0
    slope_min: float = 0.7
    slope_max: float = 1.3
    oscillation_cutoff_hz: float = 1.0  # f_o
    oscillation_window_s: float = 0.5  # T_w
    oscillation_threshold_m_s: float = 0.012  # σ_o
    oscillation_watch: bool = True
    oscillation_quiet_s: float = 2.0  # T_q
    oscillation_recover_per_s: float = 0.01  # ρ
    oscillation_min: float = 0.05  # h_min
    oscillation_swings: float = 2.5  # c_o

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
        for name in (
            "oscillation_cutoff_hz",
            "oscillation_window_s",
            "oscillation_threshold_m_s",
        ):
            object.__setattr__(
                self, name, as_scalar(getattr(self, name), name, low=0.0, low_open=True)
            )
        for name in ("oscillation_quiet_s", "oscillation_recover_per_s", "oscillation_swings"):
            object.__setattr__(self, name, as_scalar(getattr(self, name), name, low=0.0))
        object.__setattr__(
            self,
            "oscillation_min",
            as_scalar(self.oscillation_min, "oscillation_min", low=0.0, low_open=True, high=1.0),
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
        self.stability = 1.0  # h: the oscillation watch's factor
        # the watch's state as Python floats (3-vectors: cheaper than numpy's small arrays)
        self._p_prev: list[float] | None = None
        self._v_prev = [0.0, 0.0, 0.0]
        self._u1 = [0.0, 0.0, 0.0]
        self._u = [0.0, 0.0, 0.0]
        self._signs = [0.0, 0.0, 0.0]  # sᵢ
        self.swings = 0.0  # c
        self._t = 0.0  # the watch's own clock [s]
        self._halved_at: float | None = None  # when h was last halved on an oscillation
        self._margined = True  # the margin halving after the last oscillation is done
        self.oscillation_m_s = 0.0  # σ

    def _watch(self, dt: float, p_B: Vec3) -> None:
        """The oscillation watch of the module docstring, one controller period dt."""
        p = self.params
        pos = p_B.tolist()
        if self._p_prev is not None:
            v = [(a - b) / dt for a, b in zip(pos, self._p_prev, strict=True)]
            # first-order high-pass twice: u ← a (u + x - x_prev), a = τ/(τ + Δt), τ = 1/(2π f_o)
            tau = 1.0 / (2.0 * math.pi * p.oscillation_cutoff_hz)
            a = tau / (tau + dt)
            u1 = [a * (u + x - x0) for u, x, x0 in zip(self._u1, v, self._v_prev, strict=True)]
            u = [a * (w + x - x0) for w, x, x0 in zip(self._u, u1, self._u1, strict=True)]
            self._v_prev, self._u1, self._u = v, u1, u
            power = u[0] * u[0] + u[1] * u[1] + u[2] * u[2]
            ms = self.oscillation_m_s**2
            ms += min(1.0, dt / p.oscillation_window_s) * (power - ms)
            self.oscillation_m_s = math.sqrt(ms)
            self.swings *= math.exp(-dt / _SWING_WINDOW_S)
            big = p.oscillation_threshold_m_s
            for i, ui in enumerate(u):
                if abs(ui) > big:
                    sign = math.copysign(1.0, ui)
                    if self._signs[i] == -sign:
                        self.swings += 1.0
                    self._signs[i] = sign
            self._t += dt
            if (
                self.oscillation_m_s > p.oscillation_threshold_m_s
                and self.swings >= p.oscillation_swings
            ):  # oscillating: halve the slope, count afresh
                self.stability = max(p.oscillation_min, 0.5 * self.stability)
                self.swings = 0.0
                self._halved_at, self._margined = self._t, False
            elif (
                not self._margined
                and self._halved_at is not None
                and self._t - self._halved_at >= p.oscillation_quiet_s
            ):  # quiet at h after oscillating at 2h: h/2 for a gain margin of 2
                self.stability = max(p.oscillation_min, 0.5 * self.stability)
                self._margined = True
            elif self._margined:
                self.stability = min(
                    1.0, self.stability * math.exp(p.oscillation_recover_per_s * dt)
                )
        self._p_prev = pos

    def step(self, t: float, F: Vec3, slope: Vec3, deadband: Vec3, p_B: Vec3 | None = None) -> Vec3:
        """The law's velocity for the force F; `p_B` the tip's measured position (None: no
        oscillation watch)."""
        p = self.params
        e = max(0.0, scaled_norm(F, deadband) - 1.0)
        dt = None if self._t_prev is None else t - self._t_prev
        e_dot = (e - self._e_prev) / dt if dt is not None and dt > 0.0 else 0.0
        self._t_prev, self._e_prev = t, e
        if p_B is not None and dt is not None and dt > 0.0 and p.oscillation_watch:
            self._watch(dt, p_B)
        # g = clip(1 + k tanh(ė/ė_ref), g_min, g_max)
        g = 1.0 + p.intent_gain * math.tanh(e_dot / p.intent_rate_per_s)
        self.factor = g = min(max(g, p.slope_min), p.slope_max)
        return deadband_linear(F, (self.stability * g) * slope, deadband)

    def step_twist(
        self,
        t: float,
        F: Vec3,
        tau: Vec3,
        translation: AdmittanceGains,
        rotation: AdmittanceGains,
        p_B: Vec3 | None = None,
    ) -> Vec:
        """The twist [v; ω] of one controller tick: v from this law with the translation's slope
        and deadband, ω from the rotation's own law (`apply_law`), as a new 6-vector."""
        v = self.step(t, F, translation.slope, translation.deadband, p_B)
        return np.concatenate([v, apply_law(tau, rotation)])
