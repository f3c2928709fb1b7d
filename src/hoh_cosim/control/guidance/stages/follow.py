"""Following the breath as a stage (`hoh_cosim.control.follow`): in contact, while the hand steers,
the contact force's departure from its level and the surface's estimated speed move the probe along
its axis. It acts only while the hand's request steers; in any other mode it stops, and the next
contact starts afresh."""

from __future__ import annotations

from hoh_cosim.control.follow import BreathFollower, FollowParams
from hoh_cosim.control.guidance.tick import Command, Tick
from hoh_cosim.control.supervisor import Status

__all__ = ["FollowStage"]

_FOLLOWING = int(Status.FOLLOWING)


class FollowStage:
    """v ← v + v_follow along the probe axis (status FOLLOWING while it acts)."""

    def __init__(self, params: FollowParams) -> None:
        self.follower = BreathFollower(params)

    def retune(self, params: FollowParams) -> None:
        self.follower.params = params

    def reset(self) -> None:
        self.follower.stop()

    rest = reset

    def step(self, tick: Tick, command: Command) -> Command:
        axis = tick.axis
        if axis is None or not axis.any():
            self.follower.stop()
            return command
        v_follow = self.follower.step(
            tick.dt,
            tick.F,
            tick.F_probe,
            axis,
            tick.t,
            tick.p_BT,
            tick.F_meas,
            tick.F_probe_meas,
            tick.ft_age,
        )
        if v_follow is not None:
            command.v = command.v + v_follow
            command.status |= _FOLLOWING
        return command
