"""Breathing: the surface's rate, depth and shape, its seeding, and how it reaches the contact."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from hoh_cosim.errors import ConfigError
from plant_models.breathing import Breathing, BreathingParams, breath_value
from plant_models.plant import Plant, PlantParams
from plant_models.tissue import PhantomParams, contact_force


def run(params: BreathingParams, seconds: float, dt: float = 1e-3, seed: int = 3) -> np.ndarray:
    """(t, h, ḣ, phase) rows, one a step."""
    b = Breathing(params, rng=np.random.default_rng(seed))
    rows = []
    for k in range(round(seconds / dt)):
        out = b.step(k * dt, dt, {})
        rows.append(((k + 1) * dt, out["offset_m"][0], out["rate_m_s"][0], out["phase"][0]))
    return np.array(rows)


def breaths(rows: np.ndarray) -> list[tuple[float, float]]:
    """(start time, peak depth) of every whole breath: a new breath where the phase wraps."""
    starts = np.flatnonzero(np.diff(rows[:, 3]) < -0.5) + 1
    return [(rows[a, 0], float(rows[a:b, 1].max())) for a, b in itertools.pairwise(starts)]


@pytest.mark.parametrize("rate", [12.0, 15.0, 20.0])
@pytest.mark.parametrize("amplitude", [0.005, 0.015])
def test_rate_and_depth_are_the_parameters_on_average(rate: float, amplitude: float) -> None:
    # the surface is a function of time: 10 ms steps see the same breaths as 1 ms ones
    rows = run(
        BreathingParams(rate_per_min=rate, amplitude_m=amplitude, irregularity=0.1), 300.0, dt=0.01
    )
    found = breaths(rows)
    periods = np.diff([t for t, _ in found])
    # 60-100 breaths: the mean period within 3 standard errors of a 10 % spread
    assert 60.0 / np.mean(periods) == pytest.approx(rate, rel=0.05)
    assert np.mean([peak for _, peak in found]) == pytest.approx(amplitude, rel=0.06)
    # the surface rests at end-expiration and never goes below it nor past the largest breath
    assert rows[:, 1].min() >= 0.0
    assert rows[:, 1].max() <= amplitude * (1.0 + 2.5 * 0.1) + 1e-12
    # and the breaths do vary
    assert np.std(periods) / np.mean(periods) > 0.03


def test_without_irregularity_every_breath_is_the_same() -> None:
    rows = run(BreathingParams(rate_per_min=15.0, amplitude_m=0.010, irregularity=0.0), 40.0)
    found = breaths(rows)
    np.testing.assert_allclose(np.diff([t for t, _ in found]), 4.0, atol=1.5e-3)
    np.testing.assert_allclose([p for _, p in found], 0.010, rtol=1e-5)


def test_the_rate_is_the_derivative_of_the_offset() -> None:
    rows = run(BreathingParams(shape_n=2), 20.0, dt=1e-4)
    numeric = np.gradient(rows[:, 1], rows[:, 0])
    assert np.max(np.abs(numeric - rows[:, 2])) < 1e-3 * np.max(np.abs(rows[:, 2]))
    # continuous across breaths (the rate is zero where a breath ends)
    assert np.max(np.abs(np.diff(rows[:, 2]))) < 0.01 * np.max(np.abs(rows[:, 2]))


@pytest.mark.parametrize("n", [1, 2, 3])
def test_lujans_shape(n: int) -> None:
    h, h_dot = breath_value(0.01, 4.0, 0.5, n)
    assert (h, h_dot) == pytest.approx((0.01, 0.0), abs=1e-15)
    assert breath_value(0.01, 4.0, 0.0, n) == (0.0, 0.0)
    # a larger n rests longer near end-expiration
    assert breath_value(0.01, 4.0, 0.2, n)[0] == pytest.approx(
        0.01 * math.sin(0.2 * math.pi) ** (2 * n)
    )


def test_any_step_gives_the_same_surface() -> None:
    fine = run(BreathingParams(), 30.0, dt=1e-3)
    coarse = run(BreathingParams(), 29.0, dt=7e-3)
    t = coarse[:, 0]
    rows = np.rint(t / 1e-3).astype(int) - 1
    # the same values but for the rounding of the times (k · dt + dt)
    np.testing.assert_allclose(coarse[:, 1:], fine[rows, 1:], rtol=1e-12, atol=1e-15)


def test_seeded() -> None:
    a = run(BreathingParams(), 30.0, seed=1)
    b = run(BreathingParams(), 30.0, seed=1)
    c = run(BreathingParams(), 30.0, seed=2)
    np.testing.assert_array_equal(a, b)
    assert not np.allclose(a[:, 1], c[:, 1])
    # a reset starts the same breaths again
    block = Breathing(BreathingParams(), rng=np.random.default_rng(1))
    first = [block.step(k * 0.01, 0.01, {})["offset_m"][0] for k in range(500)]
    block.reset()
    again = [block.step(k * 0.01, 0.01, {})["offset_m"][0] for k in range(500)]
    assert first == again


def test_still_before_the_start() -> None:
    rows = run(BreathingParams(start_s=5.0), 10.0)
    assert not rows[rows[:, 0] < 5.0, 1:].any()
    assert rows[rows[:, 0] > 5.0, 1].max() > 0.0


# -- the patient moving away (the clinical study's planted contact loss) ---------------------------

AWAY = {"away_s": 5.0, "away_m": 0.015, "away_time_s": 0.3}  # 15 mm within 0.3 s


def test_the_move_away_reaches_its_distance_and_stays() -> None:
    still = run(BreathingParams(), 8.0)
    moved = run(BreathingParams(**AWAY), 8.0)
    t, d = moved[:, 0], still[:, 1] - moved[:, 1]  # inward: the offset decreases by d
    assert not d[t <= 5.0].any()
    np.testing.assert_allclose(d[t >= 5.3], 0.015, rtol=1e-12)
    ramp = (t > 5.0) & (t < 5.3)
    assert np.all(np.diff(d[ramp]) > 0.0)
    assert d[np.argmin(np.abs(t - 5.15))] == pytest.approx(
        0.0075, rel=1e-9
    )  # half way at half time
    # the raised cosine and its derivative; the phases do not move
    u = np.clip((t - 5.0) / 0.3, 0.0, 1.0)
    np.testing.assert_allclose(d, 0.015 * (1.0 - np.cos(np.pi * u)) / 2.0, rtol=1e-9, atol=1e-15)
    d_dot = 0.015 * np.pi * np.sin(np.pi * u) / 0.6
    np.testing.assert_allclose(still[:, 2] - moved[:, 2], d_dot, rtol=1e-9, atol=1e-15)
    np.testing.assert_array_equal(still[:, 3], moved[:, 3])


def test_the_move_away_is_continuous_and_its_rate_is_its_derivative() -> None:
    rows = run(BreathingParams(**AWAY), 6.0, dt=1e-4)
    near = (rows[:, 0] > 4.9) & (rows[:, 0] < 5.4)  # both ends of the ramp
    top_rate = 0.015 * math.pi / 0.6  # D π / (2 T_a), the ramp's steepest
    # 0.1 ms at the steepest ramp is 7.9 µm; at its largest acceleration (D π² / 2 T_a², 0.82 m/s²)
    # the rate moves 82 µm/s: a step of a linear ramp's rate (D / T_a, 0.05 m/s) would not pass
    assert np.max(np.abs(np.diff(rows[near, 1]))) < 1e-4 * 1.05 * top_rate
    assert np.max(np.abs(np.diff(rows[near, 2]))) < 1e-4 * 1.05 * 0.015 * math.pi**2 / 0.18
    numeric = np.gradient(rows[:, 1], rows[:, 0])
    assert np.max(np.abs(numeric - rows[:, 2])) < 1e-3 * top_rate


def test_the_move_away_is_a_function_of_time_alone() -> None:
    fine = run(BreathingParams(**AWAY), 8.0, dt=1e-3)
    coarse = run(BreathingParams(**AWAY), 7.9, dt=7e-3)
    rows = np.rint(coarse[:, 0] / 1e-3).astype(int) - 1
    np.testing.assert_allclose(coarse[:, 1:], fine[rows, 1:], rtol=1e-12, atol=1e-15)


def test_without_a_distance_there_is_no_move_away() -> None:
    default = run(BreathingParams(), 10.0)
    np.testing.assert_array_equal(run(BreathingParams(away_s=5.0, away_time_s=1.0), 10.0), default)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"rate_per_min": 0.0}, r"rate_per_min must be > 0"),
        ({"amplitude_m": -0.001}, r"amplitude_m must be >= 0"),
        ({"irregularity": 0.5}, r"irregularity must be <= 0.4"),
        ({"shape_n": 0}, r"shape_n: expected an integer from 1 to 5, got 0"),
        ({"shape_n": 1.5}, r"shape_n: expected an integer from 1 to 5, got 1.5"),
        ({"away_s": -1.0}, r"away_s must be >= 0.0, got -1.0"),
        ({"away_m": -0.001}, r"away_m must be >= 0.0, got -0.001"),
        ({"away_m": 0.2}, r"away_m must be <= 0.1, got 0.2"),
        ({"away_time_s": 0.0}, r"away_time_s must be > 0.0, got 0.0"),
    ],
)
def test_bad_parameters_are_refused(kwargs: dict, message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        BreathingParams(**kwargs)


# -- how the surface reaches the contact ------------------------------------------------------------


@pytest.mark.parametrize("h", [0.0, 0.002, 0.007])
def test_an_offset_plane_is_the_plane_moved_along_its_normal(h: float) -> None:
    n = np.array([0.3, 0.0, 1.0]) / math.hypot(0.3, 1.0)
    still = PhantomParams(plane_point_B=[0.0, 0.0, 0.2], plane_normal_B=n)
    moved = PhantomParams(plane_point_B=np.array([0.0, 0.0, 0.2]) + h * n, plane_normal_B=n)
    p, v = np.array([0.01, 0.02, 0.195]), np.array([0.01, 0.0, -0.02])
    a = contact_force(still, p, v, offset_m=h, offset_rate_m_s=0.0)
    b = contact_force(moved, p, v)
    np.testing.assert_allclose(a.force_B, b.force_B, rtol=1e-12)
    assert a.depth == pytest.approx(b.depth, abs=1e-15)


def test_a_rising_surface_pushes_like_a_sinking_probe() -> None:
    """Hunt-Crossley's damping sees the depth's rate: a surface rising at ḣ is a probe moving
    into it at ḣ; exactly on the plane, to first order on the ellipsoid."""
    for phantom, tolerance in (
        (PhantomParams(plane_point_B=[0.0, 0.0, 0.2]), 1e-12),
        (PhantomParams(shape="ellipsoid"), 0.02),
    ):
        top = (
            np.array([0.0, 0.0, 0.2])
            if phantom.shape == "plane"
            else phantom.ellipsoid_center_B + np.array([0.0, 0.0, phantom.ellipsoid_axes[2]])
        )
        tip = top - [0.0, 0.0, 0.004]
        rising = contact_force(phantom, tip, np.zeros(3), offset_m=0.002, offset_rate_m_s=0.01)
        sinking = contact_force(phantom, tip - [0.0, 0.0, 0.002], np.array([0.0, 0.0, -0.01]))
        np.testing.assert_allclose(rising.force_B, sinking.force_B, rtol=tolerance)
        assert rising.force_B[2] > contact_force(phantom, tip, np.zeros(3), 0.002).force_B[2]


@pytest.mark.parametrize("shape", ["plane", "ellipsoid"])
def test_the_plant_feels_the_breathing(shape: str) -> None:
    """The UR5 holding still above the phantom: the contact force follows the surface."""
    # 5 mm below the tip at home (-0.10, -0.45, 0.25): the ellipsoid's depth is its first-order
    # distance, within 0.2 mm of the true one 5 mm off the surface
    phantom = (
        PhantomParams(plane_point_B=[0.0, 0.0, 0.245])
        if shape == "plane"
        else PhantomParams(
            shape="ellipsoid",
            ellipsoid_center_B=[-0.10, -0.45, 0.145],
            ellipsoid_axes=[0.17, 0.25, 0.10],
        )
    )
    tolerance = 1e-9 if shape == "plane" else 2e-4
    plant = Plant(PlantParams(phantom=phantom))
    zero = np.zeros(3)
    forces = []
    for h in (0.0, 0.004, 0.008, 0.012):
        out = plant.step(
            0.0,
            1e-3,
            {
                "twist_cmd_B": np.zeros(6),
                "F_hand_B": zero,
                "tau_hand_B": zero,
                "F_tip_B": zero,
                "surface_offset_m": np.array([h]),
                "surface_rate_m_s": np.array([0.0]),
            },
        )
        forces.append(out["F_contact_B"][2])
        # the depth grows by the offset
        assert out["penetration"][0] == pytest.approx(h - 0.005, abs=tolerance)
    assert forces[0] == forces[1] == 0.0  # 5 mm above the skin: the first 4 mm touch nothing
    assert 0.0 < forces[2] < forces[3]
    # without the inputs (every scenario without breathing), a still surface
    still = plant.step(
        0.001,
        1e-3,
        {"twist_cmd_B": np.zeros(6), "F_hand_B": zero, "tau_hand_B": zero, "F_tip_B": zero},
    )
    assert still["penetration"][0] == pytest.approx(-0.005, abs=tolerance)
