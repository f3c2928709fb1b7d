"""The probe and its housing: geometry, mass, the wrench they put on the wrist sensor, cable drag.

Frames (DESIGN.md §5): E flange, S wrist F/T sensor, P probe-contact sensor, H the handle where the
hand pushes, C the tool's centre of mass, T the probe tip (the robot's TCP), K where the cable leaves
the housing.

Geometry (ours, with the seed's figures where it has them):
- S sits on the flange turned half a turn about x (R_ES = Rx(π)), so that at the home pose (probe
  pointing down) R_BS is the seed's eq. 1; the probe sensor is mounted as eq. 2 says (R_SP of
  `hoh_cosim.control.frames`). S's z axis points from the tool towards the robot, so the tool hangs
  along -z_S.
- 0.48 kg below the wrist sensor (the seed's scale, 5.B); centre of mass x, y as the seed's fit
  (-0.01250, -0.00033) m (4.B), z = -0.075 m (the seed did not identify it: about a third of the way
  down a 0.20 m housing-and-probe).
- The FT-150 is 37.5 mm thick (flange to S); the probe sensor 60 mm, the handle 90 mm and the tip
  200 mm below S. The TCP frame T has the flange's orientation.
- Inertia about C: a 0.48 kg cylinder of radius 3 cm and length 0.2 m.

The wrench on the wrist sensor is Newton–Euler on the tool, everything in the base frame B:

    f = F_hand + F_contact + F_cable + m (g - a_C)
    τ_S = τ_hand + r_SH × F_hand + r_ST × F_contact + r_SK × F_cable + r_SC × m (g - a_C)
          - (I_C α + ω × I_C ω)

then turned into S. At rest and untouched it is exactly `tool_weight_wrench_S`, the estimator's model.

Cable drag (seed 5.B, Fig. 17): the probe's cable leaves the housing at K along its y axis and runs
to an anchor A fixed beside the robot. It pulls K towards A with a constant tension and hangs part of
its weight on K. The pull depends on where K is relative to A, not only on the direction of gravity,
so no mass and centre of mass can model it: tilting the tool 45° one way and 135° the other leaves
different residuals after gravity compensation, as the seed saw.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from hoh_cosim.control.frames import R_SP_SEED, rotvec_to_matrix, skew
from hoh_cosim.control.vectors import (
    Rot3,
    Vec3,
    as_nonnegative_vector,
    as_rotation,
    as_scalar,
    as_vector,
    cross3,
    frozen,
)

__all__ = ["CableDrag", "ToolLoads", "ToolModel", "cable_force_B"]

R_X_HALF_TURN = frozen(rotvec_to_matrix([math.pi, 0.0, 0.0]))


@dataclass(frozen=True)
class CableDrag:
    """A cable from the housing (point K, in S) to an anchor A fixed in the base frame."""

    UNITS: ClassVar[dict[str, Any]] = {
        "p_SK_S": "m",
        "anchor_B": "m",
        "tension_N": "N",
        "hanging_weight_N": "N",
    }

    enabled: bool = False
    p_SK_S: Vec3 = field(default_factory=lambda: frozen([0.0, 0.035, -0.05]))  # [m] exit point
    anchor_B: Vec3 = field(default_factory=lambda: frozen([0.25, -0.45, 0.05]))  # [m]
    tension_N: float = 0.6  # [N] pull towards the anchor
    hanging_weight_N: float = 0.3  # [N] of the cable's weight hanging on K

    def __post_init__(self) -> None:
        object.__setattr__(self, "p_SK_S", as_vector(self.p_SK_S, 3, "p_SK_S"))
        object.__setattr__(self, "anchor_B", as_vector(self.anchor_B, 3, "anchor_B"))
        object.__setattr__(self, "tension_N", as_scalar(self.tension_N, "tension_N", low=0.0))
        object.__setattr__(
            self, "hanging_weight_N", as_scalar(self.hanging_weight_N, "hanging_weight_N", low=0.0)
        )


@dataclass(frozen=True)
class ToolModel:
    """Mass properties and mounting of everything below the wrist sensor."""

    UNITS: ClassVar[dict[str, Any]] = {
        "mass_kg": "kg",
        "p_SC_S": "m",
        "inertia_C_S": "kg.m2",
        "p_ES_E": "m",
        "R_ES": "1",
        "R_SP": "1",
        "p_SP_S": "m",
        "p_SH_S": "m",
        "p_ST_S": "m",
        "probe_mass_kg": "kg",
    }

    mass_kg: float = 0.48
    p_SC_S: Vec3 = field(default_factory=lambda: frozen([-0.01250, -0.00033, -0.075]))  # [m]
    inertia_C_S: Vec3 = field(default_factory=lambda: frozen([1.7e-3, 1.7e-3, 2.2e-4]))  # [kg m²]
    p_ES_E: Vec3 = field(default_factory=lambda: frozen([0.0, 0.0, 0.0375]))  # [m]
    R_ES: Rot3 = field(default_factory=lambda: R_X_HALF_TURN.copy())
    R_SP: Rot3 = field(default_factory=lambda: R_SP_SEED.copy())
    p_SP_S: Vec3 = field(default_factory=lambda: frozen([0.0, 0.0, -0.06]))  # [m]
    p_SH_S: Vec3 = field(default_factory=lambda: frozen([0.0, 0.0, -0.09]))  # [m] handle
    p_ST_S: Vec3 = field(default_factory=lambda: frozen([0.0, 0.0, -0.20]))  # [m] probe tip
    probe_mass_kg: float = 0.0  # [kg] below the probe sensor (not modelled by default)
    cable: CableDrag = field(default_factory=CableDrag)

    def __post_init__(self) -> None:
        object.__setattr__(self, "mass_kg", as_scalar(self.mass_kg, "mass_kg", low=0.0))
        object.__setattr__(
            self, "probe_mass_kg", as_scalar(self.probe_mass_kg, "probe_mass_kg", low=0.0)
        )
        for name in ("p_SC_S", "p_ES_E", "p_SP_S", "p_SH_S", "p_ST_S"):
            object.__setattr__(self, name, as_vector(getattr(self, name), 3, name))
        object.__setattr__(
            self, "inertia_C_S", as_nonnegative_vector(self.inertia_C_S, 3, "inertia_C_S")
        )
        object.__setattr__(self, "R_ES", as_rotation(self.R_ES, "R_ES"))
        object.__setattr__(self, "R_SP", as_rotation(self.R_SP, "R_SP"))

    def flange_frames(self) -> dict[str, tuple[Vec3, Rot3]]:
        """Every tool frame's (p_EX_E, R_EX): S, P, H, C, T (TCP, with the flange's orientation)."""

        def at(p_SX_S: Vec3, R_SX: Rot3) -> tuple[Vec3, Rot3]:
            return self.p_ES_E + self.R_ES @ p_SX_S, self.R_ES @ R_SX

        eye = np.eye(3)
        return {
            "ft_sensor": (self.p_ES_E.copy(), self.R_ES.copy()),
            "probe_sensor": at(self.p_SP_S, self.R_SP),
            "handle": at(self.p_SH_S, eye),
            "tool_com": at(self.p_SC_S, eye),
            "tcp": at(self.p_ST_S, self.R_ES.T),
        }


def cable_force_B(cable: CableDrag, p_BK_B: Vec3, g_B: Vec3) -> Vec3:
    """Force of the cable on the housing at K, in B: tension towards the anchor plus hanging weight."""
    to_anchor = cable.anchor_B - p_BK_B
    n = math.sqrt(float(to_anchor @ to_anchor))
    pull = to_anchor * (cable.tension_N / n) if n > 0.0 else np.zeros(3)
    g = math.sqrt(float(g_B @ g_B))
    return pull + g_B * (cable.hanging_weight_N / g)


class ToolLoads:
    """What ideal sensors read, from the tool's motion and the forces on it (Newton–Euler above).

    Computed in S, where the tool's geometry is constant: the three moment arms become one product
    with a precomputed [[r_SH]× [r_ST]× [r_SC]×] and the inertia stays diagonal.
    """

    def __init__(self, tool: ToolModel, g_B: Vec3) -> None:
        self.tool = tool
        self.g_B = np.asarray(g_B, dtype=np.float64)
        self._g_B_floats = tuple(self.g_B.tolist())
        self._arms = np.hstack([skew(tool.p_SH_S), skew(tool.p_ST_S), skew(tool.p_SC_S)])
        self._inertia_floats = tuple(tool.inertia_C_S.tolist())
        self._R_PS = tool.R_SP.T.copy()
        self._make_scratch()

    def _make_scratch(self) -> None:
        """The rows in B and in S, and views of them, written by every reading (no result refers
        to them)."""
        self._rows_B = np.empty((6, 3))
        self._rows_B_flat = self._rows_B.reshape(18)
        self._rows_S = np.empty((6, 3))
        self._forces_S = self._rows_S[:3].reshape(9)  # F_hand, F_contact, m (g - a_C)
        self._F_contact_S = self._rows_S[1]

    # A copy (pickle, deepcopy: an FMU's state) would turn the views into arrays of their own:
    # copies are made without the scratch, which is made anew.
    _SCRATCH = ("_rows_B", "_rows_B_flat", "_rows_S", "_forces_S", "_F_contact_S")

    def __getstate__(self) -> dict[str, Any]:
        return {k: v for k, v in self.__dict__.items() if k not in self._SCRATCH}

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
        self._make_scratch()

    def readings(
        self,
        R_BS: Rot3,
        a_C_B: Vec3 | list[float],
        omega_B: Vec3 | list[float],
        alpha_B: Vec3 | list[float],
        F_hand_B: Vec3 | list[float],
        tau_hand_B: Vec3 | list[float],
        F_contact_B: Vec3 | list[float],
        p_BK_B: Vec3 | None = None,
        a_P_B: Vec3 | None = None,
    ) -> tuple[np.ndarray, Vec3]:
        """(wrench of the tool on the wrist sensor in S, force of the probe on the probe sensor in P).

        The probe sensor carries the contact force and the weight and inertia of the probe part below
        it (`probe_mass_kg`, accelerating with `a_P_B`). The 3-vectors may be arrays or lists of
        floats (lists are faster).
        """
        tool = self.tool
        m = tool.mass_kg
        gx, gy, gz = self._g_B_floats
        a0, a1, a2 = a_C_B
        # rows turned into S in one product: v_S = R_BSᵀ v_B  <=>  row_S = row_B R_BS
        self._rows_B_flat[:] = [
            *F_hand_B,
            *F_contact_B,
            m * (gx - a0),  # m (g - a_C)
            m * (gy - a1),
            m * (gz - a2),
            *tau_hand_B,
            *omega_B,
            *alpha_B,
        ]
        rows_S = self._rows_B.dot(R_BS, self._rows_S)
        (h0, h1, h2), (c0, c1, c2), (b0, b1, b2), (t0, t1, t2), (wx, wy, wz), (ax, ay, az) = (
            rows_S.tolist()
        )
        f0, f1, f2 = h0 + c0 + b0, h1 + c1 + b1, h2 + c2 + b2
        r0, r1, r2 = self._arms.dot(self._forces_S).tolist()
        # I α + ω × I ω with the diagonal inertia of S, in plain floats (three components)
        ix, iy, iz = self._inertia_floats
        tau0 = t0 + r0 - (ix * ax + (iz - iy) * wy * wz)
        tau1 = t1 + r1 - (iy * ay + (ix - iz) * wz * wx)
        tau2 = t2 + r2 - (iz * az + (iy - ix) * wx * wy)
        if tool.cable.enabled and p_BK_B is not None:
            k0, k1, k2 = (R_BS.T @ cable_force_B(tool.cable, p_BK_B, self.g_B)).tolist()
            f0, f1, f2 = f0 + k0, f1 + k1, f2 + k2
            k0, k1, k2 = cross3(tool.cable.p_SK_S, (k0, k1, k2)).tolist()
            tau0, tau1, tau2 = tau0 + k0, tau1 + k1, tau2 + k2
        wrench_S = np.array((f0, f1, f2, tau0, tau1, tau2))

        F_P_S = self._F_contact_S  # the contact force, already in S
        if tool.probe_mass_kg > 0.0:
            a = np.zeros(3) if a_P_B is None else a_P_B
            F_P_S = F_P_S + R_BS.T @ (tool.probe_mass_kg * (self.g_B - a))
        return wrench_S, self._R_PS.dot(F_P_S)
