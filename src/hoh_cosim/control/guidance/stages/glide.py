"""Glide as a stage (`hoh_cosim.control.glide`): eq. 10's translation lighter for a steady push,
with a moving deadband, and quieter along the probe in contact. Part of the hand's request; in a
mode that does not steer by the request (braking, holding, handing back, recovering) it rests:
nothing of it is carried into the next push."""

from __future__ import annotations

import numpy as np

from hoh_cosim.control.admittance import AdmittanceGains
from hoh_cosim.control.glide import Glide, GlideParams
from hoh_cosim.control.guidance.tick import Command, Tick

__all__ = ["GlideStage"]


class GlideStage:
    """The translation's request through glide; the rotation's as the law gave it."""

    def __init__(self, params: GlideParams) -> None:
        self.glide = Glide(params)
        self.translation: AdmittanceGains | None = None
        self.use_probe = True

    def retune(self, params: GlideParams, translation: AdmittanceGains, use_probe: bool) -> None:
        self.glide.params = params
        self.translation, self.use_probe = translation, use_probe
        if not params.enabled:  # switched off: nothing of it left for a later switch on
            self.glide.reset()

    def reset(self) -> None:
        self.glide.reset()

    rest = reset

    def step(self, tick: Tick, command: Command) -> Command:
        assert self.translation is not None
        axis = tick.axis if self.use_probe else None
        c = None if axis is None else -float(tick.F_probe.dot(axis))
        v = self.glide.step(tick.dt, tick.F, self.translation.slope, self.translation.deadband, c)
        command.v, command.law = v, np.concatenate([v, command.w])
        return command
