"""The controller's modes (control/guidance/modes.py and detectors.py): the transition table as its
docstring means it, each of its rows driven through a real HandGuidingController, the transitions
that must not happen, and the supervisor's limits on the command in every mode."""

from __future__ import annotations

import dataclasses
import itertools
from collections.abc import Callable

import numpy as np
import pytest

from hoh_cosim.control.admittance import ROTATION_GAINS, TRANSLATION_GAINS
from hoh_cosim.control.controller import ControllerParams, HandGuidingController
from hoh_cosim.control.guidance.modes import TRANSITIONS, Event, Mode, next_mode
from hoh_cosim.control.hold import HoldEnd, HoldParams
from hoh_cosim.control.recovery import RecoveryParams
from hoh_cosim.control.release import ReleaseParams
from hoh_cosim.control.supervisor import LimitParams, Status
from tests.patient import DT, K, Patient

# --- the table, written out from the modes' docstring --------------------------------------------

S, F, C, B, H, HB, R = (
    Mode.STOPPED,
    Mode.FREE,
    Mode.CONTACT,
    Mode.BRAKING,
    Mode.HOLDING,
    Mode.HANDING_BACK,
    Mode.RECOVERING,
)
_ = None  # the mode is kept

COLUMNS = (
    Event.STOP,
    Event.GO,
    Event.TOUCH_DOWN,
    Event.LIFT_OFF,
    Event.RELEASED,
    Event.PUSHED,
    Event.HOLD_READY,
    Event.TOUCHED,
    Event.HANDED_BACK,
    Event.CONTACT_LOST,
    Event.TRAVEL_LIMIT,
    Event.RECOVERED,
    Event.CONTACT_BACK,
    Event.RECOVERY_FAILED,
)
# fmt: off
ROWS = {
    #                 STOP GO TOUCH LIFT REL PUSH READY TOUCHED BACK LOST TRAVEL RECOV CBACK FAIL
    Mode.STOPPED:      (_, F,  _,    _,   _,  _,   _,    _,      _,   _,   _,     _,    _,    _),
    Mode.FREE:         (S, _,  C,    _,   B,  _,   H,    _,      _,   _,   _,     _,    _,    _),
    Mode.CONTACT:      (S, _,  _,    F,   B,  _,   H,    _,      _,   R,   _,     _,    _,    _),
    Mode.BRAKING:      (S, _,  _,    _,   _,  F,   H,    _,      _,   _,   _,     _,    _,    _),
    Mode.HOLDING:      (S, _,  _,    _,   _,  _,   _,    HB,     C,   R,   B,     _,    _,    _),
    Mode.HANDING_BACK: (S, _,  _,    _,   _,  _,   _,    _,      C,   B,   B,     _,    _,    _),
    Mode.RECOVERING:   (S, _,  _,    _,   _,  F,   _,    _,      _,   _,   _,     H,    C,    B),
}
# fmt: on
EXPECTED = {
    (mode, event): mode if to is None else to
    for mode, row in ROWS.items()
    for event, to in zip(COLUMNS, row, strict=True)
}


def test_the_expected_table_names_every_mode_and_event():
    assert set(ROWS) == set(Mode)
    assert set(COLUMNS) == set(Event)


@pytest.mark.parametrize(
    ("mode", "event"),
    list(itertools.product(Mode, Event)),
    ids=[f"{m.name}-{e.name}" for m, e in itertools.product(Mode, Event)],
)
def test_next_mode_follows_the_table(mode, event):
    assert next_mode(mode, event) == EXPECTED[mode, event]


def test_the_table_lists_no_transition_that_keeps_the_mode():
    assert [pair for pair, to in TRANSITIONS.items() if to == pair[0]] == []


def test_every_mode_is_reachable_from_stopped():
    reached, frontier = {Mode.STOPPED}, [Mode.STOPPED]
    while frontier:
        mode = frontier.pop()
        for (start, _event), to in TRANSITIONS.items():
            if start == mode and to not in reached:
                reached.add(to)
                frontier.append(to)
    assert reached == set(Mode)


# --- a controller over a patient ------------------------------------------------------------------

