"""Contact recovery as a stage (`hoh_cosim.control.recovery`): the contact was lost while holding
or scanning, and the robot brings the probe back along the last surface normal at a capped speed.
The loss, the contact's return, the limits of the search and the hand taking over are the mode
machine's detectors (`hoh_cosim.control.guidance.detectors`); this stage commands the approach and
owns its state."""

from __future__ import annotations

from hoh_cosim.control.guidance.tick import ZERO3, Command, Tick
from hoh_cosim.control.recovery import ContactRecovery, RecoveryParams
from hoh_cosim.control.supervisor import Status

__all__ = ["RecoveryStage"]

_RECOVERING = int(Status.RECOVERING)


class RecoveryStage:
    """v = the approach along -n̂ (with the hand's request across it); ω: the hand's, or rest."""

    def __init__(self, params: RecoveryParams) -> None:
        self.recovery = ContactRecovery(params)

    def retune(self, params: RecoveryParams) -> None:
        self.recovery.params = params

    def reset(self) -> None:
        self.recovery.reset()

    def step(self, tick: Tick, command: Command) -> Command:
        recovery = self.recovery
        command.v = recovery.command(command.v)
        if recovery.hands_off:
            command.w = ZERO3
        command.status |= _RECOVERING
        return command
