"""The estimator block: raw sensor packets in, filtered hand and probe forces in the base frame out.

Seed 000, Fig. 5, per tick:

    FT-150 packet ──▶ rebias ──▶ gravity compensation ──▶ Kalman (F, τ) ──▶ align to B ──▶ F̂_hand, τ̂_hand
    FSE103 packet ──▶ rebias ──────────────────────────▶ Kalman (F)    ──▶ align to B ──▶ F̂_probe

- A packet is new when its counter changed (counters start at 0, meaning "no packet yet"). A packet
  with a NaN or an infinity is rejected and counted; it never reaches a filter.
- Rebias (3.B.1): the first N packets after `reset()` or `start_rebias()` (seed: 500), taken while
  nobody touches the tool, give the sensor offset b = mean(w - w_weight(R_BS)). Until both sensors are
  rebiased the outputs are zero and `ready` is 0.
- Gravity compensation (3.D, eq. 4–5) with the tool model and the current R_BS.
- Filtering (3.E) per sensor axis in the sensor's own frame, where each axis has its own noise; the
  filters predict on every tick and correct on packets. Our ordering differs from Fig. 5, which aligns
  first: the seed's alignment was a constant axis permutation, so the two orders are the same filter
  with the axes relabelled, and ours stays right when the sensor turns.
- Alignment (3.C): the estimates are turned into the base frame with the current R_BS, and
  R_BP = R_BS · R_SP for the probe sensor.
- The contact's lever: the probe tip T (the probe correction's `tip_S`) from the torque reference
  point R, turned into B, gives the probe's axis in B (handle to tip, `probe_axis_B`) and the
  moment of the filtered contact force about R (`tau_probe_B` = p_RT_B × F̂_probe_B), which the
  controller takes out of the torque as eq. 12 takes the force out of the force.
- Probe correction (`hoh_cosim.control.probe_correction`): each rebiased probe packet goes through
  the correction `probe_correction.kind` names before its filter. With `probe_correction.check_s` > 0
  the rebias is followed by the probe check: for that long the outputs stay zero and `ready` 0 (the
  controller holds the robot still), the hand is off the handle, someone presses the probe tip, and
  each probe packet is paired with the latest compensated wrist packet (the reference) for the
  online map. Once ready, the consistency check compares the two sensors across the probe's axis.
- The contact across the axis from the wrist (`probe_correction.across_from_wrist_s` T > 0): the
  consistency check's mismatch, the wrist's contact force across the axis (from its force and
  torque, `probe_correction`'s docstring) less the probe's, low-passed over its 0.5 s, is
  low-passed again over T and added to F̂_probe (and its moment to τ̂_probe). Across the axis the
  probe force is then the probe's above about 1 / (2π T) and the wrist's below: the wrist has no
  housing and no play, but the grip's own torque on the handle reads as contact force, τ_g / 0.11
  m. The play (0.2-0.8 N per axis) leaves the probe's reading up to twice its width off wherever a
  contact stops moving the housing, and the hand pays that error for as long as it lasts
  (docs/decisions/0061-across-axis-from-wrist.md). The second low-pass follows the
  mismatch only while it is within `across_within_N` (1.2 N) and holds otherwise: a hand twisting
  the handle to tilt the probe reads as a larger one (0.35 N·m, a tilt of 0.1 rad/s under the
  rotation's default law, as 3.2 N), and followed, it would turn the hand's torque into a push
  across the axis.

Sign convention: each sensor reports the wrench that the tool side puts on it. The wrist sensor then
reads hand + contact + weight, the probe sensor contact (+ the probe's weight if it hangs below it), so
F_hand - F_probe is the hand's own force (eq. 11–12).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, ClassVar, Literal, Protocol

import numpy as np

from hoh_cosim.control.baselines import (
    ButterworthFilter,
    ButterworthParams,
    OneEuroFilter,
    OneEuroParams,
    ZeroOrderHold,
)
from hoh_cosim.control.block import WRENCH_UNITS, Port
from hoh_cosim.control.filters import LeadLowpassFilter, LeadLowpassParams
from hoh_cosim.control.frames import R_BS_EQ1, R_SP_SEED
from hoh_cosim.control.gravity import SEED_TOOL, GravityModel, ToolParams
from hoh_cosim.control.kalman import KalmanBank, KalmanParams, SteadyStateForceKalman
from hoh_cosim.control.kernels import (
    KernelConsistency,
    KernelKalmanBank,
    compiled_bank,
    estimator_tick,
    kernels_enabled,
    warm_up,
)
from hoh_cosim.control.probe_correction import (
    HANDLE_S,
    ContactConsistency,
    ProbeCorrection,
    ProbeCorrectionParams,
)
from hoh_cosim.control.vectors import (
    GRAVITY_B,
    Rot3,
    Vec,
    Vec3,
    Wrench,
    as_rotation,
    as_scalar,
    as_vector,
    frozen,
)
from hoh_cosim.errors import ConfigError

__all__ = [
    "FILTER_KINDS",
    "FT150_NOISE_MAX",
    "FT150_NOISE_MAX_S",
    "FT150_TORQUE_NOISE_MAX_S",
    "Estimator",
    "EstimatorParams",
    "FilterBank",
    "SignalFilter",
    "default_kalman",
    "import_filter_libraries",
    "make_filter_bank",
]

FilterKind = Literal["kalman", "steady_kalman", "lead_lowpass", "butterworth", "one_euro", "none"]
FILTER_KINDS: tuple[str, ...] = (
    "kalman",
    "steady_kalman",
    "lead_lowpass",
    "butterworth",
    "one_euro",
    "none",
)

FT150_NOISE_MAX = frozen([1.15, 1.06, 0.31])
"""[N] The seed's static FT-150 noise, max |noise| on x, y, z (section 4.C). The seed aligned before it
filtered (Fig. 5), so these are base-frame axes at its home pose."""
FT150_NOISE_MAX_S = frozen(np.abs(R_BS_EQ1.T) @ FT150_NOISE_MAX)
"""[N] The same per sensor axis: eq. 1 puts the sensor's y along base x, so (1.06, 1.15, 0.31)."""
FT150_TORQUE_NOISE_MAX_S = frozen(0.05 * FT150_NOISE_MAX_S)
"""[N·m] Assumed per sensor axis: the seed reports no torque noise; the force noise on a 5 cm lever."""
FSE103_NOISE_MAX = frozen([0.15, 0.15, 0.15])
"""[N] Assumed: the seed reports no FSE103 noise figure."""
NOISE_MAX_PER_SIGMA = 3.5
"""The max |noise| of ~2000 Gaussian samples is about 3.5 σ."""