ZERO = (0.0, 0.0, 0.0)
SURFACE_Z = 0.3  # tests/patient.py's surface, still unless a test moves it
AIR_Z = SURFACE_Z + 0.01  # the tip 10 mm above it
CONTACT_Z = SURFACE_Z - 0.008  # 8 mm into it: 9.6 N
ACROSS = (3.0, 0.0, 0.0)  # [N] a push across the probe: a touch while holding (test_hold.py)
AWAY = SURFACE_Z - 0.1  # the patient moved 10 cm away: nothing touches
HOLD = HoldParams(enabled=True)
RECOVERY = RecoveryParams(enabled=True)


def controller_params(
    release: bool = True,
    hold: HoldParams | None = None,
    recovery: RecoveryParams | None = None,
    **fields: object,
) -> ControllerParams:
    """The defaults with the release on (unless told), and the hold and the recovery as given."""
    return ControllerParams(
        release=ReleaseParams(enabled=release),
        hold=hold or HoldParams(),
        recovery=recovery or RecoveryParams(),
        **fields,
    )


EVERY_FEATURE = controller_params(hold=HOLD, recovery=RECOVERY)


class Bench:
    """A controller over tests/patient.py's patient (still unless a test moves its surface), the
    tip's height integrated from the command. The hand's force is set per tick; F̃ is exactly it
    (the wrist reads hand and contact, the probe sensor the contact) and so is its raw packet,
    unless `raw` says otherwise (a let-go: the packet falls before the estimate). Every tick's
    outputs, mode and tip height (the one the controller read) are kept."""

    def __init__(self, params: ControllerParams, z: float = CONTACT_Z) -> None:
        self.ctl = HandGuidingController(params)
        self.patient = Patient(amplitude_m=0.0)
        self.patient.z = z
        self.k = 0
        self.mode = self.ctl.mode
        self.outs: list[dict[str, np.ndarray]] = []
        self.modes: list[Mode] = []
        self.zs: list[float] = []

    @property
    def t(self) -> float:
        """The time of the next tick."""
        return self.k * DT

    @property
    def status(self) -> Status:
        return Status(int(self.outs[-1]["status"][0]))

    def move_surface(self, z: float) -> None:
        self.patient.surface = lambda t: z

    def step(self, hand=ZERO, raw=None, torque=ZERO, **ports) -> Mode:
        t = self.t
        inputs = self.patient.inputs(t)
        contact = inputs["F_probe_B"]
        hand = np.asarray(hand, dtype=float)
        inputs["F_hand_B"] = hand + contact
        inputs["F_hand_meas_B"] = (hand if raw is None else np.asarray(raw, dtype=float)) + contact
        inputs["tau_hand_B"] = np.asarray(torque, dtype=float)
        inputs.update(
            {name: np.atleast_1d(np.asarray(v, dtype=float)) for name, v in ports.items()}
        )
        out = self.ctl.step(t, DT, inputs)
        self.zs.append(self.patient.z)
        self.patient.z += out["twist_B"][2] * DT
        self.k += 1
        self.mode = Mode(int(out["mode"][0]))
        assert self.mode == self.ctl.mode  # the port and the attribute agree
        self.outs.append(out)
        self.modes.append(self.mode)
        return self.mode

    def run(self, seconds: float, **hand) -> list[Mode]:
        """The modes of `seconds` of ticks."""
        return [self.step(**hand) for _ in range(round(seconds / DT))]

    def until(self, mode: Mode, within_s: float, **hand) -> Mode:
        """Step until a tick ends in `mode` (at most `within_s`); the mode that tick began in."""
        for _ in range(round(within_s / DT)):
            before = self.mode
            if self.step(**hand) == mode:
                return before
        raise AssertionError(f"not {mode.name} within {within_s} s, but {self.mode.name}")


def let_go(bench: Bench, push=(5.0, 0.0, 0.0), push_s: float = 0.3) -> tuple[Mode, Mode]:
    """A push held `push_s`, then let go as test_release.py's detected release: the raw packet at
    once back to nothing, the estimate falling at 120 N/s. (the mode before the let-go, the mode at
    the end of its first tick)"""
    push = np.asarray(push, dtype=float)
    bench.run(push_s, hand=push)
    before = bench.mode
    after = bench.step(hand=push * (1.0 - 120.0 * DT / np.linalg.norm(push)), raw=ZERO)
    return before, after


def holding(params: ControllerParams = EVERY_FEATURE) -> Bench:
    """A quiet hand in contact from the start, held (settle_s + engage_s, 1.5 s by default)."""
    bench = Bench(params)
    assert bench.until(Mode.HOLDING, 2.0) == Mode.CONTACT
    return bench


ROWS_SHOWN: set[tuple[Mode, Event]] = set()


