"""Release detection: the hand lets go of the handle, and the robot brakes to rest (seed 000, 5.C).

The seed's users felt "inertia" when they let go: the filtered force fell through the deadband of
eq. 10 tens of milliseconds after the hand did, and the command then ramped down at the
acceleration limit. This block tells a release from ordinary steering early and says so; the
controller then commands rest with the braking deceleration (`LimitParams.max_brake_accel`).

Per controller tick, with F̂ the filtered hand force (contact-compensated, eq. 11-12), F_raw the
newest unfiltered packet (compensated the same way), η the deadband of eq. 10 and ‖x‖_η = ‖x ⊘ η‖
(axes with η = 0 left out):

    trend       n = ‖F̂‖_η ,   ṅ = (n - n_prev) / Δt over the last tick,
                ṅ_w = (n - n(t - w)) / w over the last `trend_s` w
    release     guiding  and  ‖F_raw‖_b <= 1  and
                    ( (n + h ṅ_w <= 1  and  ṅ_w <= -ṅ_min)
                      or (‖F̂ - F_raw‖_b >= k_gap  and  ṅ <= -ṅ_min) )
                with b = max(η, raw_band_N) per axis: the raw packet's own noise band, so that a
                narrow deadband does not wait for a quiet packet
                (the newest packet is already back inside that band and the estimate is falling
                fast: it will be inside within the horizon h, or the packet is already k_gap
                noise bands below it: the hand has let go; a light push whose raw packet dips
                into the deadband by noise is not falling fast, and no noise puts a packet of a
                firm push k_gap > 1 bands away from the estimate)
    hold        released: the command is rest until a push that grows (ṅ > 0) and that the raw
                packet confirms above its noise band (‖F_raw‖_b > 1) is either firm, n > k_re
                (re-engage at once), or
                outside the deadband, n > 1, after hold_s: neither the estimate still falling
                after the release nor the filter's undershoot, which falls back towards zero,
                moves the robot again

The trend of the estimate is the "release detection" of the literature on variable admittance
(Lecours, Mayer-St-Onge and Gosselin, ICRA 2012: the operator's intent read from the sign of the
acceleration of the motion they ask for: decelerating means stopping); here the force's own fall,
confirmed by the raw packet, decides before the filtered force reaches the deadband.

Why the gap. The filters follow a step in a few tens of milliseconds (`lead_lowpass`: a 47 ms time
constant), so one controller period after the first packet that shows the release the estimate of
a 5 N push has fallen by about 6 %, and the horizon alone waits one or two more periods (8 ms each
on a CB3, the tip at 5 cm/s: 0.4 mm each). The packet itself is the evidence: back inside its
noise band while the estimate is k_gap = 3 bands (3.5 N on x) further out is more than the
sensor's noise (at most one band) and the estimate's lag of a hand's steering (a hand's force
changes at under 10 Hz) make together; it is a release, or the hand easing off so fast that braking
to rest is what it asks for.

Why the horizon's trend is taken over 40 ms. The estimate moves at each packet by the filter's
gain times the packet's noise, and the controller sees that step within one tick. In contact the
compensated packet carries the probe sensor's error too (0.67 N RMS on x on the clinical study's
scan, against the FT-150's 0.33 N alone), and the estimate of a light push there steps by 0.1-0.2 N
per packet: over one 8 ms tick that is 13-26 deadbands a second, the fall of a let-go. With the
packet inside its band by noise, the hand still pushing, the one-tick trend braked the robot 41
times over the study's twenty hold-mode scans and 659 times over glide's twenty (its pushes are
lighter), and the hold took each brake in contact for a let-go. Over eight packets the steps
average out; a let-go's fall does not (docs/decisions/0058-release-horizon-trend-40-ms.md).
The gap keeps the one-tick trend: a packet k_gap bands below the estimate is itself the evidence,
and a firm push's release is still decided at the first tick after its first packet.

State: the phase (`ReleasePhase`): IDLE (no motion asked), GUIDING (the law commands motion),
RELEASED_AIR or RELEASED_CONTACT (the hand let go with the probe in the air or in contact with the
patient). Both released phases brake to rest; in contact, hold-on-release
(`hoh_cosim.control.hold`, if on) then holds the contact force instead of the position.
"""

from __future__ import annotations

import enum
import math
from collections import deque
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from hoh_cosim.control.history import keep_span
from hoh_cosim.control.vectors import Vec3, as_nonnegative_vector, as_scalar, frozen

