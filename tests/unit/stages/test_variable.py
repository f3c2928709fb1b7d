"""The variable law's stage: the twist of `VariableAdmittance.step_twist` tick by tick (the pure
reference against the compiled block), eq. 10 when the intent's gain is off, and a reset that
forgets the last excess force and the oscillation watch."""

from __future__ import annotations

import numpy as np

from hoh_cosim.control.admittance import ROTATION_GAINS, TRANSLATION_GAINS, apply_law
from hoh_cosim.control.guidance.stages import variable as variable_module
from hoh_cosim.control.guidance.stages.variable import VariableLaw
from hoh_cosim.control.supervisor import Status
from hoh_cosim.control.variable_admittance import VariableAdmittance, VariableAdmittanceParams
from tests.unit.stages.ticks import DT, assert_reads_only, make_command, make_tick


def variable_stage(params: VariableAdmittanceParams) -> VariableLaw:
    stage = VariableLaw(params)
    stage.retune(params, TRANSLATION_GAINS, ROTATION_GAINS)
    return stage


def push_ticks(rng: np.random.Generator, n: int = 200) -> list:
    """A push that grows and falls with noise, the tip swinging at 2 Hz (the watch's input)."""
    ticks = []
    for i in range(n):
        t = i * DT
        F = 6.0 * np.sin(np.pi * t / (n * DT)) * np.array([1.0, 0.5, -0.3]) + rng.normal(0, 0.2, 3)
        p = np.array([0.3, 0.0, 0.3]) + 0.01 * np.sin(2 * np.pi * 2.0 * t) * np.array([1, 0, 0])
        tau = rng.normal(0.0, 0.3, 3)
        ticks.append(make_tick(t, F_hand_B=F, tau_hand_B=tau, p_BT_B=p))
    return ticks


def test_each_tick_is_the_pure_laws_twist(rng):
    params = VariableAdmittanceParams(intent_gain=0.3, intent_rate_per_s=5.0)
    stage, pure = variable_stage(params), VariableAdmittance(params)
    factors = []
    for tick in push_ticks(rng):
        command = stage.step(tick, make_command())
        factors.append(stage.block.factor)
        want = pure.step_twist(
            tick.t, tick.F, tick.tau, TRANSLATION_GAINS, ROTATION_GAINS, tick.p_BT
        )
        np.testing.assert_allclose(command.law, want, rtol=1e-12, atol=1e-15)
        np.testing.assert_array_equal(command.law, np.concatenate([command.v, command.w]))
    assert min(factors) < 1.0 < max(factors)  # the intent moved the slope both ways


def test_without_the_intent_gain_and_the_watch_it_is_eq_10(rng):
    stage = variable_stage(VariableAdmittanceParams(intent_gain=0.0, oscillation_watch=False))
    for tick in push_ticks(rng, 50):
        command = stage.step(tick, make_command())
        np.testing.assert_allclose(command.v, apply_law(tick.F, TRANSLATION_GAINS), rtol=1e-12)
        np.testing.assert_allclose(command.w, apply_law(tick.tau, ROTATION_GAINS), rtol=1e-12)


def test_the_status_steering_and_braking_pass_through_untouched(rng):
    stage = variable_stage(VariableAdmittanceParams())
    status = int(Status.PASSIVITY)
    command = make_command(status=status, steering=False)
    out = stage.step(push_ticks(rng, 1)[0], command)
    assert (out.status, out.steering, out.braking) == (status, False, False)


def test_reset_forgets_the_last_force_and_the_watch(rng):
    params = VariableAdmittanceParams(intent_gain=0.3, intent_rate_per_s=5.0)
    ticks = push_ticks(rng, 200)[:60]  # the push growing: the intent raises the slope
    stage = variable_stage(params)
    for tick in ticks[:-1]:
        stage.step(tick, make_command())
    kept = stage.step(ticks[-1], make_command()).law.copy()
    stage.reset()
    again = stage.step(ticks[-1], make_command()).law
    fresh = variable_stage(params).step(ticks[-1], make_command()).law
    np.testing.assert_array_equal(again, fresh)
    assert not np.allclose(kept, fresh)  # without the reset the state showed


def test_it_reads_only_the_tick_and_the_command(rng):
    stage = variable_stage(VariableAdmittanceParams())
    assert_reads_only(variable_module, stage, push_ticks(rng, 1)[0], make_command())
