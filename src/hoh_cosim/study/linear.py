"""Linear analysis with python-control: each filter's frequency response, and the stability margins of
the linearised hand-robot loop.

Filters, each relative to the raw reading as the controller would see it unfiltered (the last packet
held), which is what the seed's "lag added by the filter" compares against (Fig. 20):

- Kalman (eq. 9, in its steady state): between packets the filter predicts every tick, on a packet it
  corrects. Over one packet period T = N·dt that is a linear time-invariant system at rate 1/T with
  the prior as its state (A = Fᴺ, K from `steady_state_gain`):
      s⁺ = A (I - K H) s + A K z,    y = M (I - K H) s + M K z,    M = (1/N) Σⱼ H Fʲ (j < N),
  y being the mean of the N tick outputs after the packet: the held raw reading spans the same ticks,
  so the ratio of the two at a frequency is the filter's gain and phase against it, exactly.
- Butterworth: its transfer function at the tick rate, run on the held reading: exact.
- lead_lowpass (`hoh_cosim.control.filters`): its two first-order sections at the packet rate, run
  once per packet and held like the raw reading: exact.
- 1€ (Casiez et al.): an exponential smoother per packet whose cutoff rises with the signal's speed,
  fc = min_cutoff + β |ẋ|. Linearised at a given speed (for a sinusoid of amplitude a at f, the mean
  |ẋ| = 4 a f), it is the first-order system y_k = y_{k-1} + α (z_k - y_{k-1}) at the packet rate.
- none: 1.

The loop, along one base axis, with the robot a velocity source (speedL) and the admittance law in its
linear region (eq. 10 beyond the deadband; the deadband only lowers the gain, so the linear loop is the
worst case):

    hand:   F = K_h (p_ref - p(t - τ_h)) + D_h (v_ref - v(t - τ_h))      (the operator model;
            τ_h = 0 for an `intrinsic` hand, whose stiffness is the muscles' own)
    sensor: F̂ = G_filter · e^{-s τ_s} F,  τ_s = latency + (N - 1) dt / 2 (the held packet's mean age)
    robot:  v = α F̂ delayed by τ_r = latency_cycles / rate + 1 / (2 rate) + controller period / 2
    open loop:  L(s) = α (K_h + D_h s) / s · G_filter(s) · e^{-s (τ_h + τ_s + τ_r)}

L is evaluated on a frequency grid with the delays exact (no Padé), as a python-control FRD, and
`stability_margins` reads the margins off it. L has one pole at the origin and none in the right half
plane, so the loop is stable while the gain margin exceeds 1; since L is proportional to α, the slope at
which it loses stability is α · (gain margin).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from hoh_cosim.control.baselines import one_euro_alpha
from hoh_cosim.control.estimator import FILTER_KINDS, EstimatorParams, FilterKind
from hoh_cosim.control.filters import lead_lowpass_sections
from hoh_cosim.control.kalman import (
    H_FORCE,
    KalmanParams,
    steady_state_gain,
    transition_matrix,
)
from hoh_cosim.errors import ConfigError

__all__ = [
    "LoopMargins",
    "LoopModel",
    "filter_response",
    "filter_system",
    "frd_margins",
    "lag_ms",
    "loop_margins",
    "loop_model",
    "open_loop",
    "variable_law_lead",
]

OMEGA = np.logspace(-2, math.log10(0.98 * math.pi / 0.005), 3000)
"""[rad/s] The analysis grid: 0.01 rad/s to just under the packet rate's Nyquist frequency."""


def _kalman_axis_system(params: KalmanParams, axis: int, dt: float, ticks: int):
    import control

    K9, _ = steady_state_gain(params, dt, ticks)
    F = transition_matrix(dt)
    idx = [axis, 3 + axis, 6 + axis]  # eq. 9's ordering: force, its rate, its acceleration
    Fa = F[np.ix_(idx, idx)]
    K = K9[np.ix_(idx, [axis])]
    H = H_FORCE[np.ix_([axis], idx)]
    A = np.linalg.matrix_power(Fa, ticks)
    M = sum(H @ np.linalg.matrix_power(Fa, j) for j in range(ticks)) / ticks
    I_KH = np.eye(3) - K @ H
    return control.ss(A @ I_KH, A @ K, M @ I_KH, M @ K, dt * ticks)


def _kalman_system(params: EstimatorParams, axis: int, dt: float, ticks: int, signal_speed: float):
    return _kalman_axis_system(params.hand_force_kalman, axis, dt, ticks)


def _butterworth_system(
    params: EstimatorParams, axis: int, dt: float, ticks: int, signal_speed: float
):
    import control
    from scipy import signal as sps

    b, a = sps.butter(params.butterworth.order, params.butterworth.cutoff_hz, fs=1.0 / dt)
    return control.tf(b, a, dt)


