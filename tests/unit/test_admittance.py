"""Admittance laws (eq. 10 and alternatives), contact compensation (eq. 11–12), the fixture (3.F.3)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from hoh_cosim.control.admittance import (
    LAWS,
    ROTATION_GAINS,
    TRANSLATION_GAINS,
    AdmittanceGains,
    apply_law,
    contact_compensated,
    deadband_linear,
    horizontal_fixture,
    isotropic_deadband,
)
from hoh_cosim.errors import ConfigError

ALPHA = 0.0125  # [m/(s·N)] seed 3.F.1
ETA = np.array([0.95, 0.95, 0.25])  # [N]


@pytest.mark.parametrize(
    ("F", "expected"),
    [
        ([0.5, -0.9, 0.2], [0.0, 0.0, 0.0]),  # inside the deadband
        ([0.95, -0.95, 0.25], [0.0, 0.0, 0.0]),  # on its edge
        ([2.95, 0.0, 0.0], [0.025, 0.0, 0.0]),  # 0.0125 · (2.95 - 0.95)
        ([0.0, -4.95, 0.0], [0.0, -0.05, 0.0]),
        ([0.0, 0.0, -1.25], [0.0, 0.0, -0.0125]),  # z has η = 0.25
        ([10.95, 10.95, 8.25], [0.125, 0.125, 0.1]),
    ],
)
def test_eq10_at_sample_forces(F, expected):
    np.testing.assert_allclose(
        deadband_linear(np.array(F), np.full(3, ALPHA), ETA), expected, atol=1e-15
    )


def test_default_gains_are_the_seeds():
    np.testing.assert_array_equal(TRANSLATION_GAINS.slope, [ALPHA] * 3)
    np.testing.assert_array_equal(TRANSLATION_GAINS.deadband, ETA)
    assert TRANSLATION_GAINS.law == "deadband_linear"


forces = st.lists(st.floats(-60.0, 60.0, allow_nan=False), min_size=3, max_size=3).map(np.array)
gains_for_law = {
    "deadband_linear": TRANSLATION_GAINS,
    "isotropic": AdmittanceGains(law="isotropic"),
    "sigmoid": AdmittanceGains(law="sigmoid"),
    "rotation": ROTATION_GAINS,
}


@pytest.mark.parametrize("name", sorted(gains_for_law))
@given(F=forces)
def test_law_is_odd(name, F):
    g = gains_for_law[name]
    np.testing.assert_allclose(apply_law(-F, g), -apply_law(F, g), atol=1e-15)


@pytest.mark.parametrize("name", sorted(gains_for_law))
@given(F=forces)
def test_law_moves_along_the_force_on_every_axis(name, F):
    v = apply_law(F, gains_for_law[name])
    assert np.all(v * F >= 0.0)


unit_cube = st.lists(st.floats(-1.0, 1.0), min_size=3, max_size=3).map(np.array)


@pytest.mark.parametrize("name", ["deadband_linear", "isotropic", "rotation"])
@given(u=unit_cube)
def test_law_is_zero_inside_the_deadband(name, u):
    g = gains_for_law[name]
    if name == "isotropic":  # inside the ellipsoid ‖F ⊘ η‖ <= 1
        u = u / max(1.0, float(np.linalg.norm(u)) * (1.0 + 1e-9))  # strictly inside
    np.testing.assert_array_equal(apply_law(u * g.deadband, g), 0.0)


@pytest.mark.parametrize("name", sorted(gains_for_law))
@pytest.mark.parametrize("axis", [0, 1, 2])
@given(a=st.floats(0.0, 60.0), b=st.floats(0.0, 60.0))
def test_law_is_monotone_along_each_axis(name, axis, a, b):
    g = gains_for_law[name]
    lo, hi = sorted((a, b))
    F_lo, F_hi = np.zeros(3), np.zeros(3)
    F_lo[axis], F_hi[axis] = lo, hi
    assert apply_law(F_hi, g)[axis] >= apply_law(F_lo, g)[axis]
    if hi > lo and lo > g.deadband[axis] and g.law != "sigmoid":
        assert apply_law(F_hi, g)[axis] > apply_law(F_lo, g)[axis]  # strictly outside


@given(F=forces)
def test_isotropic_law_equals_eq10_along_an_axis(F):
    for axis in range(3):
        along = np.zeros(3)
        along[axis] = F[axis]
        np.testing.assert_allclose(
            isotropic_deadband(along, np.full(3, ALPHA), ETA),
            deadband_linear(along, np.full(3, ALPHA), ETA),
            atol=1e-15,
        )


@given(F=forces, rotvec=st.lists(st.floats(-3, 3), min_size=3, max_size=3))
def test_isotropic_law_with_equal_gains_does_not_depend_on_direction(F, rotvec):
    from hoh_cosim.control.frames import rotvec_to_matrix

    slope, eta = np.full(3, ALPHA), np.full(3, 0.95)
    R = rotvec_to_matrix(rotvec)
    v, v_turned = isotropic_deadband(F, slope, eta), isotropic_deadband(R @ F, slope, eta)
    np.testing.assert_allclose(v_turned, R @ v, atol=1e-12)


def test_eq10_has_direction_dependent_corners_that_the_isotropic_law_removes():
    # 1.2 N along a diagonal: each axis sees 0.85 N < η, eq. 10 does not move; the isotropic law does
    F = 1.2 * np.array([1.0, 1.0, 0.0]) / np.sqrt(2.0)
    np.testing.assert_array_equal(deadband_linear(F, np.full(3, ALPHA), np.full(3, 0.95)), 0.0)
    assert np.linalg.norm(isotropic_deadband(F, np.full(3, ALPHA), np.full(3, 0.95))) > 0.0


def test_sigmoid_undershoots_eq10_over_the_working_range():
    # seed Fig. 21: "the sigmoidal function undershoots the linear one"
    sig = AdmittanceGains(law="sigmoid")
    for f in np.linspace(1.5, 8.0, 30):
        F = np.array([f, 0.0, 0.0])
        assert apply_law(F, sig)[0] < apply_law(F, TRANSLATION_GAINS)[0]


def test_sigmoid_saturates_at_its_maximum_speed():
    sig = AdmittanceGains(law="sigmoid")
    v = apply_law(np.array([500.0, -500.0, 0.0]), sig)
    np.testing.assert_allclose(v[:2], [0.10, -0.10], rtol=1e-9)


def test_contact_compensation_cancels_a_pure_contact_force():
    # the patient pushes back on the probe: the wrist feels it too; the hand does nothing
    F_probe = np.array([0.5, -0.2, 8.0])
    F_hand = F_probe.copy()  # what the wrist sensor reads: F̃_hand + F_probe with F̃_hand = 0
    v = deadband_linear(contact_compensated(F_hand, F_probe), np.full(3, ALPHA), ETA)
    np.testing.assert_array_equal(v, 0.0)  # no bounce
    assert deadband_linear(F_hand, np.full(3, ALPHA), ETA)[2] > 0.0  # without it: bounce up


def test_fixture_blocks_upward_motion_in_contact():
    up = np.array([0.0, 0.0, 1.0])
    v, engaged = horizontal_fixture(np.array([0.02, -0.01, 0.03]), np.array([0, 0, 3.0]), 1.0, up)
    np.testing.assert_array_equal(v, [0.02, -0.01, 0.0])
    assert engaged


def test_fixture_leaves_downward_motion_free():
    up = np.array([0.0, 0.0, 1.0])
    v_in = np.array([0.02, 0.0, -0.03])
    v, engaged = horizontal_fixture(v_in, np.array([0, 0, 3.0]), 1.0, up)
    np.testing.assert_array_equal(v, v_in)
    assert engaged


def test_fixture_releases_without_contact():
    up = np.array([0.0, 0.0, 1.0])
    v_in = np.array([0.0, 0.0, 0.05])
    v, engaged = horizontal_fixture(v_in, np.array([0.0, 0.0, 0.9]), 1.0, up)
    np.testing.assert_array_equal(v, v_in)
    assert not engaged


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        (
            {"law": "cubic"},
            r"law: expected one of deadband_linear, isotropic, sigmoid, variable, got 'cubic'",
        ),
        ({"slope": [0.1, -0.1, 0.1]}, r"slope must be >= 0 on every axis, got \[0.1, -0.1, 0.1\]"),
        ({"deadband": [1.0, 1.0]}, r"deadband: expected 3 values, got 2"),
        ({"sigmoid_max_speed": [0.1, 0.0, 0.1]}, r"sigmoid_max_speed must be > 0 on every axis"),
    ],
)
def test_gains_reject_bad_values(kwargs, message):
    with pytest.raises(ConfigError, match=message):
        AdmittanceGains(**kwargs)


def test_every_law_is_listed():
    assert set(LAWS) == {"deadband_linear", "isotropic", "sigmoid", "variable"}
