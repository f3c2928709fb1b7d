"""Imperfect force sensors: the Robotiq FT-150 on the wrist and the Variense FSE103 on the probe.

Both sample the true reading at their own packet rate, deliver each packet after a transport latency,
and hold the last delivered packet with a counter that counts packets (0 before the first). Packet k
is sampled at (k + 1)/rate: with a 1 kHz tick the 200 Hz FT-150 gives exactly one packet every 5 ticks.
A step advances from t to t + dt with the input held; packets sampled in (t, t + dt] take that input.

Every imperfection has a size, and a size of zero switches it off; `ideal=True` switches them all off
at once (the packet rate and latency stay: they are the interface, not an error).

FT-150 (seed 4.C and notes/hardware.md):
- white noise per axis, σ = the seed's static max |noise| / 3.5 (the max of ~2000 Gaussian samples);
  the seed measured 1.15, 1.06, 0.31 N on base x, y, z at home, which are the sensor's y, x, z
  (eq. 1); torques on a 5 cm lever (the seed gives no torque figure);
- an offset (the unzeroed sensor) and a slow random-walk drift of it (0.005 N/√s: ~0.1 N in 10 min);
- quantisation of the stream's printed values, assumed 0.01 N and 0.0005 N·m;
- 200 Hz (the seed saw a packet every 5 ms; 100 and 62.5 Hz are also seen), 2 ms latency (assumed:
  the stream goes through the UR controller and TCP).

FSE103 (seed 3.B.2, Fig. 6, 4.A, 5.A):
- 50 Hz, 2 ms latency, white noise σ = 0.15 N / 3.5 (assumed; the seed gives no figure), an offset;
- the housing: its compliance and friction give a backlash (a play of width w per axis: the output
  follows the force only once it has moved more than w, so loading and unloading differ: the "loops"
  of the seed's Fig. 13), then it redirects force between axes and scales them (a matrix C) with a
  mild quadratic stiffening κ:  m = C y + κ ⊙ y ⊙ |y|,  y = play_w(f);
- the housing's characterisation (C, κ, w) is drawn per session from `characterisation_seed` and
  `session`: session 2 is the "next day" of the seed's Fig. 15, after other people used the probe.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from hoh_cosim.control.block import WRENCH_UNITS, Port
from hoh_cosim.control.estimator import (
    FSE103_NOISE_MAX,
    FT150_NOISE_MAX_S,
    FT150_TORQUE_NOISE_MAX_S,
)
from hoh_cosim.control.vectors import (
    Vec,
    as_nonnegative_vector,
    as_scalar,
    as_vector,
    frozen,
)
from hoh_cosim.errors import ConfigError
from plant_models.kernels import ft_packet, kernels_enabled

__all__ = [
    "FSE103Params",
    "FSE103Sensor",
    "FT150Params",
    "FT150Sensor",
    "HousingCharacterisation",
    "HousingParams",
    "PacketClock",
    "housing_characterisation",
]


class PacketClock:
    """Packet k sampled at phase + (k + 1)/rate, delivered `latency_s` later.

    A packet is due at t_end when its time is <= t_end + eps (eps = 1e-9/rate absorbs the rounding
    of the master's times). `next_sample_s` is the time of the next packet to sample (while
    `measure()` runs, of the packet it measures); `next_due_s` the earliest time at which a packet is
    sampled or delivered: a step ending at t_end with t_end + eps < next_due_s has nothing to do.
    The rate, latency and phase are read at construction and at `reset()`.
    """

    def __init__(self, rate_hz: float, latency_s: float, phase_s: float = 0.0) -> None:
        self.rate_hz = rate_hz
        self.latency_s = latency_s
        self.phase_s = phase_s
        self.reset()

    def reset(self) -> None:
        self.sampled = 0  # packets sampled so far
        self.delivered = 0  # packets delivered so far: the counter
        self._in_flight: deque[tuple[float, Vec]] = deque()
        self.latest: Vec | None = None
        self.eps = 1e-9 / self.rate_hz
        self.next_sample_s = self.next_due_s = self.sample_time(0)

    def sample_time(self, k: int) -> float:
        return self.phase_s + (k + 1) / self.rate_hz

    def advance(self, t_end: float, measure: Callable[[], Vec], lost: bool = False) -> None:
        """Sample every packet due by `t_end` with `measure()` (or lose it: a dropout), deliver
        every packet due by then."""
        t_due = t_end + self.eps
        in_flight = self._in_flight
        while self.next_sample_s <= t_due:
            if not lost:
                in_flight.append((self.next_sample_s + self.latency_s, measure()))
            self.sampled += 1
            self.next_sample_s = self.sample_time(self.sampled)
        while in_flight and in_flight[0][0] <= t_due:
            self.latest = in_flight.popleft()[1]
            self.delivered += 1
        self.next_due_s = (
            min(self.next_sample_s, in_flight[0][0]) if in_flight else self.next_sample_s
        )


def _rate_and_latency(params: object) -> None:
    object.__setattr__(
        params, "rate_hz", as_scalar(params.rate_hz, "rate_hz", low=0.0, low_open=True)
    )
    object.__setattr__(params, "latency_s", as_scalar(params.latency_s, "latency_s", low=0.0))


class _PacketSensor:
    """What both sensors share: a packet clock sampling `_measure(true)` per packet, and the last
    delivered packet held with its counter."""

    variable_step: ClassVar[bool] = True  # packets at their own times: every one in a long step
    true_port: ClassVar[str]
    value_port: ClassVar[str]
    size: ClassVar[int]
    clock: PacketClock
    params: Any

    def __init__(self, params: Any, rng: np.random.Generator | None = None) -> None:
        """The parameters, the generator (seeded 0 when none is given), the packet clock at the
        parameters' rate and latency, then `reset()`."""
        self.params = params
        self.rng = rng if rng is not None else np.random.default_rng(0)
        self.clock = PacketClock(self.params.rate_hz, self.params.latency_s)
        self.reset()

    def reset(self) -> None:
        raise NotImplementedError

    def retune(self, params: Any) -> None:
        """New parameters while running: a dropout (`connected`), an offset jump, other noise."""
        self.params = params

    def _measure(self, true: Vec) -> Vec:
        raise NotImplementedError

    def _hold_initial(self) -> None:
        """The outputs before the first packet: zeros, counter 0 (after the clock's reset)."""
        self._held = {self.value_port: np.zeros(self.size), "counter": np.array([0.0])}
        self._idle()

    def _idle(self) -> None:
        """`idle_until` (the block contract): a step ending before the clock's next packet is
        sampled or delivered, less its tolerance, does nothing and returns the held outputs."""
        self.idle_until = self.clock.next_due_s - self.clock.eps

    def step(self, t: float, dt: float, inputs: Mapping[str, Vec]) -> dict[str, Vec]:
        if t + dt < self.idle_until:  # no packet sampled or delivered in this step
            return self._held
        clock = self.clock
        true = inputs[self.true_port]
        delivered = clock.delivered
        clock.advance(t + dt, lambda: self._measure(true), lost=not self.params.connected)
        self._idle()
        if delivered != clock.delivered:
            # new arrays only when a packet arrives: between packets the held ones are returned.
            # A packet's array is made by `_measure` for it alone and never changed: no copy.
            self._held = {
                self.value_port: clock.latest,
                "counter": np.array([float(clock.delivered)]),
            }
        return self._held


