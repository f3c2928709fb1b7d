"""Following the breath while the hand steers, in the controller: the breath's swing out of the
contact force as the loop predicts, a push that sets a new level, nothing out of contact and no step
into it, a short gap in the contact that keeps the level, the travel bound, and nothing while the
hold holds."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hoh_cosim.control.controller import ControllerParams, HandGuidingController
from hoh_cosim.control.follow import BreathFollower, FollowParams
from hoh_cosim.control.hold import HoldParams, surface_filter_gain
from hoh_cosim.control.release import ReleaseParams
from hoh_cosim.control.supervisor import Status
from hoh_cosim.errors import ConfigError
from tests.patient import AXIS, DT, K, Patient, run

FOLLOWING = int(Status.FOLLOWING)


def following_controller(**follow) -> HandGuidingController:
    return HandGuidingController(ControllerParams(follow=FollowParams(enabled=True, **follow)))


def swing(forces: np.ndarray) -> float:
    """Peak to peak over the last 8 s (two breaths at 15 a minute)."""
    late = forces[-round(8.0 / DT) :]
    return float(late.max() - late.min())


def rate_response(hz: float, dt: float, omega: float) -> complex:
    """The surface filter's estimated speed over the true one, for a surface moving at ω."""
    k = np.array(surface_filter_gain(hz, dt))
    F = np.array([[1.0, dt, 0.5 * dt * dt], [0.0, 1.0, dt], [0.0, 0.0, 1.0]])
    A = (np.eye(3) - np.outer(k, [1.0, 0.0, 0.0])) @ F  # x_n = A x_(n-1) + k m_n
    z = np.exp(1j * omega * dt)
    return complex(np.linalg.solve(np.eye(3) - A / z, k)[1]) / (1j * omega)


@pytest.mark.parametrize("surface_gain", [0.0, 0.4])
def test_the_breaths_swing_leaves_the_contact_as_the_loop_predicts(surface_gain):
    # 5 mm at 15 a minute on 8 mm of depth: a still robot sees k · 2 · 5 mm = 12 N of swing
    still, _, _ = run(HandGuidingController(), Patient(amplitude_m=0.005), 0.0, 24.0)
    assert swing(still) == pytest.approx(2 * K * 0.005, rel=0.02)

    ctl = following_controller(surface_gain=surface_gain)
    forces, flags, _ = run(ctl, Patient(amplitude_m=0.005), 0.0, 24.0)
    assert np.all(flags[round(0.5 / DT) :] & FOLLOWING)
    # with c̄ the level, c̄' = (c - c̄) / τ, and k̂ = k: the tip's speed is g (c - c̄) / k + κ ṡ̂,
    # ṡ̂ = H ṡ the surface filter's estimate, and c = k (s - z), so
    #     c / (k s) = (jω - κ H jω) / (jω + g jωτ / (1 + jωτ)),
    # without the feed-forward |1 + jωτ| / |1 + gτ + jωτ| = 0.68 at ω = 2π · 0.25 /s (g = 1.5 /s,
    # τ = 4 s); with κ = 0.4 and the 1 Hz filter (|H| = 1.11 at the breath) 0.375
    omega, g, tau = 2 * math.pi * 0.25, FollowParams().gain_per_s, 4.0
    jw = complex(0.0, omega)
    H = rate_response(1.0, DT, omega)
    predicted = abs(jw * (1.0 - surface_gain * H)) / abs(jw + g * jw * tau / (1.0 + jw * tau))
    ratio = swing(forces) / swing(still)
    assert ratio == pytest.approx(predicted, abs=0.03)
    # the level is the sonographer's: the mean force stays where the contact began (9.6 N)
    assert np.mean(forces[-round(8.0 / DT) :]) == pytest.approx(K * 0.008, abs=0.6)


