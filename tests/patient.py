"""A breathing patient under a robot that integrates its commanded speed, for the controller's
tests of what it does in contact (hold-on-release, following the breath)."""

from __future__ import annotations

import numpy as np

from tests.estimates import controller_inputs

DT = 8e-3  # the CB3's 125 Hz
AXIS = np.array([0.0, 0.0, -1.0])  # the probe points down
K = 1200.0  # [N/m] the tissue


class Patient:
    """A breathing surface under a robot that integrates its commanded speed: the contact force is
    k (surface - tip) along the axis, the wrist reads hand and contact, the probe sensor contact."""

    def __init__(self, amplitude_m: float = 0.01, rate_hz: float = 0.25) -> None:
        self.z = 0.3 - 0.008  # the tip, 8 mm into a surface at 0.3 m (9.6 N)
        self.amplitude, self.rate = amplitude_m, rate_hz

    def surface(self, t: float) -> float:
        return 0.3 + self.amplitude * np.sin(2 * np.pi * self.rate * t)

    def force(self, t: float) -> float:
        return max(0.0, K * (self.surface(t) - self.z))

    def inputs(self, t: float, hand_N: float = 0.0, hand_x_N: float = 0.0) -> dict:
        c = self.force(t)
        contact = -c * AXIS  # the phantom pushes the probe up
        hand = np.array([hand_x_N, 0.0, -hand_N])
        return controller_inputs(
            F_hand_B=hand + contact,  # the wrist's estimate: eq. 11-12 leaves the hand
            F_probe_B=contact,
            F_hand_meas_B=hand + contact,
            p_BT_B=[0.3, 0.0, self.z],
            probe_axis_B=AXIS,
        )


def run(ctl, patient, t0, t1, **hand):
    forces, flags, xs = [], [], []
    x = 0.0
    for k in range(round(t0 / DT), round(t1 / DT)):
        t = k * DT
        out = ctl.step(t, DT, patient.inputs(t, **hand))
        patient.z += out["twist_B"][2] * DT
        x += out["twist_B"][0] * DT
        forces.append(patient.force(t))
        flags.append(int(out["status"][0]))
        xs.append(x)
    return np.array(forces), np.array(flags), np.array(xs)
