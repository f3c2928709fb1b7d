"""Glide: eq. 10 lighter for a steady push than for a quick one, with a smaller deadband once the
probe moves, and quieter along the probe for a hand keeping the contact. The block's gains against
the lag networks', its deadbands at rest and in motion, what it leaves after a release, and the
controller around it (off by default, reset when braking, in contact by the probe force, eq. 10
only)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hoh_cosim.control.admittance import AdmittanceGains
from hoh_cosim.control.controller import ControllerParams, HandGuidingController
from hoh_cosim.control.glide import Glide, GlideParams
from hoh_cosim.control.release import ReleaseParams
from hoh_cosim.control.supervisor import Status
from hoh_cosim.errors import ConfigError
from tests.estimates import controller_inputs

DT = 2e-3
SLOPE = np.full(3, 0.0125)  # eq. 10's α, the seed's
DEADBAND = np.array([0.95, 0.95, 0.25])  # eq. 10's η, the seed's


def drive(glide: Glide, forces: np.ndarray, contact_N: float | None = None) -> np.ndarray:
    """The command for each row of `forces` (one per tick), the probe force along its axis
    `contact_N` throughout."""
    return np.array([glide.step(DT, F, SLOPE, DEADBAND, contact_N) for F in forces])


def along(axis: int, values) -> np.ndarray:
    out = np.zeros((len(values), 3))
    out[:, axis] = values
    return out


def along_x(values) -> np.ndarray:
    return along(0, values)


def amplitude(x: np.ndarray) -> float:
    """The amplitude of a sinusoid from its samples over whole periods."""
    return float(np.sqrt(2.0) * np.std(x))


def test_a_steady_push_meets_the_light_slope_beyond_the_moving_deadband():
    # 1.5 N held for 6 s: the deadband settles to 0.3 N (0.5 s), the lag to r α (0.32 s)
    v = drive(Glide(GlideParams(enabled=True)), along_x(np.full(round(6.0 / DT), 1.5)))
    assert v[-1, 0] == pytest.approx(3.2 * 0.0125 * (1.5 - 0.3), rel=1e-3)
    assert np.all(v[:, 1:] == 0.0)
    # the first tick is eq. 10's (and the lag's first step of it): breaking away costs the seed's η
    follow = 1.0 - math.exp(-2.0 * math.pi * 0.5 * DT)
    assert v[0, 0] == pytest.approx(0.0125 * (1.5 - 0.95) * (1.0 + 2.2 * follow), rel=1e-9)
    # and the command only grows while the push holds (no overshoot to unwind)
    assert np.all(np.diff(v[:, 0]) >= -1e-15)


@pytest.mark.parametrize("f_hz", [2.0, 4.0])
def test_a_quick_force_meets_the_lag_networks_gain_near_eq_10s_slope(f_hz):
    # 0.2 N at f on a steady 1.5 N push: the command's swing at f is the lag network's
    # |α (r + j f / f_c) / (1 + j f / f_c)| of it (1.24 α at 2 Hz, 1.07 α at 4 Hz), not r α
    t = np.arange(round(12.0 / DT)) * DT
    v = drive(Glide(GlideParams(enabled=True)), along_x(1.5 + 0.2 * np.sin(2 * np.pi * f_hz * t)))
    late = t >= 6.0
    swing = amplitude(v[late, 0])
    x = f_hz / 0.5
    gain = 0.0125 * abs(complex(3.2, x) / complex(1.0, x))
    assert swing == pytest.approx(gain * 0.2, rel=0.03)
    assert gain < 1.25 * 0.0125 < 3.2 * 0.0125


def test_at_rest_the_seeds_deadband_holds_and_in_motion_the_moving_one():
    # (rest_s 0: the deadband is back at eq. 10's as soon as the push falls inside; the glide
    # through a dip is the test below)
    glide = Glide(GlideParams(enabled=True, rest_s=0.0))
    # a hand resting on the handle at 0.9 N (tremor, a sensor's error) moves nothing
    assert np.all(drive(glide, along_x(np.full(round(3.0 / DT), 0.9))) == 0.0)
    # a push of 1.2 N breaks away; eased to 0.5 N after 1 s it keeps the probe going (eq. 10
    # would stop at once), and at 0.25 N, inside the moving deadband, it stops
    moving = drive(glide, along_x(np.r_[np.full(500, 1.2), np.full(500, 0.5)]))
    # (the deadband 2 s into its 0.5 s approach: 0.3 N and 1.8 % of the way from 0.95)
    assert moving[-1, 0] == pytest.approx(3.2 * 0.0125 * (0.5 - 0.3), rel=0.05)
    assert glide.active
    stopped = drive(glide, along_x(np.full(200, 0.25)))
    assert not glide.active
    # the law's own part stops at once; the low-passed part decays over release_s (50 ms)
    assert stopped[25, 0] < 0.4 * moving[-1, 0]
    assert abs(stopped[-1, 0]) < 1e-3 * moving[-1, 0]
    # back at rest the seed's deadband is back: 0.9 N adds nothing to the residual's decay
    rest = drive(glide, along_x(np.full(200, 0.9)))
    assert np.all((rest[:, 0] >= 0.0) & (rest[:, 0] <= stopped[-1, 0]))
    assert np.all(np.diff(rest[:, 0]) <= 0.0)


def test_a_push_that_turns_breaks_away_again():
    glide = Glide(GlideParams(enabled=True, rest_s=0.0))
    drive(glide, along_x(np.full(1000, 1.5)))
    # -0.6 N: beyond the moving deadband but the other way, and inside the seed's: no motion
    # back (after the forward part's decay)
    back = drive(glide, along_x(np.full(200, -0.6)))
    assert np.all(back[:, 0] >= 0.0)
    assert abs(back[-1, 0]) < 1e-3 * 3.2 * 0.0125 * 1.2
    # -1.1 N breaks away the other way, at eq. 10's deadband first
    turned = drive(glide, along_x(np.full(1, -1.1)))
    assert turned[0, 0] == pytest.approx(-0.0125 * (1.1 - 0.95), rel=0.02)


def test_a_gliding_probe_keeps_the_moving_deadband_through_a_dip_and_a_turn():
    def after_a_glide(rest_s: float) -> Glide:
        glide = Glide(GlideParams(enabled=True, rest_s=rest_s))
        # 1.5 N for 1 s: the probe breaks away and travels well past glide_travel_m (5 mm)
        drive(glide, along_x(np.full(round(1.0 / DT), 1.5)))
        assert glide.travel[0] > 0.005
        # the push dips to 0.2 N for 0.6 s, inside the moving deadband: the probe stops
        dip = drive(glide, along_x(np.full(round(0.6 / DT), 0.2)))
        assert np.all(dip[-10:, 0] == 0.0)
        return glide

    gliding, resting = after_a_glide(1.0), after_a_glide(0.0)
    # 0.5 N after the dip: the gliding probe goes on at once, at the moving deadband's slope...
    eta = gliding.deadband[0] + (0.3 - gliding.deadband[0]) * (1.0 - math.exp(-DT / 0.5))
    on = drive(gliding, along_x(np.full(round(1.0 / DT), 0.5)))
    follow = 1.0 - math.exp(-2.0 * math.pi * 0.5 * DT)
    assert eta < 0.35
    assert on[0, 0] == pytest.approx(0.0125 * (0.5 - eta) * (1.0 + 2.2 * follow), rel=1e-9)
    assert gliding.deadband[0] == pytest.approx(0.3, abs=0.01)
    assert on[-1, 0] > 0.8 * 3.2 * 0.0125 * (0.5 - 0.3)
    # ... where the probe at rest again must break away from eq. 10's 0.95 N first
    assert np.all(drive(resting, along_x(np.full(round(1.0 / DT), 0.5))) == 0.0)
    # the push turns to -0.6 N: the gliding probe comes back without breaking away (once the
    # low-passed forward part has turned), the resting one does not move
    back = drive(gliding, along_x(np.full(round(2.0 / DT), -0.6)))
    assert back[-1, 0] == pytest.approx(-3.2 * 0.0125 * (0.6 - 0.3), rel=0.02)
    assert np.all(drive(resting, along_x(np.full(round(2.0 / DT), -0.6))) == 0.0)


def test_a_glide_rests_after_rest_s_and_a_short_push_never_glides():
    glide = Glide(GlideParams(enabled=True))
    drive(glide, along_x(np.full(round(1.0 / DT), 1.5)))
    # the hand stops pushing: the command is under 1 mm/s 0.18 s later (the low-passed part's
    # 50 ms decay from 4 cm/s), and rest_s (1 s) after that the probe is at rest again
    drive(glide, along_x(np.zeros(round(1.0 / DT))))
    assert glide.active
    drive(glide, along_x(np.zeros(round(0.3 / DT))))
    assert not glide.active
    assert glide.travel[0] == 0.0
    # and 0.9 N (a hand resting on the handle, a sensor's error) moves nothing
    assert np.all(drive(glide, along_x(np.full(round(2.0 / DT), 0.9))) == 0.0)
    # a push that breaks away but moves the probe less than glide_travel_m (a sensor's error
    # across the probe that the hand holding its place stops): back to eq. 10's at its first dip
    short = Glide(GlideParams(enabled=True))
    moved = drive(short, along_x(np.full(round(0.3 / DT), 1.2)))
    assert 0.0 < float(np.sum(moved[:, 0]) * DT) < 0.005
    drive(short, along_x(np.full(round(0.6 / DT), 0.2)))
    assert not short.active
    assert np.all(drive(short, along_x(np.full(round(1.0 / DT), 0.5))) == 0.0)


def test_the_travel_after_a_release_is_bounded_by_the_release_decay():
    # a steady push at 1 cm/s, then the hand lets go: the tip goes on by the low-passed part's
    # (r - 1) v / r · release_s = 0.34 mm at most (eq. 10 would stop at once)
    force = 0.3 + 0.01 / (3.2 * 0.0125)
    # it breaks away first, and the deadband comes down under the push
    push = np.r_[np.full(750, 1.5), np.full(round(5.0 / DT), force)]
    glide = Glide(GlideParams(enabled=True))
    v = drive(glide, along_x(push))
    assert v[-1, 0] == pytest.approx(0.01, rel=1e-3)
    after = drive(glide, along_x(np.zeros(round(1.0 / DT))))
    travel = float(np.sum(after[:, 0]) * DT)
    assert 0.0 < travel <= 2.2 / 3.2 * 0.01 * 0.05 * 1.01
    # and it ends: the law asks for nothing at all within 0.5 s (the release detector reads that)
    assert np.all(after[round(0.5 / DT) :] == 0.0)
    assert np.all(glide.slow == 0.0)
    # a longer release_s carries it further, in proportion
    slow = Glide(GlideParams(enabled=True, release_s=0.15))
    drive(slow, along_x(push))
    slow_travel = float(np.sum(drive(slow, along_x(np.zeros(round(1.0 / DT))))[:, 0]) * DT)
    assert slow_travel == pytest.approx(3.0 * travel, rel=0.05)


def test_with_no_lag_and_no_moving_deadband_it_is_eq_10():
    rng = np.random.default_rng(23)
    forces = rng.normal(0.0, 1.5, size=(2000, 3))
    forces[:, 0] += np.linspace(-2.0, 2.0, 2000)
    params = GlideParams(enabled=True, low_slope_ratio=[1, 1, 1], moving_deadband=DEADBAND)
    v = drive(Glide(params), forces)
    eq10 = np.sign(forces) * SLOPE * np.maximum(np.abs(forces) - DEADBAND, 0.0)
    np.testing.assert_allclose(v, eq10, rtol=0.0, atol=1e-15)


def quiet_gain(f_hz: float, q: float = 1.0 / 3.0, f_q: float = 0.5) -> float:
    """|(1 + j q f / f_q) / (1 + j f / f_q)|: the quiet part's lag network at f."""
    x = f_hz / f_q
    return abs(complex(1.0, q * x) / complex(1.0, x))