def shows(*rows: tuple[Mode, Event]) -> Callable:
    """Marks a behaviour test with the rows of the table it drives the controller through."""

    def mark(test: Callable) -> Callable:
        ROWS_SHOWN.update(rows)
        return test

    return mark


# --- stopped, and back -----------------------------------------------------------------------------


def _into_free() -> Bench:
    bench = Bench(EVERY_FEATURE, z=AIR_Z)
    bench.step()
    return bench


def _into_contact() -> Bench:
    bench = Bench(EVERY_FEATURE)
    bench.step()
    return bench


def _into_braking() -> Bench:
    bench = _into_free()
    let_go(bench)
    return bench


def _into_handing_back() -> Bench:
    bench = holding()
    bench.step(hand=ACROSS)
    return bench


def _into_recovering() -> Bench:
    bench = holding()
    bench.move_surface(AWAY)
    bench.until(Mode.RECOVERING, 0.5)
    return bench


INTO = {
    Mode.FREE: _into_free,
    Mode.CONTACT: _into_contact,
    Mode.BRAKING: _into_braking,
    Mode.HOLDING: holding,
    Mode.HANDING_BACK: _into_handing_back,
    Mode.RECOVERING: _into_recovering,
}
STOPS = {
    "nonfinite": ({"F_hand_B": [np.nan, 0.0, 0.0]}, Status.NONFINITE),
    "not ready": ({"ready": 0.0}, Status.NOT_READY),
    "stale FT-150": ({"ft_age": 1.0}, Status.STALE_FT),
    "stale probe": ({"probe_age": 1.0}, Status.STALE_PROBE),
    "force stop": ({"F_probe_B": [0.0, 0.0, 30.0]}, Status.FORCE_STOP),
}


@shows(*((mode, Event.STOP) for mode in INTO))
@pytest.mark.parametrize("cause", list(STOPS))
@pytest.mark.parametrize("mode", list(INTO), ids=lambda m: m.name)
def test_a_stop_flag_stops_every_mode(mode, cause):
    bench = INTO[mode]()
    assert bench.mode == mode
    ports, flag = STOPS[cause]
    assert bench.step(**ports) == Mode.STOPPED
    assert bench.status & flag
    np.testing.assert_array_equal(bench.outs[-1]["twist_B"], 0.0)


@shows((Mode.STOPPED, Event.GO))
@pytest.mark.parametrize(("z", "guiding"), [(AIR_Z, Mode.FREE), (CONTACT_Z, Mode.CONTACT)])
def test_the_first_tick_without_a_stop_flag_guides_in_the_air_or_in_contact(z, guiding):
    # in contact, TOUCH_DOWN follows GO in the same tick
    bench = Bench(controller_params(), z=z)
    assert bench.mode == Mode.STOPPED  # a new controller
    assert bench.step(ready=0.0) == Mode.STOPPED
    assert bench.step() == guiding


def test_a_nonfinite_input_stays_stopped_with_good_inputs_until_reset():
    bench = _into_free()
    assert bench.step(F_hand_B=[np.inf, 0.0, 0.0]) == Mode.STOPPED
    assert set(bench.run(1.0)) == {Mode.STOPPED}
    assert bench.status & Status.NONFINITE  # latched
    bench.ctl.reset()
    assert bench.step() == Mode.FREE


# --- guiding: on and off the patient --------------------------------------------------------------


@shows((Mode.FREE, Event.TOUCH_DOWN))
def test_the_probe_force_past_touch_down_is_contact():
    bench = Bench(controller_params(), z=SURFACE_Z - 1.9 / K)  # 1.9 N: under touch_down_N
    assert set(bench.run(0.5)) == {Mode.FREE}
    bench.patient.z = SURFACE_Z - 2.1 / K
    assert bench.step() == Mode.CONTACT


@shows((Mode.CONTACT, Event.LIFT_OFF))
def test_the_probe_force_under_lift_off_is_the_air_with_hysteresis():
    bench = Bench(controller_params())
    assert bench.step() == Mode.CONTACT
    bench.patient.z = SURFACE_Z - 1.6 / K  # between lift_off_N and touch_down_N: still contact
    assert set(bench.run(0.5)) == {Mode.CONTACT}
    bench.patient.z = SURFACE_Z - 1.4 / K
    assert bench.step() == Mode.FREE


