"""The hand-guiding controller block: estimated forces in, a speedL twist command out (seed 000, 3.F).

Per tick:

    checks     the supervisor's `check_inputs`: non-finite input (latched) · estimator not ready ·
               stale FT-150 or probe data · probe force at the stop limit (latched)
                                                                  → any of these: zero twist, stop flag
    law        F̃ = F_hand - F_probe (eq. 11–12, if contact compensation is on) and, with it,
               τ̃ = τ_hand - p_RT × F_probe (the contact's moment about the torque's reference
               point, `contact_torque`); v = law(F̃) (eq. 10 or an alternative: `variable` adapts
               eq. 10's slope to the hand's intent), ω = law(τ̃)
    glide      eq. 10 lighter for a steady push than for a quick one, with a smaller deadband
               once the probe moves, and quieter along the probe for a hand keeping the contact
               (`hoh_cosim.control.glide`, if on; eq. 10's law only): part of the law, before the
               release detector reads it
    release    the hand let go (`hoh_cosim.control.release`, if on): the command is rest, braked at
               `max_brake_accel`, until the hand pushes again
    hold       hold-on-release (`hoh_cosim.control.hold`, if on): in contact, once the hand let go
               or has asked for nothing a while, the robot holds the probe's axial contact force
               (a PI along the probe axis) and the rest of the pose, until a touch of the handle
               hands back (blended) or the contact is lost (then rest)
    passivity  the passivity observer and controller with its energy tank
               (`hoh_cosim.control.passivity`, if on; not while braking or holding): the command
               yields to the hand when the robot has given back more energy than it took
    fixture    while |F_probe| > threshold no motion out of the surface (3.F.3, if on; not while
               holding): along `fixture_up_B` (the seed's horizontal plane) or, with
               `fixture_normal` = contact, along the estimated surface normal, the probe force's
               direction
    follow     following the breath while the hand steers (`hoh_cosim.control.follow`, if on; not
               while braking or holding): in contact, the axial contact force's departure from its
               level over about a breath, g (c - c̄) / k̂, and the surface's estimated speed,
               κ ṡ, are added along the probe axis, after the
               fixture (which keeps the hand from lifting the probe off; riding a rising abdomen
               is not that)
    limits     the supervisor's `limit_command`: speed clamp · acceleration clamp (the braking
               deceleration towards rest after a release) · probe-force soft cap · workspace box

The order puts the hard limits last: the soft force cap and the workspace box override the
acceleration clamp, never the other way round. The output is a TCP twist [v; ω] in the base frame with
UR speedL semantics, and a `Status` (see `hoh_cosim.control.supervisor`) whose `ok` the runner obeys.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, ClassVar, Literal

import numpy as np

from hoh_cosim.control.admittance import (
    ROTATION_GAINS,
    TRANSLATION_GAINS,
    AdmittanceGains,
    apply_law,
    contact_compensated,
    horizontal_fixture,
)
from hoh_cosim.control.block import TWIST_UNITS, Port
from hoh_cosim.control.follow import BreathFollower, FollowParams
from hoh_cosim.control.glide import Glide, GlideParams
from hoh_cosim.control.hold import ContactHold, HoldEnd, HoldParams, HoldPhase
from hoh_cosim.control.kernels import passivity_controller, release_detector, variable_law
from hoh_cosim.control.passivity import PassivityParams
from hoh_cosim.control.release import ReleaseDetector, ReleaseParams, ReleasePhase
from hoh_cosim.control.supervisor import (
    LATCHED_FLAGS,
    STOP_FLAGS,
    LimitParams,
    Status,
    check_inputs,
    limit_command,
)
from hoh_cosim.control.variable_admittance import VariableAdmittanceParams
from hoh_cosim.control.vectors import Vec, Vec3, as_scalar, as_unit_vector, frozen
from hoh_cosim.errors import ConfigError

__all__ = ["FIXTURE_NORMALS", "ControllerParams", "HandGuidingController"]

FixtureNormal = Literal["fixed", "contact"]
FIXTURE_NORMALS: tuple[str, ...] = ("fixed", "contact")

_FIXTURE = int(Status.FIXTURE)
_RELEASED = int(Status.RELEASED)
_BRAKING = int(Status.BRAKING)
_PASSIVITY = int(Status.PASSIVITY)
_HOLDING = int(Status.HOLDING) | _RELEASED  # the hand let go: RELEASED too
_HANDING_BACK = int(Status.HANDING_BACK)
_FOLLOWING = int(Status.FOLLOWING)
_LATCHED = int(LATCHED_FLAGS)
_STOP = int(STOP_FLAGS)


@dataclass(frozen=True)
class ControllerParams:
    UNITS: ClassVar[dict[str, Any]] = {
        "rotation.slope": "rad/(s.N.m)",
        "rotation.deadband": "N.m",
        "rotation.sigmoid_max_speed": "rad/s",
        "rotation.sigmoid_midpoint": "N.m",
        "rotation.sigmoid_steepness": "1/(N.m)",
        "fixture_threshold_N": "N",
        "fixture_up_B": "1",
        "ft_period_s": "s",
        "probe_period_s": "s",
    }
    TUNABLE: ClassVar[frozenset[str]] = frozenset(
        {
            "translation",
            "rotation",
            "contact_compensation",
            "contact_torque",
            "virtual_fixture",
            "fixture_threshold_N",
            "fixture_up_B",
            "fixture_normal",
            "limits",
            "release",
            "variable",
            "passivity",
            "hold",
            "follow",
            "glide",
        }
    )

    translation: AdmittanceGains = TRANSLATION_GAINS
    rotation: AdmittanceGains = ROTATION_GAINS
    contact_compensation: bool = True  # eq. 11–12
    # ... and the contact's moment out of the torque (the estimator's tau_probe_B)
    contact_torque: bool = True
    virtual_fixture: bool = False  # 3.F.3
    fixture_threshold_N: float = 1.0  # [N] contact force that engages the fixture
    fixture_up_B: Vec3 = field(default_factory=lambda: frozen([0.0, 0.0, 1.0]))  # unit, in B
    # fixed: no motion along fixture_up_B (the seed's horizontal plane); contact: none along the
    # estimated surface normal, the probe force's direction
    fixture_normal: FixtureNormal = "fixed"
    limits: LimitParams = field(default_factory=LimitParams)
    release: ReleaseParams = field(default_factory=ReleaseParams)  # release detection, brake
    variable: VariableAdmittanceParams = field(default_factory=VariableAdmittanceParams)
    passivity: PassivityParams = field(default_factory=PassivityParams)
    hold: HoldParams = field(default_factory=HoldParams)  # hold-on-release
    follow: FollowParams = field(default_factory=FollowParams)  # the breath, while steered
    glide: GlideParams = field(default_factory=GlideParams)  # eq. 10 lighter for a steady push
    use_probe: bool = True  # False: no probe sensor (no compensation, fixture or force limits)
    ft_period_s: float = 0.005  # [s] expected FT-150 packet period (seed: 5 ms)
    probe_period_s: float = 0.02  # [s] expected FSE103 packet period (50 Hz)

    def __post_init__(self) -> None:
        if self.glide.enabled and self.translation.law != "deadband_linear":
            raise ConfigError(
                "glide.enabled: glide works on eq. 10's law; expected translation.law "
                f"deadband_linear, got {self.translation.law!r}"
            )
        if self.fixture_normal not in FIXTURE_NORMALS:
            raise ConfigError(
                f"fixture_normal: expected one of {', '.join(FIXTURE_NORMALS)}, "
                f"got {self.fixture_normal!r}"
            )
        object.__setattr__(self, "fixture_up_B", as_unit_vector(self.fixture_up_B, "fixture_up_B"))
        object.__setattr__(
            self,
            "fixture_threshold_N",
            as_scalar(self.fixture_threshold_N, "fixture_threshold_N", low=0.0),
        )
        for name in ("ft_period_s", "probe_period_s"):
            object.__setattr__(
                self, name, as_scalar(getattr(self, name), name, low=0.0, low_open=True)
            )


class HandGuidingController:
    """Admittance, contact compensation, virtual fixture and limits under the block contract."""

    inputs: ClassVar[tuple[Port, ...]] = (
        Port("F_hand_B", 3, "N", "estimated external force on the tool (hand + contact), in B"),
        Port("tau_hand_B", 3, "N.m", "estimated external torque on the tool, in B"),
        Port("F_probe_B", 3, "N", "estimated contact force on the probe, in B"),
        Port("ft_age", 1, "s", "time since the last FT-150 packet"),
        Port("probe_age", 1, "s", "time since the last probe-sensor packet"),
        Port("ready", 1, "1", "1 when the estimator's outputs are valid"),
        Port("p_BT_B", 3, "m", "measured TCP position in the base frame"),
        Port("F_hand_meas_B", 3, "N", "newest compensated, unfiltered wrist force, in B (held)"),
        Port("tau_probe_B", 3, "N.m", "the contact force's moment about the torque's point, in B"),
        Port("probe_axis_B", 3, "1", "the probe's axis in B, a unit vector from handle to tip"),
        Port(
            "F_probe_meas_B",
            3,
            "N",
            "newest corrected, unfiltered probe-sensor force, in B (held): the hold's force",
        ),
    )
    # left out of a scenario it is 0, and the hold regulates the wrist's packet instead
    OPTIONAL_INPUTS: ClassVar[frozenset[str]] = frozenset({"F_probe_meas_B"})
    outputs: ClassVar[tuple[Port, ...]] = (
        Port(
            "twist_B",
            6,
            TWIST_UNITS,
            "commanded TCP twist [v; ω] in the base frame (speedL)",
        ),
        Port(
            "twist_law_B",
            6,
            TWIST_UNITS,
            "the admittance law's twist before the fixture and the limits",
        ),
        Port(
            "status",
            1,
            "1",
            "Status flags of this tick (hoh_cosim.control.supervisor.Status)",
            flags=Status,
        ),
        Port(
            "brake_accel",
            1,
            "m/s2",
            "speedL's acceleration while braking to rest after a release, 0 otherwise",
        ),
    )

    def __init__(self, params: ControllerParams | None = None) -> None:
        self.retune(params or ControllerParams())
        self.reset()

    def retune(self, params: ControllerParams) -> None:
        """New parameters without losing the state (latched stops, the last command)."""
        self.params = params
        if hasattr(self, "_release"):
            self._release.params = params.release
            self._variable.params = params.variable
            self._passivity.params = params.passivity
            self._hold.params = params.hold
            self._follow.params = params.follow
            self._glide.params = params.glide
            if not params.glide.enabled:  # switched off: nothing of it left for a later switch on
                self._glide.reset()
        # Both laws elementwise and of one kind: run them as one 6-vector law (half the work).
        tr, rot = params.translation, params.rotation
        self._law6: AdmittanceGains | None = None
        if tr.law == rot.law and tr.law not in ("isotropic", "variable"):
            self._law6 = _stack_gains(tr, rot)
        self._box = (
            params.limits.workspace_min_B.tolist(),
            params.limits.workspace_max_B.tolist(),
        )

    def reset(self) -> None:
        """Clear the latched stops and the previous command."""
        self._latched = 0
        self._bits = 0
        self._v_prev = np.zeros(3)
        self._w_prev = np.zeros(3)
        # compiled (hoh_cosim.control.kernels) unless HOH_COSIM_KERNELS=pure
        self._release = release_detector(self.params.release)
        self._variable = variable_law(self.params.variable)
        self._passivity = passivity_controller(self.params.passivity)
        self._hold = ContactHold(self.params.hold)
        self._follow = BreathFollower(self.params.follow)
        self._glide = Glide(self.params.glide)

    @property
    def release(self) -> ReleaseDetector:
        """The release detector and its state (phase, time of the last release)."""
        return self._release

    def prepare(self, dt: float) -> None:
        """What can be computed before a loop stepped every `dt` (the hold's and the follow's
        filter gains), so that no cycle of a robot's loop pays for it."""
        if self.params.hold.enabled:
            self._hold.prepare(dt)
        if self.params.follow.enabled:
            self._follow.prepare(dt)

    @property
    def follow(self) -> BreathFollower:
        """Following the breath while the hand steers, and its state (level, blend)."""
        return self._follow

    @property
    def glide(self) -> Glide:
        """Glide's state (the moving deadband, the low-passed command)."""
        return self._glide

    @property
    def hold(self) -> ContactHold:
        """Hold-on-release and its state (phase, setpoint, why the last hold ended)."""
        return self._hold

    @property
    def status(self) -> Status:
        """The flags of the last step."""
        return Status(self._bits)

    def step(self, t: float, dt: float, inputs: Mapping[str, Vec]) -> dict[str, Vec]:
        p = self.params
        lim = p.limits
        status = self._latched | check_inputs(
            inputs,
            lim,
            ft_period_s=p.ft_period_s,
            probe_period_s=p.probe_period_s,
            use_probe=p.use_probe,
        )
        self._latched |= status & _LATCHED
        if status & _STOP:
            self._v_prev = np.zeros(3)
            self._w_prev = np.zeros(3)
            self._bits = status
            self._release.reset()
            self._variable.reset()
            self._passivity.reset()
            self._hold.stop()
            self._follow.stop()
            self._glide.reset()
            return {
                "twist_B": np.zeros(6),
                "twist_law_B": np.zeros(6),
                "status": np.array([float(status)]),
                "brake_accel": _NO_BRAKE,
            }

        F_probe = inputs["F_probe_B"]
        F = inputs["F_hand_B"]
        tau = inputs["tau_hand_B"]
        compensated = p.use_probe and p.contact_compensation
        if compensated:
            F = contact_compensated(F, F_probe)
            tau_probe = inputs.get("tau_probe_B")
            if p.contact_torque and tau_probe is not None:
                # τ̃ = τ_hand - p_RT × F_probe: the contact's moment is not the hand's
                tau = tau - tau_probe
        if self._law6 is not None:
            twist_law = apply_law(np.concatenate([F, tau]), self._law6)
            v, w = twist_law[:3], twist_law[3:]
        else:
            if p.translation.law == "variable":
                twist_law = self._variable.step_twist(
                    t, F, tau, p.translation, p.rotation, inputs["p_BT_B"]
                )
                v, w = twist_law[:3], twist_law[3:]
            else:
                v = apply_law(F, p.translation)
                w = apply_law(tau, p.rotation)
                twist_law = np.concatenate([v, w])
        if p.glide.enabled:
            axis = inputs.get("probe_axis_B") if p.use_probe else None
            c = None if axis is None else -float(F_probe.dot(axis))
            v = self._glide.step(dt, F, p.translation.slope, p.translation.deadband, c)
            twist_law = np.concatenate([v, w])

        hold = self._hold
        holding = hold.active
        F_raw = None
        if p.release.enabled or self._release.released or holding or p.hold.enabled:
            F_raw = inputs.get("F_hand_meas_B")
            if F_raw is not None and compensated:
                F_raw = contact_compensated(F_raw, F_probe)
        braking = False
        if (p.release.enabled or self._release.released) and not holding:
            braking = self._release.step(
                t,
                F,
                F_raw,
                p.translation.deadband,
                bool(twist_law.any()),
                F_probe if p.use_probe else None,
            )
            if braking:
                v, w = _ZERO3, _ZERO3
                status |= _RELEASED

        if p.use_probe and (p.hold.enabled or holding):
            axis = inputs.get("probe_axis_B")
            if not holding and p.hold.enabled and axis is not None:
                in_contact = braking and self._release.phase == ReleasePhase.RELEASED_CONTACT
                if hold.watch(t, F, p.translation.deadband, axis, F_probe, in_contact):
                    hold.engage(
                        t,
                        F,
                        inputs.get("F_hand_meas_B"),
                        F_probe,
                        axis,
                        inputs["p_BT_B"],
                        self._v_prev,
                        inputs.get("F_probe_meas_B"),
                    )
                    holding = True
            if holding:
                v_hold = hold.step(
                    t,
                    dt,
                    F,
                    F_raw,
                    p.translation.deadband,
                    inputs.get("F_hand_meas_B"),
                    F_probe,
                    inputs["p_BT_B"],
                    v,
                    inputs.get("F_probe_meas_B"),
                    inputs["probe_age"][0],
                    inputs["ft_age"][0],
                )
                if v_hold is not None:
                    braking = False
                    if hold.phase == HoldPhase.HOLDING:
                        v, w = v_hold, _ZERO3
                        status |= _HOLDING
                    else:  # handing back: ω = β ω_law, as v is blended in the hold
                        v, w = v_hold, hold.blend * w
                        status |= _HANDING_BACK
                elif hold.ended == HoldEnd.HANDED_BACK:
                    self._release.resume()
                    holding = False
                else:  # the contact lost, or the tip too far: rest, until the hand pushes
                    self._release.hold_at_rest(t)
                    v, w = _ZERO3, _ZERO3
                    braking = True
                    holding = False
                    status |= _RELEASED

        if braking or holding:
            self._glide.reset()
        if p.passivity.enabled:
            v, acted = self._passivity.step(
                t, F, inputs["p_BT_B"], v, control=not braking and not holding
            )
            if acted:
                status |= _PASSIVITY

        if p.use_probe and p.virtual_fixture and not holding:
            up = p.fixture_up_B
            if p.fixture_normal == "contact":
                size = float(F_probe.dot(F_probe))
                up = F_probe / math.sqrt(size) if size > 0.0 else up
            v, engaged = horizontal_fixture(v, F_probe, p.fixture_threshold_N, up)
            if engaged:
                status |= _FIXTURE
        if p.use_probe and p.follow.enabled:
            axis = inputs.get("probe_axis_B")
            if braking or holding or axis is None or not axis.any():
                self._follow.stop()
            else:
                v_follow = self._follow.step(
                    dt,
                    F,
                    F_probe,
                    axis,
                    t,
                    inputs["p_BT_B"],
                    inputs.get("F_hand_meas_B"),
                    inputs.get("F_probe_meas_B"),
                    float(inputs["ft_age"][0]),
                )
                if v_follow is not None:
                    v = v + v_follow
                    status |= _FOLLOWING
        v, w, clamped = limit_command(
            v,
            w,
            self._v_prev,
            self._w_prev,
            dt,
            F_probe if p.use_probe else None,
            inputs["p_BT_B"],
            lim,
            self._box,
            braking=braking,
        )
        status |= clamped

        self._v_prev, self._w_prev = v, w
        self._bits = status
        return {
            "twist_B": np.concatenate([v, w]),
            "twist_law_B": twist_law,
            "status": np.array([float(status)]),
            "brake_accel": np.array([lim.max_brake_accel]) if braking else _NO_BRAKE,
        }


_ZERO3 = frozen(np.zeros(3))
_NO_BRAKE = frozen([0.0])


def _stack_gains(tr: AdmittanceGains, rot: AdmittanceGains) -> AdmittanceGains:
    """One gains object over [force; torque] for the elementwise laws."""
    stacked = AdmittanceGains.__new__(AdmittanceGains)  # six values: skip the 3-vector checks
    for f in dataclasses.fields(AdmittanceGains):
        a, b = getattr(tr, f.name), getattr(rot, f.name)
        object.__setattr__(
            stacked, f.name, a if f.name == "law" else frozen(np.concatenate([a, b]))
        )
    return stacked
