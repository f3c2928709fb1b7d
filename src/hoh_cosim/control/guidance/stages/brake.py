"""The release brake as a stage (seed 000, 5.C; `hoh_cosim.control.release`): once the hand has
let go, the command is rest, shed at the braking deceleration (`LimitParams.max_brake_accel`) by the
supervisor's limits, until the hand pushes again. The release detector that tells the release is
the mode machine's (`hoh_cosim.control.guidance.detectors`); this stage owns its state."""

from __future__ import annotations

from hoh_cosim.control.guidance.tick import ZERO3, Command, Tick
from hoh_cosim.control.kernels import release_detector
from hoh_cosim.control.release import ReleaseDetector, ReleaseParams
from hoh_cosim.control.supervisor import Status

__all__ = ["ReleaseBrake"]

_RELEASED = int(Status.RELEASED)


class ReleaseBrake:
    """Rest, braked (status RELEASED)."""

    def __init__(self, params: ReleaseParams) -> None:
        self.detector: ReleaseDetector = release_detector(params)

    def retune(self, params: ReleaseParams) -> None:
        self.detector.params = params

    def reset(self) -> None:
        self.detector.reset()

    def step(self, tick: Tick, command: Command) -> Command:
        command.v = command.w = ZERO3
        command.braking = True
        command.status |= _RELEASED
        return command
