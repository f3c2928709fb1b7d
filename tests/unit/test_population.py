"""The population of sonographers and their patients: the documented ranges, seeded per operator,
and the tremor's calibration on the hand holding the probe."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hoh_cosim.control.vectors import GRAVITY_B
from hoh_cosim.cosim.metrics import high_passed
from hoh_cosim.errors import ConfigError
from plant_models.freehand import FreehandParams, FreehandProbe
from plant_models.operator import Operator, OperatorParams
from plant_models.population import (
    RANGES,
    PopulationParams,
    draw_operator,
    draw_patient,
)
from plant_models.tissue import PhantomParams

N = 300


@pytest.fixture(scope="module")
def people() -> list:
    return [(draw_operator(RANGES, 7, i), draw_patient(RANGES, 7, i)) for i in range(N)]


def test_every_draw_is_within_its_documented_range(people) -> None:
    r = RANGES
    for hand, patient in people:
        for name in ("stiffness", "damping", "reaction_delay_s", "tremor_hz", "tremor_rms_N"):
            low, high = getattr(r, name)
            assert low <= getattr(hand, name) <= high, name
        low, high = r.grip_stiffness
        assert low <= hand.grip_stiffness <= high
        mean, sd = r.grip_strength_female_N if hand.female else r.grip_strength_male_N
        assert abs(hand.grip_strength_N - mean) <= 2.5 * sd + 1e-9
        assert hand.max_force_N == max(r.min_force_N, r.push_fraction * hand.grip_strength_N)
        assert 12.0 <= patient.rate_per_min <= 20.0
        assert 0.005 <= patient.amplitude_m <= 0.015


def test_the_draws_spread_over_the_ranges(people) -> None:
    hands = [h for h, _ in people]
    stiffness = [h.stiffness for h in hands]
    assert min(stiffness) < 230.0
    assert max(stiffness) > 570.0
    tremor = np.log([h.tremor_rms_N for h in hands])
    # log-uniform: as many below the geometric middle as above
    assert abs(np.mean(tremor < math.log(math.sqrt(0.011 * 0.14))) - 0.5) < 0.1
    women = [h for h in hands if h.female]
    assert abs(len(women) / N - 0.5) < 0.1
    assert np.mean([h.grip_strength_N for h in women]) == pytest.approx(320.0, rel=0.05)
    rates = [p.rate_per_min for _, p in people]
    assert min(rates) < 12.5
    assert max(rates) > 19.5


def test_an_operator_is_the_same_person_in_any_study() -> None:
    assert draw_operator(RANGES, 1, 4) == draw_operator(RANGES, 1, 4)
    assert draw_patient(RANGES, 1, 4) == draw_patient(RANGES, 1, 4)
    assert draw_operator(RANGES, 1, 4) != draw_operator(RANGES, 2, 4)
    assert draw_operator(RANGES, 1, 4) != draw_operator(RANGES, 1, 5)


def test_the_values_are_the_blocks_parameters() -> None:
    hand = draw_operator(RANGES, 1, 0)
    params = OperatorParams(intrinsic=True, **hand.operator_values())
    assert params.stiffness == hand.stiffness
    assert FreehandParams(**hand.grip_values()).grip_stiffness == hand.grip_stiffness


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        (
            {"stiffness": (600.0, 200.0)},
            r"stiffness: expected 0.0 <= low <= high, got \[600.0, 200.0\]",
        ),
        ({"tremor_rms_N": (0.0, 0.2)}, r"tremor_rms_N: expected low > 0"),
        ({"female_fraction": 1.5}, r"female_fraction must be <= 1.0"),
        ({"grip_strength_male_N": (100.0, 95.0)}, r"grip_strength_male_N: expected a mean above"),
    ],
)
def test_bad_ranges_are_refused(kwargs: dict, message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        PopulationParams(**kwargs)


def tremor_acceleration_g(tremor_rms_N: float, stiffness: float, damping: float) -> float:
    """Peak acceleration [g] of the probe held freehand in the air by a hand with this tremor: the
    RMS of the high-passed acceleration along its largest axis, times √2."""
    dt = 2e-3
    probe = FreehandProbe(FreehandParams(phantom=PhantomParams(shape="none")))
    hand = Operator(
        OperatorParams(
            task="hold",
            intrinsic=True,
            stiffness=stiffness,
            damping=damping,
            tremor_rms_N=tremor_rms_N,
            tremor_hz=9.0,
            feedforward_B=-0.48 * GRAVITY_B,
        ),
        rng=np.random.default_rng(2),
    )
    out = probe.initial_outputs()
    v = []
    for k in range(round(6.0 / dt)):
        h = hand.step(
            k * dt,
            dt,
            {"p_BT_B": out["p_BT_B"], "twist_B": out["twist_B"], "F_contact_B": out["F_contact_B"]},
        )
        out = probe.step(
            k * dt,
            dt,
            {
                "F_hand_B": h["F_hand_B"],
                "tau_hand_B": h["tau_hand_B"],
                "F_tip_B": np.zeros(3),
                "hand_on": h["hand_on"],
            },
        )
        v.append(out["twist_B"][:3].copy())
    a = np.gradient(np.array(v), dt, axis=0)[500:]
    rms = np.sqrt(np.mean(high_passed(a, 2.0, dt) ** 2, axis=0))
    return float(math.sqrt(2.0) * rms.max() / 9.81)


def test_the_tremor_moves_the_held_probe_as_normal_hand_tremor_does() -> None:
    """Wade, Gresty and Findley 1982: normal postural hand tremor 0.0015 to 0.035 g peak. The
    population's tremor forces, on the hands that move least and most, span it."""
    low = tremor_acceleration_g(RANGES.tremor_rms_N[0], RANGES.stiffness[1], RANGES.damping[1])
    high = tremor_acceleration_g(RANGES.tremor_rms_N[1], RANGES.stiffness[0], RANGES.damping[0])
    assert 0.0012 < low < 0.0018
    assert 0.030 < high < 0.040