def default_kalman(noise_max: Vec3, bandwidth: Vec3 = (1.0e4, 1.0e4, 3.0e4)) -> KalmanParams:
    """Kalman tuning for a sensor whose static max |noise| per axis is `noise_max`.

    r = σ² with σ = noise_max / 3.5; q = `bandwidth` · r, so every axis gets the same shape of
    response. The seed trusts z more (4.C): z gets three times the bandwidth. With the seed's FT-150
    noise, a packet every 5 ms and a 1 ms tick this cuts the max |noise| 2.4–3.5x (median 3.3 over 20
    seeds) and leads a 0.5 Hz sinusoid by 4–6 ms with 1 % overshoot.
    """
    r = (np.asarray(noise_max, dtype=np.float64) / NOISE_MAX_PER_SIGMA) ** 2
    return KalmanParams(q=frozen(np.asarray(bandwidth) * r), r=frozen(r))


class SignalFilter(Protocol):
    """One three-axis filter: `step(dt, z)` every tick, `z` the new packet or None."""

    def reset(self) -> None: ...

    def step(self, dt: float, z: Vec | None) -> Vec: ...


class FilterBank(Protocol):
    """The estimator's three channels (hand force, hand torque, probe force) stepped together."""

    def reset(self) -> None: ...

    def step_bank(self, dt: float, measurements: Sequence[Vec | None]) -> Vec: ...


