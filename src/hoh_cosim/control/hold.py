"""Hold-on-release: the hand lets go with the probe on the patient, and the robot holds the contact.

The seed's aim (000, 1.A) was to "maneuver to a point-of-interest and then release, having the robot
do all the strenuous holding". With eq. 10 alone the robot holds the probe still while the patient's
abdomen breathes under it: the contact force swings by the breath's depth times the tissue's
stiffness (10 mm on about 1200 N/m is 12 N). Holding the force instead of the position is what the
hand does freehand, and what this block does once the hand is off the handle.

    engage     in contact (the probe force above `contact_N`) for at least `settle_s` (a
               touch-down's bounce is no release), when the release detector tells a release in
               contact (`ReleasePhase.RELEASED_CONTACT`), or when the hand has asked for nothing
               for `engage_s`: its compensated force F̃ (eq. 11-12) inside the quiet band, across
               the probe axis b = max(η, raw band) per base axis as the release detector's, along
               the axis `axial_band_N` (the probe sensor's error along its axis, and the two
               sensors' filters' different lags, which the hand's push there cannot be told from).
               A hand resting still on the handle cannot be told from no hand: the hold engages
               then too, and the hand's next push hands back
    setpoint   c_ref: the probe sensor's axial contact force averaged over the last `window_s`
               before the engagement (about a breath: on a breathing patient the force at one
               instant is the breath's phase, the sonographer's level is its mean), clipped to
               [`contact_N`, `max_force_N`]; it moves there from the force at the engagement at
               `ramp_N_s`
    retake     (`retake_band_N` > 0) while holding, a hand that went on pushing or pulling along
               the axis (F̃·a beyond `retake_band_N`) for `retake_push_s` or longer held the
               contact where it wanted it, the hold's force plus its own; once it is still (inside
               the band) for `engage_s`, by letting go or by settling, the setpoint moves to the
               probe sensor's axial force averaged over that push (its last `window_s`). A hold
               that engaged on a hand easing off rather than letting go (the release detector
               tells both) then keeps the hand's level, not the window's before it. The band must
               be above F̃'s own error along the axis with nobody's hand, under a newton only
               after a probe check: off by default (docs/decisions/0052-hold-retake.md)
    hold       along a line l, the probe axis a (handle to tip, from the estimator) unless
               `motion` says otherwise (below), z = p_BT·l the tip's depth coordinate, c the
               axial contact force (pressing positive, along a whatever the line):
                   m = z - (c - c_ref) / k̂         where the tip must be for c = c_ref: the surface
                                                    plus the depth of c_ref (tissue stiffness k̂)
                   ŝ, ṡ, s̈  a constant-acceleration Kalman filter on m (steady-state gain,
                            bandwidth `observer_hz`): the breathing surface, smooth
                   u = ṡ_τ + k_z (s_τ - z) + k_i ∫ (c_ref - c) / k̂ dt
                            s_τ, ṡ_τ: the filter's state `lookahead_s` ahead (the robot's delay)
                   v = u l,   ω = 0
               With k̂ = k the measurement m does not depend on the robot at all (m = surface +
               depth): the robot follows a filtered surface (feed-forward) and its own exactly
               measured position (k_z), so the force sensor's noise reaches the tip only through the
               filter's band (3 Hz: a trade between the breath's tracking and the noise passed,
               docs/decisions/0048-hold-surface-filter-at-3-hz.md); a k̂ off by a factor ρ = k / k̂
               leaves a loop of gain 1 - ρ, stable for 0 < ρ < 2. The slow integral takes out what
               the linearisation leaves (the tissue stiffens with depth). Across the line and in
               rotation the command is rest: the rest of the pose held
    line       (`motion`) `axis`, the default: l = a. `normal`: l starts at a and follows the
               contact's direction, the wrist's force low-passed over `normal_tau_s` while no hand
               touches (F̃ inside the quiet band, and inside the retake's band along the axis).
               The breath moves the surface along its normal; where that differs from the axis (12°
               on the flank of the clinical study's abdomen) a hold along the axis slides the probe
               over the skin at every breath, and friction, turning over at each breath's turn and
               felt by the wrist, both moves the contact and drives the loop into a limit cycle at
               12-16 Hz (docs/decisions/0053-hold-along-surface-normal.md). Friction
               averages out over breaths, and the mean is the normal. The filter's state, the
               tip's history and the guards' origins move with the line
    hand back  a touch of the handle: F̃ departs from its value at the engagement by more than the
               quiet band (scaled as above; across the axis widened, per base axis, by the range
               of the probe's force over the last `swing_s`, `_swing`), confirmed by the raw packet
               and either firm (more than `reengage_factor` bands) or lasting `confirm_s`; the
               admittance's command is then blended in over `blend_s` (v = (1 - β) v_hold +
               β v_law, β from 0 to 1), the hold running meanwhile, so the command has no step
    guards     the hold ends, and the robot brakes to rest, when the contact is lost (the probe force
               under `loss_N`) for `loss_s` or while the tip moved `loss_m` along the line, or when
               the tip has moved `max_travel_m` along the line from where the hold began: it never
               chases a patient who moved away. Its own speed is at most `max_speed`; the
               supervisor's limits (speed, acceleration, soft cap, workspace, stops) apply after it,
               as to every command

Which force (`force_source`). `wrist`, the default: the axial component of the wrist sensor's
newest packet (compensated, unfiltered: `F_hand_meas_B`, hand and contact together), the contact
alone once the hand is off (the FT-150's 0.09 N σ along the probe). A hand resting on the handle
when the hold engages is in it: its opening is a step of its share, which the loop answers by
drawing the probe back (docs/decisions/0046-hold-regulates-wrist-force.md: the cause of the hold's
image jitter in the clinical study, not the sensor's noise). `probe`: the probe sensor's newest
packet (`F_probe_meas_B`, else its filtered estimate), which the hand is not in; but the housing's
play (0.2-0.8 N per axis, seed 3.B.2) hides the contact's changes inside it, the measurement then
follows the tip's own position (m = z), and the loop, which commands the velocity it estimates,
limit-cycles at about 1.6 Hz (3.4 N std in the clinical view): kept for the measurement, not for
use. `combined`: the wrist's packet plus the hand's share ĥ that the probe sensor tells at a hand's
event (`HandShare`): c = c_w + ĥ, free of the play where the contact moves under the hold, free of
the hand where it opens or pushes. In every case m takes the tip's position when the regulated
packet was sampled (the packet's age and `latency_s` back), and the filter predicts over that delay
besides `lookahead_s`. The probe sensor decides contact, the setpoint, the soft cap and the stop.
`max_force_N` stays below the supervisor's soft cap (20 N) so that the loop never leans on it.
"""

