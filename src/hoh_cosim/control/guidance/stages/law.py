"""The admittance law as a stage (seed 000, eq. 10; `hoh_cosim.control.admittance`): the hand's
request from F̃ and τ̃, v = law(F̃), ω = law(τ̃), for the laws without state (eq. 10, the isotropic
deadband, the sigmoid)."""

from __future__ import annotations

import dataclasses

import numpy as np

from hoh_cosim.control.admittance import AdmittanceGains, apply_law
from hoh_cosim.control.guidance.tick import Command, Tick
from hoh_cosim.control.kernels import deadband_law6, kernels_enabled, warm_up_laws
from hoh_cosim.control.vectors import frozen

__all__ = ["AdmittanceLaw"]


class AdmittanceLaw:
    """v = law(F̃), ω = law(τ̃); both laws elementwise and of one kind run as one 6-vector law."""

    def __init__(self, translation: AdmittanceGains, rotation: AdmittanceGains) -> None:
        self.translation, self.rotation = translation, rotation
        self._law6: AdmittanceGains | None = None
        if translation.law == rotation.law and translation.law not in ("isotropic", "variable"):
            self._law6 = _stacked(translation, rotation)  # half the work
        # eq. 10 on both at once, compiled (`hoh_cosim.control.kernels`; the same bits)
        self._compiled = self._law6 is not None and self._law6.law == "deadband_linear"
        self._compiled = self._compiled and kernels_enabled()
        if self._compiled:
            warm_up_laws()

    def reset(self) -> None:
        """No state."""

    def step(self, tick: Tick, command: Command) -> Command:
        if self._compiled:
            gains = self._law6
            law = deadband_law6(tick.F, tick.tau, gains.slope, gains.deadband)
            command.v, command.w = law[:3], law[3:]
        elif self._law6 is not None:
            law = apply_law(np.concatenate([tick.F, tick.tau]), self._law6)
            command.v, command.w = law[:3], law[3:]
        else:
            command.v = apply_law(tick.F, self.translation)
            command.w = apply_law(tick.tau, self.rotation)
            law = np.concatenate([command.v, command.w])
        command.law = law
        return command


def _stacked(tr: AdmittanceGains, rot: AdmittanceGains) -> AdmittanceGains:
    """One gains object over [force; torque] for the elementwise laws."""
    stacked = AdmittanceGains.__new__(AdmittanceGains)  # six values: skip the 3-vector checks
    for f in dataclasses.fields(AdmittanceGains):
        a, b = getattr(tr, f.name), getattr(rot, f.name)
        object.__setattr__(
            stacked, f.name, a if f.name == "law" else frozen(np.concatenate([a, b]))
        )
    return stacked