@dataclass(frozen=True)
class EstimatorParams:
    """Everything the estimator needs to know about the tool, the sensors and the filters."""

    UNITS: ClassVar[dict[str, Any]] = {
        "g_B": "m/s2",
        "R_SP": "1",
        "p_SR_S": "m",
        "probe_mass_kg": "kg",
        "ft_rebias_packets": "1",
        "probe_rebias_packets": "1",
        "ft_bias": ("N", "N", "N", "N.m", "N.m", "N.m"),
        "probe_bias": "N",
        "hand_torque_kalman.q": "N2.m2/s5",
        "hand_torque_kalman.r": "N2.m2",
        "hand_torque_kalman.p0": ("N2.m2", "N2.m2/s2", "N2.m2/s4"),
        "one_euro_torque.beta": "1/(N.m)",
        "ft_packet_period_s": "s",
        "probe_packet_period_s": "s",
    }

    tool: ToolParams = SEED_TOOL
    g_B: Vec3 = field(default_factory=lambda: GRAVITY_B.copy())  # [m/s²]
    R_SP: Rot3 = field(default_factory=lambda: R_SP_SEED.copy())  # probe sensor P in wrist sensor S
    # [m] the point R the torque is taken about: the handle, so that the hand's push there is a
    # force and only its twist a torque (docs/decisions/0041-contact-torque-compensation.md)
    p_SR_S: Vec3 = field(default_factory=lambda: HANDLE_S.copy())
    probe_mass_kg: float = 0.0  # [kg] what hangs below the probe sensor (the seed: not modelled)
    use_probe: bool = True
    ft_rebias_packets: int = 500  # seed 3.B.1; 0: use ft_bias as given
    probe_rebias_packets: int = 500  # seed 3.B.2; 0: use probe_bias as given
    ft_bias: Wrench = field(default_factory=lambda: frozen(np.zeros(6)))  # [N, N·m]
    probe_bias: Vec3 = field(default_factory=lambda: frozen(np.zeros(3)))  # [N]
    filter: FilterKind = "kalman"
    hand_force_kalman: KalmanParams = field(
        default_factory=lambda: default_kalman(FT150_NOISE_MAX_S)
    )
    hand_torque_kalman: KalmanParams = field(
        default_factory=lambda: default_kalman(FT150_TORQUE_NOISE_MAX_S)
    )
    probe_force_kalman: KalmanParams = field(
        default_factory=lambda: default_kalman(FSE103_NOISE_MAX)
    )
    lead_lowpass: LeadLowpassParams = field(default_factory=LeadLowpassParams)
    butterworth: ButterworthParams = field(default_factory=ButterworthParams)
    one_euro_force: OneEuroParams = field(default_factory=OneEuroParams)
    one_euro_torque: OneEuroParams = field(
        default_factory=lambda: OneEuroParams(min_cutoff_hz=1.0, beta=1.0, d_cutoff_hz=1.0)
    )
    ft_packet_period_s: float = 0.005  # [s] expected, for the steady-state Kalman gain
    probe_packet_period_s: float = 0.02  # [s] expected (FSE103 at 50 Hz)
    probe_correction: ProbeCorrectionParams = field(default_factory=ProbeCorrectionParams)

    def __post_init__(self) -> None:
        if self.filter not in FILTER_KINDS:
            raise ConfigError(
                f"filter: expected one of {', '.join(FILTER_KINDS)}, got {self.filter!r}"
            )
        object.__setattr__(self, "g_B", as_vector(self.g_B, 3, "g_B"))
        object.__setattr__(self, "R_SP", as_rotation(self.R_SP, "R_SP"))
        object.__setattr__(self, "p_SR_S", as_vector(self.p_SR_S, 3, "p_SR_S"))
        object.__setattr__(
            self, "probe_mass_kg", as_scalar(self.probe_mass_kg, "probe_mass_kg", low=0.0)
        )
        object.__setattr__(self, "ft_bias", as_vector(self.ft_bias, 6, "ft_bias"))
        object.__setattr__(self, "probe_bias", as_vector(self.probe_bias, 3, "probe_bias"))
        for name in ("ft_rebias_packets", "probe_rebias_packets"):
            value = getattr(self, name)
            if not isinstance(value, int) or isinstance(value, bool) or value < 0:
                raise ConfigError(f"{name} must be an integer >= 0, got {value!r}")
        for name in ("ft_packet_period_s", "probe_packet_period_s"):
            object.__setattr__(
                self, name, as_scalar(getattr(self, name), name, low=0.0, low_open=True)
            )