from __future__ import annotations

import enum
import functools
import math
from collections import deque
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from hoh_cosim.control.history import keep_span, sample_at
from hoh_cosim.control.release import scaled_norm
from hoh_cosim.control.vectors import Vec, Vec3, as_nonnegative_vector, as_scalar, frozen
from hoh_cosim.errors import ConfigError

__all__ = [
    "FORCE_SOURCES",
    "ContactHold",
    "HoldEnd",
    "HoldParams",
    "HoldPhase",
    "surface_filter_gain",
    "surface_observer_gain",
]


FORCE_SOURCES = ("combined", "wrist", "probe")
"""The sensor whose newest packet the hold regulates (module docstring)."""
MOTIONS = ("axis", "normal")
"""The line the hold moves the tip along (module docstring)."""
_HISTORY_S = 0.1  # [s] the tip positions kept to match a packet's age (the FSE103's is under 0.02)


class HoldPhase(enum.IntEnum):
    """What the hold does."""

    OFF = 0  # the admittance law has the robot
    HOLDING = 1  # the robot holds the contact force, the hand is off
    BLENDING = 2  # handing back: the law's command is blended in


class HoldEnd(enum.IntEnum):
    """Why the last hold ended."""

    NONE = 0
    HANDED_BACK = 1  # a touch of the handle
    CONTACT_LOST = 2  # the probe left the patient
    TRAVEL = 3  # the tip moved too far along the axis
    STOPPED = 4  # the controller commanded zero (a stop flag: stale or bad data, the force stop)


