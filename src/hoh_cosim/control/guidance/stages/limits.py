"""The supervisor's limits as the last stage of every mode (`hoh_cosim.control.supervisor`): speed,
acceleration (the braking deceleration towards rest after a release), the probe-force soft cap and
the workspace box. No stage before it and no mode commands past them."""

from __future__ import annotations

from hoh_cosim.control.guidance.tick import Command, Tick
from hoh_cosim.control.supervisor import LimitParams, limit_command

__all__ = ["Limits"]


class Limits:
    """The command within the limits, from the last tick's command; the clamps' flags."""

    def __init__(self, params: LimitParams) -> None:
        self.params = params
        self._box = (params.workspace_min_B.tolist(), params.workspace_max_B.tolist())

    def reset(self) -> None:
        """No state: the last command is the tick's."""

    def step(self, tick: Tick, command: Command) -> Command:
        command.v, command.w, clamped = limit_command(
            command.v,
            command.w,
            tick.v_last,
            tick.w_last,
            tick.dt,
            tick.probe,
            tick.p_BT,
            self.params,
            self._box,
            braking=command.braking,
        )
        command.status |= clamped
        return command
