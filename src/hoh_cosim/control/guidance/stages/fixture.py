"""The virtual fixture as a stage (seed 000, 3.F.3; `hoh_cosim.control.admittance`): while the
probe force exceeds a threshold, no motion out of the surface: along a fixed up direction (the
seed's horizontal plane) or along the estimated surface normal, the probe force's direction."""

from __future__ import annotations

import math

from hoh_cosim.control.admittance import horizontal_fixture
from hoh_cosim.control.guidance.tick import Command, Tick
from hoh_cosim.control.supervisor import Status
from hoh_cosim.control.vectors import Vec3

__all__ = ["Fixture"]

_FIXTURE = int(Status.FIXTURE)


class Fixture:
    """`normal` fixed: no motion along `up_B`; contact: none along F_probe / |F_probe|."""

    def __init__(self, threshold_N: float, up_B: Vec3, normal: str) -> None:
        self.threshold_N, self.up_B, self.normal = threshold_N, up_B, normal

    def reset(self) -> None:
        """No state."""

    def step(self, tick: Tick, command: Command) -> Command:
        up = self.up_B
        F_probe = tick.F_probe
        if self.normal == "contact":
            size = float(F_probe.dot(F_probe))
            up = F_probe / math.sqrt(size) if size > 0.0 else up
        command.v, engaged = horizontal_fixture(command.v, F_probe, self.threshold_N, up)
        if engaged:
            command.status |= _FIXTURE
        return command