@dataclass(frozen=True)
class HoldParams:
    """Hold-on-release (module docstring). Off by default: see
    docs/decisions/0043-hold-on-release.md."""

    UNITS: ClassVar[dict[str, Any]] = {
        "stiffness_N_m": "N/m",
        "force_noise_N": "N",
        "observer_hz": "Hz",
        "position_gain": "1/s",
        "ki": "1/s",
        "lookahead_s": "s",
        "latency_s": "s",
        "contact_N": "N",
        "max_force_N": "N",
        "engage_s": "s",
        "engage_still_m": "m",
        "settle_s": "s",
        "window_s": "s",
        "ramp_N_s": "N/s",
        "axial_band_N": "N",
        "share_band_N": "N",
        "share_window_s": "s",
        "share_event_s": "s",
        "share_rest_s": "s",
        "share_min_N": "N",
        "share_filter_s": "s",
        "raw_band_N": "N",
        "reengage_factor": "1",
        "confirm_s": "s",
        "touch_tau_s": "s",
        "blend_s": "s",
        "engage_blend_s": "s",
        "swing_s": "s",
        "normal_max_deg": "deg",
        "normal_tau_s": "s",
        "retake_band_N": "N",
        "retake_push_s": "s",
        "loss_N": "N",
        "loss_s": "s",
        "loss_m": "m",
        "max_travel_m": "m",
        "max_speed": "m/s",
    }

    enabled: bool = False
    # FORCE_SOURCES: what the hold regulates (module docstring); the clinical study's hold mode
    # sets combined, rehearsed in simulation only so far
    # (docs/decisions/0045-hold-combined-force-in-study.md)
    force_source: str = "wrist"
    # MOTIONS: the line the tip moves along while held (module docstring); normal: the contact's
    # direction, the wrist's force low-passed over normal_tau_s (several breaths: friction flips
    # with each) while no hand touches, kept within normal_max_deg of the axis (friction tilts
    # the contact force by at most atan μ, 11° for μ = 0.2 on gel)
    motion: str = "axis"
    normal_tau_s: float = 5.0
    normal_max_deg: float = 30.0
    # the hand's share (`HandShare`): an event is the sensors' difference moving past the band
    # within the window; it is followed that long at most, one each way per hold, a rest apart,
    # and undone if it moved the share less than share_min_N (the probe's play at a breath's turn)
    share_band_N: float = 1.0  # [N]
    share_window_s: float = 0.3  # [s]
    share_event_s: float = 0.3  # [s]
    share_rest_s: float = 1.0  # [s]
    share_min_N: float = 1.5  # [N]
    share_filter_s: float = 0.02  # [s] the difference's low-pass (the sensors' noise)
    latency_s: float = 0.002  # [s] a packet's sample to its arrival (FSE103 and FT-150 alike)
    # k̂ [N/m]: the tissue's stiffness about the working force (the simulated phantom's is
    # 1000-1560 N/m at 5-20 N; a factor of two either way stays stable, module docstring)
    stiffness_N_m: float = 1200.0
    force_noise_N: float = 0.09  # [N] σ of the regulated force's packets (FT-150 along z)
    # the surface filter's bandwidth: a breath's sin⁴ shape has its second harmonic at up to
    # 0.67 Hz (20 a minute), which a constant-acceleration filter follows with an error of about
    # (f / observer_hz)³ of it; tremor's 8-12 Hz stays out
    # (docs/decisions/0048-hold-surface-filter-at-3-hz.md)
    observer_hz: float = 3.0
    position_gain: float = 10.0  # k_z [1/s]
    ki: float = 0.5  # k_i [1/s]: the force error's slow integral
    lookahead_s: float = 0.02  # [s] the robot's delay, predicted over
    contact_N: float = 2.0  # [N] probe force that counts as contact for a hold
    max_force_N: float = 18.0  # [N] the highest setpoint, under the supervisor's 20 N soft cap
    engage_s: float = 0.5  # [s] the hand asks for nothing this long in contact: hold
    # [m] the quiet hand must also have kept the probe within this across its axis over the last
    # engage_s: glide moves the probe under eq. 10's deadband, so a hand steering it lightly over
    # the skin is inside the quiet band and would be held (0: the band alone)
    engage_still_m: float = 0.0
    # [s] in contact this long before anything engages a hold: the probe touching down bounces,
    # and the hand's push falling then reads as a release (the rehearsal's press: at 0.1 s)
    settle_s: float = 1.0
    window_s: float = 4.0  # [s] the setpoint's average (a breath at 15 a minute)
    ramp_N_s: float = 10.0  # [N/s] the setpoint's way from the force at the engagement
    # [N] the quiet band along the probe axis: the two sensors' filters lag differently, so a
    # contact force changing 3 N in 0.1 s (a hand opening on a held probe) reads as up to 2.6 N of
    # F̃ along the axis for about 0.2 s (docs/decisions/0043-hold-on-release.md)
    axial_band_N: float = 2.5
    raw_band_N: Vec3 = field(default_factory=lambda: frozen([1.15, 1.15, 0.31]))  # across it
    reengage_factor: float = 2.0  # a touch this many bands strong hands back at once
    confirm_s: float = 0.15  # [s] ... a weaker one (above one band) after this long
    touch_tau_s: float = 0.5  # [s] across the axis, F̃'s reference follows it this slowly
    # [s] the touch's band widened by the probe's force range over this long (`_swing`); 0: off
    swing_s: float = 0.0
    # ... along the probe too, by the range along it (a contact that comes back fast after the
    # patient moved away reads as F̃ along the probe for as long; False: across only)
    swing_along: bool = False
    blend_s: float = 0.2  # [s] the hand-back's blend
    # [s] the engagement's blend: the command before the hold, kept, gives way to the hold's over
    # this long while its surface filter settles (0: the hold's at once)
    engage_blend_s: float = 0.0
    # [N] the retake's band along the probe (module docstring); 0: no retake. The clinical study's
    # hold, after a probe check, sets 1 N: F̃·a with nobody's hand read -0.6 to +0.6 N there
    retake_band_N: float = 0.0
    retake_push_s: float = 1.0  # [s] the least push (or pull) beyond it that sets a level
    loss_N: float = 0.5  # [N] probe force under which the contact is lost
    loss_s: float = 0.2  # [s] lost this long: the hold ends
    loss_m: float = 0.003  # [m] ... or the tip moved this far along the axis while lost
    max_travel_m: float = 0.03  # [m] the farthest the hold moves the tip along the axis
    max_speed: float = 0.05  # [m/s] the hold's own speed limit (breathing needs about 0.02)

    def __post_init__(self) -> None:
        object.__setattr__(
            self, "raw_band_N", as_nonnegative_vector(self.raw_band_N, 3, "raw_band_N")
        )
        if self.force_source not in FORCE_SOURCES:
            raise ConfigError(
                f"force_source: expected one of {', '.join(FORCE_SOURCES)}, "
                f"got {self.force_source!r}"
            )
        if self.motion not in MOTIONS:
            raise ConfigError(f"motion: expected one of {', '.join(MOTIONS)}, got {self.motion!r}")
        object.__setattr__(
            self,
            "normal_max_deg",
            as_scalar(self.normal_max_deg, "normal_max_deg", low=0.0, high=90.0),
        )
        for name in (
            "ki",
            "lookahead_s",
            "latency_s",
            "share_band_N",
            "share_event_s",
            "share_rest_s",
            "share_min_N",
            "engage_s",
            "engage_still_m",
            "settle_s",
            "confirm_s",
            "blend_s",
            "engage_blend_s",
            "swing_s",
            "retake_band_N",
            "loss_s",
        ):
            object.__setattr__(self, name, as_scalar(getattr(self, name), name, low=0.0))
        for name in (
            "stiffness_N_m",
            "force_noise_N",
            "observer_hz",
            "position_gain",
            "window_s",
            "normal_tau_s",
            "touch_tau_s",
            "share_window_s",
            "share_filter_s",
            "retake_push_s",
            "ramp_N_s",
            "contact_N",
            "axial_band_N",
            "loss_N",
            "loss_m",
            "max_travel_m",
            "max_speed",
        ):
            object.__setattr__(
                self, name, as_scalar(getattr(self, name), name, low=0.0, low_open=True)
            )
        object.__setattr__(
            self,
            "max_force_N",
            as_scalar(self.max_force_N, "max_force_N", low=self.contact_N),
        )
        object.__setattr__(
            self, "reengage_factor", as_scalar(self.reengage_factor, "reengage_factor", low=1.0)
        )


