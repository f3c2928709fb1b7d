"""Contact recovery: the patient moved away from the probe, and the robot brings it back.

A patient who shifts, coughs or pulls in the belly takes the skin away from the probe faster than a
hand or a hold follows: the contact is lost. Hands off (the hold had the probe), nothing brings it
back, and the seed's law (000, 3.F) has the robot wait where it is; under the hand, the
sonographer presses until the image returns. Multi-modal robotic ultrasound controllers recover
such a loss themselves (Tsinghua's, 2023, among them): the robot moves the probe back along the
last surface normal at a capped speed until it touches again. Here:

    normal     n̂, the contact's outward direction: the probe force's direction low-passed over
               `normal_tau_s` while in contact (above `contact_N`), from the probe axis's reverse
               at the first contact; friction tilts a single reading, its mean is the normal
    approach   on a loss, from where the tip is (p₀, t₀): v = u d, d = -n̂ (into the patient),
               u = `speed_m_s`; with a hand on the handle its request across d is kept, and along
               d the larger of the two (the hand may press faster, never slower)
    back       the probe force above `contact_N` for `confirm_s`: the contact is back (the hold,
               if it had the probe, takes it again at its level, and the supervisor's soft cap
               bounds the force meanwhile)
    gave up    the tip `max_travel_m` along d from p₀, or `max_s` since t₀, without the
               contact: the robot rests until the hand pushes
    taken      under the hand, the hand pulls the probe back out (F̃ · d below -`pull_N` for
               `pull_s`): the hand has it

A loss is told by the hold's own guards while it holds (`hoh_cosim.control.hold`), and while the
hand scans by the contact's watch (`hoh_cosim.control.guidance.detectors`): after a contact of at least `established_s`, the probe
force under the controller's `lift_off_N` for `loss_s` while neither the hand pulled (F̃ along the
probe below -`pull_N`) nor the tip moved `loss_m` out along the probe: a hand lifting the probe
off does one or the other. Off by
default; the `clinical` preset has it (docs/decisions).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from hoh_cosim.control.vectors import Vec3, as_scalar

__all__ = ["ContactRecovery", "RecoveryParams"]


@dataclass(frozen=True)
class RecoveryParams:
    """Contact recovery (module docstring)."""

    UNITS: ClassVar[dict[str, Any]] = {
        "speed_m_s": "m/s",
        "contact_N": "N",
        "confirm_s": "s",
        "max_travel_m": "m",
        "max_s": "s",
        "normal_tau_s": "s",
        "pull_N": "N",
        "pull_s": "s",
        "established_s": "s",
        "loss_s": "s",
        "loss_m": "m",
    }

    enabled: bool = False
    # [m/s] the approach: a 15 mm gap closes in 0.5 s, and the force rises at about 36 N/s on
    # 1200 N/m of tissue, 0.7 N for a 20 ms packet of the probe sensor
    speed_m_s: float = 0.03
    contact_N: float = 2.0  # [N] the probe force that counts as the contact back (the hold's)
    confirm_s: float = 0.03  # [s] ... held this long (a packet and a half at 50 Hz)
    max_travel_m: float = 0.03  # [m] the farthest the recovery moves the tip (twice a 15 mm loss)
    max_s: float = 3.0  # [s] the longest it looks for the contact
    normal_tau_s: float = 1.0  # [s] the normal's low-pass (a few friction reversals)
    # [N] under the hand, F̃ against the approach beyond this for pull_s: the hand pulls the probe
    # out (above F̃'s error with nobody's hand in the air, the play's 0.5-1 N, and its transients
    # as the contact goes and comes: the two sensors' filters lag differently)
    pull_N: float = 2.0
    pull_s: float = 0.1
    # [s] under the hand, only a contact that lasted this long can be lost (a finger's push on the
    # tip, a touch-down's bounce is none)
    established_s: float = 1.0
    # under the hand, the probe force under the controller's lift_off_N (no contact) for loss_s ...
    loss_s: float = 0.2  # [s] (the hold's guards' figure) ...
    loss_m: float = 0.003  # [m] ... with the tip moved less than this out along the probe

    def __post_init__(self) -> None:
        for name in ("confirm_s", "pull_N", "pull_s", "established_s"):
            object.__setattr__(self, name, as_scalar(getattr(self, name), name, low=0.0))
        for name in (
            "speed_m_s",
            "contact_N",
            "max_travel_m",
            "max_s",
            "normal_tau_s",
            "loss_s",
            "loss_m",
        ):
            object.__setattr__(
                self, name, as_scalar(getattr(self, name), name, low=0.0, low_open=True)
            )


class ContactRecovery:
    """The recovery's state (module docstring): the normal while in contact, and one approach."""

    def __init__(self, params: RecoveryParams | None = None) -> None:
        self.params = params or RecoveryParams()
        self.reset()

    def reset(self) -> None:
        self.normal = np.zeros(3)  # n̂, outward (the probe force's direction), low-passed
        self.direction = np.zeros(3)  # d = -n̂ at the loss: the approach
        self.active = False
        self.hands_off = True  # the loss came while the hold had the probe
        self.recoveries = 0  # approaches begun since the reset
        self._t0 = 0.0
        self._p0 = np.zeros(3)
        self._back_since: float | None = None
        self._pull_since: float | None = None

    def observe(self, dt: float, F_probe_B: Vec3 | None, axis_B: Vec3 | None) -> None:
        """One tick outside a recovery: the normal follows the contact's direction."""
        if F_probe_B is None or self.active:
            return
        size = math.sqrt(float(F_probe_B.dot(F_probe_B)))
        if size <= self.params.contact_N:
            return
        unit = F_probe_B / size
        if not self.normal.any():  # the first contact: from the probe axis's reverse
            self.normal = -axis_B if axis_B is not None and axis_B.any() else unit
        w = min(dt / self.params.normal_tau_s, 1.0)
        normal = self.normal + w * (unit - self.normal)
        size = math.sqrt(float(normal.dot(normal)))
        if size > 1e-9:  # (a contact exactly against the normal, half a time constant: kept)
            self.normal = normal / size

    def start(self, t: float, p_BT_B: Vec3, axis_B: Vec3 | None, hands_off: bool) -> None:
        """An approach from the tip's position now along -n̂ (the probe axis if no contact was
        seen yet)."""
        normal = self.normal
        if not normal.any():
            normal = -axis_B if axis_B is not None and axis_B.any() else np.array([0.0, 0.0, 1.0])
        self.direction = -normal
        self.active, self.hands_off = True, hands_off
        self._t0, self._p0 = t, p_BT_B.copy()
        self._back_since = self._pull_since = None
        self.recoveries += 1

    def stop(self) -> None:
        """The approach is over (back, given up, or taken by the hand)."""
        self.active = False

    def back(self, t: float, F_probe_B: Vec3 | None) -> bool:
        """Whether the contact is back: the probe force above `contact_N` for `confirm_s`."""
        p = self.params
        if F_probe_B is None or float(F_probe_B.dot(F_probe_B)) <= p.contact_N * p.contact_N:
            self._back_since = None
            return False
        if self._back_since is None:
            self._back_since = t
        return t - self._back_since >= p.confirm_s - 1e-9

    def gave_up(self, t: float, p_BT_B: Vec3) -> bool:
        """Whether the approach went `max_travel_m` or `max_s` without the contact."""
        p = self.params
        travel = float((p_BT_B - self._p0).dot(self.direction))
        return travel >= p.max_travel_m - 1e-12 or t - self._t0 >= p.max_s - 1e-9

    def pulled(self, t: float, F: Vec3) -> bool:
        """Whether the hand pulls the probe back out, in an approach under the hand: F̃ against the
        approach beyond `pull_N` for `pull_s`. Hands off, no pull ends the approach: F̃'s errors
        as the contact goes and comes are no hand (one who takes the handle meets the hold at the
        contact, and a touch hands back)."""
        p = self.params
        if self.hands_off or float(F.dot(self.direction)) >= -p.pull_N:
            self._pull_since = None
            return False
        if self._pull_since is None:
            self._pull_since = t
        return t - self._pull_since >= p.pull_s - 1e-9

    def command(self, v_request: Vec3) -> Vec3:
        """v: the hand's request across d, and along d the larger of the request and the approach
        speed."""
        d = self.direction
        along = float(v_request.dot(d))
        return v_request + (max(along, self.params.speed_m_s) - along) * d