@pytest.mark.parametrize(
    ("hand_N", "slope_z"),
    [(RECOVERY.pull_N + 1.0, 0.0125), (0.45, 0.2)],
    ids=["pulling beyond pull_N", "lifting lightly, the tip moving out"],
)
def test_a_hand_lifting_the_probe_off_is_a_lift_off_not_a_loss(hand_N, slope_z):
    slope = TRANSLATION_GAINS.slope.copy()
    slope[2] = slope_z
    translation = dataclasses.replace(TRANSLATION_GAINS, slope=slope)
    bench = Bench(controller_params(release=False, recovery=RECOVERY, translation=translation))
    assert set(bench.run(1.2)) == {Mode.CONTACT}  # established
    lift = (0.0, 0.0, hand_N)  # up, out of the patient
    assert bench.until(Mode.FREE, 1.0, hand=lift) == Mode.CONTACT
    assert Mode.RECOVERING not in bench.modes
    assert bench.ctl.recovery.recoveries == 0
    # the cause: the pull at the first tick under lift_off_N, else the tip loss_m out within
    # loss_s (not the time alone)
    lift_off_N = bench.ctl.params.lift_off_N
    first = next(k for k, z in enumerate(bench.zs) if K * (SURFACE_Z - z) < lift_off_N)
    ticks, out = len(bench.zs) - 1 - first, bench.zs[-1] - bench.zs[first]
    if hand_N > RECOVERY.pull_N:
        assert ticks == 0
    else:
        assert out >= RECOVERY.loss_m
        assert ticks * DT < RECOVERY.loss_s


@pytest.mark.parametrize(
    ("contact_s", "after"),
    [(0.5, Mode.FREE), (1.5, Mode.RECOVERING)],
    ids=["a finger's push: lift off", "an established contact: lost"],
)
def test_only_an_established_contact_can_be_lost(contact_s, after):
    bench = Bench(controller_params(release=False, recovery=RECOVERY), z=SURFACE_Z)
    bench.move_surface(SURFACE_Z + 0.005)  # the surface pushes the tip: 6 N
    assert bench.step() == Mode.CONTACT
    bench.run(contact_s - DT)
    bench.move_surface(SURFACE_Z - 0.005)  # ... and falls away, the tip where it was
    if after == Mode.FREE:
        assert bench.step() == Mode.FREE  # at once
    else:
        modes = bench.run(RECOVERY.loss_s)
        assert set(modes) == {Mode.CONTACT}  # waits loss_s from the first tick without
        assert bench.step() == Mode.RECOVERING
    assert (Mode.RECOVERING in bench.modes) == (after == Mode.RECOVERING)


def test_a_dip_shorter_than_loss_s_keeps_the_contact():
    bench = Bench(controller_params(release=False, recovery=RECOVERY))
    bench.run(1.2)
    bench.move_surface(SURFACE_Z - 0.01)
    bench.run(RECOVERY.loss_s - 3 * DT)
    bench.move_surface(SURFACE_Z)
    assert set(bench.run(0.5)) == {Mode.CONTACT}


# --- the release and its brake --------------------------------------------------------------------


@shows((Mode.FREE, Event.RELEASED), (Mode.CONTACT, Event.RELEASED))
@pytest.mark.parametrize(("z", "guiding"), [(AIR_Z, Mode.FREE), (CONTACT_Z, Mode.CONTACT)])
def test_a_let_go_brakes(z, guiding):
    bench = Bench(controller_params(), z=z)
    assert let_go(bench) == (guiding, Mode.BRAKING)
    assert bench.status & Status.RELEASED
    assert bench.status & Status.BRAKING  # the speed shed at max_brake_accel


def test_a_let_go_is_not_a_release_with_the_release_off():
    bench = Bench(controller_params(release=False), z=AIR_Z)
    let_go(bench)
    assert Mode.BRAKING not in bench.modes


@shows((Mode.BRAKING, Event.PUSHED))
@pytest.mark.parametrize(("z", "guiding"), [(AIR_Z, Mode.FREE), (CONTACT_Z, Mode.CONTACT)])
def test_a_firm_push_after_a_let_go_guides_again(z, guiding):
    # in contact PUSHED leads to FREE and TOUCH_DOWN to CONTACT in the same tick
    bench = Bench(controller_params(), z=z)
    let_go(bench)
    assert set(bench.run(0.3)) == {Mode.BRAKING}  # hands off: at rest
    assert bench.step(hand=(5.0, 0.0, 0.0)) == guiding
    assert not bench.status & Status.RELEASED


