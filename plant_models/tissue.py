"""The phantom the probe touches: a soft surface with Hunt–Crossley contact and sliding friction.

Normal force (Hunt & Crossley 1975, with Marhefka & Orin's 1999 form of the damping):

    F_n = max(0, k δⁿ (1 + 3/2 · c · δ̇))    for penetration δ > 0, zero out of contact

a nonlinear spring-damper that is zero at first touch, grows with depth and never pulls (the max).
Friction opposes sliding: Coulomb μ F_n, smoothed over a small velocity so that it does not chatter,
plus a viscous term b v_t (the coupling gel).

Parameters of a gel abdominal phantom (ours, reasoned from its material): soft-tissue phantoms of
gelatin, agar or PVA are made with Young's moduli of a few tens of kPa. A Hertz contact of a probe face
of 2 cm radius on E = 30 kPa (ν ≈ 0.49, E* ≈ 40 kPa) gives k = 4/3 E* √R ≈ 7.5e3 N/m^1.5 and n = 1.5:
7.5 N at 1 cm and 21 N at 2 cm of indentation, the forces of an abdominal scan. c = 0.5 s/m is a
moderately lossy gel. μ = 0.2 for a probe sliding on gel, b = 2 N·s/m.

Breathing moves the surface along its outward normal (`contact_force`'s offset; see
`plant_models.breathing`).

Shapes: a plane (default) or an ellipsoid, a curved abdomen. For the ellipsoid the depth is the
first-order distance -f/|∇f| of its implicit function f = Σ((x - c)ᵢ/aᵢ)² - 1, exact on the surface and
within a few per cent for the centimetres a probe presses in.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, ClassVar, Literal, NamedTuple

import numpy as np

from hoh_cosim.control.vectors import (
    Vec3,
    as_positive_vector,
    as_scalar,
    as_unit_vector,
    as_vector,
    frozen,
)
from hoh_cosim.errors import ConfigError

__all__ = ["SHAPES", "Contact", "PhantomParams", "contact_force", "surface_depth"]

_NO_FORCE = frozen([0.0, 0.0, 0.0])

SHAPES = ("plane", "ellipsoid", "none")


@dataclass(frozen=True)
class PhantomParams:
    UNITS: ClassVar[dict[str, Any]] = {
        "plane_point_B": "m",
        "plane_normal_B": "1",
        "ellipsoid_center_B": "m",
        "ellipsoid_axes": "m",
        "stiffness": "N/m1.5",
        "exponent": "1",
        "damping": "s/m",
        "friction": "1",
        "viscous_friction": "N.s/m",
        "stiction_velocity": "m/s",
    }

    shape: Literal["plane", "ellipsoid", "none"] = "plane"
    plane_point_B: Vec3 = field(default_factory=lambda: frozen([0.0, 0.0, 0.0]))  # [m]
    plane_normal_B: Vec3 = field(default_factory=lambda: frozen([0.0, 0.0, 1.0]))  # outward
    ellipsoid_center_B: Vec3 = field(default_factory=lambda: frozen([-0.10, -0.45, -0.05]))
    ellipsoid_axes: Vec3 = field(default_factory=lambda: frozen([0.20, 0.15, 0.25]))  # [m]
    stiffness: float = 7.5e3  # k [N/m^n]
    exponent: float = 1.5  # n
    damping: float = 0.5  # c [s/m]
    friction: float = 0.2  # μ
    viscous_friction: float = 2.0  # b [N·s/m]
    stiction_velocity: float = 1.0e-3  # [m/s] Coulomb friction reaches 76 % of μ F_n here

    def __post_init__(self) -> None:
        if self.shape not in SHAPES:
            raise ConfigError(f"shape: expected one of {', '.join(SHAPES)}, got {self.shape!r}")
        object.__setattr__(self, "plane_point_B", as_vector(self.plane_point_B, 3, "plane_point_B"))
        object.__setattr__(
            self, "plane_normal_B", as_unit_vector(self.plane_normal_B, "plane_normal_B")
        )
        object.__setattr__(
            self, "ellipsoid_center_B", as_vector(self.ellipsoid_center_B, 3, "ellipsoid_center_B")
        )
        object.__setattr__(
            self, "ellipsoid_axes", as_positive_vector(self.ellipsoid_axes, 3, "ellipsoid_axes")
        )
        for name in ("stiffness", "exponent", "stiction_velocity"):
            object.__setattr__(
                self, name, as_scalar(getattr(self, name), name, low=0.0, low_open=True)
            )
        for name in ("damping", "friction", "viscous_friction"):
            object.__setattr__(self, name, as_scalar(getattr(self, name), name, low=0.0))


class Contact(NamedTuple):
    force_B: Vec3  # force of the phantom on the probe tip
    depth: float  # [m] penetration, > 0 in contact
    normal_B: Vec3  # outward surface normal at the contact


def surface_depth(params: PhantomParams, p_B: Vec3) -> tuple[float, Vec3]:
    """Penetration depth of the point p (positive inside) and the outward normal there."""
    if params.shape == "plane":
        n = params.plane_normal_B
        return float((params.plane_point_B - p_B).dot(n)), n
    if params.shape == "ellipsoid":
        axes = params.ellipsoid_axes
        u = (p_B - params.ellipsoid_center_B) / axes
        f = float(u.dot(u)) - 1.0
        grad = 2.0 * u / axes
        g = math.sqrt(grad.dot(grad))
        if g == 0.0:  # at the centre: deepest; any direction
            return float(np.min(axes)), np.array([0.0, 0.0, 1.0])
        return -f / g, grad / g
    return -math.inf, np.array([0.0, 0.0, 1.0])


def contact_force(
    params: PhantomParams,
    p_B: Vec3,
    v_B: Vec3,
    offset_m: float = 0.0,
    offset_rate_m_s: float = 0.0,
) -> Contact:
    """Force of the phantom on a probe tip at p moving with velocity v.

    `offset_m` moves the surface along its outward normal (breathing: > 0 raises it), at
    `offset_rate_m_s`: the depth grows by the offset, δ = δ₀ + h, and its rate by the surface's
    speed, δ̇ = -v·n + ḣ. The surface moves along its normal only, so sliding is unchanged.
    """
    depth, n = surface_depth(params, p_B)
    depth += offset_m
    if depth <= 0.0:
        return Contact(_NO_FORCE, depth, n)
    v_n = float(v_B.dot(n))
    depth_rate = -v_n + offset_rate_m_s
    spring = params.stiffness * depth**params.exponent
    F_n = max(0.0, spring * (1.0 + 1.5 * params.damping * depth_rate))
    # F = F_n n - (μ F_n tanh(|v_t|/v_s)/|v_t| + b) v_t  with  v_t = v - (v·n) n
    n0, n1, n2 = n.tolist()
    v0, v1, v2 = v_B.tolist()
    t0, t1, t2 = v0 - v_n * n0, v1 - v_n * n1, v2 - v_n * n2
    force = [F_n * n0, F_n * n1, F_n * n2]
    v_t = np.array((t0, t1, t2))
    speed = math.sqrt(v_t.dot(v_t))
    if speed > 0.0:
        friction = params.friction * F_n * math.tanh(speed / params.stiction_velocity)
        c = friction / speed + params.viscous_friction
        force = [force[0] - c * t0, force[1] - c * t1, force[2] - c * t2]
    return Contact(np.array(force), depth, n)
