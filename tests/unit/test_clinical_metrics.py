"""The clinical metric set's pieces: the jitter in the probe's frame, the goal's timing, and the
paired comparisons of the study."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from hoh_cosim.control.frames import rotvec_to_matrix
from hoh_cosim.cosim.clinical import _first_held, jitter
from hoh_cosim.study.clinical import MODES, TASKS, paired_change

DT = 1e-3
R_DOWN = np.array([[0.0, -1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])  # x_T = -y_B, z_T = -z_B


def motion(t: np.ndarray, displacement_T: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Tip positions for a displacement given in the probe's frame, the probe pointing down."""
    p = (R_DOWN @ displacement_T.T).T
    return p, np.tile(R_DOWN.reshape(9), (len(t), 1))


def test_a_tremor_along_the_array_is_lateral_jitter() -> None:
    t = np.arange(0.0, 20.0, DT)
    a = 50e-6
    p, R = motion(t, np.column_stack([a * np.sin(2 * math.pi * 9.0 * t), 0 * t, 0 * t]))
    j = jitter(t, p, R, DT)
    assert j["jitter_lateral_mm"] == pytest.approx(1e3 * a / math.sqrt(2.0), rel=0.01)
    assert j["jitter_axial_mm"] < 1e-9
    assert j["jitter_elevation_mm"] < 1e-9
    assert j["jitter_image_mm"] == pytest.approx(j["jitter_lateral_mm"])
    assert j["jitter_rotation_deg"] < 1e-9


def test_breathing_and_the_task_are_not_jitter() -> None:
    """10 mm of breathing at 0.25 Hz along the beam and a 5 cm sweep across: under 0.1 % leaks
    into the jitter band."""
    t = np.arange(0.0, 30.0, DT)
    breath = 0.005 * (1.0 - np.cos(2 * math.pi * 0.25 * t))
    sweep = 0.05 * (1.0 - np.cos(2 * math.pi * t / 20.0)) / 2.0
    p, R = motion(t, np.column_stack([0 * t, sweep, breath]))
    j = jitter(t, p, R, DT)
    assert j["jitter_axial_mm"] < 1e-3 * 10.0
    assert j["jitter_elevation_mm"] < 1e-3 * 50.0


def test_a_wobble_is_rotation_jitter() -> None:
    t = np.arange(0.0, 10.0, DT)
    angle = math.radians(0.1) * np.sin(2 * math.pi * 10.0 * t)
    R = np.array([(rotvec_to_matrix([0.0, x, 0.0]) @ R_DOWN).reshape(9) for x in angle])
    j = jitter(t, np.zeros((len(t), 3)), R, DT)
    assert j["jitter_rotation_deg"] == pytest.approx(0.1 / math.sqrt(2.0), rel=0.01)


def test_too_short_a_window_gives_no_jitter() -> None:
    t = np.arange(0.0, 1.5, DT)
    p, R = motion(t, np.zeros((len(t), 3)))
    assert set(jitter(t, p, R, DT).values()) == {None}


def test_a_goal_counts_once_it_holds() -> None:
    t = np.arange(0.0, 3.0, 0.1)
    ok = (t > 0.45) & (t < 0.75) | (t > 1.45)
    assert _first_held(t, ok, 0.5) == pytest.approx(1.5)
    assert _first_held(t, np.zeros_like(ok), 0.5) is None


def test_paired_change_per_operator_with_its_confidence_interval() -> None:
    freehand = [10.0, 8.0, 12.0, 9.0, None]
    assisted = [2.0, 4.0, 3.0, None, 1.0]
    s = paired_change(freehand, assisted)
    per = [80.0, 50.0, 75.0]
    assert s["per_operator"] == pytest.approx(per)
    assert (s["n"], s["min"], s["max"]) == (3, 50.0, 80.0)
    assert s["mean"] == pytest.approx(np.mean(per))
    half = stats.t.ppf(0.975, 2) * np.std(per, ddof=1) / math.sqrt(3)
    assert s["ci95"] == pytest.approx([np.mean(per) - half, np.mean(per) + half])
    # worse than freehand is negative; one pair has no interval
    one = paired_change([2.0], [3.0])
    assert one["per_operator"] == pytest.approx([-50.0])
    assert one["ci95"] is None


def test_the_closed_sets() -> None:
    """One freehand mode, assisted ones on the robot; the three tasks of the issue."""
    assert [m for m in MODES.values() if not m.assisted] == [MODES["freehand"]]
    assert set(TASKS) == {"view", "scan", "press"}
    assert dict(TASKS["scan"].operator)["target_force_N"] == 8.0
    assert dict(TASKS["press"].operator)["target_force_N"] == 15.0
    assert dict(TASKS["scan"].operator)["length_m"] == 0.10