def test_a_release_in_the_air_is_never_held():
    bench = Bench(controller_params(hold=HOLD), z=AIR_Z)
    assert let_go(bench) == (Mode.FREE, Mode.BRAKING)
    assert set(bench.run(3.0)) == {Mode.BRAKING}
    assert bench.ctl.hold.holds == 0


# --- the hold ---------------------------------------------------------------------------------------


@shows((Mode.CONTACT, Event.HOLD_READY))
def test_a_quiet_hand_in_contact_is_held_after_settle_s_and_engage_s():
    bench = Bench(controller_params(hold=HOLD))
    assert bench.until(Mode.HOLDING, 2.0) == Mode.CONTACT
    t_held = bench.t - DT  # contact from t = 0
    assert HOLD.settle_s + HOLD.engage_s - 1e-9 <= t_held <= HOLD.settle_s + HOLD.engage_s + 2 * DT
    assert bench.status & Status.HOLDING


@shows((Mode.BRAKING, Event.HOLD_READY))
def test_a_let_go_in_contact_before_it_settled_brakes_and_is_held_once_settled():
    bench = Bench(controller_params(hold=HOLD))
    assert let_go(bench) == (Mode.CONTACT, Mode.BRAKING)
    assert bench.until(Mode.HOLDING, 1.0) == Mode.BRAKING
    # at settle_s from the first contact: the release in contact, not engage_s of a quiet hand
    assert HOLD.settle_s - 1e-9 <= bench.t - DT <= HOLD.settle_s + 2 * DT


def test_a_let_go_in_contact_once_settled_is_held_in_the_same_tick():
    # RELEASED (to BRAKING) and HOLD_READY (to HOLDING) in one tick
    bench = Bench(controller_params(hold=dataclasses.replace(HOLD, engage_s=5.0)))
    assert set(bench.run(1.2)) == {Mode.CONTACT}  # settled, and quiet for too short a while
    assert let_go(bench) == (Mode.CONTACT, Mode.HOLDING)


@shows((Mode.FREE, Event.HOLD_READY))
def test_a_probe_held_under_touch_down_n_but_in_the_holds_contact_is_held_from_the_air():
    # the hold's contact_N (2 N) under the controller's touch_down_N: at 3 N the mode is FREE
    bench = Bench(
        controller_params(hold=HOLD, touch_down_N=5.0, lift_off_N=4.0), z=SURFACE_Z - 3.0 / K
    )
    assert bench.step() == Mode.FREE
    assert bench.until(Mode.HOLDING, 2.0) == Mode.FREE


def test_a_release_while_holding_keeps_holding():
    push = (0.0, 0.0, -2.0)  # along the probe, inside the hold's axial band: no touch
    bench = holding()
    releases = bench.ctl.release.releases
    let_go(bench, push=push)
    assert set(bench.modes[-round(0.3 / DT) :]) == {Mode.HOLDING}
    assert set(bench.run(0.5)) == {Mode.HOLDING}
    assert bench.ctl.release.releases == releases
    # the same let-go under the hand in contact is a release
    contact = Bench(controller_params())
    assert let_go(contact, push=push) == (Mode.CONTACT, Mode.BRAKING)


@shows((Mode.HOLDING, Event.TOUCHED), (Mode.HANDING_BACK, Event.HANDED_BACK))
def test_a_push_across_the_probe_while_holding_hands_back_over_blend_s():
    bench = holding()
    assert bench.step(hand=ACROSS) == Mode.HANDING_BACK
    t_touch = bench.t - DT
    assert bench.until(Mode.CONTACT, 1.0, hand=ACROSS) == Mode.HANDING_BACK
    assert HOLD.blend_s - 1e-9 <= bench.t - DT - t_touch <= HOLD.blend_s + DT + 1e-9
    assert bench.ctl.hold.ended == HoldEnd.HANDED_BACK


@shows((Mode.HOLDING, Event.HANDED_BACK))
def test_without_a_blend_a_touch_hands_back_at_once():
    bench = holding(controller_params(hold=dataclasses.replace(HOLD, blend_s=0.0)))
    assert bench.step(hand=ACROSS) == Mode.CONTACT
    assert bench.ctl.hold.ended == HoldEnd.HANDED_BACK