@pytest.mark.parametrize("f_hz", [2.0, 4.0])
def test_in_contact_a_small_quick_push_along_the_probe_meets_a_third_of_the_slope(f_hz):
    # 0.2 N at f on a steady 0.7 N push along z (inside the 1 N push band): in contact the
    # command's swing is eq. 10's times the lag network's gain (0.40 at 2 Hz, 0.35 at 4 Hz);
    # out of contact, and on x in contact, it is eq. 10's
    t = np.arange(round(10.0 / DT)) * DT
    wave = 0.7 + 0.2 * np.sin(2 * np.pi * f_hz * t)
    late = t >= 5.0
    v = drive(Glide(GlideParams(enabled=True)), along(2, wave), contact_N=8.0)
    assert amplitude(v[late, 2]) == pytest.approx(quiet_gain(f_hz) * 0.0125 * 0.2, rel=0.03)
    assert quiet_gain(f_hz) < 0.41
    # a steady push meets eq. 10's own slope along the probe (r = 1 there)
    assert v[late, 2].mean() == pytest.approx(0.0125 * (0.7 - 0.25), rel=1e-3)
    free = drive(Glide(GlideParams(enabled=True)), along(2, wave), contact_N=2.0)
    np.testing.assert_allclose(free[:, 2], 0.0125 * (wave - 0.25), rtol=1e-12)
    across = drive(Glide(GlideParams(enabled=True)), along(0, wave), contact_N=8.0)
    unsheltered = drive(Glide(GlideParams(enabled=True)), along(0, wave))
    np.testing.assert_array_equal(across, unsheltered)


