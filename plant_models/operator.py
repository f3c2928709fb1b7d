"""The sonographer's hand: a delayed impedance that pushes the handle through a task.

The hand wants the probe tip at a reference that the task moves (a circle, a line scan, a point to
hold). It pushes with

    F_hand = sat( K (p_ref(t) - p(t - τ)) + D (v_ref(t) - v(t - τ)) )

where p and v are the tip's position and velocity as the operator perceives them, a reaction delay τ
late, K and D the stiffness and damping of a relaxed arm, and sat a limit on the force a hand gives.
A transparent robot follows a light push, so the hand needs little force and small errors; a sluggish
or jittery one needs more force for the same path. The pressing tasks add a force loop along the
probe axis: the hand pushes (proportional and integral on the delayed contact force error) until the
phantom pushes back with the target force, then relaxes.

Figures (ours, from the literature's ranges):
- reaction delay τ = 150 ms: voluntary corrections to what a person sees or feels take roughly
  100–200 ms (long-latency reflexes are faster, visual reaction times slower);
- K = 300 N/m, D = 20 N·s/m: hand stiffness measured in relaxed, maintained postures is of the order
  of a few hundred N/m and hand damping of ten to a few tens of N·s/m (Mussa-Ivaldi, Hogan and Bizzi
  1985; Tsuji et al. 1995);
- at most 25 N: above the forces of a scan (the seed's limit on contact force is 20–25 N).

Additions for the clinical study (`hoh_cosim.study.clinical`), each off by default so that every
other scenario keeps its numbers:
- `intrinsic`: the hand's stiffness and damping act on the tip as it is, not as perceived a
  reaction delay ago: they are the muscles' own viscoelasticity (and the fastest reflexes), which
  needs no reaction (Hogan 1985, "Impedance control: an approach to manipulation"; the stiffness
  that Mussa-Ivaldi, Hogan and Bizzi 1985 and Tsuji et al. 1995 measured is of that kind). The
  reaction delay then delays what is voluntary: the press loop on the felt contact force. Along the
  pressing direction the stiffness gives way to the press and the damping stays. A hand holding a
  probe with nothing else (`plant_models.freehand`) needs this: a delayed stiffness on a free
  0.48 kg probe oscillates;
- `feedforward_B`: a constant force the hand adds, what a person does with a weight it knows: a
  sonographer holding the probe alone carries its weight without waiting to feel it sag (Flanagan
  and Wing 1997, J. Neurosci. 17(4):1519-1528: grip and load forces anticipate a known load); on
  the robot nothing, the arm carries the tool;
- physiological tremor: a force of `tremor_rms_N` (RMS of its magnitude) in a band
  `tremor_bandwidth_hz` wide around `tremor_hz`, the 8–12 Hz component of physiological tremor
  (Elble 2003, "Physiologic and enhanced physiologic tremor", Handbook of Clinical
  Neurophysiology vol. 1, ch. 22), the sum of eight sinusoids per axis at seeded frequencies and
  phases (a function of time: any step gives the same force). It is added while the hand follows
  a task;
- the grip: the hand holds the probe's orientation at the task's start with a
  rotational stiffness and damping, a torque -K_r θ - D_r ω on the handle (θ from the `R_BT`
  input). On the robot the contact's torque about the wrist sensor turns the probe through the
  rotational admittance unless something resists it: a real hand does. Freehand, the grip is part
  of `plant_models.freehand` (the stiff joint its integrator treats implicitly), and this one off.

The `view` task: press to the target force while moving the tip `length_m` along `direction_B` on
a minimum-jerk path over `reach_s`, then hold it there (reach a view and keep it); with `next_s`,
move on to the next view `next_length_m` further along `direction_B` then, over `reach_s` again
(0: no next view).

Letting go (for hold-on-release, `hoh_cosim.control.hold`): `let_go_s` after the task's start the
hand opens, its force falling to nothing over `let_go_ramp_s` (a hand opening on a handle takes
about a tenth of a second), and stays off the handle until `retake_s`, when it takes the handle
again and goes on with its task where the task then is (its press loop as it was). Both are 0 by
default, meaning never: the hand never lets go.

Tasks: `off` (no hand on the handle), `hold` (keep the tip where it was), `circle`, `line` (a line
scan, back and forth), `press` (press to a target contact force and hold), `scan` (press and line scan
together), `push_release` (push with a constant force, then let go), `probe_push` (the hand off the
handle presses the probe tip directly: the seed's way of collecting probe-sensor data, Fig. 6 and 14).
Every task starts at `start_s`; before that the hand is off (so the estimator can rebias), and the tip
position then is the task's origin. With `probe_check_s` > 0 the hand presses the probe tip for that
long before the task starts (the estimator's probe check).

Probe pushes: one every `push_s` seconds, each a raised-cosine rise and fall of the force to a peak
drawn uniformly in [`push_min_N`, `push_max_N`], along a direction drawn uniformly within
`push_cone_deg` of the direction a surface would push the tip (-`press_direction_B`). The draws come
from the scenario's seed, in order, so they do not depend on the step size.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, ClassVar, Literal

import numpy as np

from hoh_cosim.control.block import TWIST_UNITS, Port
from hoh_cosim.control.vectors import Vec, Vec3, as_scalar, as_unit_vector, as_vector, frozen
from hoh_cosim.errors import ConfigError
from plant_models.tasks import CONTACT_TASKS, PLANES, TASKS, TaskName

__all__ = ["PLANES", "TASKS", "Operator", "OperatorParams"]

_XYZ = tuple[float, float, float]

_TREMOR_COMPONENTS = 8  # sinusoids per axis

# constant outputs, returned again and again: read-only
_ZERO = frozen([0.0, 0.0, 0.0])
_IDENTITY = frozen(np.eye(3).reshape(9))
_ON = frozen([1.0])
_OFF = frozen([0.0])


def _impedance(
    K: float, D: float, p_ref: _XYZ, p_seen: Sequence[float], v_ref: _XYZ, v_seen: Sequence[float]
) -> _XYZ:
    """K (p_ref - p_seen) + D (v_ref - v_seen), axis by axis."""
    (r0, r1, r2), (x0, x1, x2), (u0, u1, u2), (v0, v1, v2) = p_ref, p_seen, v_ref, v_seen
    return (
        K * (r0 - x0) + D * (u0 - v0),
        K * (r1 - x1) + D * (u1 - v1),
        K * (r2 - x2) + D * (u2 - v2),
    )


@dataclass(frozen=True)
class OperatorParams:
    task: TaskName = "circle"
    start_s: float = 0.0  # [s] the hand takes the handle
    # circle: radius and period, in a plane of the base frame; the speed ramps up over ramp_s
    radius_m: float = 0.04
    period_s: float = 4.0  # also the back-and-forth period of a line scan
    plane: Literal["xy", "xz", "yz"] = "xy"
    ramp_s: float = 1.0
    # line scan: direction and length
    direction_B: Vec3 = field(default_factory=lambda: frozen([1.0, 0.0, 0.0]))
    length_m: float = 0.10
    # press and scan: contact force along the probe's pressing direction
    target_force_N: float = 8.0
    press_direction_B: Vec3 = field(default_factory=lambda: frozen([0.0, 0.0, -1.0]))
    force_kp: float = 0.2  # [N/N]
    force_ki: float = 0.2  # [1/s]
    approach_force_N: float = 1.0  # [N] pushed until contact is felt
    contact_threshold_N: float = 0.5  # [N] contact force that counts as touching
    # view: the reach's duration (minimum jerk), then hold; then, at next_s, the next view
    reach_s: float = 5.0
    next_s: float = 0.0  # [s] after the start (0: no next view)
    next_length_m: float = 0.02
    # letting go of the handle and taking it again, after the start (0: never)
    let_go_s: float = 0.0
    let_go_ramp_s: float = 0.1
    retake_s: float = 0.0
    # push then release
    push_force_B: Vec3 = field(default_factory=lambda: frozen([5.0, 0.0, 0.0]))  # [N]
    release_s: float = 3.0  # [s]
    # pushes on the probe tip, hand off the handle (task probe_push, or before any task)
    probe_check_s: float = 0.0  # [s] before start_s
    push_s: float = 2.0  # [s] per push
    push_min_N: float = 2.0
    push_max_N: float = 15.0
    push_cone_deg: float = 60.0
    # the human
    stiffness: float = 300.0  # K [N/m]
    damping: float = 20.0  # D [N·s/m]
    reaction_delay_s: float = 0.15  # τ [s]
    max_force_N: float = 25.0
    released: bool = False  # True: the hand has let go of the handle (a scheduled release)
    # the clinical study's hand (module docstring); the defaults leave today's hand unchanged
    intrinsic: bool = False  # stiffness and damping on the tip as it is, not as perceived
    feedforward_B: Vec3 = field(default_factory=lambda: frozen([0.0, 0.0, 0.0]))  # [N]
    tremor_rms_N: float = 0.0
    tremor_hz: float = 10.0
    tremor_bandwidth_hz: float = 2.0
    grip_stiffness: float = 0.0  # K_r [N·m/rad] the grip's torque on the handle
    grip_damping: float = 0.0  # D_r [N·m·s/rad]

    UNITS: ClassVar[dict[str, Any]] = {
        "start_s": "s",
        "radius_m": "m",
        "period_s": "s",
        "ramp_s": "s",
        "direction_B": "1",
        "length_m": "m",
        "target_force_N": "N",
        "press_direction_B": "1",
        "force_kp": "1",
        "force_ki": "1/s",
        "approach_force_N": "N",
        "contact_threshold_N": "N",
        "push_force_B": "N",
        "release_s": "s",
        "reach_s": "s",
        "next_s": "s",
        "next_length_m": "m",
        "let_go_s": "s",
        "let_go_ramp_s": "s",
        "retake_s": "s",
        "feedforward_B": "N",
        "tremor_rms_N": "N",
        "tremor_hz": "Hz",
        "tremor_bandwidth_hz": "Hz",
        "grip_stiffness": "N.m/rad",
        "grip_damping": "N.m.s/rad",
        "probe_check_s": "s",
        "push_s": "s",
        "push_min_N": "N",
        "push_max_N": "N",
        "push_cone_deg": "deg",
        "stiffness": "N/m",
        "damping": "N.s/m",
        "reaction_delay_s": "s",
        "max_force_N": "N",
    }
    TUNABLE: ClassVar[frozenset[str]] = frozenset(
        {
            "released",
            "target_force_N",
            "push_force_B",
            "release_s",
            "stiffness",
            "damping",
            "max_force_N",
        }
    )

    def __post_init__(self) -> None:
        if self.task not in TASKS:
            raise ConfigError(f"task: expected one of {', '.join(TASKS)}, got {self.task!r}")
        if self.plane not in PLANES:
            raise ConfigError(f"plane: expected one of {', '.join(PLANES)}, got {self.plane!r}")
        for name in (
            "start_s",
            "ramp_s",
            "reaction_delay_s",
            "force_kp",
            "force_ki",
            "damping",
            "target_force_N",
            "approach_force_N",
            "contact_threshold_N",
            "probe_check_s",
            "push_min_N",
            "tremor_rms_N",
            "grip_stiffness",
            "grip_damping",
            "next_s",
            "next_length_m",
            "let_go_s",
            "let_go_ramp_s",
            "retake_s",
        ):
            object.__setattr__(self, name, as_scalar(getattr(self, name), name, low=0.0))
        for name in (
            "radius_m",
            "period_s",
            "length_m",
            "stiffness",
            "max_force_N",
            "push_s",
            "reach_s",
            "tremor_hz",
        ):
            object.__setattr__(
                self, name, as_scalar(getattr(self, name), name, low=0.0, low_open=True)
            )
        object.__setattr__(self, "release_s", as_scalar(self.release_s, "release_s"))
        object.__setattr__(self, "direction_B", as_unit_vector(self.direction_B, "direction_B"))
        object.__setattr__(
            self, "press_direction_B", as_unit_vector(self.press_direction_B, "press_direction_B")
        )
        object.__setattr__(self, "push_force_B", as_vector(self.push_force_B, 3, "push_force_B"))
        object.__setattr__(self, "feedforward_B", as_vector(self.feedforward_B, 3, "feedforward_B"))
        object.__setattr__(
            self,
            "tremor_bandwidth_hz",
            as_scalar(
                self.tremor_bandwidth_hz, "tremor_bandwidth_hz", low=0.0, high=self.tremor_hz
            ),
        )
        object.__setattr__(
            self, "push_max_N", as_scalar(self.push_max_N, "push_max_N", low=self.push_min_N)
        )
        object.__setattr__(
            self,
            "push_cone_deg",
            as_scalar(self.push_cone_deg, "push_cone_deg", low=0.0, high=180.0),
        )


class Operator:
    """The hand on the handle under the block contract."""

    inputs: ClassVar[tuple[Port, ...]] = (
        Port("p_BT_B", 3, "m", "probe tip position in the base frame"),
        Port("twist_B", 6, TWIST_UNITS, "probe tip twist in the base frame"),
        Port("F_contact_B", 3, "N", "force of the phantom on the probe tip, in B"),
        Port("R_BT", 9, "1", "probe tip orientation in the base frame, row by row (the grip)"),
    )
    OPTIONAL_INPUTS: ClassVar[frozenset[str]] = frozenset({"R_BT"})
    """Inputs that may be left unconnected: R_BT then stays where the robot's home has it."""
    outputs: ClassVar[tuple[Port, ...]] = (
        Port("F_hand_B", 3, "N", "force of the hand on the handle, in B"),
        Port("tau_hand_B", 3, "N.m", "torque of the hand on the handle, in B"),
        Port("p_ref_B", 3, "m", "where the hand wants the probe tip"),
        Port("hand_on", 1, "1", "1 while the hand pushes the handle, else 0"),
        Port("F_tip_B", 3, "N", "force of the hand directly on the probe tip, in B"),
    )

    def __init__(
        self, params: OperatorParams | None = None, rng: np.random.Generator | None = None
    ) -> None:
        self.params = params or OperatorParams()
        rng = rng if rng is not None else np.random.default_rng(0)
        self._push_seed = int(rng.integers(2**63))
        self._tremor_seed = int(rng.integers(2**63))  # drawn after: the pushes stay as they were
        self.reset()

    def retune(self, params: OperatorParams) -> None:
        """New parameters while running (a release, a new target force): the task goes on."""
        self.params = params

    def reset(self) -> None:
        self._history: deque[tuple[list[float], list[float], list[float]]] | None = None
        self._origin: Vec | None = None  # read-only: returned as p_ref by push_release
        self._origin_xyz: list[float] = []
        self._integral = 0.0
        self._touched = False
        self._push_rng = np.random.default_rng(self._push_seed)
        self._pushes: list[tuple[float, Vec3]] = []  # (peak [N], unit direction), drawn in order
        self._derived_from: OperatorParams | None = None
        tremor = np.random.default_rng(self._tremor_seed)
        # per axis and component: the frequency's place in the band (-1/2 to 1/2), the phase
        self._tremor_u = tremor.uniform(-0.5, 0.5, (3, _TREMOR_COMPONENTS))
        self._tremor_phase = tremor.uniform(0.0, 2.0 * math.pi, (3, _TREMOR_COMPONENTS))

    def _derive(self) -> None:
        """What `step` uses of the parameters, vectors as Python floats (again when they change)."""
        p = self.params
        i, j = PLANES[p.plane]
        self._u1 = tuple(float(k == i) for k in range(3))  # the circle's plane
        self._u2 = tuple(float(k == j) for k in range(3))
        self._omega = 2.0 * math.pi / p.period_s
        self._line_xyz = p.direction_B.tolist()
        self._d_xyz = p.press_direction_B.tolist()
        self._d_is_axis = sum(x != 0.0 for x in self._d_xyz) == 1  # see `_dot_d`
        self._ff_xyz = p.feedforward_B.tolist() if p.feedforward_B.any() else None
        self._gripping = p.grip_stiffness > 0.0 or p.grip_damping > 0.0
        # the task's times, 0 meaning never
        self._next_s = p.next_s if p.next_s > 0.0 else math.inf
        self._let_go_s = p.let_go_s if p.let_go_s > 0.0 else math.inf
        self._retake_s = p.retake_s if p.retake_s > 0.0 else math.inf
        self._derived_from = p

    def _perceived(
        self, dt: float, now: tuple[list[float], list[float], list[float]]
    ) -> tuple[list[float], list[float], list[float]]:
        """The tip position, velocity and contact force as they were a reaction delay ago."""
        history = self._history
        if history is None:  # now and the τ/dt steps before it, dt the first step's
            history = self._history = deque(maxlen=round(self.params.reaction_delay_s / dt) + 1)
        history.append(now)
        return history[0]

    def _reference_xyz(self, tau: float) -> tuple[_XYZ, _XYZ]:
        """`reference` as float triples."""
        p = self.params
        if p.task == "circle":
            omega = self._omega
            if tau < p.ramp_s:  # angular speed ramps up linearly: no jerk at the start
                phi, phi_dot = 0.5 * omega * tau * tau / p.ramp_s, omega * tau / p.ramp_s
            else:
                phi, phi_dot = omega * (tau - 0.5 * p.ramp_s), omega
            c, s = math.cos(phi), math.sin(phi)
            # p = r ((c - 1) u1 + s u2),  v = r φ̇ (-s u1 + c u2)
            r, r_dot, c1, s_ = p.radius_m, p.radius_m * phi_dot, c - 1.0, -s
            (a0, a1, a2), (b0, b1, b2) = self._u1, self._u2
            return (
                (r * (c1 * a0 + s * b0), r * (c1 * a1 + s * b1), r * (c1 * a2 + s * b2)),
                (
                    r_dot * (s_ * a0 + c * b0),
                    r_dot * (s_ * a1 + c * b1),
                    r_dot * (s_ * a2 + c * b2),
                ),
            )
        if p.task == "view":  # minimum jerk to the view, then still; then the next one
            length, since = p.length_m, tau
            if tau >= self._next_s:
                length, since = p.next_length_m, tau - self._next_s
            x = min(since / p.reach_s, 1.0)
            s = length * x * x * x * (10.0 - 15.0 * x + 6.0 * x * x)
            s_dot = length * 30.0 * x * x * (1.0 - x) * (1.0 - x) / p.reach_s
            if tau >= self._next_s:
                s += p.length_m
            e0, e1, e2 = self._line_xyz
            return (s * e0, s * e1, s * e2), (s_dot * e0, s_dot * e1, s_dot * e2)
        if p.task in ("line", "scan"):  # back and forth, starting and turning at rest
            omega = self._omega
            s = 0.5 * p.length_m * (1.0 - math.cos(omega * tau))
            s_dot = 0.5 * p.length_m * omega * math.sin(omega * tau)
            e0, e1, e2 = self._line_xyz
            return (s * e0, s * e1, s * e2), (s_dot * e0, s_dot * e1, s_dot * e2)
        return (0.0, 0.0, 0.0), (0.0, 0.0, 0.0)

    def reference(self, tau: float) -> tuple[Vec, Vec]:
        """(p_ref, v_ref) `tau` seconds after the task started, relative to its origin."""
        if self.params is not self._derived_from:
            self._derive()
        offset, v_ref = self._reference_xyz(tau)
        return np.array(offset), np.array(v_ref)

    def step(self, t: float, dt: float, inputs: Mapping[str, Vec]) -> dict[str, Vec]:
        p = self.params
        if p is not self._derived_from:
            self._derive()
        p_now = inputs["p_BT_B"]
        p_seen, v_seen, F_contact_seen = self._perceived(
            dt, (p_now.tolist(), inputs["twist_B"][:3].tolist(), inputs["F_contact_B"].tolist())
        )
        t_end = t + dt
        if p.task == "probe_push" and t_end >= p.start_s:
            return self._out(_ZERO, p_now.copy(), on=False, tip=self.tip_push(t_end - p.start_s))
        if p.probe_check_s > 0.0 and p.start_s - p.probe_check_s <= t_end < p.start_s:
            tip = self.tip_push(t_end - (p.start_s - p.probe_check_s))
            return self._out(_ZERO, p_now.copy(), on=False, tip=tip)
        if p.task in ("off", "probe_push") or p.released or t_end < p.start_s:
            return self._out(_ZERO, p_now.copy(), on=False)
        if self._origin is None:
            self._origin = frozen(p_now)
            self._origin_xyz = self._origin.tolist()
            self._R_origin = np.array(inputs.get("R_BT", _IDENTITY), dtype=float).reshape(3, 3)
        tau = t_end - p.start_s
        if self._let_go_s <= tau < self._retake_s:  # the hand lets go, off until it retakes
            if tau >= self._let_go_s + p.let_go_ramp_s:  # off: the task's reference stays its goal
                (o0, o1, o2), (x0, x1, x2) = self._origin_xyz, self._reference_xyz(tau)[0]
                return self._out(_ZERO, np.array((o0 + x0, o1 + x1, o2 + x2)), on=False)
            opening = 1.0 - (tau - self._let_go_s) / p.let_go_ramp_s
            out = self._task_step(p, tau, t_end, dt, inputs, p_now, F_contact_seen, p_seen, v_seen)
            out["F_hand_B"] = out["F_hand_B"] * opening
            out["tau_hand_B"] = out["tau_hand_B"] * opening
            return out
        return self._task_step(p, tau, t_end, dt, inputs, p_now, F_contact_seen, p_seen, v_seen)

    def _task_step(
        self,
        p: OperatorParams,
        tau: float,
        t_end: float,
        dt: float,
        inputs: Mapping[str, Vec],
        p_now: Vec,
        F_contact_seen: Sequence[float],
        p_seen: Sequence[float],
        v_seen: Sequence[float],
    ) -> dict[str, Vec]:
        """The hand on the handle, doing its task `tau` seconds after its start."""
        if p.task == "push_release":
            if t_end < p.release_s:
                return self._out(self._saturate(p.push_force_B.tolist()), self._origin, on=True)
            return self._out(_ZERO, self._origin, on=False)

        offset, v_ref = self._reference_xyz(tau)
        (o0, o1, o2), (x0, x1, x2) = self._origin_xyz, offset
        p_ref = (o0 + x0, o1 + x1, o2 + x2)
        grip = self._grip(inputs) if self._gripping else None
        if p.intrinsic:
            F = self._intrinsic(p_ref, v_ref, p_now, inputs["twist_B"], F_contact_seen, dt)
            return self._out(self._hand(F, t_end), np.array(p_ref), on=True, tau=grip)
        F = _impedance(p.stiffness, p.damping, p_ref, p_seen, v_ref, v_seen)
        if p.task in CONTACT_TASKS:
            d0, d1, d2 = self._d_xyz
            # F - (F·d) d: the impedance acts across the pressing direction only
            a = self._dot_d(F)
            F = (F[0] - a * d0, F[1] - a * d1, F[2] - a * d2)
            # + press(-F_contact·d) d: the press along it, on the contact force felt
            c0, c1, c2 = F_contact_seen
            a = self._press(self._dot_d((-c0, -c1, -c2)), dt)
            F = (F[0] + a * d0, F[1] + a * d1, F[2] + a * d2)
        return self._out(self._hand(F, t_end), np.array(p_ref), on=True, tau=grip)

    def _intrinsic(
        self,
        p_ref: _XYZ,
        v_ref: _XYZ,
        p_now: Vec,
        twist: Vec,
        F_contact_seen: Sequence[float],
        dt: float,
    ) -> _XYZ:
        """The hand with `intrinsic` (module docstring): K (p_ref - p) + D (v_ref - v) on the tip
        as it is; on a contact task K acts across the pressing direction d only and the press
        (on the contact force as perceived) along it."""
        p = self.params
        K, D = p.stiffness, p.damping
        (r0, r1, r2), (u0, u1, u2) = p_ref, v_ref
        x0, x1, x2 = p_now.tolist()
        v0, v1, v2 = twist[:3].tolist()
        k0, k1, k2 = K * (r0 - x0), K * (r1 - x1), K * (r2 - x2)
        F = (k0 + D * (u0 - v0), k1 + D * (u1 - v1), k2 + D * (u2 - v2))
        if p.task in CONTACT_TASKS:
            d0, d1, d2 = self._d_xyz
            c0, c1, c2 = F_contact_seen
            # - (K e · d) d + press(-F_contact · d) d
            a = self._press(self._dot_d((-c0, -c1, -c2)), dt) - self._dot_d((k0, k1, k2))
            F = (F[0] + a * d0, F[1] + a * d1, F[2] + a * d2)
        return F

    def _hand(self, F: Sequence[float], t: float) -> Vec3:
        """F with the feed-forward, saturated, with the tremor at time t (module docstring)."""
        if self._ff_xyz is not None:
            (f0, f1, f2), (a0, a1, a2) = F, self._ff_xyz
            F = (f0 + a0, f1 + a1, f2 + a2)
        out = self._saturate(F)
        if self.params.tremor_rms_N > 0.0:
            out = out + self.tremor(t)
        return out

    def tremor(self, t: float) -> Vec3:
        """The tremor force at time t [N]: per axis the sum of the components, each of amplitude
        a = rms / (√3 · √(n/2)), so that the force's magnitude has `tremor_rms_N` as its RMS."""
        p = self.params
        hz = p.tremor_hz + p.tremor_bandwidth_hz * self._tremor_u
        a = p.tremor_rms_N / math.sqrt(3.0 * _TREMOR_COMPONENTS / 2.0)
        return a * np.sin(2.0 * math.pi * hz * t + self._tremor_phase).sum(axis=1)

    def _dot_d(self, v: Sequence[float]) -> float:
        """v · d (d the pressing direction), the value numpy's `v @ d` gives. With d along an axis
        every product is exact and at most one is not zero: the sum has that value in any order,
        fused or not, so Python's is numpy's; otherwise numpy computes it."""
        if self._d_is_axis:
            d0, d1, d2 = self._d_xyz
            return 0.0 + v[0] * d0 + v[1] * d1 + v[2] * d2
        return float(np.array(v) @ self.params.press_direction_B)

    def _press(self, contact_N: float, dt: float) -> float:
        """Force along the pressing direction: a gentle approach until contact is felt, then a PI
        loop on the (delayed) contact force; negative means lifting the probe."""
        p = self.params
        if not self._touched:
            if contact_N < p.contact_threshold_N:
                return p.approach_force_N
            self._touched = True
            self._integral = 0.0
        error = p.target_force_N - contact_N
        push = p.force_kp * error + self._integral
        # integrate unless the push is at a limit and the error drives it further
        limit = p.max_force_N
        if not ((push >= limit and error > 0.0) or (push <= -limit and error < 0.0)):
            self._integral += p.force_ki * error * dt
        return min(max(push, -limit), limit)

    def tip_push(self, tau: float) -> Vec3:
        """The force on the probe tip `tau` seconds into the pushes (module docstring)."""
        p = self.params
        k, phase = divmod(tau / p.push_s, 1.0)
        while len(self._pushes) <= k:
            rng = self._push_rng
            peak = float(rng.uniform(p.push_min_N, p.push_max_N))
            cos_cone = math.cos(math.radians(p.push_cone_deg))
            c = float(rng.uniform(cos_cone, 1.0))
            phi = float(rng.uniform(0.0, 2.0 * math.pi))
            axis = -p.press_direction_B
            u1 = np.cross(axis, [1.0, 0.0, 0.0] if abs(axis[0]) < 0.9 else [0.0, 1.0, 0.0])
            u1 /= np.linalg.norm(u1)
            u2 = np.cross(axis, u1)
            s = math.sqrt(max(0.0, 1.0 - c * c))
            self._pushes.append((peak, c * axis + s * (math.cos(phi) * u1 + math.sin(phi) * u2)))
        peak, direction = self._pushes[int(k)]
        return peak * 0.5 * (1.0 - math.cos(2.0 * math.pi * phase)) * direction

    def _saturate(self, F: Sequence[float]) -> Vec3:
        """F limited to `max_force_N` in norm, as an array."""
        limit = self.params.max_force_N
        f0, f1, f2 = F
        # |F| here and numpy's sqrt(F @ F) differ by a few ulps at most: well below the limit F is
        # kept either way; near or above it, the norm is numpy's
        if math.sqrt(f0 * f0 + f1 * f1 + f2 * f2) < limit * (1.0 - 1e-9):
            return np.array(F)
        F_arr = np.array(F)
        n = math.sqrt(float(F_arr @ F_arr))
        return F_arr * (limit / n) if n > limit else F_arr

    def _grip(self, inputs: Mapping[str, Vec]) -> Vec3:
        """The grip's torque, -K_r θ - D_r ω: θ the rotation vector from the orientation at the
        task's start to the current one, ω the tip's angular velocity (module docstring)."""
        p = self.params
        R = np.asarray(inputs.get("R_BT", _IDENTITY), dtype=float).reshape(3, 3)
        (r00, r01, r02), (r10, r11, r12), (r20, r21, r22) = (R @ self._R_origin.T).tolist()
        # θ from the skew part: sin|θ| θ/|θ| = vee(Rrel - Rrelᵀ)/2 (the grip's angles are small)
        x, y, z = 0.5 * (r21 - r12), 0.5 * (r02 - r20), 0.5 * (r10 - r01)
        s = math.sqrt(x * x + y * y + z * z)
        scale = math.atan2(s, 0.5 * (r00 + r11 + r22 - 1.0)) / s if s > 1e-12 else 1.0
        w0, w1, w2 = inputs["twist_B"][3:].tolist()
        K, D = p.grip_stiffness, p.grip_damping
        return np.array((-K * scale * x - D * w0, -K * scale * y - D * w1, -K * scale * z - D * w2))

    @staticmethod
    def _out(
        F: Vec3, p_ref: Vec3, on: bool, tip: Vec3 | None = None, tau: Vec3 | None = None
    ) -> dict[str, Vec]:
        """The outputs; `F`, `p_ref`, `tip` and `tau` are arrays no one changes (fresh or
        read-only)."""
        return {
            "F_hand_B": F,
            "tau_hand_B": _ZERO if tau is None else tau,
            "p_ref_B": p_ref,
            "hand_on": _ON if on else _OFF,
            "F_tip_B": _ZERO if tip is None else tip,
        }
