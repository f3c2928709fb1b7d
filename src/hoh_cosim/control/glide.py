"""Glide: eq. 10 lighter for a steady push than for a quick one, and quieter along the probe for a
hand keeping the contact (the law's part, per base axis).

Eq. 10 (seed 000, 3.F.1) is one slope α for every frequency of the hand's force: ẋ = α (|F̃| - η)
sgn F̃. Its two costs pull its gains in opposite directions
(docs/decisions/0054-scan-effort-and-lighter-laws.md): the hand pays η + v / α to move the probe at
v (1.75 N at 1 cm/s with the seed's gains, against a scan's freehand 3-4 N), and the image pays α
for every newton of F̃ above 2 Hz (the admittance integrates it, α/s: tremor, sensor noise, the loop
with the contact). A lighter law saves the hand and shakes the image; a heavier one steadies the
image and tires the hand. Glide splits them by frequency, and the deadband by whether the probe
already moves:

    η_i     the deadband on axis i: eq. 10's η_i at rest; once the push beyond it moves the probe,
            it approaches `moving_deadband` over `settle_s` while the push keeps its sign and
            stays beyond it; back to η_i (at once) as soon as the push falls inside or turns,
            unless the probe glides: once this push has moved it `glide_travel_m` along the
            axis, the lower deadband stays while the push dips inside it or turns, either way,
            until the command has stayed under `rest_speed_m_s` for `rest_s`. Static and kinetic
            friction: breaking away asks for η, keeping going for less, so the hand at rest on
            the handle (tremor, noise, the sensors' errors) still moves nothing, and a hand
            steering a scan does not break away again at every dip of its push or at the turn
    u_i     = α_i (|F̃_i| - η_i)⁺ sgn F̃_i                (eq. 10 with that deadband)
    ū_i     u_i low-passed at `corner_hz`; while u_i = 0 it decays over `release_s` instead
    ẋ_i     = u_i + (r_i - 1) ū_i                        (r_i = `low_slope_ratio`)

For a push held beyond the deadband the slope is r α (light: 3.2 α = 0.04 m/(s·N) by default
on the base's x and y); above the corner it falls back to α, so the image's band (2 Hz and up)
meets nearly eq. 10's own slope. Without the deadband u + (r - 1) ū is the lag network
α (r + τ s) / (1 + τ s), τ = 1 / (2π f_c): r α for a steady push, |α (r + j f / f_c) / (1 + j f /
f_c)| above (1.24 α at 2 Hz for r = 3.2 and f_c = 0.5 Hz, 1.07 α at 4 Hz). Its real part,
α (r + (f / f_c)²) / (1 + (f / f_c)²), is positive at every frequency: as an admittance it is
passive, storing the low-passed part of the motion and giving back no more than it stored. The
deadband before it only ever passes less of F̃ on (u has F̃'s sign and at most its size times α);
the passivity controller (`hoh_cosim.control.passivity`, if on) watches the whole command.

Why the moving deadband as well: the hand pays η_i at any slope, and η = 0.95 N alone is a quarter
of a scan's freehand force; the 75 % effort target leaves the hand 0.9-1.0 N in all. At rest the
deadband stays eq. 10's, so a view or a press, where the hand sits on the handle, sees the seed's
law.

Why it stays while the probe glides: a hand that steers by where the probe goes lets its push dip
as the probe catches up, and the lag's part carries the probe on a little; each dip inside the
moving deadband used to cost the hand η again, and the scan's line turns twice
(docs/decisions/0060-glide-keeps-going.md). The travel it needs first keeps a push that is only the
sensors' error across the probe (the probe sensor's play, up to twice its 0.2-0.8 N) from gliding:
such a push moves the probe a millimetre or two before the hand holding its place stops it.

Along the probe (z) the defaults leave the light part out (r = 1, the moving deadband the default
η_z): a lighter law along the probe speeds up the hand's press loop, which its reaction delay
leaves little phase for (docs/decisions/0056-glide.md).

Along the probe, in contact, glide is quieter instead: the image's jitter is the probe's motion
along the beam above 2 Hz, which eq. 10 makes of F̃'s content there (the sensors' noise after their
filters, 0.03-0.04 N each, and the hand's own force;
docs/decisions/0049-assisted-jitter-is-the-loops.md). While the probe force along its axis exceeds
`contact_N`:

    w_i     = u_i + (r_i - 1) ū_i                        (the command above)
    w̄_i     w_i low-passed at `quiet_hz` (always, in contact or not)
    γ_i     the quiet part's weight: a b_i. a rises from 0 to 1 over `quiet_blend_s` once the
            contact begins (0 out of contact); b_i falls from 1 to 0 as |F̃_i| goes from
            `quiet_push_N` to `quiet_push_N` + `quiet_push_span_N`
    ẋ_i     = w_i + γ_i (1 - q_i) (w̄_i - w_i)          (q_i = `quiet_ratio`, at most 1)

With γ = 1 it is the lag network (1 + q τ s) / (1 + τ s), τ = 1 / (2π f_q), on the law's command:
the law's slope for a steady push (the same travel, only later), q of it well above f_q (0.40 at 2
Hz and 0.35 at 4 Hz for q = 1/3 and f_q = 0.5 Hz). Its price is phase at the hand's press loop's
crossover, about 2.8 rad/s (`hoh_cosim.study.clinical.FREEHAND_PRESS`): -25° at 0.5 Hz, more than
the loop can spare (without the gate below, -21° at 0.7 Hz already limit-cycled one press of
twenty). Hence the gate on the push: the hand's press loop pushes along the probe beyond 1 N (the
follow's and the hold's band for a push) when it presses to a new force, and when it begins to
swing. There the quiet part gives way to eq. 10 and its phase. It quiets what is small: the sensors'
noise and the fine corrections of a hand keeping the contact. A swing of the press loop cannot grow
past the size at which eq. 10's phase is back. The blend keeps it out of the touch-down, where the
approaching probe must stop at once and the sensors' different lags make F̃ swing. Out of contact
the command is w as it is. On x and y the default q is 1: there the command is w exactly. Like the
low-passed part, w̄ is zero once under 1 µm/s while the law commands nothing.

After a release the low-passed part decays over `release_s` (50 ms), not the corner's 0.32 s: at a
steady 1 cm/s it carries the tip 0.34 mm further than eq. 10 would, against the 1 m/s² limit's
own 0.05 mm (the supervisor's acceleration clamp comes after; at 6 cm/s, 2 mm against its 2 mm),
and is zero once under 1 µm/s (0.4 s after a 1 cm/s push): the law at rest asks for nothing.
Reset whenever the controller stops, brakes after a release or holds. Only with eq. 10's law
(`translation.law` deadband_linear). Off by default (docs/decisions/0056-glide.md).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from hoh_cosim.control.admittance import deadband_linear
from hoh_cosim.control.vectors import Vec3, as_nonnegative_vector, as_scalar, as_vector, frozen
from hoh_cosim.errors import ConfigError

__all__ = ["Glide", "GlideParams"]

_REST = 1e-6
"""[m/s] The low-passed parts' decay ends here, at rest: an exponential never reaches zero, and a
law that still asked for a nanometre a second would keep the release detector guiding (it reads
whether the law asks for motion) long after the hand let go."""


@dataclass(frozen=True)
class GlideParams:
    """Glide's lag and moving deadband (module docstring), per base axis where a vector."""

    UNITS: ClassVar[dict[str, Any]] = {
        "low_slope_ratio": "1",
        "corner_hz": "Hz",
        "moving_deadband": "N",
        "settle_s": "s",
        "glide_travel_m": "m",
        "rest_s": "s",
        "rest_speed_m_s": "m/s",
        "release_s": "s",
        "quiet_ratio": "1",
        "quiet_hz": "Hz",
        "contact_N": "N",
        "quiet_blend_s": "s",
        "quiet_push_N": "N",
        "quiet_push_span_N": "N",
    }

    enabled: bool = False
    # r: the slope a steady push meets, in multiples of eq. 10's α (1: the lag does nothing)
    low_slope_ratio: Vec3 = field(default_factory=lambda: frozen([3.2, 3.2, 1.0]))
    corner_hz: float = 0.5  # f_c: above it the slope falls back to α
    # [N] the deadband once the probe moves (the smaller of this and eq. 10's η per axis)
    moving_deadband: Vec3 = field(default_factory=lambda: frozen([0.3, 0.3, 0.25]))
    settle_s: float = 0.5  # [s] the deadband's approach to moving_deadband while the push lasts
    # the probe glides once the push has moved it this far along the axis: the moving deadband then
    # stays through the push's dips and turns until the command rests under rest_speed_m_s for
    # rest_s (0: back at eq. 10's deadband as soon as the push falls inside or turns)
    glide_travel_m: float = 0.005
    rest_s: float = 1.0
    rest_speed_m_s: float = 0.001
    release_s: float = 0.05  # [s] the low-passed part's decay once eq. 10 commands nothing
    # q: in contact, the slope a quick push meets, in multiples of a steady push's (1: as it is)
    quiet_ratio: Vec3 = field(default_factory=lambda: frozen([1.0, 1.0, 1.0 / 3.0]))
    quiet_hz: float = 0.5  # f_q: above it, in contact, the slope falls to q times
    contact_N: float = 3.0  # [N] the probe force along its axis above which the probe is in contact
    quiet_blend_s: float = 0.5  # [s] the quiet part's way in once the contact begins
    quiet_push_N: float = 1.0  # [N] a push beyond this on an axis ...
    quiet_push_span_N: float = 0.5  # [N] ... and this much more meets eq. 10 (the quiet part out)

    def __post_init__(self) -> None:
        ratio = as_vector(self.low_slope_ratio, 3, "low_slope_ratio")
        if np.any(ratio < 1.0):
            raise ConfigError(f"low_slope_ratio must be >= 1 on every axis, got {ratio.tolist()}")
        object.__setattr__(self, "low_slope_ratio", ratio)
        quiet = as_vector(self.quiet_ratio, 3, "quiet_ratio")
        if np.any(quiet <= 0.0) or np.any(quiet > 1.0):
            raise ConfigError(f"quiet_ratio must be in (0, 1] on every axis, got {quiet.tolist()}")
        object.__setattr__(self, "quiet_ratio", quiet)
        object.__setattr__(
            self,
            "moving_deadband",
            as_nonnegative_vector(self.moving_deadband, 3, "moving_deadband"),
        )
        for name in ("glide_travel_m", "rest_s"):
            object.__setattr__(self, name, as_scalar(getattr(self, name), name, low=0.0))
        for name in (
            "corner_hz",
            "settle_s",
            "rest_speed_m_s",
            "release_s",
            "quiet_hz",
            "contact_N",
            "quiet_blend_s",
            "quiet_push_N",
            "quiet_push_span_N",
        ):
            object.__setattr__(
                self, name, as_scalar(getattr(self, name), name, low=0.0, low_open=True)
            )