@shows((Mode.HOLDING, Event.CONTACT_LOST))
def test_the_patient_moving_away_from_a_hold_starts_the_recovery():
    bench = holding(controller_params(hold=HOLD, recovery=RECOVERY))
    bench.move_surface(AWAY)
    t_away = bench.t
    assert bench.until(Mode.RECOVERING, 0.5) == Mode.HOLDING
    assert bench.t - DT - t_away <= HOLD.loss_s + DT
    assert bench.ctl.hold.ended == HoldEnd.CONTACT_LOST
    assert bench.ctl.recovery.active
    assert bench.ctl.recovery.hands_off


def test_without_the_recovery_a_lost_hold_brakes_in_the_same_tick():
    # CONTACT_LOST to RECOVERING, and RECOVERY_FAILED to BRAKING at once
    bench = holding(controller_params(hold=HOLD))
    bench.move_surface(AWAY)
    assert bench.until(Mode.BRAKING, 0.5) == Mode.HOLDING
    assert Mode.RECOVERING not in bench.modes
    assert bench.ctl.hold.ended == HoldEnd.CONTACT_LOST
    assert bench.status & Status.RELEASED


@shows((Mode.HANDING_BACK, Event.CONTACT_LOST))
def test_the_contact_lost_while_handing_back_brakes_even_with_the_recovery():
    hold = dataclasses.replace(HOLD, blend_s=5.0)
    bench = holding(controller_params(hold=hold, recovery=RECOVERY))
    assert bench.step(hand=ACROSS) == Mode.HANDING_BACK
    bench.move_surface(AWAY)
    assert bench.until(Mode.BRAKING, 0.5, hand=ACROSS) == Mode.HANDING_BACK
    assert bench.ctl.hold.ended == HoldEnd.CONTACT_LOST
    assert bench.ctl.recovery.recoveries == 0


@shows((Mode.HOLDING, Event.TRAVEL_LIMIT))
def test_a_hold_following_a_breath_past_max_travel_m_brakes():
    hold = dataclasses.replace(HOLD, max_travel_m=0.002)
    bench = Bench(controller_params(hold=hold, recovery=RECOVERY))
    bench.patient.surface = lambda t: SURFACE_Z + 0.01 * np.sin(2 * np.pi * 0.25 * t)
    assert bench.until(Mode.HOLDING, 2.0) == Mode.CONTACT
    z_held = bench.zs[-1]
    assert bench.until(Mode.BRAKING, 2.0) == Mode.HOLDING
    assert bench.ctl.hold.ended == HoldEnd.TRAVEL
    assert abs(bench.zs[-1] - z_held) >= hold.max_travel_m - 1e-12


@shows((Mode.HANDING_BACK, Event.TRAVEL_LIMIT))
def test_a_hand_back_whose_hold_travels_past_max_travel_m_brakes():
    hold = dataclasses.replace(HOLD, max_travel_m=0.002, blend_s=5.0)
    bench = holding(controller_params(hold=hold, recovery=RECOVERY))
    z_held = bench.zs[-1]
    assert bench.step(hand=ACROSS) == Mode.HANDING_BACK
    bench.move_surface(SURFACE_Z - 0.004)  # 4.8 N left: the hold follows it down
    assert bench.until(Mode.BRAKING, 1.0, hand=ACROSS) == Mode.HANDING_BACK
    assert bench.ctl.hold.ended == HoldEnd.TRAVEL
    assert abs(bench.zs[-1] - z_held) >= hold.max_travel_m - 1e-12


# --- the recovery -----------------------------------------------------------------------------------


@shows((Mode.RECOVERING, Event.RECOVERED))
def test_the_contact_back_hands_off_is_held_again_at_the_holds_level():
    bench = holding(controller_params(hold=HOLD, recovery=RECOVERY))
    bench.run(1.0)
    level = bench.ctl.hold.target_N
    bench.move_surface(SURFACE_Z - 0.013)  # 5 mm between the tip and the skin
    assert bench.until(Mode.RECOVERING, 0.5) == Mode.HOLDING
    assert bench.until(Mode.HOLDING, 1.0) == Mode.RECOVERING
    assert bench.ctl.hold.holds == 2
    assert bench.ctl.hold.target_N == level  # kept, not the window's force at the return


def under_the_hand(recovery: RecoveryParams = RECOVERY) -> Bench:
    """In contact under the hand (no hold, no release) for longer than established_s."""
    bench = Bench(controller_params(release=False, recovery=recovery))
    assert set(bench.run(recovery.established_s + 0.2)) == {Mode.CONTACT}
    return bench