def _lead_lowpass_system(
    params: EstimatorParams, axis: int, dt: float, ticks: int, signal_speed: float
):
    import control

    (b0, b1, a1), (c0, c1, d1) = lead_lowpass_sections(params.lead_lowpass, dt * ticks)
    return control.tf(np.polymul([b0, b1], [c0, c1]), np.polymul([1.0, a1], [1.0, d1]), dt * ticks)


def _one_euro_system(
    params: EstimatorParams, axis: int, dt: float, ticks: int, signal_speed: float
):
    import control

    period = params.ft_packet_period_s
    p = params.one_euro_force
    cutoff = p.min_cutoff_hz + p.beta * abs(signal_speed)
    alpha = float(one_euro_alpha(1.0 / period, cutoff))
    return control.tf([alpha, 0.0], [1.0, alpha - 1.0], period)


def _no_system(params: EstimatorParams, axis: int, dt: float, ticks: int, signal_speed: float):
    """No filter: the held raw reading itself (gain 1)."""
    return None


# One model per estimator filter kind: the keys are FILTER_KINDS, which a unit test checks
# (tests/unit/test_closed_sets.py). Both Kalman kinds are modelled by the same steady state.
_FILTER_SYSTEMS: dict[FilterKind, Callable[[EstimatorParams, int, float, int, float], Any]] = {
    "kalman": _kalman_system,
    "steady_kalman": _kalman_system,
    "lead_lowpass": _lead_lowpass_system,
    "butterworth": _butterworth_system,
    "one_euro": _one_euro_system,
    "none": _no_system,
}


def filter_system(
    params: EstimatorParams,
    axis: int = 0,
    *,
    dt: float = 0.001,
    signal_speed: float = 0.0,
):
    """The hand-force filter of `params` on sensor axis `axis` as a discrete python-control system
    (None for no filter). `signal_speed` [N/s] is where the 1€ filter is linearised."""
    kind = params.filter
    period = params.ft_packet_period_s
    ticks = round(period / dt)
    if ticks < 1 or not math.isclose(ticks * dt, period, rel_tol=1e-6):
        raise ConfigError(f"ft_packet_period_s: {period} s is not a whole number of {dt} s ticks")
    if kind not in _FILTER_SYSTEMS:
        raise ConfigError(f"filter: expected one of {', '.join(FILTER_KINDS)}, got {kind!r}")
    return _FILTER_SYSTEMS[kind](params, axis, dt, ticks, signal_speed)


def filter_response(
    params: EstimatorParams,
    omega: np.ndarray,
    axis: int = 0,
    *,
    dt: float = 0.001,
    signal_speed: float = 0.0,
) -> np.ndarray:
    """Complex gain of the hand-force filter at `omega` [rad/s] against the held raw reading."""
    import control

    system = filter_system(params, axis, dt=dt, signal_speed=signal_speed)
    if system is None:
        return np.ones(len(omega), dtype=complex)
    nyquist = math.pi / system.dt
    if np.max(omega) >= nyquist:
        raise ConfigError(
            f"omega: up to {np.max(omega):.4g} rad/s, beyond the filter's Nyquist {nyquist:.4g}"
        )
    response = control.frequency_response(system, omega)
    return np.asarray(response.complex).reshape(-1)


def variable_law_lead(params, excess: float, omega: np.ndarray) -> np.ndarray:
    """The variable law's schedule (`hoh_cosim.control.variable_admittance`) linearised about a
    steady push of `excess` deadbands beyond the deadband: 1 + (k e₀ / ė_ref) iω, a factor of the
    loop L(iω) (the slope's own g is 1 in a steady push)."""
    return 1.0 + (params.intent_gain * excess / params.intent_rate_per_s) * 1j * omega


def lag_ms(response: complex, omega: float) -> float:
    """[ms] The delay that a phase of `response` at `omega` amounts to (negative: a lead)."""
    return -1e3 * float(np.angle(response)) / omega


@dataclass(frozen=True)
class LoopModel:
    """The linearised loop along one base axis (see the module docstring)."""

    slope: float  # α [m/(s·N)]
    hand_stiffness: float  # K_h [N/m]
    hand_damping: float  # D_h [N·s/m]
    hand_delay_s: float  # τ_h
    sensor_delay_s: float  # τ_s
    robot_delay_s: float  # τ_r

    @property
    def delay_s(self) -> float:
        return self.hand_delay_s + self.sensor_delay_s + self.robot_delay_s


