"""The hand-guiding controller block: estimated forces in, a speedL twist command out (seed 000, 3.F).

An explicit mode machine over stages. Per tick:

    read       the supervisor's `check_inputs` (non-finite input (latched) · estimator not ready ·
               stale FT-150 or probe data · probe force at the stop limit (latched)) and the
               tick's forces: F̃ = F_hand - F_probe (eq. 11-12, if contact compensation is on) and,
               with it, τ̃ = τ_hand - p_RT × F_probe (`contact_torque`)     (`guidance.tick.Tick`)
    request    the hand's request, on every tick that is not a stop: the law, v = law(F̃) (eq. 10,
               the isotropic or sigmoid law, or `variable`: eq. 10's slope following the hand's
               intent), ω = law(τ̃), then glide (eq. 10 lighter for a steady push, if on)
    mode       the detectors tell this tick's events and the transition table moves the mode
               (`guidance.modes`, `guidance.detectors`): stopped, guiding in the air or in
               contact, braking after a release, holding, handing back, recovering the contact
    stages     the mode's stages, in order, make the command of the request (`guidance.stages`):

        FREE, CONTACT   passivity (if on) · fixture (if on) · follow (if on) · limits
        BRAKING         brake: rest · passivity (watching) · fixture (if on) · limits (braking)
        HOLDING         hold: the contact force held along its line, ω = 0 · passivity
                        (watching) · limits
        HANDING_BACK    hold: blended into the request · passivity (watching) · limits
        RECOVERING      recovery: the approach along the last normal · passivity (watching) ·
                        limits
        STOPPED         zero; every stage forgets

               where the request's glide and the follow rest in every mode but guiding
    write      twist_B, twist_law_B (the request), status, brake_accel, mode

The limits (the supervisor's `limit_command`: speed clamp · acceleration clamp (the braking
deceleration towards rest after a release) · probe-force soft cap · workspace box) close every
mode's list: the soft force cap and the workspace box override the acceleration clamp, never the
other way round, and no stage or mode commands past them. The output is a TCP twist [v; ω] in the
base frame with UR speedL semantics, and a `Status` (see `hoh_cosim.control.supervisor`) whose `ok`
the runner obeys.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any, ClassVar, Literal

import numpy as np

from hoh_cosim.control.admittance import ROTATION_GAINS, TRANSLATION_GAINS, AdmittanceGains
from hoh_cosim.control.block import TWIST_UNITS, Port
from hoh_cosim.control.follow import BreathFollower, FollowParams
from hoh_cosim.control.glide import Glide, GlideParams
from hoh_cosim.control.guidance.detectors import (
    ContactWatch,
    Detector,
    HoldGuard,
    HoldWatch,
    ModeMachine,
    RecoveryWatch,
    ReleaseWatch,
    SupervisorWatch,
    TouchWatch,
)
from hoh_cosim.control.guidance.modes import GUIDING, HOLD_MODES, Mode
from hoh_cosim.control.guidance.stages.brake import ReleaseBrake
from hoh_cosim.control.guidance.stages.fixture import Fixture
from hoh_cosim.control.guidance.stages.follow import FollowStage
from hoh_cosim.control.guidance.stages.glide import GlideStage
from hoh_cosim.control.guidance.stages.hold import HoldStage
from hoh_cosim.control.guidance.stages.law import AdmittanceLaw
from hoh_cosim.control.guidance.stages.limits import Limits
from hoh_cosim.control.guidance.stages.passivity import PassivityStage
from hoh_cosim.control.guidance.stages.recovery import RecoveryStage
from hoh_cosim.control.guidance.stages.variable import VariableLaw
from hoh_cosim.control.guidance.tick import ZERO3, Command, Stage, Tick
from hoh_cosim.control.hold import ContactHold, HoldParams
from hoh_cosim.control.passivity import PassivityParams
from hoh_cosim.control.recovery import ContactRecovery, RecoveryParams
from hoh_cosim.control.release import ReleaseDetector, ReleaseParams
from hoh_cosim.control.supervisor import LATCHED_FLAGS, LimitParams, Status, check_inputs
from hoh_cosim.control.variable_admittance import VariableAdmittanceParams
from hoh_cosim.control.vectors import Vec, Vec3, as_scalar, as_unit_vector, frozen
from hoh_cosim.errors import ConfigError

__all__ = ["FIXTURE_NORMALS", "ControllerParams", "HandGuidingController"]

FixtureNormal = Literal["fixed", "contact"]
FIXTURE_NORMALS: tuple[str, ...] = ("fixed", "contact")

_LATCHED = int(LATCHED_FLAGS)


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
        "touch_down_N": "N",
        "lift_off_N": "N",
        "compensation_onset_N": "N",
    }
    TUNABLE: ClassVar[frozenset[str]] = frozenset(
        {
            "translation",
            "rotation",
            "contact_compensation",
            "compensation_onset_N",
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
            "recovery",
            "touch_down_N",
            "lift_off_N",
        }
    )

    translation: AdmittanceGains = TRANSLATION_GAINS
    rotation: AdmittanceGains = ROTATION_GAINS
    contact_compensation: bool = True  # eq. 11–12
    # [N] in the air (guiding there, or braking with the probe force under lift_off_N), eq. 11-12
    # takes the probe force in full from this size on, none of it under half of it, in proportion
    # between, and in full once in contact: what the
    # housing's play leaves in the probe sensor's reading (up to 0.8 N per axis, seed 3.B.2;
    # 0.5-0.7 N in the air after a probe check) then moves nothing in the air, where in full it
    # made the robot creep at a few mm/s (0: in full always, the seed's)
    compensation_onset_N: float = 0.0
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
    recovery: RecoveryParams = field(default_factory=RecoveryParams)  # the contact lost: back
    # [N] the probe force above which the hand guides in contact (mode CONTACT), and under which
    # the probe has left the patient (FREE): above what the housing's play leaves in the probe
    # sensor's reading in the air (0.2-0.8 N per axis, seed 3.B.2; 0.5-0.7 N after a probe check)
    touch_down_N: float = 2.0
    lift_off_N: float = 1.5
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
        for name in ("fixture_threshold_N", "compensation_onset_N"):
            object.__setattr__(self, name, as_scalar(getattr(self, name), name, low=0.0))
        for name in ("ft_period_s", "probe_period_s", "touch_down_N", "lift_off_N"):
            object.__setattr__(
                self, name, as_scalar(getattr(self, name), name, low=0.0, low_open=True)
            )
        if self.lift_off_N > self.touch_down_N:
            raise ConfigError(
                f"lift_off_N must be <= touch_down_N ({self.touch_down_N} N), got {self.lift_off_N}"
            )


class HandGuidingController:
    """Admittance, contact compensation, the modes past the seed and the limits under the block
    contract (module docstring)."""

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
        Port(
            "mode",
            1,
            "1",
            "the controller's mode at the end of this tick (hoh_cosim.control.guidance.modes.Mode)",
            flags=Mode,
        ),
    )

    def __init__(self, params: ControllerParams | None = None) -> None:
        params = params or ControllerParams()
        # the stages own the features' state; the detectors and the pipelines are rebuilt on a
        # retune around them
        self._brake = ReleaseBrake(params.release)
        self._variable = VariableLaw(params.variable)
        self._glide = GlideStage(params.glide)
        self._hold = HoldStage(params.hold)
        self._recovery = RecoveryStage(params.recovery)
        self._passivity = PassivityStage(params.passivity)
        self._follow = FollowStage(params.follow)
        self._tick, self._command = Tick(), Command()
        self.retune(params)
        self.reset()

    def retune(self, params: ControllerParams) -> None:
        """New parameters without losing the state (latched stops, the mode, the last command)."""
        self.params = p = params
        tr, rot = p.translation, p.rotation
        self._brake.retune(p.release)
        self._variable.retune(p.variable, tr, rot)
        self._glide.retune(p.glide, tr, p.use_probe)
        self._hold.retune(p.hold)
        self._recovery.retune(p.recovery)
        self._passivity.retune(p.passivity)
        self._follow.retune(p.follow)
        law = self._variable if tr.law == "variable" else AdmittanceLaw(tr, rot)
        self._request: tuple[Stage, ...] = (law, self._glide) if p.glide.enabled else (law,)
        self._machine = ModeMachine(_detectors(self, p, getattr(self, "mode", Mode.STOPPED)))
        self._pipelines, self._rests = _pipelines(self, p)
        compensated = p.use_probe and p.contact_compensation
        raw = p.release.enabled or p.hold.enabled  # the detectors that read the raw packet
        # what reads the probe's packet, axis and the sensors' ages (a hold or a recovery in
        # progress finishes after a retune that turned it off)
        features = (p.hold.enabled, p.follow.enabled, p.glide.enabled, p.recovery.enabled)
        extra = p.use_probe and (any(features) or getattr(self, "mode", Mode.STOPPED) in _FEATURED)
        lift_sq = p.lift_off_N * p.lift_off_N
        self._reading = (
            compensated,
            p.contact_torque,
            p.use_probe,
            raw,
            p.compensation_onset_N,
            extra,
            lift_sq,
        )
        self._brake_accel = frozen([p.limits.max_brake_accel])

    def reset(self) -> None:
        """Clear the latched stops, the mode, the last command and every stage's state."""
        self.mode = Mode.STOPPED
        self._latched = 0
        self._bits = 0
        self._last = (ZERO3, ZERO3)
        self._forget()

    def _forget(self) -> None:
        for stage in (self._brake, self._variable, self._glide, self._hold, self._recovery):
            stage.reset()
        for stage in (self._passivity, self._follow):
            stage.reset()
        self._machine.reset()

    @property
    def release(self) -> ReleaseDetector:
        """The release detector and its state (phase, time of the last release)."""
        return self._brake.detector

    def prepare(self, dt: float) -> None:
        """What can be computed before a loop stepped every `dt` (the hold's and the follow's
        filter gains), so that no cycle of a robot's loop pays for it."""
        if self.params.hold.enabled:
            self._hold.hold.prepare(dt)
        if self.params.follow.enabled:
            self._follow.follower.prepare(dt)

    @property
    def follow(self) -> BreathFollower:
        """Following the breath while the hand steers, and its state (level, blend)."""
        return self._follow.follower

    @property
    def glide(self) -> Glide:
        """Glide's state (the moving deadband, the low-passed command)."""
        return self._glide.glide

    @property
    def hold(self) -> ContactHold:
        """Hold-on-release and its state (phase, setpoint, why the last hold ended)."""
        return self._hold.hold

    @property
    def recovery(self) -> ContactRecovery:
        """The contact recovery and its state (the normal, the approach)."""
        return self._recovery.recovery

    @property
    def status(self) -> Status:
        """The flags of the last step."""
        return Status(self._bits)

    def step(self, t: float, dt: float, inputs: Mapping[str, Vec]) -> dict[str, Vec]:
        p = self.params
        status = self._latched | check_inputs(
            inputs,
            p.limits,
            ft_period_s=p.ft_period_s,
            probe_period_s=p.probe_period_s,
            use_probe=p.use_probe,
        )
        self._latched |= status & _LATCHED
        tick, command = self._tick, self._command
        tick.start(t, dt, status, self._last, inputs, self._reading, _AIR[self.mode])
        command.start(status)
        if not status:  # the hand's request: every mode reads it
            for stage in self._request:
                command = stage.step(tick, command)
            tick.request = command.law
        self.mode = mode = self._machine.advance(self.mode, tick)
        command.steering = mode in GUIDING
        for stage in self._pipelines[mode]:
            command = stage.step(tick, command)
        for rest in self._rests[mode]:
            rest()
        v, w = command.v, command.w
        self._last, self._bits = (v, w), command.status
        return {
            "twist_B": np.concatenate([v, w]),
            "twist_law_B": command.law,
            "status": np.array([float(command.status)]),
            "brake_accel": self._brake_accel if command.braking else _NO_BRAKE,
            "mode": _MODE_PORT[mode],
        }