@shows((Mode.CONTACT, Event.CONTACT_LOST), (Mode.RECOVERING, Event.CONTACT_BACK))
def test_a_contact_lost_under_the_hand_is_recovered_and_the_hand_has_it_again():
    bench = under_the_hand()
    bench.move_surface(SURFACE_Z - 0.012)  # 4 mm between the tip and the skin
    t_lost = bench.t
    assert bench.until(Mode.RECOVERING, 0.5) == Mode.CONTACT
    assert RECOVERY.loss_s - 1e-9 <= bench.t - DT - t_lost <= RECOVERY.loss_s + DT
    assert not bench.ctl.recovery.hands_off
    assert bench.until(Mode.CONTACT, 1.0) == Mode.RECOVERING
    assert not bench.ctl.recovery.active
    assert bench.ctl.hold.holds == 0


@shows((Mode.RECOVERING, Event.RECOVERY_FAILED))
@pytest.mark.parametrize("why", ["travel", "time"])
def test_a_recovery_that_finds_no_contact_gives_up_and_brakes(why):
    recovery = RECOVERY if why == "travel" else dataclasses.replace(RECOVERY, max_s=0.5)
    bench = under_the_hand(recovery)
    bench.move_surface(AWAY)
    bench.until(Mode.RECOVERING, 0.5)
    t0, z0 = bench.t - DT, bench.zs[-1]
    assert bench.until(Mode.BRAKING, 2.0) == Mode.RECOVERING
    elapsed, travel = bench.t - DT - t0, z0 - bench.zs[-1]  # the approach is down
    if why == "travel":
        assert travel >= recovery.max_travel_m
        assert elapsed < recovery.max_s
    else:
        assert elapsed >= recovery.max_s - 1e-9
        assert travel < recovery.max_travel_m
    assert bench.status & Status.RELEASED


@shows((Mode.RECOVERING, Event.PUSHED))
def test_a_hand_pulling_against_the_approach_takes_the_probe():
    bench = under_the_hand()
    bench.move_surface(AWAY)
    bench.until(Mode.RECOVERING, 0.5)
    # up: F̃ against the approach, under pull_N, and beyond it for less than pull_s, then longer
    assert set(bench.run(0.1, hand=(0.0, 0.0, 0.5 * RECOVERY.pull_N))) == {Mode.RECOVERING}
    pull = (0.0, 0.0, RECOVERY.pull_N + 0.5)
    modes = bench.run(RECOVERY.pull_s + 0.05, hand=pull)
    assert Mode.FREE in modes
    assert modes[: modes.index(Mode.FREE)] == [Mode.RECOVERING] * modes.index(Mode.FREE)
    assert modes.index(Mode.FREE) * DT >= RECOVERY.pull_s - DT
    assert not bench.ctl.recovery.active


@pytest.mark.parametrize("ended", ["travel limit", "recovery failed"])
def test_a_hold_ended_without_the_hand_rests_until_the_hand_pushes(ended):
    if ended == "travel limit":
        hold = dataclasses.replace(HOLD, max_travel_m=0.005)
        bench = holding(controller_params(hold=hold))
        t0 = bench.t
        bench.patient.surface = lambda t: SURFACE_Z - 0.005 * (t - t0)  # sinking at 5 mm/s
        bench.until(Mode.BRAKING, 2.0)
        assert bench.ctl.hold.ended == HoldEnd.TRAVEL
    else:
        recovery = dataclasses.replace(RECOVERY, max_s=0.3)
        bench = holding(controller_params(hold=HOLD, recovery=recovery))
        bench.move_surface(AWAY)
        bench.until(Mode.BRAKING, 1.0)
        bench.move_surface(bench.patient.z + 0.008)  # the patient back under the probe: 9.6 N
    assert set(bench.run(2.5)) == {Mode.BRAKING}
    assert bench.ctl.hold.holds == 1


def test_every_row_of_the_table_has_a_behaviour_test():
    assert set(TRANSITIONS) == ROWS_SHOWN


# --- the supervisor has the last word ---------------------------------------------------------------