def test_in_contact_a_push_beyond_the_push_band_meets_eq_10():
    # 2 N with 0.2 N at 3 Hz on it: beyond 1.5 N throughout, the quiet part is out (a press to a
    # new force, a press loop that swings); between 1 and 1.5 N it gives way in proportion
    t = np.arange(round(4.0 / DT)) * DT
    wave = 2.0 + 0.2 * np.sin(2 * np.pi * 3.0 * t)
    v = drive(Glide(GlideParams(enabled=True)), along(2, wave), contact_N=8.0)
    np.testing.assert_allclose(v[:, 2], 0.0125 * (wave - 0.25), rtol=1e-12)
    half = Glide(GlideParams(enabled=True))
    drive(half, along(2, np.full(round(3.0 / DT), 1.25)), contact_N=8.0)
    w = 0.0125 * (1.25 - 0.25)
    kick = half.step(DT, np.array([0.0, 0.0, 1.25]), SLOPE, DEADBAND, 8.0)[2]
    assert kick == pytest.approx(w, rel=1e-4)  # steady: nothing left to quiet
    half.quiet[2] = 0.0  # as if the push had just come: half of the quiet part's pull
    kick = half.step(DT, np.array([0.0, 0.0, 1.25]), SLOPE, DEADBAND, 8.0)[2]
    follow = 1.0 - math.exp(-2.0 * math.pi * 0.5 * DT)
    assert kick == pytest.approx(w - 0.5 * (2.0 / 3.0) * w * (1.0 - follow), rel=1e-9)


