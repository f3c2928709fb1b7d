"""The passivity observer and controller with its energy tank as a stage
(`hoh_cosim.control.passivity`): it watches the energy the hand puts into the robot on every tick
and, while the command is the hand's request, yields to the hand when the robot would give back
more than it took."""

from __future__ import annotations

from hoh_cosim.control.guidance.tick import Command, Tick
from hoh_cosim.control.kernels import passivity_controller
from hoh_cosim.control.passivity import PassivityController, PassivityParams
from hoh_cosim.control.supervisor import Status

__all__ = ["PassivityStage"]

_PASSIVITY = int(Status.PASSIVITY)


class PassivityStage:
    """The PO every tick; the PC on the command while it is the hand's request (`steering`)."""

    def __init__(self, params: PassivityParams) -> None:
        self.controller: PassivityController = passivity_controller(params)  # type: ignore[assignment]

    def retune(self, params: PassivityParams) -> None:
        self.controller.params = params

    def reset(self) -> None:
        self.controller.reset()

    def step(self, tick: Tick, command: Command) -> Command:
        v, acted = self.controller.step(
            tick.t, tick.F, tick.p_BT, command.v, control=command.steering
        )
        command.v = v
        if acted:
            command.status |= _PASSIVITY
        return command
