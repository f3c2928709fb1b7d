"""The admittance law's stage: v = law(F̃), ω = law(τ̃) as `apply_law` gives them, nothing else of
the command touched, no state."""

from __future__ import annotations

import numpy as np
import pytest

from hoh_cosim.control.admittance import (
    ROTATION_GAINS,
    TRANSLATION_GAINS,
    AdmittanceGains,
    apply_law,
)
from hoh_cosim.control.guidance.stages import law as law_module
from hoh_cosim.control.guidance.stages.law import AdmittanceLaw
from hoh_cosim.control.supervisor import Status
from tests.unit.stages.ticks import assert_reads_only, make_command, make_tick

COMPENSATED = (True, True, True, False, 0.0, True, 2.25)


def gains(law: str, rotation: bool = False) -> AdmittanceGains:
    base = ROTATION_GAINS if rotation else TRANSLATION_GAINS
    return AdmittanceGains(
        law=law,
        slope=base.slope,
        deadband=base.deadband,
        sigmoid_max_speed=base.sigmoid_max_speed,
        sigmoid_midpoint=base.sigmoid_midpoint,
        sigmoid_steepness=base.sigmoid_steepness,
    )


LAWS = [
    ("deadband_linear", "deadband_linear"),
    ("isotropic", "isotropic"),
    ("sigmoid", "sigmoid"),
    ("variable", "variable"),
    ("deadband_linear", "sigmoid"),
    ("isotropic", "deadband_linear"),
]


def random_tick(rng: np.random.Generator):
    return make_tick(
        reading=COMPENSATED,
        F_hand_B=rng.uniform(-8.0, 8.0, 3),
        tau_hand_B=rng.uniform(-1.0, 1.0, 3),
        F_probe_B=rng.uniform(-2.0, 2.0, 3),
        tau_probe_B=rng.uniform(-0.2, 0.2, 3),
    )


@pytest.mark.parametrize(("translation", "rotation"), LAWS)
def test_the_request_is_apply_law_on_the_compensated_force_and_torque(translation, rotation, rng):
    tr, rot = gains(translation), gains(rotation, rotation=True)
    stage = AdmittanceLaw(tr, rot)
    for _ in range(20):
        tick = random_tick(rng)
        command = stage.step(tick, make_command(rng.normal(size=3), rng.normal(size=3)))
        np.testing.assert_allclose(command.v, apply_law(tick.F, tr), rtol=1e-12, atol=0.0)
        np.testing.assert_allclose(command.w, apply_law(tick.tau, rot), rtol=1e-12, atol=0.0)
        np.testing.assert_array_equal(command.law, np.concatenate([command.v, command.w]))


def test_inside_the_deadbands_the_request_is_rest():
    stage = AdmittanceLaw(TRANSLATION_GAINS, ROTATION_GAINS)
    tick = make_tick(F_hand_B=[0.9, -0.9, 0.2], tau_hand_B=[0.05, -0.09, 0.0])
    command = stage.step(tick, make_command([0.01, 0.0, 0.0], [0.1, 0.0, 0.0]))
    assert not command.v.any()
    assert not command.w.any()
    assert not command.law.any()


def test_the_status_steering_and_braking_pass_through_untouched(rng):
    stage = AdmittanceLaw(TRANSLATION_GAINS, ROTATION_GAINS)
    status = int(Status.FIXTURE | Status.SPEED_CLAMPED)
    for steering in (True, False):
        command = make_command(status=status, steering=steering)
        command.braking = not steering
        out = stage.step(random_tick(rng), command)
        assert (out.status, out.steering, out.braking) == (status, steering, not steering)


def test_reset_forgets_nothing_because_there_is_no_state(rng):
    ticks = [random_tick(rng) for _ in range(5)]
    stage = AdmittanceLaw(TRANSLATION_GAINS, ROTATION_GAINS)
    for tick in ticks[:-1]:
        stage.step(tick, make_command())
    stage.reset()
    again = stage.step(ticks[-1], make_command())
    fresh = AdmittanceLaw(TRANSLATION_GAINS, ROTATION_GAINS).step(ticks[-1], make_command())
    np.testing.assert_array_equal(again.law, fresh.law)


def test_it_reads_only_the_tick_and_the_command(rng):
    stage = AdmittanceLaw(TRANSLATION_GAINS, ROTATION_GAINS)
    assert_reads_only(law_module, stage, random_tick(rng), make_command())