class Glide:
    """Glide of the module docstring, one controller tick at a time."""

    def __init__(self, params: GlideParams | None = None) -> None:
        self.params = params or GlideParams()
        self.reset()

    def reset(self) -> None:
        self.moving = np.zeros(3)  # the sign of the push that moves the probe, per axis; 0: at rest
        self.deadband = np.full(3, np.nan)  # η_i while moving
        self.travel = np.zeros(3)  # [m] the command's path along each axis since it broke away
        self.resting = np.zeros(3)  # [s] how long the command has stayed under rest_speed_m_s
        self._command = np.zeros(3)  # the last tick's command before the quiet part
        self.slow = np.zeros(3)  # ū
        self.quiet = np.zeros(3)  # w̄
        self.quiet_in = 0.0  # a: the quiet part's blend since the contact began

    @property
    def active(self) -> bool:
        """Whether the probe moves on any axis under a deadband below eq. 10's."""
        return bool(self.moving.any())

    def step(
        self, dt: float, F: Vec3, slope: Vec3, deadband: Vec3, contact_N: float | None = None
    ) -> Vec3:
        """The translation command for the compensated hand force `F` under eq. 10's `slope` and
        `deadband` (the translation law's gains); `contact_N` the probe force along its axis,
        pressing positive (None: no probe sensor, never in contact)."""
        p = self.params
        F = np.asarray(F, dtype=np.float64)
        size = np.abs(F)
        sign = np.sign(F)
        low = np.minimum(p.moving_deadband, deadband)
        moving = self.moving != 0.0
        beyond = moving & (size > self.deadband)
        going = beyond & (sign == self.moving)
        self.resting = np.where(
            moving & (np.abs(self._command) < p.rest_speed_m_s), self.resting + dt, 0.0
        )
        gliding = moving & (self.travel >= p.glide_travel_m) & (self.resting < p.rest_s)
        keep = going | gliding
        settle = 1.0 - math.exp(-dt / p.settle_s)
        self.deadband = np.where(keep, self.deadband + (low - self.deadband) * settle, deadband)
        starting = ~keep & (size > deadband)
        self.moving = np.where(
            keep, np.where(beyond, sign, self.moving), np.where(starting, sign, 0.0)
        )
        u = deadband_linear(F, slope, self.deadband)
        follow = 1.0 - math.exp(-2.0 * math.pi * p.corner_hz * dt)
        decay = math.exp(-dt / p.release_s)
        fading = self.slow * decay
        fading[np.abs(fading) < _REST] = 0.0
        self.slow = np.where(u == 0.0, fading, self.slow + (u - self.slow) * follow)
        w = u + (p.low_slope_ratio - 1.0) * self.slow
        self._command = w
        self.travel = np.where(self.moving != 0.0, self.travel + np.abs(w) * dt, 0.0)
        quiet = self.quiet + (w - self.quiet) * (1.0 - math.exp(-2.0 * math.pi * p.quiet_hz * dt))
        quiet[(w == 0.0) & (np.abs(quiet) < _REST)] = 0.0
        self.quiet = quiet
        if contact_N is None or contact_N <= p.contact_N:
            self.quiet_in = 0.0
            return w
        self.quiet_in = min(1.0, self.quiet_in + dt / p.quiet_blend_s)
        give = np.clip((size - p.quiet_push_N) / p.quiet_push_span_N, 0.0, 1.0)
        return w + self.quiet_in * (1.0 - give) * (1.0 - p.quiet_ratio) * (quiet - w)