def test_the_quiet_part_comes_in_over_its_blend_once_the_contact_begins():
    glide = Glide(GlideParams(enabled=True))
    drive(glide, along(2, np.full(100, 0.7)), contact_N=2.0)
    assert glide.quiet_in == 0.0
    drive(glide, along(2, np.full(1, 0.7)), contact_N=8.0)
    assert glide.quiet_in == pytest.approx(DT / 0.5)
    drive(glide, along(2, np.full(round(0.5 / DT), 0.7)), contact_N=8.0)
    assert glide.quiet_in == 1.0
    # a contact lost starts the blend afresh at the next touch
    drive(glide, along(2, np.full(1, 0.7)), contact_N=0.0)
    assert glide.quiet_in == 0.0


def test_in_contact_the_quiet_part_delays_the_travel_and_adds_none():
    # in contact for 1 s first (the blend in), then a 1 s push of 0.8 N along the probe, then
    # nothing: the tip travels what eq. 10 would (the quiet part's gain for a steady push is 1),
    # only later; then it is at rest
    glide = Glide(GlideParams(enabled=True))
    push = np.r_[
        np.zeros(round(1.0 / DT)), np.full(round(1.0 / DT), 0.8), np.zeros(round(5.0 / DT))
    ]
    v = drive(glide, along(2, push), contact_N=8.0)
    eq10 = 0.0125 * (0.8 - 0.25) * 1.0
    assert float(np.sum(v[:, 2]) * DT) == pytest.approx(eq10, rel=1e-4)
    assert np.all(v[:, 2] >= 0.0)
    # the lag's delay: (1 - q) τ = 0.21 s of the steady speed is still to come at the push's end
    during = float(np.sum(v[: round(2.0 / DT), 2]) * DT)
    assert during == pytest.approx(eq10 - 0.0125 * 0.55 * (2.0 / 3.0) / (2 * np.pi * 0.5), rel=0.02)
    # and the law at rest asks for nothing within 4 s of the push's end (the release detector)
    assert np.all(v[round(6.0 / DT) :] == 0.0)
    assert np.all(glide.quiet == 0.0)


def _hand(F_x: float) -> dict:
    return controller_inputs(F_hand_B=[F_x, 0.0, 0.0], F_hand_meas_B=[F_x, 0.0, 0.0])