def _quantise(x: Vec, step: Vec) -> Vec:
    return np.where(step > 0.0, np.round(x / np.where(step > 0.0, step, 1.0)) * step, x)


@dataclass(frozen=True)
class FT150Params:
    rate_hz: float = 200.0
    latency_s: float = 0.002
    noise_sigma: Vec = field(
        default_factory=lambda: frozen(
            np.concatenate([FT150_NOISE_MAX_S, FT150_TORQUE_NOISE_MAX_S]) / 3.5
        )
    )  # [N, N·m]
    offset: Vec = field(default_factory=lambda: frozen([1.8, -2.4, 3.1, 0.041, -0.027, 0.013]))
    drift_per_sqrt_s: Vec = field(default_factory=lambda: frozen([0.005] * 3 + [2.5e-4] * 3))
    quantisation: Vec = field(default_factory=lambda: frozen([0.01] * 3 + [5e-4] * 3))
    ideal: bool = False
    connected: bool = True  # False: every packet is lost (a dropout)

    UNITS: ClassVar[dict[str, Any]] = {
        "rate_hz": "Hz",
        "latency_s": "s",
        "noise_sigma": ("N", "N", "N", "N.m", "N.m", "N.m"),
        "offset": ("N", "N", "N", "N.m", "N.m", "N.m"),
        "drift_per_sqrt_s": ("N/s0.5",) * 3 + ("N.m/s0.5",) * 3,
        "quantisation": ("N", "N", "N", "N.m", "N.m", "N.m"),
    }
    TUNABLE: ClassVar[frozenset[str]] = frozenset(
        {"connected", "offset", "noise_sigma", "drift_per_sqrt_s"}
    )

    def __post_init__(self) -> None:
        _rate_and_latency(self)
        object.__setattr__(self, "offset", as_vector(self.offset, 6, "offset"))
        for name in ("noise_sigma", "drift_per_sqrt_s", "quantisation"):
            object.__setattr__(self, name, as_nonnegative_vector(getattr(self, name), 6, name))