class _SteadyKalmanAtFirstStep:
    """A `SteadyStateForceKalman` whose gain is designed at the first step, when dt is known."""

    def __init__(self, params: KalmanParams, packet_period_s: float) -> None:
        self.params = params
        self.packet_period_s = packet_period_s
        self._filter: SteadyStateForceKalman | None = None

    def reset(self) -> None:
        if self._filter is not None:
            self._filter.reset()

    def step(self, dt: float, z: Vec | None) -> Vec:
        if self._filter is None:
            ticks = round(self.packet_period_s / dt)
            if ticks < 1 or not math.isclose(ticks * dt, self.packet_period_s, rel_tol=1e-6):
                raise ConfigError(
                    f"steady_kalman: the packet period {self.packet_period_s} s is not a whole "
                    f"number of ticks of {dt} s"
                )
            self._filter = SteadyStateForceKalman(self.params, dt, ticks)
        return self._filter.step(dt, z)


class _SeparateFilters:
    """A `FilterBank` of independent `SignalFilter`s, one per channel."""

    def __init__(self, filters: Sequence[SignalFilter]) -> None:
        self.filters = tuple(filters)

    def reset(self) -> None:
        for f in self.filters:
            f.reset()

    def step_bank(self, dt: float, measurements: Sequence[Vec | None]) -> Vec:
        return np.concatenate(
            [f.step(dt, z) for f, z in zip(self.filters, measurements, strict=True)]
        )


def import_filter_libraries(params: EstimatorParams) -> None:
    """Import now what `params.filter` imports when it is built or first stepped (scipy.signal for
    the Butterworth filter, python-control for the steady-state Kalman gain: each most of a
    second), so that a real-time loop that builds or steps the estimator later never waits for it;
    the same for the compiled kernels (hoh_cosim.control.kernels), loaded or compiled now."""
    if params.filter == "butterworth":
        import scipy.signal  # noqa: F401
    elif params.filter == "steady_kalman":
        import control  # noqa: F401
    if kernels_enabled():
        warm_up(params.filter)


def make_filter_bank(params: EstimatorParams) -> FilterBank:
    """The three channels' filters as `params.filter` says: hand force, hand torque, probe force."""
    kalman = (params.hand_force_kalman, params.hand_torque_kalman, params.probe_force_kalman)
    periods = (params.ft_packet_period_s, params.ft_packet_period_s, params.probe_packet_period_s)
    one_euro = (params.one_euro_force, params.one_euro_torque, params.one_euro_force)
    kind = params.filter
    if kind == "kalman":
        return KalmanBank(kalman)
    if kind == "steady_kalman":
        return _SeparateFilters(
            [_SteadyKalmanAtFirstStep(k, T) for k, T in zip(kalman, periods, strict=True)]
        )
    if kind == "lead_lowpass":
        return _SeparateFilters([LeadLowpassFilter(params.lead_lowpass, T) for T in periods])
    if kind == "butterworth":
        return _SeparateFilters([ButterworthFilter(params.butterworth) for _ in range(3)])
    if kind == "one_euro":
        return _SeparateFilters([OneEuroFilter(p) for p in one_euro])
    return _SeparateFilters([ZeroOrderHold() for _ in range(3)])


class _SensorChannel:
    """One sensor's packets: a new one when its counter changes (the estimator compares the input
    with `counter` and calls `arrived`), non-finite ones rejected and counted, the time of the last
    good one, and the running mean that rebiases the sensor."""

    def __init__(self, counter_port: str, value_port: str, rebias_packets: int, given: Vec) -> None:
        self.counter_port = counter_port
        self.value_port = value_port
        self.rebias_packets = rebias_packets
        self.given = given
        self.reset()

    def reset(self) -> None:
        self.counter = 0.0  # counters start at 0: no packet yet
        self.t_last: float | None = None
        self.rejected = 0
        self.restart_rebias()

    def restart_rebias(self) -> None:
        self._count = 0
        self._total = np.zeros_like(self.given)
        self.bias: Vec | None = self.given.copy() if self.rebias_packets == 0 else None

    def arrived(self, t: float, counter: float, inputs: Mapping[str, Vec]) -> Vec | None:
        """The values of a packet whose counter differs from the last one, None if not finite."""
        self.counter = float(counter)
        values = inputs[self.value_port]
        if not _finite_sum(values):
            self.rejected += 1
            return None
        self.t_last = t
        return values

    def debiased(self, ext: Vec) -> Vec | None:
        """`ext` minus the sensor offset; None while the packet goes into the rebias mean."""
        if self.bias is not None:
            return ext - self.bias
        self._total += ext
        self._count += 1
        if self._count >= self.rebias_packets:
            self.bias = self._total / self._count
        return None


