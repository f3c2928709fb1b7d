"""The hold's stage on an engaged `ContactHold`: holding, v is the hold's law along its line and
ω = 0 (status HOLDING | RELEASED); handing back, v = (1 - β) v_hold + β v_law and ω = β ω_law
(status HANDING_BACK); reset() ends the hold."""

from __future__ import annotations

import numpy as np

from hoh_cosim.control.admittance import TRANSLATION_GAINS
from hoh_cosim.control.guidance.stages import hold as hold_module
from hoh_cosim.control.guidance.stages.hold import HoldStage
from hoh_cosim.control.hold import HoldEnd, HoldParams, HoldPhase
from hoh_cosim.control.supervisor import Status
from tests.unit.stages.ticks import DT, assert_reads_only, make_command, make_tick

PARAMS = HoldParams(enabled=True)
AXIS = np.array([0.0, 0.0, -1.0])  # the probe pointing down
P0 = np.array([0.3, 0.0, 0.3])
HOLDING = int(Status.HOLDING | Status.RELEASED)


def contact_tick(t: float, force_N: float = 6.0, z: float = 0.0):
    """The probe pressed `force_N` into the patient, nobody's hand; the tip `z` below P0."""
    F_probe = np.array([0.0, 0.0, force_N])
    return make_tick(
        t,
        F_hand_B=np.zeros(3),
        F_hand_meas_B=F_probe,  # the wrist's packet: the contact alone
        F_probe_B=F_probe,
        probe_axis_B=AXIS,
        p_BT_B=P0 - [0.0, 0.0, z],
    )


def engaged(t: float = 0.0) -> HoldStage:
    stage = HoldStage(PARAMS)
    tick = contact_tick(t)
    stage.hold.engage(t, tick.F, tick.F_meas, tick.F_probe, AXIS, tick.p_BT, np.zeros(3))
    assert stage.hold.phase == HoldPhase.HOLDING
    return stage


def breath(i: int) -> tuple[float, float]:
    """The contact force and the tip's depth at tick i of a breathing patient."""
    s = np.sin(2.0 * np.pi * 0.25 * i * DT)
    return 6.0 + 3.0 * s, 0.001 * s


def test_holding_the_command_is_the_holds_law_along_its_line_and_no_rotation(rng):
    stage, twin = engaged(), engaged().hold
    v_law, w_law = np.array([0.01, -0.02, 0.005]), np.array([0.1, 0.2, -0.1])
    for i in range(1, 200):
        force, z = breath(i)
        tick = contact_tick(i * DT, force, z)
        out = stage.step(tick, make_command(v_law, w_law, status=int(Status.FIXTURE)))
        want = twin.command(
            tick.t, DT, tick.F, tick.F_meas, tick.F_probe, tick.p_BT, v_law, None, 0.0, 0.0
        )
        np.testing.assert_array_equal(out.v, want)
        np.testing.assert_allclose(np.cross(out.v, AXIS), 0.0, atol=1e-15)  # along the line
        assert np.linalg.norm(out.v) <= PARAMS.max_speed + 1e-12
        assert not out.w.any()
        assert out.status == int(Status.FIXTURE) | HOLDING
    assert np.abs(out.v).max() > 1e-4  # the hold moved with the breath


def touched(stage: HoldStage, t: float) -> None:
    """A firm push across the handle: the hand-back begins at t."""
    hold = stage.hold
    hold.guard(t, P0, np.array([0.0, 0.0, 6.0]))
    F = np.array([8.0, 0.0, 0.0])
    assert hold.touched(t, DT, F, None, TRANSLATION_GAINS.deadband, np.array([0.0, 0.0, 6.0]))
    assert hold.phase == HoldPhase.BLENDING


def test_handing_back_blends_the_law_in_by_beta():
    # two holds driven alike, the law's request differing by u: v differs by β u, ω is β ω_law
    u, w_law = np.array([0.02, -0.01, 0.004]), np.array([0.1, -0.2, 0.3])
    stages = [engaged(), engaged()]
    for stage in stages:
        for i in range(1, 50):
            stage.step(contact_tick(i * DT), make_command())
        touched(stage, 50 * DT)
    outs = [
        s.step(contact_tick(50 * DT), make_command(v, w_law))
        for s, v in zip(stages, (0 * u, u), strict=True)
    ]
    np.testing.assert_array_equal(outs[1].v, outs[0].v)  # β = 0 on the touch's tick
    assert not outs[1].w.any()
    for i in range(51, 60):
        t = i * DT
        beta = (t - 50 * DT) / PARAMS.blend_s
        for stage in stages:
            assert not stage.hold.blended(t)
        assert stages[0].hold.blend == stages[1].hold.blend == beta
        outs = [
            s.step(contact_tick(t), make_command(v, w_law, status=int(Status.PASSIVITY)))
            for s, v in zip(stages, (0 * u, u), strict=True)
        ]
        np.testing.assert_allclose(outs[1].v - outs[0].v, beta * u, rtol=1e-12, atol=1e-15)
        np.testing.assert_allclose(outs[1].w, beta * w_law, rtol=1e-15)
        assert outs[1].status == int(Status.PASSIVITY | Status.HANDING_BACK)


def test_reset_ends_the_hold_and_a_new_engagement_starts_afresh():
    stage = engaged()
    for i in range(1, 100):
        force, z = breath(i)
        stage.step(contact_tick(i * DT, force, z), make_command())
    stage.reset()
    assert (stage.hold.phase, stage.hold.ended) == (HoldPhase.OFF, HoldEnd.STOPPED)
    t = 100 * DT
    tick = contact_tick(t)
    stage.hold.engage(t, tick.F, tick.F_meas, tick.F_probe, AXIS, tick.p_BT, np.zeros(3))
    fresh = engaged(t)
    for i in range(101, 120):
        force, z = breath(i)
        tick = contact_tick(i * DT, force, z)
        again, once = stage.step(tick, make_command()), fresh.step(tick, make_command())
        np.testing.assert_array_equal(again.v, once.v)
        assert again.status == once.status


def test_it_reads_only_the_tick_and_the_command():
    assert_reads_only(hold_module, engaged(), contact_tick(DT), make_command())


def test_the_engagements_blend_goes_from_the_command_before_to_the_holds():
    params = HoldParams(enabled=True, engage_blend_s=0.1)
    stage, twin = HoldStage(params), HoldStage(HoldParams(enabled=True))
    v_before = np.array([0.0, 0.0, -0.004])  # the guiding's last command, into the patient
    for s in (stage, twin):
        tick = contact_tick(0.0)
        s.hold.engage(0.0, tick.F, tick.F_meas, tick.F_probe, AXIS, tick.p_BT, v_before)
    gaps = []
    for i in range(1, 80):  # 0.16 s: through the blend and past it
        force, z = breath(i)
        blended = stage.step(contact_tick(i * DT, force, z), make_command()).v
        held = twin.step(contact_tick(i * DT, force, z), make_command()).v
        gamma = min(i * DT / params.engage_blend_s, 1.0)
        np.testing.assert_allclose(blended, (1 - gamma) * v_before + gamma * held, atol=1e-15)
        gaps.append(float(np.linalg.norm(blended - held)))
    assert gaps[0] > 1e-4  # at first mostly the command before: it differs from the hold's
    assert gaps[-1] == 0.0  # the blend is over: the hold's own command
