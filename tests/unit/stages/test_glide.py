"""Glide's stage: the translation's request through `Glide.step` (with the probe's axial force
in contact), the rotation's as the law gave it; rest() and reset() forget the block's state."""

from __future__ import annotations

import numpy as np
import pytest

from hoh_cosim.control.admittance import TRANSLATION_GAINS
from hoh_cosim.control.glide import Glide, GlideParams
from hoh_cosim.control.guidance.stages import glide as glide_module
from hoh_cosim.control.guidance.stages.glide import GlideStage
from hoh_cosim.control.supervisor import Status
from tests.unit.stages.ticks import DT, assert_reads_only, make_command, make_tick, same_state

PARAMS = GlideParams(enabled=True)
AXIS = np.array([0.0, 0.0, -1.0])  # the probe pointing down


def glide_stage(use_probe: bool = True) -> GlideStage:
    stage = GlideStage(PARAMS)
    stage.retune(PARAMS, TRANSLATION_GAINS, use_probe)
    return stage


def scan_ticks(rng: np.random.Generator, n: int = 300) -> list:
    """A steady push across the probe with noise, the probe pressed 6 N into the patient."""
    return [
        make_tick(
            i * DT,
            F_hand_B=np.array([2.5, 0.0, 0.4]) + rng.normal(0.0, 0.3, 3),
            F_probe_B=[0.0, 0.0, 6.0],
            probe_axis_B=AXIS,
        )
        for i in range(n)
    ]


@pytest.mark.parametrize("use_probe", [True, False])
def test_the_translation_is_glides_and_the_rotation_the_laws(use_probe, rng):
    stage, pure = glide_stage(use_probe), Glide(PARAMS)
    slope, deadband = TRANSLATION_GAINS.slope, TRANSLATION_GAINS.deadband
    for tick in scan_ticks(rng):
        w = rng.normal(0.0, 0.1, 3)
        command = stage.step(tick, make_command(rng.normal(0.0, 0.01, 3), w))
        c = 6.0 if use_probe else None  # -F_probe · axis: the probe's axial force, pressing
        np.testing.assert_array_equal(command.v, pure.step(DT, tick.F, slope, deadband, c))
        np.testing.assert_array_equal(command.w, w)
        np.testing.assert_array_equal(command.law, np.concatenate([command.v, w]))
    assert stage.glide.active  # the push moved the probe: the deadband moved
    assert (stage.glide.quiet_in > 0.0) == use_probe  # in contact only with the probe's force


def test_a_steady_push_meets_a_lighter_slope_than_eq_10(rng):
    stage = glide_stage()
    F = np.array([2.5, 0.0, 0.0])
    for i in range(1000):
        command = stage.step(make_tick(i * DT, F_hand_B=F), make_command())
    eq10 = TRANSLATION_GAINS.slope[0] * (F[0] - TRANSLATION_GAINS.deadband[0])
    assert command.v[0] > 2.0 * eq10


def test_the_status_steering_and_braking_pass_through_untouched(rng):
    status = int(Status.FOLLOWING)
    out = glide_stage().step(scan_ticks(rng, 1)[0], make_command(status=status, steering=False))
    assert (out.status, out.steering, out.braking) == (status, False, False)


@pytest.mark.parametrize("forget", ["rest", "reset"])
def test_rest_and_reset_forget_the_block_state(forget, rng):
    ticks = scan_ticks(rng)
    stage = glide_stage()
    for tick in ticks[:-1]:
        stage.step(tick, make_command())
    getattr(stage, forget)()
    same_state(stage.glide, Glide(PARAMS))
    again = stage.step(ticks[-1], make_command()).v
    np.testing.assert_array_equal(again, glide_stage().step(ticks[-1], make_command()).v)


def test_switched_off_by_a_retune_it_forgets(rng):
    stage = glide_stage()
    for tick in scan_ticks(rng, 50):
        stage.step(tick, make_command())
    off = GlideParams(enabled=False)
    stage.retune(off, TRANSLATION_GAINS, True)
    same_state(stage.glide, Glide(off))


def test_it_reads_only_the_tick_and_the_command(rng):
    assert_reads_only(glide_module, glide_stage(), scan_ticks(rng, 1)[0], make_command())