LIMITS = LimitParams(workspace_max_B=[SURFACE_Z, 0.7, 0.8])  # the tip on the box's +x face
HUGE = controller_params(
    hold=dataclasses.replace(HOLD, max_speed=1.0),
    recovery=dataclasses.replace(RECOVERY, speed_m_s=1.0),
    translation=dataclasses.replace(TRANSLATION_GAINS, slope=[10.0, 10.0, 10.0]),
    rotation=dataclasses.replace(ROTATION_GAINS, slope=[10.0, 10.0, 10.0]),
    limits=LIMITS,
)
SHOVE = (40.0, 40.0, 0.0)  # [N] across the probe, +x against the box's face
TWIST = (2.0, -2.0, 2.0)  # [N.m]


def _huge_free(bench: Bench) -> None:
    bench.patient.z = AIR_Z
    bench.run(0.3, hand=(40.0, 40.0, 40.0), torque=TWIST)
    bench.run(0.3, hand=(-40.0, -40.0, -40.0), torque=np.negative(TWIST))


def _huge_contact(bench: Bench) -> None:
    bench.run(0.3, hand=SHOVE, torque=TWIST)
    bench.run(0.3, hand=(-40.0, -40.0, 0.0), torque=np.negative(TWIST))


def _huge_braking(bench: Bench) -> None:
    bench.patient.z = AIR_Z
    let_go(bench, push=(0.0, 40.0, 0.0))
    bench.run(0.1)


def _huge_holding(bench: Bench) -> None:
    # a release in contact at full speed across: held in the same tick, the speed across shed
    # at the acceleration limit; then the skin steps 5 mm and the hold follows it
    bench.run(1.2, hand=SHOVE, torque=TWIST)
    let_go(bench, push=SHOVE)
    bench.move_surface(SURFACE_Z + 0.005)
    bench.run(0.5)


def _huge_handing_back(bench: Bench) -> None:
    bench.until(Mode.HOLDING, 2.0)
    bench.run(0.3, hand=SHOVE, torque=TWIST)


def _huge_recovering(bench: Bench) -> None:
    # the approach at 1 m/s, the hand's request across kept; then it gives up and brakes
    bench.until(Mode.HOLDING, 2.0)
    bench.move_surface(AWAY)
    bench.until(Mode.RECOVERING, 0.5)
    bench.run(0.2, hand=(0.0, 40.0, 0.0))
    bench.until(Mode.BRAKING, 1.0)
    bench.run(0.1)


def _huge_stopped(bench: Bench) -> None:
    _huge_free(bench)
    bench.step(ft_age=1.0)


HUGE_RUNS = {
    Mode.STOPPED: _huge_stopped,
    Mode.FREE: _huge_free,
    Mode.CONTACT: _huge_contact,
    Mode.BRAKING: _huge_braking,
    Mode.HOLDING: _huge_holding,
    Mode.HANDING_BACK: _huge_handing_back,
    Mode.RECOVERING: _huge_recovering,
}


@pytest.mark.parametrize("mode", list(Mode), ids=lambda m: m.name)
def test_the_command_is_within_the_limits_in_every_mode(mode):
    bench = Bench(HUGE)
    HUGE_RUNS[mode](bench)
    assert mode in bench.modes
    lim = LIMITS
    v_prev = w_prev = ZERO
    clamped = Status(0)
    for out, mode_k, z in zip(bench.outs, bench.modes, bench.zs, strict=True):
        v, w = out["twist_B"][:3], out["twist_B"][3:]
        status = Status(int(out["status"][0]))
        assert np.linalg.norm(v) <= lim.max_linear_speed * (1 + 1e-9)
        assert np.linalg.norm(w) <= lim.max_angular_speed * (1 + 1e-9)
        if mode_k == Mode.STOPPED:  # the stop's zero, not a clamp
            assert not status.ok
            np.testing.assert_array_equal(out["twist_B"], 0.0)
        else:
            accel = lim.max_brake_accel if status & Status.BRAKING else lim.max_linear_accel
            assert np.linalg.norm(v - v_prev) <= accel * DT * (1 + 1e-9), (mode_k, status)
            assert np.linalg.norm(w - w_prev) <= lim.max_angular_accel * DT * (1 + 1e-9)
            p = np.array([SURFACE_Z, 0.0, z])  # on the box's +x face
            assert not np.any((p >= lim.workspace_max_B) & (v > 0.0))
            assert not np.any((p <= lim.workspace_min_B) & (v < 0.0))
        if mode_k == mode:
            clamped |= status
        v_prev, w_prev = v, w
    if mode != Mode.STOPPED:  # the limits were at work in the mode
        assert clamped & (Status.SPEED_CLAMPED | Status.ACCEL_CLAMPED | Status.BRAKING)
