"""Following the breath while the hand steers, in the controller: the breath's swing out of the
contact force as the loop predicts, a push that sets a new level, nothing out of contact and no step
into it, a short gap in the contact that keeps the level, the travel bound, and nothing while the
hold holds."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hoh_cosim.control.controller import ControllerParams, HandGuidingController
from hoh_cosim.control.follow import FollowParams
from hoh_cosim.control.hold import HoldParams
from hoh_cosim.control.release import ReleaseParams
from hoh_cosim.control.supervisor import Status
from hoh_cosim.errors import ConfigError
from tests.patient import DT, K, Patient, run

FOLLOWING = int(Status.FOLLOWING)


def following_controller(**follow) -> HandGuidingController:
    return HandGuidingController(ControllerParams(follow=FollowParams(enabled=True, **follow)))


def swing(forces: np.ndarray) -> float:
    """Peak to peak over the last 8 s (two breaths at 15 a minute)."""
    late = forces[-round(8.0 / DT) :]
    return float(late.max() - late.min())


def test_the_breaths_swing_leaves_the_contact_as_the_loop_predicts():
    # 5 mm at 15 a minute on 8 mm of depth: a still robot sees k · 2 · 5 mm = 12 N of swing
    still, _, _ = run(HandGuidingController(), Patient(amplitude_m=0.005), 0.0, 24.0)
    assert swing(still) == pytest.approx(2 * K * 0.005, rel=0.02)

    ctl = following_controller()
    forces, flags, _ = run(ctl, Patient(amplitude_m=0.005), 0.0, 24.0)
    assert np.all(flags[round(0.5 / DT) :] & FOLLOWING)
    # with c̄ the level, c̄' = (c - c̄) / τ, and k̂ = k: c = k s (1 + τ p) / (1 + g τ + τ p), so the
    # swing left at ω = 2π · 0.25 /s is |1 + jωτ| / |1 + gτ + jωτ| = 0.44 (g = 3 /s, τ = 4 s; 0.46,
    # the first-order high-pass's ω / √(ω² + g²), for a level that never moves)
    omega, g, tau = 2 * math.pi * 0.25, 3.0, 4.0
    predicted = abs(complex(1.0, omega * tau) / complex(1.0 + g * tau, omega * tau))
    ratio = swing(forces) / swing(still)
    assert ratio == pytest.approx(predicted, abs=0.05)
    # the level is the sonographer's: the mean force stays where the contact began (9.6 N)
    assert np.mean(forces[-round(8.0 / DT) :]) == pytest.approx(K * 0.008, abs=0.6)


def test_a_push_along_the_probe_sets_a_new_level_and_is_not_fought():
    # no breath; the hand presses 1.5 N (beyond the 1 N band) for 0.5 s, the law drives the tip
    # 0.0125 · (1.5 - 0.25) · 0.5 s = 7.8 mm deeper (9.4 N more), and lets go
    for push_level_s, kept in ((0.1, True), (4.0, False)):
        ctl = following_controller(push_level_s=push_level_s)
        patient = Patient(amplitude_m=0.0)
        before, _, _ = run(ctl, patient, 0.0, 2.0)
        pressed, _, _ = run(ctl, patient, 2.0, 2.5, hand_N=1.5)
        after, flags, _ = run(ctl, patient, 2.5, 6.0)
        assert np.all(flags & FOLLOWING)
        level, pushed, left = before[-10:].mean(), pressed[-1], after[-10:].mean()
        if kept:
            # the level followed the push, 0.1 s behind it: at the push's 15 N/s it lags 1.5 N,
            # and the force stays there when the hand lets go
            assert pushed > level + 6.0
            assert pushed - 2.0 < left < pushed
        else:  # a level as slow as the breath's fights the push and pulls the force back
            assert pushed < level + 6.0
            assert left < level + 1.5


def test_no_follow_out_of_contact_and_no_step_into_it():
    ctl = following_controller()
    patient = Patient(amplitude_m=0.0)
    patient.z = 0.3 + 0.001  # 1 mm above the surface
    forces, flags, _ = run(ctl, patient, 0.0, 1.0)
    assert not np.any(forces)
    assert not np.any(flags & FOLLOWING)
    assert not ctl.follow.active
    patient.z = 0.3 - 0.004  # touched down: 4.8 N, over the 3 N contact
    out = ctl.step(1.0, DT, patient.inputs(1.0))
    assert int(out["status"][0]) & FOLLOWING
    # the level starts at the contact's force: the first command is rest, not a step
    assert np.all(out["twist_B"] == 0.0)
    assert ctl.follow.level_N == pytest.approx(K * 0.004)


def test_a_short_gap_in_the_contact_keeps_the_level_and_a_long_one_starts_afresh():
    # 9.6 N held, then the skin off the probe (an exhale's trough, or the probe lifted) for 0.5 s or
    # 6 s, then back at 4.8 N: within level_s (4 s) it is the same contact, and the follow takes the
    # force back up towards its level; after it, a new contact with the force it began with
    for gap, kept in ((0.5, True), (6.0, False)):
        ctl = following_controller()
        patient = Patient(amplitude_m=0.0)
        run(ctl, patient, 0.0, 2.0)
        assert ctl.follow.level_N == pytest.approx(K * 0.008)
        patient.z = 0.3 + 0.010
        _, flags, _ = run(ctl, patient, 2.0, 2.0 + gap)
        assert not flags[-1] & FOLLOWING
        patient.z = 0.3 - 0.004
        forces, _, _ = run(ctl, patient, 2.0 + gap, 5.0 + gap)
        assert forces[0] == pytest.approx(K * 0.004, abs=0.05)
        if kept:  # the force and the level meet between the two: 9.0 N after 3 s
            assert forces[-1] > 8.0
            assert ctl.follow.level_N > 8.0
        else:
            assert forces[-1] == pytest.approx(K * 0.004, abs=0.1)
            assert ctl.follow.level_N == pytest.approx(K * 0.004, abs=0.1)


def test_the_follow_moves_the_tip_no_farther_than_its_travel():
    # the patient sinks away at 2 mm/s for 15 s (30 mm): the follow chases the falling force, by
    # itself no farther than 20 mm, and the contact is then lost rather than chased
    class Sinking(Patient):
        def surface(self, t: float) -> float:
            return 0.3 - 0.002 * t

    patient = Sinking(amplitude_m=0.0)
    ctl = following_controller()
    z0 = patient.z
    forces, flags, _ = run(ctl, patient, 0.0, 15.0)
    assert z0 - patient.z == pytest.approx(0.020, abs=1e-6)
    assert forces[-1] == 0.0
    assert not flags[-1] & FOLLOWING
    # without the bound it would have kept the contact: the chase is the loop's, not a drift
    patient = Sinking(amplitude_m=0.0)
    forces, _, _ = run(following_controller(max_travel_m=1.0), patient, 0.0, 15.0)
    assert forces[-1] > 1.0


def test_the_hold_holds_alone_and_the_follow_stands_aside_and_forgets_its_level():
    ctl = HandGuidingController(
        ControllerParams(
            release=ReleaseParams(enabled=True),
            hold=HoldParams(enabled=True),
            follow=FollowParams(enabled=True),
        )
    )
    patient = Patient(amplitude_m=0.005)
    _, flags, _ = run(ctl, patient, 0.0, 12.0)
    holding = (flags & int(Status.HOLDING)) != 0
    assert holding[-1]  # the quiet hand engaged the hold
    assert not np.any(flags[holding] & FOLLOWING)
    assert np.all(flags[: round(0.5 / DT)] & FOLLOWING)  # before it, the breath was followed
    assert not ctl.follow.active
    assert ctl.follow.travel_m == 0.0
    assert ctl.follow.level_N == 0.0  # after the hold, a contact of its own


def test_following_is_off_by_default():
    _, flags, _ = run(HandGuidingController(), Patient(), 0.0, 2.0)
    assert not np.any(flags & FOLLOWING)


@pytest.mark.parametrize("key", ["gain_per_s", "level_s", "max_travel_m", "contact_N"])
def test_follow_params_reject_a_value_that_is_not_positive(key):
    with pytest.raises(ConfigError, match=rf"^{key} must be > 0.0, got -1.0$") as caught:
        FollowParams(**{key: -1.0})
    assert "\n" not in str(caught.value)