def _finite_sum(values: Vec) -> bool:
    """Whether `values.sum()` is finite: a packet with a NaN or an infinity is not.

    Σ|vᵢ| < 1e308 bounds every partial sum, in any order, below the largest double, so the sum is
    finite; anything else (a NaN, an infinity, values near the largest double) asks the sum itself.
    """
    if sum(map(abs, values.tolist())) < 1e308:
        return True
    return math.isfinite(float(values.sum()))


_F = ("N", "N", "N")
_ZERO3 = frozen(np.zeros(3))
_FLAG = (frozen([0.0]), frozen([1.0]))
"""The one-value outputs 0 and 1, indexed by a bool: returned again and again, never written to."""


class Estimator:
    """Alignment, rebias, gravity compensation and three filters (hand force, hand torque, probe
    force) under the block contract. See the module docstring for the pipeline."""

    inputs: ClassVar[tuple[Port, ...]] = (
        Port("wrench_S", 6, WRENCH_UNITS, "raw FT-150 wrench on the sensor, in S"),
        Port("ft_counter", 1, "1", "FT-150 packet counter: +1 per new packet, 0 before the first"),
        Port("force_P", 3, _F, "raw FSE103 force on the probe sensor, in P"),
        Port(
            "probe_counter", 1, "1", "FSE103 packet counter: +1 per new packet, 0 before the first"
        ),
        Port("R_BS", 9, "1", "orientation of the wrist sensor in the base frame, row by row"),
    )
    outputs: ClassVar[tuple[Port, ...]] = (
        Port("F_hand_B", 3, _F, "filtered external force on the tool (hand + contact), in B"),
        Port("tau_hand_B", 3, ("N.m",) * 3, "filtered external torque about the point R, in B"),
        Port("F_probe_B", 3, _F, "filtered contact force on the probe, in B"),
        Port("F_hand_meas_B", 3, _F, "latest compensated, unfiltered wrist force, in B (held)"),
        Port("ft_age", 1, "s", "time since the last accepted FT-150 packet"),
        Port("probe_age", 1, "s", "time since the last accepted FSE103 packet"),
        Port("ready", 1, "1", "1 once both sensors are rebiased and the probe check is over"),
        Port("rejected_packets", 1, "1", "packets rejected for NaN or infinite values"),
        Port("F_probe_meas_P", 3, _F, "latest rebiased probe packet, uncorrected, in P (held)"),
        Port("F_probe_corr_P", 3, _F, "the same packet corrected, in P (held)"),
        Port(
            "F_probe_meas_B",
            3,
            _F,
            "the same corrected packet turned into B, unfiltered (held): R_BS R_SP F_probe_corr_P",
        ),
        Port("probe_check", 1, "1", "1 during the probe check (hand off, probe tip pressed)"),
        Port(
            "probe_mismatch", 1, "N", "low-passed disagreement of the two sensors across the axis"
        ),
        Port("probe_drift", 1, "1", "1 while the mismatch is above its threshold"),
        Port(
            "tau_probe_B",
            3,
            ("N.m",) * 3,
            "moment of the filtered contact force about the point R, in B: p_RT_B × F_probe_B",
        ),
        Port("probe_axis_B", 3, "1", "the probe's axis in B, a unit vector from handle to tip"),
    )

    def __init__(self, params: EstimatorParams | None = None) -> None:
        self.params = p = params or EstimatorParams()
        self._weight = GravityModel(p.tool, p.g_B)
        self._probe_weight = (
            GravityModel(ToolParams(p.probe_mass_kg), p.g_B) if p.probe_mass_kg > 0 else None
        )
        self._filters = make_filter_bank(p)
        # the Kalman bank's tick, the consistency check and the turn into B as one compiled call
        # (hoh_cosim.control.kernels); the numpy code below is the reference it is checked against
        self._kernel = kernels_enabled() and isinstance(self._filters, KalmanBank)
        if self._kernel:
            self._filters = KernelKalmanBank(self._filters.channels)
        elif kernels_enabled() and isinstance(self._filters, _SeparateFilters):
            self._filters = compiled_bank(self._filters.filters) or self._filters
        if kernels_enabled():
            warm_up(p.filter)  # loaded now, never in the first ticks of a real-time loop
        self._ft = _SensorChannel("ft_counter", "wrench_S", p.ft_rebias_packets, p.ft_bias)
        self._probe = _SensorChannel(
            "probe_counter", "force_P", p.probe_rebias_packets, p.probe_bias
        )
        self._shift_torque = bool(np.any(p.p_SR_S != 0.0))
        # the tip from R, and the axis from the handle to the tip, in S (as float triples: two
        # 3x3 products and a cross product per tick cost less in floats than in numpy)
        pc = p.probe_correction
        self._p_RT_S = (pc.tip_S - p.p_SR_S).tolist()
        axis = pc.tip_S - pc.handle_S
        self._axis_S = (axis / math.sqrt(float(axis @ axis))).tolist()
        self._use_probe = p.use_probe
        self._R_SP = p.R_SP
        self._R_PS = p.R_SP.T.copy()
        self._drift_threshold_N = p.probe_correction.mismatch_threshold_N
        self._across_s = p.probe_correction.across_from_wrist_s
        self._across_within_sq = p.probe_correction.across_within_N**2
        self.correction = ProbeCorrection(p.probe_correction)
        if self._kernel:
            self._consistency = KernelConsistency(p.probe_correction, p.p_SR_S)
            self._consistency.attach(self._filters)
            self._filters.set_rotation(p.R_SP)
        else:
            self._consistency = ContactConsistency(p.probe_correction, p.p_SR_S)
        self.reset()

    def reset(self) -> None:
        self._filters.reset()
        self._ft.reset()
        self._probe.reset()
        self.correction.reset()
        self._t0: float | None = None
        # rows: F_hand, τ_hand, F_probe and F_meas in S, turned into B by one product each tick;
        # the fourth row holds the latest compensated wrist force between packets. The compiled
        # tick turns three more (kernels.IN_S_ROWS): the held probe packet R_SP f_P, and the
        # constant p_RT_S and probe axis
        self._in_S = self._filters.in_S if self._kernel else np.zeros((4, 3))
        self._in_S[...] = 0.0
        if self._kernel:
            self._in_S[5] = self._p_RT_S
            self._in_S[6] = self._axis_S
        self._m_P = np.zeros(3)
        self._f_P = np.zeros(3)
        self._check_until: float | None = None
        self._checking = False
        self._rejected = 0
        self._rejected_out = _FLAG[False]
        self._reset_mismatch()
        self._update_ready()

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
        if self._kernel:  # a copy's rows in S are its own bank's again (a view, not a copy)
            self._in_S = self._filters.in_S

    def _reset_mismatch(self) -> None:
        """The consistency check starts again: its mismatch, and the output that holds it, are 0."""
        self._consistency.reset()
        self._mismatch = 0.0
        self._mismatch_out = _FLAG[False]
        self._across_S = [0.0, 0.0, 0.0]  # the mismatch low-passed over across_from_wrist_s, in S

    def start_rebias(self) -> None:
        """Take the next N packets of each sensor as the new offset (nobody may touch the tool);
        the probe check, if any, follows again."""
        self._ft.restart_rebias()
        self._probe.restart_rebias()
        self._filters.reset()
        self._reset_mismatch()
        self._check_until = None
        self._update_ready()

    @property
    def ready(self) -> bool:
        """Both sensors rebiased (or the probe sensor not in use) and the probe check over."""
        return self._ready

    @property
    def checking(self) -> bool:
        """In the probe check: the hand must be off the handle, the probe tip pressed."""
        return self._checking

    @property
    def rejected_packets(self) -> int:
        """Packets refused for a NaN or an infinity, both sensors together."""
        return self._ft.rejected + self._probe.rejected

    def _update_ready(self, t: float | None = None) -> None:
        """Ready once rebiased and the probe check, which starts at the first step after the
        rebias (time t), is over."""
        rebiased = self._ft.bias is not None and (
            self._probe.bias is not None or not self.params.use_probe
        )
        check_s = self.params.probe_correction.check_s if self.params.use_probe else 0.0
        if rebiased and t is not None and self._check_until is None:
            self._check_until = t + check_s
        if not rebiased or check_s == 0.0:
            self._checking = False
        elif self._check_until is None or t is None:
            self._checking = True
        else:
            self._checking = t < self._check_until - 1e-9
        self._ready = rebiased and not self._checking

    def _ft_packet(self, w: Wrench, R_BS: Rot3) -> Wrench | None:
        """The compensated wrench of a new FT-150 packet, or None while rebiasing."""
        ext = self._ft.debiased(w - self._weight.weight_S(R_BS))
        if ext is None:
            return None
        if self._shift_torque:  # τ about R = τ about S - p_SR × f
            p, f = self.params.p_SR_S, ext
            ext[3:] -= (
                p[1] * f[2] - p[2] * f[1],
                p[2] * f[0] - p[0] * f[2],
                p[0] * f[1] - p[1] * f[0],
            )
        return ext

    def _probe_packet(self, f: Vec3, R_BS: Rot3) -> Vec3 | None:
        """The compensated force of a new FSE103 packet, or None while rebiasing."""
        if self._probe_weight is not None:
            f = f - self._probe_weight.weight_S(R_BS.dot(self._R_SP))[:3]
        return self._probe.debiased(f)

    def step(self, t: float, dt: float, inputs: Mapping[str, Vec]) -> dict[str, Vec]:
        if self._t0 is None:
            self._t0 = t
        R9 = inputs["R_BS"]  # turned into the matrix R_BS only where a product needs it
        ft, probe = self._ft, self._probe

        ft_z = None
        counter = inputs[ft.counter_port][0]
        if counter != ft.counter:
            w = ft.arrived(t, counter, inputs)
            ft_z = None if w is None else self._ft_packet(w, R9.reshape(3, 3))
            if ft_z is not None:
                self._in_S[3] = ft_z[:3]
        probe_z = None
        if self._use_probe:
            counter = inputs[probe.counter_port][0]
            if counter != probe.counter:
                f = probe.arrived(t, counter, inputs)
                probe_z = None if f is None else self._probe_packet(f, R9.reshape(3, 3))
            probe_age = t - (self._t0 if probe.t_last is None else probe.t_last)
        else:
            probe_age = 0.0
        ft_age = t - (self._t0 if ft.t_last is None else ft.t_last)
        if not self._ready:
            self._update_ready(t)
        if probe_z is not None:
            self._m_P = probe_z
            # corrected before it is learnt from: the output is the prediction, never the reference
            probe_z = self._f_P = self.correction.correct(probe_z)
            if self._kernel:
                self._R_SP.dot(probe_z, out=self._in_S[4])
            if self._checking:
                self.correction.reference(t, self._m_P, self._R_PS.dot(self._in_S[3]))
        rejected = ft.rejected + probe.rejected
        if rejected != self._rejected:
            self._rejected = rejected
            self._rejected_out = np.array([float(rejected)])

        # the one-value outputs that change only on an event (a rejected packet, the probe check,
        # a consistency step) are held: the same array again until the value changes
        if not self._ready:
            return {
                "F_hand_B": _ZERO3,
                "tau_hand_B": _ZERO3,
                "F_probe_B": _ZERO3,
                "F_hand_meas_B": R9.reshape(3, 3).dot(self._in_S[3]),
                "ft_age": np.array([ft_age]),
                "probe_age": np.array([probe_age]),
                "ready": _FLAG[False],
                "rejected_packets": self._rejected_out,
                "F_probe_meas_P": self._m_P,
                "F_probe_corr_P": self._f_P,
                "F_probe_meas_B": _ZERO3,
                "probe_check": _FLAG[self._checking],
                "probe_mismatch": _FLAG[False],
                "probe_drift": _FLAG[False],
                "tau_probe_B": _ZERO3,
                "probe_axis_B": _turned(R9, self._axis_S),
            }

        check = ft_z is not None and self._use_probe
        if self._kernel:  # what the numpy code below does, in one compiled call
            in_B = estimator_tick(self._filters, dt, ft_z, probe_z, R9, t, check)
            mismatch = self._consistency.mismatch if check else self._mismatch
        else:
            R_BS = R9.reshape(3, 3)
            if ft_z is None:
                forces = self._filters.step_bank(dt, (None, None, probe_z))
            else:
                forces = self._filters.step_bank(dt, (ft_z[:3], ft_z[3:], probe_z))
            in_S = self._in_S  # rows F_hand, τ_hand, F_probe (filtered), F_meas (held), in S
            in_S[:2] = forces[:6].reshape(2, 3)
            self._R_SP.dot(forces[6:], out=in_S[2])  # F_probe_S = R_SP F_P
            mismatch = self._mismatch
            if check:
                mismatch = self._consistency.step(t, in_S[0], in_S[1], in_S[2])
            # one product turns all four vectors into B: columns F_hand, τ_hand, F_probe, F_meas
            # as rows: v_B = R_BS v_S  <=>  row_B = row_S R_BSᵀ
            in_B = in_S.dot(R_BS.T)
        if mismatch != self._mismatch:
            self._mismatch = mismatch
            self._mismatch_out = np.array([mismatch])
        use_probe = self._use_probe
        F_probe_B = in_B[2] if use_probe else _ZERO3
        if self._kernel:  # the compiled tick's further rows
            F_probe_meas_B = in_B[4] if use_probe else _ZERO3
            tau_probe = in_B[7] if use_probe else _ZERO3
            axis_B = in_B[6]
        else:
            R_BS = R9.reshape(3, 3)
            F_probe_meas_B = R_BS.dot(self._R_SP.dot(self._f_P)) if use_probe else _ZERO3
            # τ_probe = p_RT_B × F_probe_B, p_RT_B = R_BS p_RT_S: the contact's moment about R
            r0, r1, r2 = _turned_xyz(R9, self._p_RT_S)
            f0, f1, f2 = F_probe_B.tolist()
            tau_probe = np.array((r1 * f2 - r2 * f1, r2 * f0 - r0 * f2, r0 * f1 - r1 * f0))
            axis_B = _turned(R9, self._axis_S)
        if self._across_s > 0.0 and use_probe:
            F_probe_B, tau_probe = self._across_from_wrist(dt, R9, F_probe_B, tau_probe)
        return {
            "F_hand_B": in_B[0],
            "tau_hand_B": in_B[1],
            "F_probe_B": F_probe_B,
            "F_hand_meas_B": in_B[3],
            "ft_age": np.array([ft_age]),
            "probe_age": np.array([probe_age]),
            "ready": _FLAG[True],
            "rejected_packets": self._rejected_out,
            # held too: replaced, never written into, when a probe packet arrives
            "F_probe_meas_P": self._m_P,
            "F_probe_corr_P": self._f_P,
            # the hold's force (hoh_cosim.control.hold): the packet without the filter's lag
            "F_probe_meas_B": F_probe_meas_B,
            "probe_check": _FLAG[self._checking],
            "probe_mismatch": self._mismatch_out,
            "probe_drift": _FLAG[self._mismatch > self._drift_threshold_N],
            "tau_probe_B": tau_probe,
            "probe_axis_B": axis_B,
        }

    def _across_from_wrist(
        self, dt: float, R9: Vec, F_probe_B: Vec3, tau_probe: Vec3
    ) -> tuple[Vec3, Vec3]:
        """F̂_probe and τ̂_probe with the wrist's part across the axis added (module docstring)."""
        m0, m1, m2 = self._consistency.mismatch_S.tolist()
        across = self._across_S
        if m0 * m0 + m1 * m1 + m2 * m2 <= self._across_within_sq:
            a = dt / (self._across_s + dt)
            o0, o1, o2 = across
            self._across_S = across = [o0 + (m0 - o0) * a, o1 + (m1 - o1) * a, o2 + (m2 - o2) * a]
        R = R9.tolist()
        l0, l1, l2 = lift = _turned_xyz_list(R, across)
        r0, r1, r2 = _turned_xyz_list(R, self._p_RT_S)
        moment = (r1 * l2 - r2 * l1, r2 * l0 - r0 * l2, r0 * l1 - r1 * l0)
        return F_probe_B + np.array(lift), tau_probe + np.array(moment)


def _turned_xyz(R9: Vec, v: list[float]) -> tuple[float, float, float]:
    """R v for R given row by row (9 values) and v a float triple."""
    return _turned_xyz_list(R9.tolist(), v)


def _turned_xyz_list(R: list[float], v: list[float]) -> tuple[float, float, float]:
    """`_turned_xyz` for R already as 9 floats."""
    a, b, c, d, e, f, g, h, i = R
    x, y, z = v
    return a * x + b * y + c * z, d * x + e * y + f * z, g * x + h * y + i * z


def _turned(R9: Vec, v: list[float]) -> Vec:
    """`_turned_xyz` as an array."""
    return np.array(_turned_xyz(R9, v))
