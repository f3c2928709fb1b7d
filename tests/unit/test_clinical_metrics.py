"""The clinical metric set's pieces: the jitter in the probe's frame, the goal's timing, the
recovery from the patient moving away, and the paired comparisons of the study."""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from scipy import stats

from hoh_cosim.control.frames import rotvec_to_matrix
from hoh_cosim.cosim.clinical import _first_held, clinical_metrics, jitter
from hoh_cosim.cosim.recording import Recording, recording_layout
from hoh_cosim.cosim.scenario import Scenario, load_scenario
from hoh_cosim.study.clinical import MODES, TASKS, paired_change

SCENARIOS = Path(__file__).resolve().parents[2] / "scenarios"
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


# -- recovery from the patient moving away at 10 s, 10 N before -----------------------------------

AWAY_S = 10.0
RUN_S = 16.0


def clinical_run(away_m: float) -> Scenario:
    """The assisted rig, the patient moving away 15 mm at `AWAY_S` (or never, with `away_m` 0)."""
    overrides = [f"breathing.away_s={AWAY_S}", f"breathing.away_m={away_m}"]
    return load_scenario(SCENARIOS / "clinical_assisted.yaml", overrides, duration_s=RUN_S)


def pressed(scenario: Scenario, force: np.ndarray) -> Recording:
    """A recording of `scenario`: zeros but the phantom's force `force` [N] along the pressing
    direction (down), and the tip in the phantom wherever that force is positive."""
    t = np.arange(round(RUN_S / DT) + 1) * DT
    columns, names = recording_layout(list(scenario.components.values()))
    values = np.zeros((len(t), max(s.stop for s in columns.values())))
    values[:, columns["plant.F_contact_B"]] = np.outer(force, [0.0, 0.0, 1.0])  # pushes back up
    values[:, columns["plant.penetration"]] = np.where(force > 0.0, 1e-3, -1e-3)[:, None]
    return Recording(t, values, columns, names, 1.0, "inprocess")


def force_profile(after: Callable[[np.ndarray], np.ndarray]) -> np.ndarray:
    """10 N from 4 s to `AWAY_S`, then `after` (a function of time)."""
    t = np.arange(round(RUN_S / DT) + 1) * DT
    return np.where(t < AWAY_S, np.where(t >= 4.0, 10.0, 0.0), after(t))


def lost_and_back(t: np.ndarray) -> np.ndarray:
    """Lost at the move, back at 9 N 1.2 s later, overshooting to 14 N at 12 s."""
    back = 9.0 + 5.0 * np.exp(-(((t - 12.0) / 0.2) ** 2))
    return np.where(t < AWAY_S + 1.2 - DT / 2, 0.0, back)


def test_a_lost_contact_recovers_when_its_force_is_back() -> None:
    force = force_profile(lost_and_back)
    scenario = clinical_run(0.015)
    m, notes = clinical_metrics(scenario, pressed(scenario, force))
    assert m["recovery_time_s"] == pytest.approx(1.2, abs=DT)
    assert m["recovery_peak_N"] == pytest.approx(14.0)
    assert not [n for n in notes if "came back" in n]


def test_without_a_move_away_there_is_no_recovery() -> None:
    force = force_profile(lost_and_back)
    scenario = clinical_run(0.0)
    m, notes = clinical_metrics(scenario, pressed(scenario, force))
    assert m["recovery_time_s"] is None
    assert m["recovery_peak_N"] is None
    assert not [n for n in notes if "moved away" in n or "came back" in n]


def test_a_contact_kept_over_half_its_force_recovers_at_once() -> None:
    force = force_profile(lambda t: 10.0 - 3.0 * np.exp(-(((t - 10.5) / 0.1) ** 2)))  # down to 7 N
    scenario = clinical_run(0.015)
    m, _ = clinical_metrics(scenario, pressed(scenario, force))
    assert m["recovery_time_s"] == 0.0
    assert m["recovery_peak_N"] == pytest.approx(10.0)


def test_a_contact_that_never_comes_back_has_no_recovery_time() -> None:
    # back to 7 N only: under 80 % of the 10 N before
    force = force_profile(lambda t: np.where(t < 12.0, 0.0, 7.0))
    scenario = clinical_run(0.015)
    m, notes = clinical_metrics(scenario, pressed(scenario, force))
    assert m["recovery_time_s"] is None
    assert m["recovery_peak_N"] == pytest.approx(7.0)
    assert (
        "clinical: the contact never came back to 80% of its force before the patient moved away "
        "by the end of the run"
    ) in notes


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
    """One freehand mode, assisted ones on the robot; the three tasks of issue 23 and the recovery
    of issue 51."""
    assert [m for m in MODES.values() if not m.assisted] == [MODES["freehand"]]
    assert set(TASKS) == {"view", "scan", "press", "recover"}
    assert dict(TASKS["scan"].operator)["target_force_N"] == 8.0
    assert dict(TASKS["press"].operator)["target_force_N"] == 15.0
    assert dict(TASKS["scan"].operator)["length_m"] == 0.10