def test_the_controller_glides_only_when_asked():
    def command(ctl: HandGuidingController, seconds: float, F_x: float) -> float:
        for k in range(round(seconds / DT)):
            out = ctl.step(k * DT, DT, _hand(F_x))
        return float(out["twist_law_B"][0])

    assert ControllerParams().glide.enabled is False
    assert command(HandGuidingController(), 3.0, 1.5) == pytest.approx(0.0125 * 0.55)
    gliding = HandGuidingController(ControllerParams(glide=GlideParams(enabled=True)))
    assert command(gliding, 3.0, 1.5) == pytest.approx(3.2 * 0.0125 * 1.2, rel=0.01)
    assert gliding.glide.active
    # switched off mid-session (a scenario's event, a retune): eq. 10 at once, nothing kept
    gliding.retune(ControllerParams())
    assert not gliding.glide.active
    assert np.all(gliding.glide.slow == 0.0)
    assert command(gliding, 0.1, 1.5) == pytest.approx(0.0125 * 0.55)


def test_the_controller_is_quieter_along_the_probe_only_in_contact():
    # the hand's force along the probe 0.7 N with 0.2 N at 3 Hz on it, the probe pressed by 8 N
    # along its axis (handle to tip: down) or by 2 N, under the contact's 3 N: F̃ the same (the
    # wrist reads the hand's force and the contact's, eq. 11-12 takes the contact out)
    def command(contact_N: float) -> np.ndarray:
        ctl = HandGuidingController(ControllerParams(glide=GlideParams(enabled=True)))
        F_probe = np.array([0.0, 0.0, contact_N])
        out = []
        for k in range(round(6.0 / DT)):
            push = 0.7 + 0.2 * math.sin(2 * math.pi * 3.0 * k * DT)
            inputs = controller_inputs(
                F_hand_B=F_probe + np.array([0.0, 0.0, -push]),
                F_probe_B=F_probe,
                probe_axis_B=[0.0, 0.0, -1.0],
            )
            out.append(ctl.step(k * DT, DT, inputs)["twist_law_B"][2])
        return np.array(out[round(3.0 / DT) :])

    free, pressed = command(2.0), command(8.0)
    assert amplitude(free) == pytest.approx(0.0125 * 0.2, rel=0.03)
    assert amplitude(pressed) == pytest.approx(quiet_gain(3.0) * 0.0125 * 0.2, rel=0.03)
    # down, at eq. 10's slope for the steady push either way
    for v in (free, pressed):
        assert v.mean() == pytest.approx(-0.0125 * (0.7 - 0.25), rel=1e-3)


def test_the_controller_forgets_the_glide_while_it_brakes_after_a_release():
    ctl = HandGuidingController(
        ControllerParams(glide=GlideParams(enabled=True), release=ReleaseParams(enabled=True))
    )
    t = 0.0
    for _ in range(round(3.0 / DT)):
        ctl.step(t, DT, _hand(1.5))
        t += DT
    assert ctl.glide.active
    released = False
    for _ in range(round(0.5 / DT)):
        out = ctl.step(t, DT, _hand(0.0))
        t += DT
        released |= bool(int(out["status"][0]) & int(Status.RELEASED))
    assert released
    assert not ctl.glide.active
    assert np.all(ctl.glide.slow == 0.0)


def test_glide_refuses_a_law_other_than_eq_10_and_bad_parameters():
    with pytest.raises(
        ConfigError, match=r"expected translation\.law deadband_linear, got 'sigmoid'"
    ):
        ControllerParams(
            glide=GlideParams(enabled=True), translation=AdmittanceGains(law="sigmoid")
        )
    with pytest.raises(ConfigError, match="low_slope_ratio must be >= 1"):
        GlideParams(low_slope_ratio=[0.5, 1.0, 1.0])
    with pytest.raises(ConfigError, match="corner_hz"):
        GlideParams(corner_hz=0.0)
    with pytest.raises(ConfigError, match="moving_deadband"):
        GlideParams(moving_deadband=[-0.1, 0.3, 0.25])
    for bad in ([1.0, 1.0, 0.0], [1.5, 1.0, 1.0]):
        with pytest.raises(ConfigError, match=r"quiet_ratio must be in \(0, 1\] on every axis"):
            GlideParams(quiet_ratio=bad)
    with pytest.raises(ConfigError, match="quiet_hz"):
        GlideParams(quiet_hz=-1.0)
    with pytest.raises(ConfigError, match="quiet_push_span_N"):
        GlideParams(quiet_push_span_N=0.0)
    assert math.isfinite(GlideParams().release_s)