__all__ = ["ReleaseDetector", "ReleaseParams", "ReleasePhase", "scaled_norm"]


class ReleasePhase(enum.IntEnum):
    """Where the hand is, as the release detector sees it."""

    IDLE = 0  # no motion asked: the force is inside the deadband
    GUIDING = 1  # the law commands motion
    RELEASED_AIR = 2  # the hand let go, the probe in the air: brake to rest
    RELEASED_CONTACT = 3  # the hand let go with the probe on the patient (hold-on-release, if on)

    @property
    def released(self) -> bool:
        return self >= ReleasePhase.RELEASED_AIR


@dataclass(frozen=True)
class ReleaseParams:
    """When a fall of the hand force counts as letting go, and how the brake lets go again.

    enabled: False keeps the seed's behaviour (the command follows the law down through the
        deadband at the acceleration limit).
    horizon_s: h, how far ahead the estimate's trend is extrapolated.
    min_fall_per_s: ṅ_min [1/s], the fall of ‖F̂‖_η (deadbands per second) that counts as letting
        go: 20/s is a 5 N push on η = 0.95 N gone within a quarter second.
    gap_bands: k_gap, how many noise bands b the raw packet must lie from the estimate to tell a
        release before the estimate's trend does.
    trend_s: w, the span over which the horizon's trend ṅ_w is taken (0: the last tick alone).
    hold_s: how long the brake holds unless a firm push (‖F̂‖_η > reengage_factor) comes.
    reengage_factor: k_re, a push this many deadbands strong ends the hold at once.
    contact_threshold_N: probe contact force above which a release is RELEASED_CONTACT.
    in_contact: False: the detector listens while the hand guides in the air only (the controller's
        mode FREE); in contact a let-go is the hold's to tell (a quiet hand), and the contact's own
        changes (the two sensors' filters lag differently) are no release.
    raw_band_N: [N] per base axis, the raw packet's noise band (the FT-150's max |noise|, about
        1.15, 1.06, 0.31 N, seed 4.C): inside max(η, this) a packet counts as "no push".
    """

    UNITS: ClassVar[dict[str, Any]] = {
        "horizon_s": "s",
        "trend_s": "s",
        "min_fall_per_s": "1/s",
        "gap_bands": "1",
        "hold_s": "s",
        "reengage_factor": "1",
        "contact_threshold_N": "N",
        "raw_band_N": "N",
    }

    enabled: bool = False
    horizon_s: float = 0.05
    trend_s: float = 0.04  # eight FT-150 packets, five CB3 cycles
    min_fall_per_s: float = 20.0
    gap_bands: float = 3.0
    hold_s: float = 0.15
    reengage_factor: float = 2.0
    contact_threshold_N: float = 1.0
    in_contact: bool = True
    raw_band_N: Vec3 = field(default_factory=lambda: frozen([1.15, 1.15, 0.31]))

    def __post_init__(self) -> None:
        object.__setattr__(
            self, "raw_band_N", as_nonnegative_vector(self.raw_band_N, 3, "raw_band_N")
        )
        for name in ("horizon_s", "trend_s", "hold_s", "contact_threshold_N"):
            object.__setattr__(self, name, as_scalar(getattr(self, name), name, low=0.0))
        object.__setattr__(
            self,
            "min_fall_per_s",
            as_scalar(self.min_fall_per_s, "min_fall_per_s", low=0.0, low_open=True),
        )
        object.__setattr__(
            self, "reengage_factor", as_scalar(self.reengage_factor, "reengage_factor", low=1.0)
        )
        object.__setattr__(self, "gap_bands", as_scalar(self.gap_bands, "gap_bands", low=1.0))


def scaled_norm(F: Vec3, deadband: Vec3) -> float:
    """‖F ⊘ η‖ over the axes with η > 0: 1 on the deadband's ellipsoid, below 1 inside it."""
    total = 0.0
    for f, eta in zip(F.tolist(), deadband.tolist(), strict=True):
        if eta > 0.0:
            total += (f / eta) ** 2
    return math.sqrt(total)


