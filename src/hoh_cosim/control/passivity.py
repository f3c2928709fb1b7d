"""A passivity observer and controller with a bounded energy tank on the admittance loop.

Hannaford and Ryu (IEEE T-RA 18(1), 2002, "Time-domain passivity control of haptic interfaces")
watch the energy that flows into a one-port and, when it turns negative (the port has put out
energy it never took in), dissipate the excess with a time-varying damper. The port here is the
robot as the hand feels it, in admittance causality: force in (the hand's force F̂, contact-
compensated, eq. 11-12), velocity out (the tip's measured velocity v, from the TCP positions).
Their passivity observer (PO), one controller period Δt at a time:

    E(n) = E(n-1) + F̂(n) · v(n) Δt                      (energy into the robot since the start)

A robot that only yields to the hand takes energy in (F̂ · v >= 0); delays between the hand and
the motion (sensor, filter, controller period, the robot's own cycle) can make it give energy back,
which is how admittance control goes unstable against a stiff hand or a rigid table. Ferraguti,
Preda, Manurung, Bonfè, Lambercy, Gassert, Muradore, Fiorini and Secchi (IEEE T-RO 31(4), 2015,
"An energy tank-based interactive control architecture for autonomous and teleoperated robotic
surgery") keep such energy in a tank with an upper bound, so that a long passive push cannot store
a reservoir that a later oscillation would draw on for seconds before anything acts:

    E(n) = min(E_max, E(n-1) + F̂(n) · v(n) Δt)           (the tank)

The passivity controller (PC) acts on the next command v_c so that the tank, counting the command's
own flow, stays non-negative (the series element of Hannaford and Ryu's admittance-type PC):

    P = F̂ · v_c ;   if E(n) + P Δt < 0:   v_c ← v_c + β F̂,   β = -(E(n) + P Δt) / (Δt ‖F̂‖²)

that is, the command is given just the yield along the hand's force that dissipates the deficit:
the robot stops pushing back against the hand. β >= 0 is a damping (a conductance), and the PC does
nothing while the tank holds energy: in ordinary guiding the law is untouched.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

from hoh_cosim.control.vectors import Vec3, as_scalar

__all__ = ["PassivityController", "PassivityParams"]


@dataclass(frozen=True)
class PassivityParams:
    """enabled: False leaves the law's command untouched; tank_max_J: E_max, the tank's bound
    (also its content at the start)."""

    UNITS: ClassVar[dict[str, Any]] = {"tank_max_J": "J"}

    enabled: bool = False
    tank_max_J: float = 0.02

    def __post_init__(self) -> None:
        object.__setattr__(
            self, "tank_max_J", as_scalar(self.tank_max_J, "tank_max_J", low=0.0, low_open=True)
        )


class PassivityController:
    """The PO, the tank and the PC of the module docstring, stepped at the controller's rate."""

    def __init__(self, params: PassivityParams | None = None) -> None:
        self.params = params or PassivityParams()
        self.reset()

    def reset(self) -> None:
        self.energy_J = self.params.tank_max_J  # the tank starts full
        self._t_prev: float | None = None
        self._p_prev: list[float] | None = None
        self.dissipated_J = 0.0  # energy the PC has dissipated since the reset

    def observe(self, t: float, F: Vec3, p_B: Vec3) -> float:
        """The PO: the tip's velocity since the last tick from its positions, the energy that
        flowed in with the force `F`; returns Δt (0 on the first tick)."""
        dt = 0.0
        pos = p_B.tolist()
        if self._t_prev is not None and self._p_prev is not None and t > self._t_prev:
            dt = t - self._t_prev
            # F̂ · v Δt = F̂ · (p - p_prev), v the mean velocity over Δt
            f0, f1, f2 = F.tolist()
            q0, q1, q2 = self._p_prev
            work = f0 * (pos[0] - q0) + f1 * (pos[1] - q1) + f2 * (pos[2] - q2)
            # E(n) = min(E_max, E(n-1) + F̂ · v Δt)
            self.energy_J = min(self.params.tank_max_J, self.energy_J + work)
        self._t_prev, self._p_prev = t, pos
        return dt

    def control(self, v_c: Vec3, F: Vec3, dt: float) -> tuple[Vec3, bool]:
        """The PC on the next command: (v_c, False) while the tank covers it, else the command
        with the yield along F̂ that keeps the tank at zero, and True."""
        if dt <= 0.0:
            return v_c, False
        P = float(F.dot(v_c))
        deficit = self.energy_J + P * dt
        FF = float(F.dot(F))
        if deficit >= 0.0 or FF == 0.0:
            return v_c, False
        beta = -deficit / (dt * FF)
        self.dissipated_J += -deficit
        return v_c + beta * F, True

    def step(self, t: float, F: Vec3, p_B: Vec3, v_c: Vec3, control: bool) -> tuple[Vec3, bool]:
        """One controller tick: the PO (`observe`), then, if `control`, the PC on the command
        (`control`); the command (v_c itself when the PC did not act) and whether it acted."""
        dt = self.observe(t, F, p_B)
        if not control:
            return v_c, False
        return self.control(v_c, F, dt)