def surface_observer_gain(params: HoldParams, dt: float) -> Vec:
    """The steady-state gain K (3) of the surface filter: a constant-acceleration Kalman filter
    stepped and corrected every `dt`, measurement variance r = (force_noise_N / k̂)², the
    acceleration's white noise q = ω_n⁶ r dt (ω_n = 2π observer_hz: the continuous filter's
    bandwidth for a measurement noise density r dt). K = P Hᵀ / (H P Hᵀ + r), P the predicted
    covariance's fixed point (the discrete algebraic Riccati equation, scipy's solver: under a
    millisecond, against tens for the recursion iterated, which must not run inside a robot's
    cycle); kept per (noise, stiffness, bandwidth, dt), and `ContactHold.prepare` computes it before
    a session's loop."""
    return np.array(
        _gain(params.force_noise_N, params.stiffness_N_m, params.observer_hz, float(dt))
    )


def surface_filter_gain(hz: float, dt: float) -> tuple[float, ...]:
    """The steady-state gain of `surface_observer_gain`'s filter for a bandwidth `hz` and a step
    `dt`. It does not depend on the noise's size or the stiffness: q and r scale together."""
    return _gain(1.0, 1.0, hz, float(dt))


@functools.lru_cache(maxsize=64)
def _gain(noise_N: float, stiffness_N_m: float, hz: float, dt: float) -> tuple[float, ...]:
    from scipy.linalg import solve_discrete_are

    r = (noise_N / stiffness_N_m) ** 2
    q = (2.0 * math.pi * hz) ** 6 * r * dt
    F = np.array([[1.0, dt, 0.5 * dt * dt], [0.0, 1.0, dt], [0.0, 0.0, 1.0]])
    # filterpy's discrete white-noise model, as hoh_cosim.control.kalman's
    white = np.array(
        [
            [0.25 * dt**4, 0.5 * dt**3, 0.5 * dt**2],
            [0.5 * dt**3, dt**2, dt],
            [0.5 * dt**2, dt, 1.0],
        ]
    )
    # P = F P Fᵀ - F P Hᵀ (H P Hᵀ + r)⁻¹ H P Fᵀ + Q, H = [1 0 0]: the dual (filter) form
    P = solve_discrete_are(F.T, np.array([[1.0], [0.0], [0.0]]), (q * dt) * white, np.array([[r]]))
    return tuple((P[:, 0] / (P[0, 0] + r)).tolist())


def _split_norm(F: Vec3, axis: Vec3, band: Vec3, axial_band: float) -> float:
    """max(‖F_⊥ ⊘ b‖, |F·a| / b_a): F's size against the quiet band, across and along the axis."""
    f0, f1, f2 = F.tolist()
    a0, a1, a2 = axis.tolist()
    along = f0 * a0 + f1 * a1 + f2 * a2
    across = np.array((f0 - along * a0, f1 - along * a1, f2 - along * a2))
    return max(scaled_norm(across, band), abs(along) / axial_band)


class HandShare:
    """ĥ, the hand's share of the wrist's axial force: what the combined force c = c_w + ĥ adds to
    the wrist's packet c_w for the contact (module docstring, "which force").

    d = c_p - c_w, the probe's axial force less the wrist's, is the hand's push plus the probe
    sensor's error (its play, its gain error times the contact force, its noise). A hand opening
    on the handle or taking it moves d by newtons in a tenth of a second; the probe's play, where
    the breath turns the contact force about, by up to about 1 N. So (d low-passed over
    `share_filter_s`, against its values over the last `share_window_s`):

        event    d's range over the window passes `share_band_N`: ĥ takes d's change from the
                 window's start at once, then each tick's, for `share_event_s` at most; one event
                 each way (d rising: a push; falling: a hand opening) per hold, none within
                 `share_rest_s` of the last one's end
        undone   an event that ends (d's range back under the band) having moved ĥ by less than
                 `share_min_N` is taken back: the probe's play, not a hand, and that way is free
                 again
        else     ĥ holds: the wrist's packet, free of the play, regulates the contact
    """

    def __init__(self, params: HoldParams) -> None:
        self.params = params
        self.reset(0.0)

    def reset(self, share: float) -> None:
        self.share = share  # ĥ [N]
        self._d_f = share
        self._window: deque[tuple[float, float]] = deque()  # (t, d low-passed)
        self._t0: float | None = None  # when d began to move past the band
        self._following = False  # ... and ĥ follows it
        self._total = 0.0  # what this event moved ĥ by
        self._sign = 0
        self._ways: set[int] = set()  # the ways an event has moved ĥ in this hold
        self._end = -math.inf  # when the last followed event ended

    def step(self, t: float, dt: float, d: float) -> None:
        p = self.params
        d_f = self._d_f + (d - self._d_f) * min(dt / p.share_filter_s, 1.0)
        window = self._window
        window.append((t, d_f))
        while t - window[0][0] > p.share_window_s + 1e-9:
            window.popleft()
        values = [x for _, x in window]
        moving = max(values) - min(values) > p.share_band_N
        if moving and self._t0 is None:
            self._t0 = t
            change = d_f - window[0][1]
            self._sign = 1 if change > 0.0 else -1
            self._following = (
                t - self._end >= p.share_rest_s - 1e-9 and self._sign not in self._ways
            )
            if self._following:
                self._ways.add(self._sign)
                self.share += change
                self._total = change
        elif moving and self._following and t - self._t0 < p.share_event_s - 1e-9:
            self.share += d_f - self._d_f
            self._total += d_f - self._d_f
        elif not moving and self._t0 is not None:
            self._t0 = None
            if self._following:
                self._following = False
                self._end = t
                if abs(self._total) < p.share_min_N:  # the play, not a hand: undone
                    self.share -= self._total
                    self._ways.discard(self._sign)
        self._d_f = d_f


