"""The tick's compensated hand force: eq. 11-12 in full in contact; with an onset, in the air, none
of the probe force under half of it and all of it from the onset on."""

from __future__ import annotations

import numpy as np
import pytest

from hoh_cosim.control.admittance import contact_compensated
from hoh_cosim.control.guidance.tick import Tick
from tests.estimates import controller_inputs

ONSET = 2.0  # [N]
READING = (True, False, True, False, ONSET, False, 2.25)  # compensation on, with the onset
HAND = np.array([0.4, -0.2, 1.5])


def compensated(probe_N: float, air: bool) -> np.ndarray:
    tick = Tick()
    inputs = controller_inputs(F_hand_B=HAND, F_probe_B=[0.0, 0.0, probe_N])
    tick.start(0.0, 0.002, 0, (np.zeros(3), np.zeros(3)), inputs, READING, air)
    return tick.F


@pytest.mark.parametrize("probe_N", [0.3, 0.6, 0.99])
def test_in_the_air_a_probe_force_under_half_the_onset_is_not_taken_out(probe_N):
    np.testing.assert_array_equal(compensated(probe_N, air=True), HAND)


def test_in_the_air_the_probe_force_is_taken_out_in_part_then_in_full():
    full = contact_compensated(HAND, np.array([0.0, 0.0, 1.5]))
    part = compensated(1.5, air=True)  # w = 2 * 1.5 / 2 - 1 = 0.5
    np.testing.assert_allclose(part, contact_compensated(HAND, np.array([0.0, 0.0, 0.75])))
    assert not np.allclose(part, full)
    big = np.array([0.0, 0.0, 3.0])
    np.testing.assert_array_equal(compensated(3.0, air=True), contact_compensated(HAND, big))


@pytest.mark.parametrize("probe_N", [0.3, 1.5, 6.0])
def test_in_contact_the_probe_force_is_taken_out_in_full_whatever_its_size(probe_N):
    want = contact_compensated(HAND, np.array([0.0, 0.0, probe_N]))
    np.testing.assert_array_equal(compensated(probe_N, air=False), want)
