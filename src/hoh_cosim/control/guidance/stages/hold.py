"""Hold-on-release as a stage (`hoh_cosim.control.hold`): hands off in contact, the robot keeps
the probe's contact force through the breaths; after a touch of the handle, the hand's request is
blended in. The hold's watch, guards and touch are the mode machine's detectors
(`hoh_cosim.control.guidance.detectors`); this stage runs its force law and owns its state."""

from __future__ import annotations

from hoh_cosim.control.guidance.tick import ZERO3, Command, Tick
from hoh_cosim.control.hold import ContactHold, HoldParams, HoldPhase
from hoh_cosim.control.supervisor import Status

__all__ = ["HoldStage"]

_HOLDING = int(Status.HOLDING) | int(Status.RELEASED)  # the hand let go: RELEASED too
_HANDING_BACK = int(Status.HANDING_BACK)


class HoldStage:
    """Holding: v = the hold's law along its line, ω = 0. Handing back: v = (1 - β) v_hold + β
    v_law, ω = β ω_law."""

    def __init__(self, params: HoldParams) -> None:
        self.hold = ContactHold(params)

    def retune(self, params: HoldParams) -> None:
        self.hold.params = params

    def reset(self) -> None:
        self.hold.stop()

    def step(self, tick: Tick, command: Command) -> Command:
        hold = self.hold
        v = hold.command(
            tick.t,
            tick.dt,
            tick.F,
            tick.F_meas,
            tick.F_probe,
            tick.p_BT,
            command.v,
            tick.F_probe_meas,
            tick.probe_age,
            tick.ft_age,
        )
        if hold.phase == HoldPhase.HOLDING:
            command.v, command.w = v, ZERO3
            command.status |= _HOLDING
        else:
            command.v, command.w = v, hold.blend * command.w
            command.status |= _HANDING_BACK
        return command