class FT150Sensor(_PacketSensor):
    """The Robotiq FT-150 wrist sensor under the block contract; noise from the injected generator."""

    true_port, value_port, size = "wrench_S_true", "wrench_S", 6

    inputs: ClassVar[tuple[Port, ...]] = (
        Port("wrench_S_true", 6, WRENCH_UNITS, "true wrench of the tool on the sensor, in S"),
    )
    outputs: ClassVar[tuple[Port, ...]] = (
        Port("wrench_S", 6, WRENCH_UNITS, "last delivered packet, held"),
        Port("counter", 1, "1", "packets delivered so far (0 before the first)"),
    )

    def __init__(
        self, params: FT150Params | None = None, rng: np.random.Generator | None = None
    ) -> None:
        self._compiled = kernels_enabled()  # a packet's arithmetic compiled, or numpy's
        self.retune(params or FT150Params())
        self.rng = rng if rng is not None else np.random.default_rng(0)
        self.clock = PacketClock(self.params.rate_hz, self.params.latency_s)
        self.reset()

    def reset(self) -> None:
        self.clock.reset()
        self._hold_initial()
        self.drift = np.zeros(6)
        self._last_sample_time = 0.0

    def retune(self, params: Any) -> None:
        self.params = params
        self._drifts = bool(np.any(params.drift_per_sqrt_s > 0.0))
        self._quantum = params.quantisation if np.all(params.quantisation > 0.0) else None
        # a drifting packet's 12 draws: the drift's 6 then the noise's 6, and their scales
        self._draw_scale = np.concatenate([params.drift_per_sqrt_s, params.noise_sigma])

    def _measure(self, true: Vec) -> Vec:
        """drift += z_d ⊙ rate √Δt ;  packet = q ⊙ rint((true + offset + drift + z_n ⊙ σ) / q),
        z_d and z_n standard normal, Δt the time since the last packet, q the quantisation."""
        p = self.params
        if p.ideal:
            return true.copy()
        t_sample = self.clock.next_sample_s
        elapsed = t_sample - self._last_sample_time
        self._last_sample_time = t_sample
        if self._drifts and self._quantum is not None and self._compiled:
            # the common case in one compiled call, to the bit the numpy below (kernels.ft_packet)
            z = self.rng.standard_normal(12)
            return ft_packet(
                z, self._draw_scale, true, p.offset, math.sqrt(elapsed), self._quantum, self.drift
            )
        if self._drifts:
            # one draw of 12 gives the same numbers as the drift's 6 then the noise's 6
            scaled = self.rng.standard_normal(12) * self._draw_scale
            self.drift = self.drift + scaled[:6] * math.sqrt(elapsed)
            noise = scaled[6:]
        else:
            noise = self.rng.standard_normal(6) * p.noise_sigma
        value = true + p.offset + self.drift + noise
        if self._quantum is not None:  # every axis quantised: the common case, two operations
            return np.rint(value / self._quantum) * self._quantum
        return _quantise(value, p.quantisation)


# --- FSE103 --------------------------------------------------------------------------------


@dataclass(frozen=True)
class HousingParams:
    """Sizes of the housing's imperfections; a session draws its characterisation from them."""

    redirection: float = 0.25  # σ of the off-diagonal coupling of C
    gain_error: float = 0.15  # σ of C's diagonal around 1
    stiffening: float = 0.01  # σ of κ [1/N]
    play_N: tuple[float, float] = (0.2, 0.8)  # w drawn uniformly in this range per axis [N]
    characterisation_seed: int = 103
    session: int = 1

    UNITS: ClassVar[dict[str, Any]] = {
        "redirection": "1",
        "gain_error": "1",
        "stiffening": "1/N",
        "play_N": "N",
        "characterisation_seed": "1",
        "session": "1",
    }

    def __post_init__(self) -> None:
        for name in ("redirection", "gain_error", "stiffening"):
            object.__setattr__(self, name, as_scalar(getattr(self, name), name, low=0.0))
        lo, hi = (as_scalar(v, "play_N", low=0.0) for v in self.play_N)
        if lo > hi:
            raise ConfigError(f"play_N: expected (low, high) with low <= high, got {self.play_N}")
        object.__setattr__(self, "play_N", (lo, hi))
        for name in ("characterisation_seed", "session"):
            if not isinstance(getattr(self, name), int):
                raise ConfigError(f"{name}: expected an integer, got {getattr(self, name)!r}")