class PlayPatient(Patient):
    """The probe sensor read through a play of width w (plant_models.sensors' housing): its reading
    moves only once the contact has moved w past it."""

    def __init__(self, play_N: float, **kwargs) -> None:
        super().__init__(**kwargs)
        self.play_N = play_N
        self.read_N: float | None = None

    def inputs(self, t: float, hand_N: float = 0.0, hand_x_N: float = 0.0) -> dict:
        out = super().inputs(t, hand_N, hand_x_N)
        c = self.force(t)
        read = c if self.read_N is None else min(max(self.read_N, c - self.play_N), c + self.play_N)
        self.read_N = read
        out["F_probe_B"] = out["F_probe_meas_B"] = -read * AXIS
        return out


def test_the_surface_fed_forward_through_the_probes_play_takes_more_of_the_swing_and_keeps_the_level():
    # the play hides the contact once it stops changing: m then moves with the tip, and the
    # feed-forward is the robot's own speed fed back with gain κ < 1 (module docstring). With
    # 0.8 N of play (the housing's widest) the loop stays put and still takes more of the swing
    swings, means = {}, {}
    for surface_gain in (0.0, 0.4, 0.9):
        patient = PlayPatient(0.8, amplitude_m=0.005)
        forces, flags, _ = run(following_controller(surface_gain=surface_gain), patient, 0.0, 40.0)
        assert np.all(flags[round(0.5 / DT) :] & FOLLOWING)
        swings[surface_gain] = swing(forces)
        means[surface_gain] = float(np.mean(forces[-round(8.0 / DT) :]))
    assert swings[0.4] < 0.8 * swings[0.0]
    assert swings[0.9] < 0.8 * swings[0.4]
    for mean in means.values():
        assert mean == pytest.approx(K * 0.008, abs=0.6)


def follower_inputs(t, z, c, hand_N=0.0):
    """The follow's own inputs for a tip at depth coordinate z (p_BT along B's z), contact c, a
    hand pressing hand_N along the probe: the wrist reads both, the probe the contact."""
    contact = -c * AXIS
    return {
        "F_tilde": hand_N * AXIS,
        "F_probe": contact,
        "axis": AXIS,
        "t": t,
        "p_BT": np.array([0.3, 0.0, z]),
        "F_wrist_meas": hand_N * AXIS + contact,
        "F_probe_meas": contact,
    }


def test_a_steady_push_along_the_probe_is_the_hands_share_and_not_the_surface():
    # a still patient and a still tip, 9.6 N; the hand presses 0.5 N along the probe from 2 s
    # (under the push band: the level stays the breath's). The wrist reads it at once and the hand's
    # share ĥ takes it over share_s: the surface's speed estimate returns to rest
    follow = BreathFollower(FollowParams(enabled=True, share_s=4.0))
    z, c = 0.3 - 0.008, K * 0.008
    rates = []
    for k in range(round(30.0 / DT)):
        t = k * DT
        follow.step(DT, **follower_inputs(t, z, c, hand_N=0.5 if t >= 2.0 else 0.0))
        rates.append(follow.surface_m_s)
    rates = np.array(rates)
    assert np.all(rates[: round(2.0 / DT)] == 0.0)
    # the push read as the surface sinking by 0.5 N / k̂ (0.42 mm), then taken back as ĥ grows
    assert rates.min() < -1e-4
    assert np.all(np.abs(rates[-round(5.0 / DT) :]) < 2e-5)
    # the probe reads 0.5 N more than the wrist: the hand's share
    assert follow.share_N == pytest.approx(0.5, abs=0.01)


