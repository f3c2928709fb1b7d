"""Following the breath while the hand steers: the patient's breathing taken out of the contact force.

Eq. 10 moves the probe only where the hand pushes it (seed 000, 3.F.1), and contact compensation
(eq. 11-12) keeps the patient's reaction out of the hand's force (3.F.2). On a breathing patient the
robot therefore holds the probe's depth while the abdomen rises and falls under it: the contact force
swings by the breath's depth times the tissue's stiffness (10 mm on about 1200 N/m is 12 N), and the
hand must steer the probe up and down with every breath to keep its level. Freehand, the hand's own
compliance rides the breath. Hold-on-release (`hoh_cosim.control.hold`) regulates the force once
the hand lets go; this block does the breath's part of that while the hand steers:

    c        the axial contact force, pressing positive: c = -F_probe · a, with a the probe axis
             (handle to tip) and F_probe the estimator's contact-force estimate
    level    c̄, the force the sonographer keeps: c low-passed over `level_s` (about a breath, so the
             breath's swing is not in it); while the hand pushes or pulls along the axis
             (|F̃ · a| > `push_band_N`, F̃ the compensated hand force of eq. 11-12) over
             `push_level_s` instead, so that a deliberate push sets a new level rather than being
             fought. Set to c when the contact begins; kept while it ends, and through a gap in the
             contact shorter than `level_s` (an exhale's trough that lifts the skin off the probe
             is no new contact)
    command  v_f = -β g (c - c̄) / k̂ · a,   |v_f| <= `max_speed`
             added to the law's command along the axis; β goes from 0 to 1 over `blend_s` once
             c > `contact_N` and back to 0 over `release_s` when it falls under it

With the tissue c = k (s - z) (s the surface, z the tip, both along a), ċ = k ṡ - g (k / k̂) (c - c̄):
for a level that did not move, the breath's force swing k ṡ would pass through a first-order
high-pass at ω_c = g k / k̂, leaving ω / √(ω² + ω_c²) of it at the breath's angular frequency ω
(about 0.4-0.6 at 12-20 breaths a minute for g = 3 /s and k̂ = k; 0.6-0.8 for the default 1.5 /s,
which leaves the breath's part to the feed-forward below). With the level's low-pass (τ =
`level_s`) it is |1 + jωτ| / |1 + ω_c τ + jωτ|, a little less (0.44 against 0.46 at 15 a minute for
3 /s): the level's corner, 1 / τ, is well under the breath. The probe force's noise reaches the tip
through g / k̂ = 0.00125 m/(s·N), a tenth of eq. 10's slope, and only in contact. A k̂ off by a
factor ρ = k / k̂ scales ω_c by ρ; the loop is one integrator and stays stable for any ρ > 0 while
ω_c is well under the sensors' and the robot's delays' corner (about 25 rad/s for 40 ms).

The loop above leaves half of the breath's swing in the contact or more, and a faster g passes
more of the probe force's noise to the tip. The surface's own motion is fed forward besides
(`surface_gain` κ > 0), as the hold estimates it (`hoh_cosim.control.hold`):

    m        z_d + c_s / k̂: where the surface is along the probe, outward. z_d = -p_BT · a, the tip
             when the wrist's newest packet was sampled (its age and `latency_s` back); c_s = c_w +
             ĥ, c_w the axial force in that packet (hand and contact: the wrist has no play), ĥ the
             hand's share along the axis, the probe packet's axial force less c_w low-passed over
             `share_s`. A slow push is in ĥ and not in m; the play in the probe sensor's housing
             (seed 3.B.2, 0.2-0.8 N per axis), which hides a contact that no longer changes, is in
             m only through ĥ
    ŝ, ṡ     a constant-acceleration filter on m, stepped and corrected every tick with the
             steady-state gain of bandwidth `surface_hz` (the breath's harmonics are under 1 Hz)
    command  v_f = -β (g (c - c̄) / k̂ + κ ṡ) · a

With k̂ = k, m does not depend on the robot, and κ = 1 would take the whole breath out. But where
the signal m gives moves with the tip (a probe packet inside the play, a quick push of the hand
that ĥ has not taken yet), the feed-forward is the robot's own speed fed back: a loop of gain κ,
which must stay under 1. With both, 0.375 of the breath's swing is left at 15 a minute (0.34-0.41
at 12-20; g = 3 /s alone left 0.44). Measured on the clinical study's runs
(docs/decisions/0059-follow-surface-feed-forward.md): with κ = 0.4 and g = 1.5 /s the image is
steadier than with g = 3 /s alone and the contact's std lower; a larger κ or g steadies the contact
more and the image less.

The follow moves the probe by itself, so it is bounded like the hold: its command since the
contact began (a gap shorter than `level_s` is the same contact), or since the hand last pushed
along the axis or steered the tip across it faster than `steer_speed` over the last 0.1 s (the
hand is moving the probe then, and the pose is its own), is kept within `max_travel_m` (more than
a deep breath's 15 mm); its speed within `max_speed`; the
supervisor's limits (speed, acceleration, soft force cap, workspace, stops) apply after it as to
every command; it never acts out of contact, while the release detector brakes, or while the hold
holds. Without contact compensation F̃ holds the contact too, reads as a push, and the level follows
c at once: the follow then does nothing. Off by default (docs/decisions/0055-follow-the-breath.md).
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from hoh_cosim.control.history import keep_span, sample_at
from hoh_cosim.control.hold import surface_filter_gain
from hoh_cosim.control.vectors import Vec3, as_scalar
from hoh_cosim.errors import ConfigError

__all__ = ["BreathFollower", "FollowParams"]


@dataclass(frozen=True)
class FollowParams:
    """Following the breath while the hand steers (module docstring)."""

    UNITS: ClassVar[dict[str, Any]] = {
        "gain_per_s": "1/s",
        "stiffness_N_m": "N/m",
        "level_s": "s",
        "push_level_s": "s",
        "push_band_N": "N",
        "contact_N": "N",
        "blend_s": "s",
        "release_s": "s",
        "max_speed": "m/s",
        "max_travel_m": "m",
        "surface_gain": "1",
        "surface_hz": "Hz",
        "share_s": "s",
        "latency_s": "s",
        "steer_speed": "m/s",
    }

    enabled: bool = False
    gain_per_s: float = 1.5  # g [1/s]: the high-pass's corner with k̂ = k
    stiffness_N_m: float = 1200.0  # k̂ [N/m], as the hold's
    level_s: float = 4.0  # [s] the level's low-pass: about a breath at 15 a minute
    push_level_s: float = 0.1  # [s] ... while the hand pushes along the axis
    push_band_N: float = 1.0  # [N] |F̃ · a| above this is the hand's push (the hold's retake band)
    contact_N: float = 3.0  # [N] the probe force above which the breath is followed
    blend_s: float = 0.5  # [s] the follow's way in once the contact begins
    release_s: float = 0.1  # [s] ... and out once it ends
    max_speed: float = 0.03  # [m/s] the follow's own speed limit (a deep fast breath needs 0.02)
    max_travel_m: float = 0.02  # [m] the farthest the follow moves the tip by itself
    surface_gain: float = 0.4  # κ: the surface's estimated speed fed forward (0: none; under 1)
    surface_hz: float = 1.0  # [Hz] the surface filter's bandwidth
    share_s: float = 4.0  # [s] the hand's share along the axis, low-passed over this
    latency_s: float = 0.002  # [s] a wrist packet's sample to its arrival (as the hold's)
    steer_speed: float = 0.002  # [m/s] the tip faster across the probe: the hand steers it

    def __post_init__(self) -> None:
        for name in (
            "gain_per_s",
            "stiffness_N_m",
            "level_s",
            "push_level_s",
            "push_band_N",
            "contact_N",
            "blend_s",
            "release_s",
            "max_speed",
            "max_travel_m",
            "surface_hz",
            "share_s",
            "steer_speed",
        ):
            object.__setattr__(
                self, name, as_scalar(getattr(self, name), name, low=0.0, low_open=True)
            )
        object.__setattr__(self, "latency_s", as_scalar(self.latency_s, "latency_s", low=0.0))
        gain = as_scalar(self.surface_gain, "surface_gain", low=0.0)
        if gain >= 1.0:
            raise ConfigError(
                f"surface_gain must be < 1.0 (the feed-forward's loop gain where the probe "
                f"sensor's play hides the contact), got {gain}"
            )
        object.__setattr__(self, "surface_gain", gain)


class BreathFollower:
    """The follow of the module docstring, one controller tick at a time, in floats."""

    def __init__(self, params: FollowParams | None = None) -> None:
        self.params = params or FollowParams()
        self.reset()

    def reset(self) -> None:
        self.level_N = 0.0  # c̄
        self.blend = 0.0  # β
        self.travel_m = 0.0  # the follow's own command integrated since its origin
        self._contact = False
        self._gap_s = math.inf  # how long the contact has been lost (inf: no level to keep)
        self.surface_m_s = 0.0  # ṡ, the surface's estimated speed outward along the axis
        self._surface: list[float] | None = None  # [ŝ, ṡ, s̈] while in contact, else None
        self.share_N = 0.0  # ĥ: the hand's share along the axis
        self._tips: deque[tuple[float, Vec3]] = deque()  # (t, p_BT) of the last ticks

    @property
    def active(self) -> bool:
        """The follow is in the command (β > 0)."""
        return self.blend > 0.0

    def stop(self) -> None:
        """Out of the command at once (a stop, a brake, a hold): the next contact starts afresh."""
        self.reset()

    def prepare(self, dt: float) -> None:
        """Compute the surface filter's gain for a step of `dt` now, before a robot's loop (also
        with `surface_gain` 0: it may be tuned on in the loop)."""
        surface_filter_gain(self.params.surface_hz, dt)

    def step(
        self,
        dt: float,
        F_tilde: Vec3,
        F_probe: Vec3,
        axis: Vec3,
        t: float | None = None,
        p_BT: Vec3 | None = None,
        F_wrist_meas: Vec3 | None = None,
        F_probe_meas: Vec3 | None = None,
        ft_age: float = 0.0,
    ) -> Vec3 | None:
        """The follow's velocity along `axis` for this tick (in B), or None while it is out.
        F_tilde: the compensated hand force; F_probe: the contact-force estimate; both in B. For
        the surface's feed-forward (`surface_gain` > 0) also the time `t`, the measured tip `p_BT`
        and the newest packets: the wrist's gravity-compensated force `F_wrist_meas` (hand and
        contact; without it F_tilde + F_probe), `ft_age` since its arrival, the probe's
        `F_probe_meas` (without it F_probe). Without `t` and `p_BT`: no feed-forward."""
        p = self.params
        a0, a1, a2 = axis.tolist()
        f0, f1, f2 = F_probe.tolist()
        c = -(f0 * a0 + f1 * a1 + f2 * a2)
        steering = False
        if t is not None and p_BT is not None:
            tips = self._tips
            tips.append((t, p_BT.copy()))  # the caller may reuse its array
            keep_span(tips, t, _HISTORY_S)
            steering = self._steered(axis)
        if c > p.contact_N:
            h0, h1, h2 = F_tilde.tolist()
            pushing = abs(h0 * a0 + h1 * a1 + h2 * a2) > p.push_band_N
            if not self._contact:
                self._contact = True
                if self._gap_s > p.level_s:  # a new contact: its own level and origin
                    self.level_N = c
                    self.travel_m = 0.0
                self._gap_s = 0.0
            if pushing or steering:
                self.travel_m = 0.0
            tau = p.push_level_s if pushing else p.level_s
            self.level_N += (c - self.level_N) * min(1.0, dt / tau)
            self.blend = min(1.0, self.blend + dt / p.blend_s)
            if p.surface_gain > 0.0 and t is not None and p_BT is not None:
                self._surface_step(
                    t, dt, c, axis, F_tilde, F_probe, F_wrist_meas, F_probe_meas, ft_age
                )
        else:  # the level kept: what is left of the blend still answers the force's fall
            self._contact = False
            self._gap_s += dt
            self._surface, self.surface_m_s = None, 0.0  # out of contact m is the tip: no surface
            self.blend = max(0.0, self.blend - dt / p.release_s)
            if self.blend == 0.0:
                return None
        u = -self.blend * (
            p.gain_per_s * (c - self.level_N) / p.stiffness_N_m + p.surface_gain * self.surface_m_s
        )
        u = min(max(u, -p.max_speed), p.max_speed)
        if dt > 0.0:  # no farther than max_travel_m from the origin
            reach = min(max(self.travel_m + u * dt, -p.max_travel_m), p.max_travel_m)
            u = (reach - self.travel_m) / dt
            self.travel_m = reach
        return np.array((u * a0, u * a1, u * a2))

    def _steered(self, axis: Vec3) -> bool:
        """Whether the tip moved across the probe's axis faster than `steer_speed` over the
        positions kept (the hand steering it over the skin)."""
        tips = self._tips
        t0, p0 = tips[0]
        t1, p1 = tips[-1]
        if t1 <= t0:
            return False
        d = p1 - p0
        across = d - d.dot(axis) * axis
        return float(across.dot(across)) > (self.params.steer_speed * (t1 - t0)) ** 2

    def _surface_step(
        self,
        t: float,
        dt: float,
        c: float,
        axis: Vec3,
        F_tilde: Vec3,
        F_probe: Vec3,
        F_wrist_meas: Vec3 | None,
        F_probe_meas: Vec3 | None,
        ft_age: float,
    ) -> None:
        """One tick of the surface's estimate in contact (module docstring): ṡ in `surface_m_s`."""
        p = self.params
        if F_wrist_meas is None:
            c_w, age = -float((F_tilde + F_probe).dot(axis)), 0.0
        else:
            c_w, age = -float(F_wrist_meas.dot(axis)), ft_age
        c_p = c if F_probe_meas is None else -float(F_probe_meas.dot(axis))
        x = self._surface
        if x is None:  # the contact begins: the hand's share as it is now
            self.share_N = c_p - c_w
        else:
            self.share_N += (c_p - c_w - self.share_N) * min(1.0, dt / p.share_s)
        z = -float(sample_at(self._tips, t - age - p.latency_s).dot(axis))
        m = z + (c_w + self.share_N) / p.stiffness_N_m
        if x is None:
            x = [m, 0.0, 0.0]
        elif dt > 0.0:
            s, s_dot, s_ddot = x
            s, s_dot = s + dt * s_dot + 0.5 * dt * dt * s_ddot, s_dot + dt * s_ddot
            k0, k1, k2 = surface_filter_gain(p.surface_hz, dt)
            innovation = m - s
            x = [s + k0 * innovation, s_dot + k1 * innovation, s_ddot + k2 * innovation]
        self._surface = x
        self.surface_m_s = x[1]


_HISTORY_S = 0.1  # [s] the tip positions kept to match a wrist packet's age (under 0.02 s)