@dataclass(frozen=True)
class HousingCharacterisation:
    C: Vec  # 3x3
    kappa: Vec  # 3 [1/N]
    play: Vec  # 3 [N]


def _play(state: Vec, f: Vec, width: Vec) -> Vec:
    """The play's new state, min(max(state, f - w), f + w) axis by axis, compared as np.clip
    compares: x > f - w keeps x, then x < f + w keeps it, and a NaN is kept."""
    out = []
    for x, f_i, w in zip(state.tolist(), f.tolist(), width.tolist(), strict=True):
        low, high = f_i - w, f_i + w
        x = x if x != x or x > low else low
        out.append(x if x != x or x < high else high)
    return np.array(out)


def housing_characterisation(params: HousingParams) -> HousingCharacterisation:
    """The housing of one session: deterministic in (characterisation_seed, session)."""
    rng = np.random.default_rng([params.characterisation_seed, params.session])
    C = np.eye(3) + rng.normal(0.0, params.redirection, (3, 3)) * (1.0 - np.eye(3))
    C[np.diag_indices(3)] += rng.normal(0.0, params.gain_error, 3)
    kappa = rng.normal(0.0, params.stiffening, 3)
    play = rng.uniform(params.play_N[0], params.play_N[1], 3)
    return HousingCharacterisation(frozen(C), frozen(kappa), frozen(play))


@dataclass(frozen=True)
class FSE103Params:
    rate_hz: float = 50.0
    latency_s: float = 0.002
    noise_sigma: Vec = field(default_factory=lambda: frozen(FSE103_NOISE_MAX / 3.5))  # [N]
    offset: Vec = field(default_factory=lambda: frozen([0.3, -0.2, 0.5]))  # [N]
    housing: HousingParams = field(default_factory=HousingParams)
    redirection: bool = True  # C and κ
    hysteresis: bool = True  # the play
    ideal: bool = False
    connected: bool = True  # False: every packet is lost (a dropout)

    UNITS: ClassVar[dict[str, Any]] = {
        "rate_hz": "Hz",
        "latency_s": "s",
        "noise_sigma": "N",
        "offset": "N",
    }
    TUNABLE: ClassVar[frozenset[str]] = frozenset({"connected", "offset", "noise_sigma"})

    def __post_init__(self) -> None:
        _rate_and_latency(self)
        object.__setattr__(self, "offset", as_vector(self.offset, 3, "offset"))
        object.__setattr__(
            self, "noise_sigma", as_nonnegative_vector(self.noise_sigma, 3, "noise_sigma")
        )


class FSE103Sensor(_PacketSensor):
    """The Variense FSE103 in its housing under the block contract."""

    true_port, value_port, size = "force_P_true", "force_P", 3

    inputs: ClassVar[tuple[Port, ...]] = (
        Port("force_P_true", 3, "N", "true force of the probe on the sensor, in P"),
    )
    outputs: ClassVar[tuple[Port, ...]] = (
        Port("force_P", 3, "N", "last delivered packet, held"),
        Port("counter", 1, "1", "packets delivered so far (0 before the first)"),
    )

    def __init__(
        self, params: FSE103Params | None = None, rng: np.random.Generator | None = None
    ) -> None:
        params = params or FSE103Params()
        self.housing = housing_characterisation(params.housing)
        super().__init__(params, rng)

    def reset(self) -> None:
        self.clock.reset()
        self._hold_initial()
        self.play_state = np.zeros(3)

    def housing_output(self, f: Vec) -> Vec:
        """What the housing passes to the sensing element for the force f (advances the play)."""
        p, h = self.params, self.housing
        y = f
        if p.hysteresis:
            self.play_state = _play(self.play_state, f, h.play)
            y = self.play_state
        if p.redirection:
            y = h.C @ y + h.kappa * y * np.abs(y)
        return y

    def _measure(self, true: Vec) -> Vec:
        p = self.params
        if p.ideal:
            return true.copy()
        return self.housing_output(true) + p.offset + self.rng.standard_normal(3) * p.noise_sigma