_NO_BRAKE = frozen([0.0])
# the probe off the patient after the last tick's mode: guiding in the air (or stopped); braking,
# if the probe force is under lift_off_N (a release in the air: `Tick.start`); else in contact
_AIR = {mode: None if mode == Mode.BRAKING else mode in (Mode.STOPPED, Mode.FREE) for mode in Mode}
_FEATURED = HOLD_MODES | {Mode.RECOVERING}
_MODE_PORT = {mode: frozen([float(mode)]) for mode in Mode}


def _detectors(
    controller: HandGuidingController, p: ControllerParams, mode: Mode
) -> tuple[Detector, ...]:
    """The detectors of `hoh_cosim.control.guidance.detectors`, in their order, less those whose
    events cannot come with these parameters from `mode` on (a hold in progress finishes)."""
    tr = p.translation
    hold, recovery = controller._hold.hold, controller._recovery.recovery
    holding = p.use_probe and (p.hold.enabled or mode in HOLD_MODES)
    recovering = p.recovery.enabled or holding or mode == Mode.RECOVERING
    braking = p.release.enabled or recovering or mode == Mode.BRAKING
    out: list[Detector] = [SupervisorWatch()]
    if braking:
        out.append(ReleaseWatch(controller._brake.detector, tr.deadband, p.release.enabled))
    if holding or mode == Mode.RECOVERING:  # (it engages the hold after a recovery too)
        enabled = p.use_probe and p.hold.enabled
        out.append(HoldWatch(hold, tr.deadband, enabled, p.release.contact_threshold_N))
    if holding:
        out += [HoldGuard(hold), TouchWatch(hold, tr.deadband)]
    if recovering:
        out.append(RecoveryWatch(recovery, p.recovery.enabled))
    out.append(ContactWatch(p.touch_down_N, p.lift_off_N, recovery, p.recovery.enabled))
    return tuple(out)