def loop_model(scenario, axis: int = 0) -> LoopModel:
    """The loop of a hand-guiding scenario (operator, plant, ft150, controller) along base `axis`."""
    op = scenario.component_of_kind("operator")
    plant = scenario.component_of_kind("plant")
    ft = scenario.component_of_kind("ft150")
    ctrl = scenario.component_of_kind("controller")
    missing = [
        k
        for k, c in (("operator", op), ("plant", plant), ("ft150", ft), ("controller", ctrl))
        if c is None
    ]
    if missing:
        raise ConfigError(f"{scenario.path}: the loop model needs a {' and a '.join(missing)}")
    dt = scenario.dt_s
    ft_period = 1.0 / ft.params.rate_hz
    ticks = max(1, round(ft_period / dt))
    arm = plant.params.arm
    return LoopModel(
        slope=float(ctrl.params.translation.slope[axis]),
        hand_stiffness=float(op.params.stiffness),
        hand_damping=float(op.params.damping),
        # an intrinsic hand's stiffness and damping act on the tip as it is (plant_models.operator)
        hand_delay_s=0.0 if op.params.intrinsic else float(op.params.reaction_delay_s),
        sensor_delay_s=float(ft.params.latency_s) + (ticks - 1) * dt / 2.0,
        robot_delay_s=arm.latency_cycles / arm.rate_hz + 0.5 / arm.rate_hz + 0.5 * ctrl.every * dt,
    )


def open_loop(model: LoopModel, filter_gain: np.ndarray, omega: np.ndarray):
    """L(iω) as a python-control FRD."""
    import control

    s = 1j * omega
    L = (
        model.slope
        * (model.hand_stiffness + model.hand_damping * s)
        / s
        * filter_gain
        * np.exp(-s * model.delay_s)
    )
    return control.frd(L, omega)


@dataclass(frozen=True)
class LoopMargins:
    gain_margin: float  # factor (inf: none)
    phase_margin_deg: float
    crossover_rad_s: float  # where |L| = 1
    phase_crossover_rad_s: float  # where ∠L = -180°
    critical_slope: float  # α at which the loop loses stability

    @property
    def gain_margin_db(self) -> float:
        return 20.0 * math.log10(self.gain_margin) if math.isfinite(self.gain_margin) else math.inf


def loop_margins(model: LoopModel, filter_gain: np.ndarray, omega: np.ndarray) -> LoopMargins:
    """The smallest gain and phase margins over every crossover on the grid (a delayed loop crosses
    -180° many times; the loop goes unstable at the first crossover whose gain reaches 1)."""
    gms, pms, wpcs, wgcs = frd_margins(open_loop(model, filter_gain, omega))
    if gms.size:
        i = int(np.argmin(gms))
        gm, wpc = float(gms[i]), float(wpcs[i])
    else:
        gm, wpc = math.inf, math.nan
    if pms.size:
        j = int(np.argmin(pms))
        pm, wgc = float(pms[j]), float(wgcs[j])
    else:
        pm, wgc = math.inf, math.nan
    return LoopMargins(gm, pm, wgc, wpc, model.slope * gm)


def frd_margins(loop) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Every gain margin, phase margin, phase crossover and gain crossover of the FRD `loop`: the
    first, second, fourth and fifth of python-control's `stability_margins(loop, returnall=True)`,
    the same numbers to the bit (tests/unit/test_linear.py), in a quarter of its time.

    It reads them off the same interpolating spline in the same way: the crossings are the grid
    intervals where the sign of |L| - 1 or of ∠(-L) changes (-180° crossings only where Re L <= 0),
    each refined by Brent's method on the spline. `stability_margins` also finds every local
    minimum of |1 + L| (the stability margin, which the loop analysis does not use), and evaluates
    the spline on the whole grid once per quantity; here the grid is evaluated once. The spline
    gives the same value at a frequency whatever else is evaluated with it (one point at a time),
    so the values, and with them every root, are the same.
    """
    import control
    from scipy.optimize import brentq

    L = control.frd(loop.complex.reshape(-1), loop.omega, smooth=True)
    w = L.omega
    on_grid = L(1j * w)

    def phase_from_180(x: float) -> float:
        return np.angle(-L(1j * x))

    def gain_above_1(x: float) -> float:
        return np.abs(L(1j * x)) - 1

    # ∠(-L) changes sign at -180° (and at 0°, which Re L > 0 tells apart)
    at = np.where(np.diff(np.sign(np.angle(-on_grid))))[0]
    at = at[np.real(on_grid[at]) <= 0]
    w_180 = np.array([brentq(phase_from_180, w[i], w[i + 1]) for i in at])
    # |L| crosses 1
    at = np.where(np.diff(np.sign(np.abs(on_grid) - 1)))[0]
    w_c = np.array([brentq(gain_above_1, w[i], w[i + 1]) for i in at])
    with np.errstate(all="ignore"):  # |L| = 0 gives an infinite margin
        gm = 1.0 / np.abs(L(1j * w_180))
    pm = np.remainder(np.angle(L(1j * w_c), deg=True), 360.0) - 180.0
    return np.asarray(gm, dtype=float), np.asarray(pm, dtype=float), w_180, w_c