def test_the_surface_takes_the_tip_where_the_wrists_packet_was_sampled():
    # a still surface; the tip moves ±2 mm at 1 Hz into it; the wrist's packets come every 5 ms,
    # each sampled 2 ms before it arrives and held. With the packet's age, m = z + c / k̂ is the
    # surface at every tick and the speed estimate stays at rest; without it, the tip's speed
    # leaks in (up to 12.6 mm/s · the 2-7 ms the packet is old)
    worst = {}
    for with_age in (True, False):
        follow = BreathFollower(FollowParams(enabled=True))
        sampled_at, packet_c = 0.0, K * 0.008
        for k in range(round(6.0 / (DT / 4))):
            t = k * DT / 4  # a 2 ms tick
            tip = 0.3 - 0.008 + 0.002 * math.sin(2 * math.pi * t)
            if t - 0.002 >= sampled_at + 0.005 - 1e-9:  # a packet sampled 2 ms ago arrives
                sampled_at += 0.005
                packet_c = K * (0.3 - (0.3 - 0.008 + 0.002 * math.sin(2 * math.pi * sampled_at)))
            age = t - sampled_at - 0.002 if with_age else 0.0
            inputs = follower_inputs(t, tip, packet_c)
            follow.step(DT / 4, **inputs, ft_age=age)
            if t > 2.0:
                worst[with_age] = max(worst.get(with_age, 0.0), abs(follow.surface_m_s))
    assert worst[True] < 1e-5
    assert worst[False] > 1e-4


def test_a_push_along_the_probe_sets_a_new_level_and_is_not_fought():
    # no breath; the hand presses 1.5 N (beyond the 1 N band) for 0.5 s, the law drives the tip
    # 0.0125 · (1.5 - 0.25) · 0.5 s = 7.8 mm deeper (9.4 N more), and lets go
    peaks = {}
    for push_level_s, kept in ((0.1, True), (4.0, False)):
        ctl = following_controller(push_level_s=push_level_s)
        patient = Patient(amplitude_m=0.0)
        before, _, _ = run(ctl, patient, 0.0, 2.0)
        pressed, _, _ = run(ctl, patient, 2.0, 2.5, hand_N=1.5)
        after, flags, _ = run(ctl, patient, 2.5, 6.0)
        assert np.all(flags & FOLLOWING)
        level, pushed, left = before[-10:].mean(), pressed[-1], after[-10:].mean()
        peaks[kept] = pushed
        if kept:
            # the level followed the push, 0.1 s behind it: at the push's 15 N/s it lags 1.5 N,
            # and the force stays there when the hand lets go
            assert pushed > level + 6.0
            assert pushed - 2.0 < left < pushed
        else:  # a level as slow as the breath's pulls the force back once the hand lets go
            assert left < level + 1.5
    # ... and it fought the push while it lasted (18.6 N against 16.7 at g = 1.5 /s)
    assert peaks[False] < peaks[True] - 1.0


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


def test_a_tip_steered_across_the_probe_moves_the_travels_origin():
    # the surface sinks 2 mm/s under a tip that the hand steers sideways at 5 mm/s (over the skin
    # the surface under the probe changes): the depth is the hand's, and the follow keeps the
    # contact past its 20 mm. The tip's position comes in one array updated in place, as an
    # engine's input buffer does
    class Sinking(Patient):
        def surface(self, t: float) -> float:
            return 0.3 - 0.002 * t

    for across_m_s, kept in ((0.005, True), (0.0, False)):
        patient, ctl = Sinking(amplitude_m=0.0), following_controller()
        z0, p_BT = patient.z, np.array([0.3, 0.0, patient.z])
        for k in range(round(15.0 / DT)):
            t = k * DT
            inputs = patient.inputs(t)
            p_BT[0] = 0.3 + across_m_s * t
            p_BT[2] = patient.z
            inputs["p_BT_B"] = p_BT
            patient.z += ctl.step(t, DT, inputs)["twist_B"][2] * DT
        if kept:
            assert z0 - patient.z > 0.025
            assert patient.force(15.0) > 3.0
        else:
            assert z0 - patient.z == pytest.approx(0.020, abs=1e-6)


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


@pytest.mark.parametrize("value", [1.0, -0.1])
def test_the_surface_gain_must_be_under_one_and_not_negative(value):
    with pytest.raises(ConfigError, match=r"^surface_gain must be ") as caught:
        FollowParams(surface_gain=value)
    assert "\n" not in str(caught.value)
    assert str(value) in str(caught.value)