def _pipelines(
    controller: HandGuidingController, p: ControllerParams
) -> tuple[dict[Mode, tuple[Stage, ...]], dict[Mode, tuple[Callable[[], None], ...]]]:
    """Each mode's stages in order, and what rests on its ticks (module docstring)."""
    probe = p.use_probe
    passivity = (controller._passivity,) if p.passivity.enabled else ()
    fixture: tuple[Stage, ...] = ()
    if probe and p.virtual_fixture:
        fixture = (Fixture(p.fixture_threshold_N, p.fixture_up_B, p.fixture_normal),)
    follow = (controller._follow,) if probe and p.follow.enabled else ()
    limits = (Limits(p.limits),)
    guiding = (*passivity, *fixture, *follow, *limits)
    pipelines: dict[Mode, tuple[Stage, ...]] = {
        Mode.STOPPED: (),
        Mode.FREE: guiding,
        Mode.CONTACT: guiding,
        Mode.BRAKING: (controller._brake, *passivity, *fixture, *limits),
        Mode.HOLDING: (controller._hold, *passivity, *limits),
        Mode.HANDING_BACK: (controller._hold, *passivity, *limits),
        Mode.RECOVERING: (controller._recovery, *passivity, *limits),
    }
    # the request's glide and the follow carry nothing out of the guiding modes
    resting = tuple(
        stage.rest
        for stage, on in ((controller._glide, p.glide.enabled), (controller._follow, bool(follow)))
        if on
    )
    rests = {mode: () if mode in GUIDING else resting for mode in Mode}
    rests[Mode.STOPPED] = (controller._forget,)
    return pipelines, rests