class ContactHold:
    """The hold's state machine and its force law (module docstring), stepped by the controller."""

    def __init__(self, params: HoldParams | None = None) -> None:
        self.params = params or HoldParams()
        self._gain_key: tuple[int, float] | None = None
        self._gain = np.zeros(3)
        self.reset()

    def reset(self) -> None:
        self.phase = HoldPhase.OFF
        self.setpoint_N = 0.0  # c_ref now
        self.target_N = 0.0  # where c_ref is going: the level before the engagement
        self.force_N = 0.0  # the regulated force, last tick
        self.ended = HoldEnd.NONE  # why the last hold ended
        self.holds = 0  # holds begun since the reset
        self.blend = 0.0  # β: 0 while holding, rising to 1 while handing back
        self._window: deque[tuple[float, float]] | None = None  # the probe's axial force
        self._window_sum = 0.0
        self._quiet_since: float | None = None
        self._contact_since: float | None = None
        self._surface = [0.0, 0.0, 0.0]  # ŝ, ṡ, s̈ along the line
        self._integral = 0.0  # [m] ∫ (c_ref - c) / k̂ dt
        self._axis = np.zeros(3)
        self._line = np.zeros(3)  # the line the tip moves along (`motion`)
        self._normal = np.zeros(3)  # the contact's pressing force, low-passed (`motion` normal)
        self._F0 = np.zeros(3)  # F̃ at the engagement
        self._low = [0.0, 0.0]
        self._ref = [np.zeros(3), np.zeros(3)]
        self._p0 = 0.0  # the tip along the line at the engagement
        self._touch_since: float | None = None
        self._t_back: float | None = None
        self._lost_since: float | None = None
        self._lost_at = 0.0  # the tip along the line when the contact was lost
        self._band_key: tuple[int, int] | None = None
        self._band_value = np.zeros(3)
        self._history: deque[tuple[float, float]] = deque()  # (t, z) of the last ticks
        self._turned = 0.0  # [m] what the line's turns moved z by since the engagement
        self._recent: deque[tuple[float, float, float, float]] = deque()  # (t, F_probe_B)
        self._pushes: deque[tuple[float, float]] = deque()  # (t, probe's axial force), held
        self._push = (0.0, 0.0)  # (start, end) of the hand's last push beyond the retake band
        self._pushing_since: float | None = None
        self._still_since: float | None = None
        self._hand = HandShare(self.params)  # ĥ, the hand's share (force_source combined)
        self._listening = False  # the retake listens this tick (the tick began holding)
        self._touched_at: float | None = None  # the tick of a touch, on that tick
        self._n = 0.0  # the touch's size this tick (`_touch`), for the line's following
        self._t_engaged = -math.inf  # when the hold began, and the command before it
        self._v_before = np.zeros(3)

    @property
    def active(self) -> bool:
        return self.phase != HoldPhase.OFF

    @property
    def line(self) -> Vec3:
        """The unit vector the tip moves along while held (`motion`), in the base frame."""
        return self._line.copy()

    def _band(self, deadband: Vec3) -> Vec3:
        """b = max(η, raw_band_N), kept while η and the parameters stay the same objects."""
        key = (id(deadband), id(self.params))
        if self._band_key != key:
            self._band_key, self._band_value = key, np.maximum(deadband, self.params.raw_band_N)
            self._band_of = (deadband, self.params)  # keeps the ids valid
        return self._band_value

    def prepare(self, dt: float) -> None:
        """Compute the surface filter's gain for a step of `dt` now, before a robot's loop, so
        that no cycle pays for it (an engagement would otherwise)."""
        self._observer_gain(dt)

    def _observer_gain(self, dt: float) -> list[float]:
        key = (id(self.params), dt)
        if self._gain_key != key:
            self._gain_key, self._gain = key, surface_observer_gain(self.params, dt)
            self._gain_of = self.params  # keeps the id valid
        return self._gain.tolist()

    def regulated(
        self,
        F_meas_B: Vec3 | None,
        F_probe_B: Vec3,
        axis_B: Vec3,
        F_probe_meas_B: Vec3 | None = None,
        t: float | None = None,
        dt: float = 0.0,
    ) -> tuple[float, bool]:
        """(c, from the probe): the axial contact force the hold regulates, pressing positive (the
        phantom pushes the probe back along -a, so c = -F·a), `force_source` (module docstring):
        combined c = c_w + ĥ, wrist c_w, probe c_p; the probe's newest packet where it is wired
        (exactly zero: not wired), else its filtered estimate; the wrist's newest packet, else the
        probe's. The flag says whether the newest packet's age is the probe's."""
        p = self.params
        if F_probe_meas_B is not None and F_probe_meas_B.any():
            c_p = -float(F_probe_meas_B.dot(axis_B))
        else:
            c_p = -float(F_probe_B.dot(axis_B))
        if F_meas_B is None or p.force_source == "probe":
            return c_p, True
        c_w = -float(F_meas_B.dot(axis_B))
        if p.force_source == "wrist":
            return c_w, False
        # c = c_w + ĥ: the wrist's packet, plus the hand's share as the two sensors' difference
        # tells it at a hand's event (`HandShare`)
        if t is not None:
            self._hand.step(t, dt, c_p - c_w)
        return c_w + self._hand.share, False

    def _delayed(self, t: float, z: float, age: float) -> float:
        """The tip along the line when the regulated packet was sampled (`age` after its arrival,
        `latency_s` before it), from the positions of the last ticks: the force and the position
        the surface estimate combines must be of the same instant (module docstring). The history
        holds z less the line's turns so far (`_turned`), which the answer adds back."""
        history = self._history
        turned = self._turned
        history.append((t, z - turned))
        keep_span(history, t, _HISTORY_S)
        return turned + sample_at(history, t - age - self.params.latency_s)

    def watch(
        self,
        t: float,
        F: Vec3,
        deadband: Vec3,
        axis_B: Vec3,
        F_probe_B: Vec3,
        released_in_contact: bool,
        moved_m: float = 0.0,
    ) -> bool:
        """While off: whether to engage now (module docstring): a release in contact, or the hand
        quiet (F̃ inside the quiet band, and with `engage_still_m` the probe kept within it across
        its axis: `moved_m` over the last `engage_s`) in contact for `engage_s`. Keeps the
        setpoint's window."""
        p = self.params
        contact = float(F_probe_B.dot(F_probe_B)) > p.contact_N * p.contact_N
        if not contact or not axis_B.any():
            self._quiet_since = self._contact_since = None
            self._window = None
            return False
        self._observe(t, -float(F_probe_B.dot(axis_B)))
        if self._contact_since is None:
            self._contact_since = t
        if t - self._contact_since < p.settle_s - 1e-9:  # a touch-down's bounce is no release
            return False
        if released_in_contact:
            return True
        if (0.0 < p.engage_still_m < moved_m) or _split_norm(
            F, axis_B, self._band(deadband), p.axial_band_N
        ) > 1.0:
            self._quiet_since = None
            return False
        if self._quiet_since is None:
            self._quiet_since = t
        return t - self._quiet_since >= p.engage_s - 1e-9

    def _observe(self, t: float, c_probe: float) -> None:
        """One tick of the setpoint's window (the probe's axial force in contact)."""
        window = self._window
        if window is None:
            self._window = window = deque()
            self._window_sum = 0.0
        window.append((t, c_probe))
        self._window_sum += c_probe
        while t - window[0][0] >= self.params.window_s - 1e-9:
            self._window_sum -= window.popleft()[1]

    def engage(
        self,
        t: float,
        F: Vec3,
        F_meas_B: Vec3 | None,
        F_probe_B: Vec3,
        axis_B: Vec3,
        p_BT_B: Vec3,
        v_prev: Vec3,
        F_probe_meas_B: Vec3 | None = None,
        keep_level: bool = False,
    ) -> None:
        """Begin a hold: the setpoint starts at the regulated force now and moves to the level
        before it (`keep_level`: the last hold's level, as after the contact's recovery); the
        surface filter starts where the tip is, at its last commanded speed along the axis (no
        step in the command)."""
        p = self.params
        self._axis = axis_B.copy()
        if F_meas_B is not None:  # ĥ starts at the two sensors' difference now: c = c_p
            c_w = -float(F_meas_B.dot(axis_B))
            F_p = (
                F_probe_meas_B if F_probe_meas_B is not None and F_probe_meas_B.any() else F_probe_B
            )
            self._hand = HandShare(p)
            self._hand.reset(-float(F_p.dot(axis_B)) - c_w)
        c, _ = self.regulated(F_meas_B, F_probe_B, axis_B, F_probe_meas_B)
        level = c if not self._window else self._window_sum / len(self._window)
        if keep_level and self.holds:
            level = self.target_N
        self.target_N = min(max(level, p.contact_N), p.max_force_N)
        self.setpoint_N = c
        self.force_N = c
        self._window = None
        self._line = axis_B.copy()
        self._normal = c * axis_B
        z = float(p_BT_B.dot(axis_B))
        self._surface = [z, float(v_prev.dot(axis_B)), 0.0]
        self._history = deque([(t, z)])
        self._turned = 0.0
        self._recent = deque()
        self._integral = 0.0
        self._F0 = F.copy()
        self._low = [float(F.dot(axis_B))] * 2  # the lowest F̃·a since, filtered and raw
        across0 = F - float(F.dot(axis_B)) * axis_B
        self._ref = [across0, across0.copy()]  # F̃ across the axis, followed slowly
        self._p0 = z
        self._touch_since = self._t_back = self._lost_since = None
        self._quiet_since = None
        self._pushes = deque()
        self._push = (t, t)
        self._pushing_since, self._still_since = None, t
        self.blend = 0.0
        self.phase = HoldPhase.HOLDING
        self.ended = HoldEnd.NONE
        self.holds += 1
        self._t_engaged, self._v_before = t, v_prev.copy()

    def stop(self) -> None:
        """The controller commanded zero (a stop flag): a hold in progress ends (STOPPED), and
        everything it was watching starts again."""
        holds, was = self.holds, self.active
        self.reset()
        self.holds = holds
        if was:
            self.ended = HoldEnd.STOPPED

    def _touch(
        self, dt: float, F: Vec3, a: Vec3, band: Vec3, which: int, axial: float | None = None
    ) -> float:
        """F̃'s departure against the quiet band (> 1: a touch), module docstring.

        `wrist`: F̃ away from its value at the engagement and from nothing (the hand opening, F̃
        falling from its value at the engagement to nothing, is no touch). `combined` (the robot
        no longer yields to the hand's push, and the probe sensor's misreading makes F̃ with
        nobody's hand nonzero: about a quarter of the contact force along the axis in the
        simulated housing): along the axis a push, F̃·a above the lowest it has been since the
        engagement; across it, a departure from a reference and from nothing. The reference
        follows F̃ with `touch_tau_s` (slow changes are the contact's: the misreading across the
        axis grows with the force the hold keeps through the breaths) but stays within one band
        of F̃ at the engagement, so that a hand pushing slowly sideways is heard once it pushes
        two bands. `which`: 0 the filtered F̃, 1 the raw one; `axial` the band along the axis
        (default `axial_band_N`)."""
        p = self.params
        axial = p.axial_band_N if axial is None else axial
        if p.force_source != "combined":
            return min(
                _split_norm(F - self._F0, a, band, axial),
                _split_norm(F, a, band, axial),
            )
        along = float(F.dot(a))
        low = self._low[which] = min(self._low[which], along)
        across = F - along * a
        ref = self._ref[which]
        n_across = min(scaled_norm(across - ref, band), scaled_norm(across, band))
        ref = ref + (across - ref) * min(dt / p.touch_tau_s, 1.0)
        F0 = self._F0 - float(self._F0.dot(a)) * a
        self._ref[which] = np.minimum(np.maximum(ref, F0 - band), F0 + band)
        return max(n_across, (along - low) / axial)

    def _retake(self, t: float, push: float, c_probe: float) -> None:
        """One tick of the retake (module docstring): `push` F̃·a, `c_probe` the probe's axial
        force."""
        p = self.params
        pushes = self._pushes
        pushes.append((t, c_probe))
        while t - pushes[0][0] > p.window_s + p.engage_s + 0.5:
            pushes.popleft()
        if abs(push) > p.retake_band_N:
            if self._pushing_since is None:
                start, end = self._push
                # still for less than engage_s in between: the same push (a hand opening
                # crosses the band and its filters' lag takes F̃ out again for 0.2 s)
                self._pushing_since = start if end > start and t - end < p.engage_s else t
            self._still_since = None
            return
        if self._still_since is None:
            self._still_since = t
            if self._pushing_since is not None:
                self._push = (self._pushing_since, t)
            self._pushing_since = None
        start, end = self._push
        if end - start >= p.retake_push_s - 1e-9 and t - self._still_since >= p.engage_s - 1e-9:
            since = max(start, end - p.window_s)
            values = [c for when, c in pushes if since <= when < end]
            if values:
                level = sum(values) / len(values)
                self.target_N = min(max(level, p.contact_N), p.max_force_N)
            self._push = (t, t)

    def _follow_normal(
        self, dt: float, touch: float, F: Vec3, F_meas_B: Vec3, p_BT_B: Vec3
    ) -> None:
        """`motion` normal: the line follows the contact's direction, the wrist's force (the
        contact alone with nobody's hand) low-passed over `normal_tau_s`, starting from the axis,
        while no hand touches: `touch` (`_touch`) at most one band, and F̃ along the axis inside
        the retake's band where there is one (a hand pushing on along the probe). Moving along
        the axis where the surface's normal differs slides the probe over the skin at every
        breath, and friction flips along the axis at each breath's turn; over several breaths it
        cancels, and the mean is the normal (docs/decisions/0053-hold-along-surface-normal.md). The
        surface filter's state, the tip's history and the guards' origins (the travel's, and the
        lost contact's) move to the new line with it."""
        p = self.params
        if touch > 1.0 or (0.0 < p.retake_band_N < abs(float(F.dot(self._axis)))):
            return
        w = min(dt / p.normal_tau_s, 1.0)
        self._normal = normal = self._normal - w * (F_meas_B + self._normal)
        size = float(np.linalg.norm(normal))
        if size < p.contact_N:
            return
        line = normal / size
        if float(line.dot(self._axis)) < math.cos(math.radians(p.normal_max_deg)):
            return
        # the same tip, measured along the new line: shift what is kept along the old one
        old = self._line
        shift = float(p_BT_B.dot(line)) - float(p_BT_B.dot(old))
        s, s_dot, s_ddot = self._surface
        self._surface = [s + shift, s_dot, s_ddot]
        self._turned += shift
        self._p0 += shift
        self._lost_at += shift
        self._line = line

    def _swing(self, t: float, F_probe_B: Vec3) -> Vec3:
        """The range of the probe's force, per base axis, over the last `swing_s`. Under the hold
        a hand on the handle pushes the robot, not the contact, so the probe sensor's reading
        moves only with the contact. F̃ is the wrist's force less the probe's, whose estimate
        lags the wrist's by about 60 ms: a contact that swings fast (friction turning over as a
        hand lets go) reads as F̃ of about that swing for as long (2.3 N across for 0.15 s on a
        view, docs/decisions/0053-hold-along-surface-normal.md), which a touch must
        exceed."""
        recent = self._recent
        recent.append((t, *F_probe_B.tolist()))
        while t - recent[0][0] > self.params.swing_s + 1e-9:
            recent.popleft()
        return np.array(
            [max(row[i] for row in recent) - min(row[i] for row in recent) for i in (1, 2, 3)]
        )

    def _end(self, why: HoldEnd) -> None:
        self.phase = HoldPhase.OFF
        self.ended = why
        self.blend = 0.0
        self._quiet_since = None

    def _law(self, dt: float, c: float, z: float, z_d: float, delay: float) -> float:
        """The hold's speed along the axis (module docstring)."""
        p = self.params
        k = p.stiffness_N_m
        # the setpoint on its way to the level before the engagement
        step = p.ramp_N_s * dt
        self.setpoint_N += min(max(self.target_N - self.setpoint_N, -step), step)
        e = self.setpoint_N - c
        # m = z - (c - c_ref) / k̂: where the tip must be; the surface filter predicts, corrects
        m = z_d + e / k
        s, s_dot, s_ddot = self._surface
        s, s_dot = s + dt * s_dot + 0.5 * dt * dt * s_ddot, s_dot + dt * s_ddot
        k0, k1, k2 = self._observer_gain(dt)
        innovation = m - s
        s, s_dot, s_ddot = s + k0 * innovation, s_dot + k1 * innovation, s_ddot + k2 * innovation
        self._surface = [s, s_dot, s_ddot]
        # u = ṡ_τ + k_z (s_τ - z) + k_i ∫ e / k̂ dt, the filter's state τ ahead
        tau = p.lookahead_s + delay
        s_ahead = s + tau * s_dot + 0.5 * tau * tau * s_ddot
        u = s_dot + tau * s_ddot + p.position_gain * (s_ahead - z) + p.ki * self._integral
        limit = p.max_speed
        # integrate unless the command is at the hold's speed limit and the error drives it on
        if not ((u >= limit and e > 0.0) or (u <= -limit and e < 0.0)):
            self._integral += e / k * dt
        return min(max(u, -limit), limit)

    def guard(self, t: float, p_BT_B: Vec3, F_probe_B: Vec3) -> HoldEnd | None:
        """The guards of an active hold, first on each of its ticks (module docstring): the
        contact lost (`loss_N` for `loss_s`, or while the tip moved `loss_m`) or the tip
        `max_travel_m` from where the hold began along its line end it (`ended` says why, and so
        does the answer); None: it goes on."""
        p = self.params
        z = float(p_BT_B.dot(self._line))
        if float(F_probe_B.dot(F_probe_B)) < p.loss_N * p.loss_N:
            if self._lost_since is None:
                self._lost_since, self._lost_at = t, z
            elif t - self._lost_since >= p.loss_s - 1e-9 or abs(z - self._lost_at) >= p.loss_m:
                self._end(HoldEnd.CONTACT_LOST)
                return HoldEnd.CONTACT_LOST
        else:
            self._lost_since = None
        if abs(z - self._p0) >= p.max_travel_m:
            self._end(HoldEnd.TRAVEL)
            return HoldEnd.TRAVEL
        # the retake listens while the tick began holding (a touch this tick ends it after)
        self._listening = self.phase == HoldPhase.HOLDING
        self._touched_at = None
        return None

    def blended(self, t: float) -> bool:
        """While handing back: β = (t - t_touch) / `blend_s`; True once the blend is over, and
        the hold ended (HANDED_BACK): the law has the robot again."""
        p = self.params
        assert self._t_back is not None
        beta = 1.0 if p.blend_s <= 0.0 else (t - self._t_back) / p.blend_s
        if beta >= 1.0 - 1e-9:
            self._end(HoldEnd.HANDED_BACK)
            return True
        self.blend = beta
        return False

    def touched(
        self, t: float, dt: float, F: Vec3, F_raw: Vec3 | None, deadband: Vec3, F_probe_B: Vec3
    ) -> bool:
        """While holding: a touch of the handle (`_touch`), confirmed by the raw packet, firm or
        lasting `confirm_s`; the band across the axis widened by the probe's own swing over the
        last `swing_s` (`_swing`). On a touch the hand-back begins (BLENDING), or with no blend
        (`blend_s` 0) the hold ends at once (HANDED_BACK). `F` and `F_raw` are the compensated
        hand force, filtered and raw."""
        p = self.params
        a = self._axis
        band = self._band(deadband)
        axial = None
        if p.swing_s > 0.0:
            swing = self._swing(t, F_probe_B)
            band = band + swing
            if p.swing_along:
                axial = p.axial_band_N + abs(float(swing.dot(a)))
        n = self._n = self._touch(dt, F, a, band, 0, axial)
        raw = F_raw is None or self._touch(dt, F_raw, a, band, 1, axial) > 1.0
        if n > 1.0 and raw:
            if self._touch_since is None:
                self._touch_since = t
            if n > p.reengage_factor or t - self._touch_since >= p.confirm_s - 1e-9:
                self.phase = HoldPhase.BLENDING
                self._t_back = self._touched_at = t
                if p.blend_s <= 0.0:
                    self._end(HoldEnd.HANDED_BACK)
                return True
        else:
            self._touch_since = None
        return False

    def command(
        self,
        t: float,
        dt: float,
        F: Vec3,
        F_meas_B: Vec3 | None,
        F_probe_B: Vec3,
        p_BT_B: Vec3,
        v_law: Vec3,
        F_probe_meas_B: Vec3 | None = None,
        probe_age: float = 0.0,
        ft_age: float = 0.0,
    ) -> Vec:
        """One tick of an active hold's force law, after its guards and its touch (`guard`,
        `blended`, `touched`): the linear velocity to command. Holding, the law's; handing back,
        (1 - β) v_hold + β `v_law` (the angular one is then β ω_law, rest while holding). `F` is the
        compensated hand force, `F_meas_B` the raw wrist packet (hand and contact, uncompensated)."""
        p = self.params
        a = self._axis
        line = self._line
        z = float(p_BT_B.dot(line))
        c, probe = self.regulated(F_meas_B, F_probe_B, a, F_probe_meas_B, t, dt)
        self.force_N = c
        if p.retake_band_N > 0.0 and self._listening:
            self._retake(t, float(F.dot(a)), -float(F_probe_B.dot(a)))
        age = (probe_age if probe else ft_age) + p.latency_s
        z_d = self._delayed(t, z, age - p.latency_s)
        v_hold = self._law(dt, c, z, z_d, age) * line
        if self.phase == HoldPhase.BLENDING:
            if self._touched_at == t:  # β = 0 on the touch's tick
                return v_hold
            # v = (1 - β) v_hold + β v_law
            beta = self.blend
            return (1.0 - beta) * v_hold + beta * v_law
        if p.motion == "normal" and F_meas_B is not None:
            self._follow_normal(dt, self._n, F, F_meas_B, p_BT_B)
        if p.engage_blend_s > 0.0 and t - self._t_engaged < p.engage_blend_s:
            # v = (1 - γ) v_before + γ v_hold, γ from 0 to 1 since the engagement
            gamma = (t - self._t_engaged) / p.engage_blend_s
            return (1.0 - gamma) * self._v_before + gamma * v_hold
        return v_hold
