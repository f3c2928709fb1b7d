"""The passivity stage: the observer on every tick, the controller on the command only while it is
the hand's request (`steering`), status PASSIVITY when it acts; checked against the pure
`PassivityController` tick by tick."""

from __future__ import annotations

import numpy as np
import pytest

from hoh_cosim.control.guidance.stages import passivity as passivity_module
from hoh_cosim.control.guidance.stages.passivity import PassivityStage
from hoh_cosim.control.passivity import PassivityController, PassivityParams
from hoh_cosim.control.supervisor import Status
from tests.unit.stages.ticks import DT, assert_reads_only, make_command, make_tick

PARAMS = PassivityParams(enabled=True, tank_max_J=0.02)
P0 = np.array([0.3, 0.0, 0.3])
F = np.array([10.0, 0.0, 0.0])
AGAINST = np.array([-0.01, 0.0, 0.0])  # a command against the hand's force


def drained(stage: PassivityStage, steering: bool):
    """The tip moved 5 mm against a 10 N push (0.05 J given back, more than the tank's 0.02 J),
    then a command against the push: the command of the second tick."""
    stage.step(make_tick(0.0, F_hand_B=F, p_BT_B=P0), make_command(AGAINST, steering=steering))
    tick = make_tick(DT, F_hand_B=F, p_BT_B=P0 - [0.005, 0.0, 0.0])
    return stage.step(tick, make_command(AGAINST, status=int(Status.FIXTURE), steering=steering))


@pytest.mark.parametrize("steering", [True, False])
def test_it_acts_only_on_the_hands_request(steering):
    stage = PassivityStage(PARAMS)
    out = drained(stage, steering)
    assert stage.controller.energy_J == pytest.approx(0.02 - 0.05)  # the PO watched either way
    if steering:
        assert out.status == int(Status.FIXTURE | Status.PASSIVITY)
        # the yield along F̂ that brings the tank, the command's flow counted, back to zero
        assert stage.controller.energy_J + float(F @ out.v) * DT == pytest.approx(0.0, abs=1e-12)
        assert np.cross(out.v - AGAINST, F) == pytest.approx(np.zeros(3))
    else:
        assert out.status == int(Status.FIXTURE)
        np.testing.assert_array_equal(out.v, AGAINST)


def test_while_the_tank_covers_it_the_command_passes():
    stage = PassivityStage(PARAMS)
    stage.step(make_tick(0.0, F_hand_B=F, p_BT_B=P0), make_command(AGAINST))
    out = stage.step(make_tick(DT, F_hand_B=F, p_BT_B=P0), make_command(AGAINST))
    np.testing.assert_array_equal(out.v, AGAINST)
    assert out.status == 0


def test_each_tick_is_the_pure_controllers(rng):
    stage, pure = PassivityStage(PARAMS), PassivityController(PARAMS)
    p, acted = P0.copy(), 0
    for i in range(400):
        p = p + rng.normal(0.0, 0.002, 3)
        tick = make_tick(i * DT, F_hand_B=rng.normal(0.0, 5.0, 3), p_BT_B=p)
        v_c, steering = rng.normal(0.0, 0.05, 3), bool(rng.random() < 0.7)
        out = stage.step(tick, make_command(v_c, steering=steering))
        want, acts = pure.step(tick.t, tick.F, tick.p_BT, v_c, control=steering)
        np.testing.assert_allclose(out.v, want, rtol=1e-12, atol=1e-15)
        assert bool(out.status & int(Status.PASSIVITY)) == acts
        acted += acts
    assert acted > 10  # the random walk drained the tank now and then
    assert stage.controller.energy_J == pytest.approx(pure.energy_J, rel=1e-9)


def test_reset_refills_the_tank_and_forgets_the_last_position():
    stage = PassivityStage(PARAMS)
    drained(stage, True)
    stage.reset()
    assert stage.controller.energy_J == PARAMS.tank_max_J
    assert stage.controller.dissipated_J == 0.0
    again, once = drained(stage, True), drained(PassivityStage(PARAMS), True)
    np.testing.assert_array_equal(again.v, once.v)
    assert again.status == once.status


def test_it_reads_only_the_tick_and_the_command():
    assert_reads_only(passivity_module, PassivityStage(PARAMS), make_tick(), make_command())
