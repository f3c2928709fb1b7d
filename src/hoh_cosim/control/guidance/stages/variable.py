"""The variable admittance as a stage (`hoh_cosim.control.variable_admittance`, law name
`variable`): eq. 10 whose slope follows the hand's intent and halves on an oscillation; the
rotation's law in the same call. Stateful: it steps on every tick that is not a stop."""

from __future__ import annotations

from hoh_cosim.control.admittance import AdmittanceGains
from hoh_cosim.control.guidance.tick import Command, Tick
from hoh_cosim.control.kernels import variable_law
from hoh_cosim.control.variable_admittance import VariableAdmittance, VariableAdmittanceParams

__all__ = ["VariableLaw"]


class VariableLaw:
    """The hand's request by the variable law (compiled unless HOH_COSIM_KERNELS=pure)."""

    def __init__(self, params: VariableAdmittanceParams) -> None:
        self.law = variable_law(params)
        self.retune(params, None, None)

    @property
    def block(self) -> VariableAdmittance:
        return self.law  # type: ignore[return-value]

    def retune(
        self,
        params: VariableAdmittanceParams,
        translation: AdmittanceGains | None,
        rotation: AdmittanceGains | None,
    ) -> None:
        self.law.params = params
        self.translation, self.rotation = translation, rotation

    def reset(self) -> None:
        self.law.reset()

    def step(self, tick: Tick, command: Command) -> Command:
        assert self.translation is not None
        assert self.rotation is not None
        law = self.law.step_twist(
            tick.t, tick.F, tick.tau, self.translation, self.rotation, tick.p_BT
        )
        command.v, command.w, command.law = law[:3], law[3:], law
        return command
