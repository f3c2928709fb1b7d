"""The hand-guiding controller's modes, the events that move it between them, and the one table of
its transitions.

    mode           what the robot does                                   its command comes from
    STOPPED        a stop flag (stale or bad data, the force stop, the    zero (a latched fault keeps
                   rebias): nothing moves                                  it until a reset)
    FREE           the hand guides the probe in the air                    the hand's request
    CONTACT        the hand guides the probe on the patient                the hand's request
    BRAKING        the hand let go (or a hold ended without it): rest,    zero, shed at the braking
                   until the hand pushes again                             deceleration
    HOLDING        hands off in contact: the robot keeps the contact      the hold's force law
                   force through the breaths
    HANDING_BACK   a touch of the handle while holding: the hand's        the hold blended into the
                   request blended in                                      hand's request
    RECOVERING     the contact was lost while holding or scanning: back   the recovery's approach
                   along the last surface normal until the contact is
                   back, within a bounded travel and time

A pair (mode, event) that `TRANSITIONS` does not list keeps the mode. The detectors that raise
the events are in `hoh_cosim.control.guidance.detectors`; each mode's stages are the controller's
(`hoh_cosim.control.controller`).
"""

from __future__ import annotations

import enum
from collections.abc import Mapping

__all__ = ["GUIDING", "HOLD_MODES", "TRANSITIONS", "Event", "Mode", "next_mode"]


class Mode(enum.IntEnum):
    """What the controller does this tick (module docstring). The values are the `mode` port's."""

    STOPPED = 0
    FREE = 1
    CONTACT = 2
    BRAKING = 3
    HOLDING = 4
    HANDING_BACK = 5
    RECOVERING = 6

    @property
    def label(self) -> str:
        """The mode as a sonographer would say it."""
        return _LABELS[self]


_LABELS = {
    Mode.STOPPED: "stopped",
    Mode.FREE: "guiding in the air",
    Mode.CONTACT: "guiding in contact",
    Mode.BRAKING: "released, braking to rest",
    Mode.HOLDING: "holding the contact",
    Mode.HANDING_BACK: "handing back",
    Mode.RECOVERING: "recovering the contact",
}

GUIDING = frozenset({Mode.FREE, Mode.CONTACT})
"""The modes in which the hand's request steers the robot."""
HOLD_MODES = frozenset({Mode.HOLDING, Mode.HANDING_BACK})
"""The modes in which the hold has the probe."""


class Event(enum.Enum):
    """What a detector tells (`hoh_cosim.control.guidance.detectors`)."""

    STOP = "stop"  # supervisor: a stop flag this tick
    GO = "go"  # supervisor: no stop flag (any more)
    TOUCH_DOWN = "touch down"  # contact: the probe force rose past the contact level
    LIFT_OFF = "lift off"  # contact: the probe left the patient (the hand lifted it)
    RELEASED = "released"  # release: the hand let go
    PUSHED = "pushed"  # release, recovery: the hand pushes again
    HOLD_READY = "hold ready"  # hold watch: hands off in contact, settled
    TOUCHED = "touched"  # touch: a touch of the handle while holding
    HANDED_BACK = "handed back"  # touch: the blend is over (or there is none)
    CONTACT_LOST = "contact lost"  # hold guard, contact: the patient left the probe
    TRAVEL_LIMIT = "travel limit"  # hold guard: the tip moved too far along its line
    RECOVERED = "recovered"  # recovery: the contact is back at its level, hands off
    CONTACT_BACK = "contact back"  # recovery: the contact is back under the hand
    RECOVERY_FAILED = "recovery failed"  # recovery: no contact within its travel and time


_TABLE: dict[tuple[Mode, Event], Mode] = {
    # a stop from anywhere; out of it into the air (TOUCH_DOWN follows in the same tick if the
    # probe is on the patient)
    **{(mode, Event.STOP): Mode.STOPPED for mode in Mode if mode != Mode.STOPPED},
    (Mode.STOPPED, Event.GO): Mode.FREE,
    # guiding
    (Mode.FREE, Event.TOUCH_DOWN): Mode.CONTACT,
    (Mode.CONTACT, Event.LIFT_OFF): Mode.FREE,
    (Mode.FREE, Event.RELEASED): Mode.BRAKING,
    (Mode.CONTACT, Event.RELEASED): Mode.BRAKING,
    (Mode.CONTACT, Event.CONTACT_LOST): Mode.RECOVERING,
    # hands off in contact: hold, from guiding or from the brake after a release in contact
    (Mode.FREE, Event.HOLD_READY): Mode.HOLDING,
    (Mode.CONTACT, Event.HOLD_READY): Mode.HOLDING,
    (Mode.BRAKING, Event.HOLD_READY): Mode.HOLDING,
    (Mode.BRAKING, Event.PUSHED): Mode.FREE,
    # the hold: a touch hands back (blended), the guards end it
    (Mode.HOLDING, Event.TOUCHED): Mode.HANDING_BACK,
    (Mode.HOLDING, Event.HANDED_BACK): Mode.CONTACT,
    (Mode.HANDING_BACK, Event.HANDED_BACK): Mode.CONTACT,
    (Mode.HOLDING, Event.CONTACT_LOST): Mode.RECOVERING,
    (Mode.HANDING_BACK, Event.CONTACT_LOST): Mode.BRAKING,
    (Mode.HOLDING, Event.TRAVEL_LIMIT): Mode.BRAKING,
    (Mode.HANDING_BACK, Event.TRAVEL_LIMIT): Mode.BRAKING,
    # recovering the contact
    (Mode.RECOVERING, Event.RECOVERED): Mode.HOLDING,
    (Mode.RECOVERING, Event.CONTACT_BACK): Mode.CONTACT,
    (Mode.RECOVERING, Event.RECOVERY_FAILED): Mode.BRAKING,
    (Mode.RECOVERING, Event.PUSHED): Mode.FREE,
}

TRANSITIONS: Mapping[tuple[Mode, Event], Mode] = _TABLE
"""(mode, event) -> the next mode; a pair not listed keeps the mode."""


def next_mode(mode: Mode, event: Event) -> Mode:
    """The mode after `event` in `mode` (`TRANSITIONS`; a pair not listed keeps the mode)."""
    return _TABLE.get((mode, event), mode)