class ReleaseDetector:
    """The release detector's state machine (module docstring), stepped at the controller's rate."""

    def __init__(self, params: ReleaseParams | None = None) -> None:
        self.params = params or ReleaseParams()
        self.reset()

    def reset(self) -> None:
        self.phase = ReleasePhase.IDLE
        self.t_release: float | None = None
        self._trend: deque[tuple[float, float]] = deque()  # (t, n) back to trend_s ago
        self.releases = 0  # how many times the hand let go since the reset
        self._band_key: tuple[int, int] | None = None
        self._band_value = np.zeros(3)

    @property
    def released(self) -> bool:
        return self.phase.released

    def resume(self) -> None:
        """The hand has the robot again (a hold-on-release handed back): guiding."""
        self.phase = ReleasePhase.GUIDING
        self.t_release = None

    def hold_at_rest(self, t: float) -> None:
        """Hold the robot at rest from time t until the hand pushes again, as after a release in
        the air (a hold-on-release that ended without the hand: the contact lost)."""
        if not self.phase.released:
            self.releases += 1
        self.phase = ReleasePhase.RELEASED_AIR
        self.t_release = t

    def _band(self, deadband: Vec3) -> Vec3:
        """b = max(η, raw_band_N), kept while η and the parameters stay the same objects."""
        key = (id(deadband), id(self.params))
        if self._band_key != key:
            self._band_key, self._band_value = key, np.maximum(deadband, self.params.raw_band_N)
            self._band_of = (deadband, self.params)  # keeps the ids valid
        return self._band_value

    def _norms(
        self, F: Vec3, F_raw: Vec3 | None, deadband: Vec3
    ) -> tuple[float, float | None, float | None]:
        """n = ‖F̂‖_η, ‖F_raw‖_b and ‖F̂ - F_raw‖_b (None without a raw packet); the compiled
        detector (`hoh_cosim.control.kernels.KernelReleaseDetector`) computes them in one call."""
        n = scaled_norm(F, deadband)
        if F_raw is None:
            return n, None, None
        band = self._band(deadband)
        return n, scaled_norm(F_raw, band), scaled_norm(F - F_raw, band)

    def step(
        self,
        t: float,
        F: Vec3,
        F_raw: Vec3 | None,
        deadband: Vec3,
        commanding: bool,
        F_probe: Vec3 | None = None,
    ) -> bool:
        """One controller tick: `F` the filtered (compensated) hand force, `F_raw` the newest
        unfiltered packet compensated the same way (None: not available, the estimate decides
        alone), `commanding` whether the law asks for motion, `F_probe` the probe contact force
        (None: no probe sensor). Returns whether the controller must hold the robot at rest."""
        p = self.params
        n, b_raw, gap = self._norms(F, F_raw, deadband)
        # the trend of the force's size, not of each axis (an axis's noise extrapolated over the
        # horizon would look like a push): ṅ over the last tick, ṅ_w over the last trend_s. The
        # oldest sample kept is the newest at least trend_s old, the one before the newest is the
        # previous tick's
        trend = self._trend
        trend.append((t, n))
        keep_span(trend, t, p.trend_s - 1e-9)
        n_dot = n_dot_w = 0.0
        if len(trend) > 1:
            (t_old, n_old), (t_prev, n_prev) = trend[0], trend[-2]
            if t > t_prev:
                n_dot = (n - n_prev) / (t - t_prev)
            if t > t_old:
                n_dot_w = (n - n_old) / (t - t_old)

        if self.phase.released:
            assert self.t_release is not None
            growing = n_dot > 0.0 and (b_raw is None or b_raw > 1.0)
            held = t - self.t_release >= p.hold_s - 1e-9
            if not (growing and (n > p.reengage_factor or (held and n > 1.0))):
                return True
            self.phase = ReleasePhase.GUIDING
            self.t_release = None
            return False

        if p.enabled and self.phase == ReleasePhase.GUIDING:
            raw_inside = b_raw is None or b_raw <= 1.0
            # n + h ṅ_w <= 1: inside the deadband within the horizon, falling fast over the last
            # trend_s; or the packet already k_gap noise bands below the estimate, which this
            # tick's fall confirms
            fall = -p.min_fall_per_s
            soon = n + p.horizon_s * n_dot_w <= 1.0 and n_dot_w <= fall
            below = gap is not None and gap >= p.gap_bands and n_dot <= fall
            if raw_inside and (soon or below):
                contact = (
                    F_probe is not None and float(F_probe.dot(F_probe)) > p.contact_threshold_N**2
                )
                self.phase = ReleasePhase.RELEASED_CONTACT if contact else ReleasePhase.RELEASED_AIR
                self.t_release = t
                self.releases += 1
                return True
        self.phase = ReleasePhase.GUIDING if commanding else ReleasePhase.IDLE
        return False
