"""The metric sets on recordings whose answers are known by construction."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from hoh_cosim.cosim.recording import Recording
from hoh_cosim.cosim.report import SETTLE_SPEED_M_S, compute_report, lag_in_window
from hoh_cosim.cosim.scenario import load_scenario

SCENARIOS = Path(__file__).resolve().parents[2] / "scenarios"
DT = 0.001


def recording(scenario, duration: float, signals: dict[str, np.ndarray]) -> Recording:
    """A recording of `scenario`'s every output: zeros except the given signals."""
    n = round(duration / DT)
    columns, names, offset = {}, {}, 0
    for spec in scenario.components.values():
        for port in spec.outputs:
            key = f"{spec.name}.{port.name}"
            columns[key] = slice(offset, offset + port.size)
            names[key] = [key] if port.size == 1 else [f"{key}[{i + 1}]" for i in range(port.size)]
            offset += port.size
    values = np.zeros((n + 1, offset))
    for key, value in signals.items():
        values[:, columns[key]] = np.asarray(value).reshape(n + 1, -1)
    return Recording(np.arange(n + 1) * DT, values, columns, names, 2.0, "inprocess")


def test_lag_in_window_finds_a_known_delay_and_a_lead():
    t = np.arange(0, 8, DT)
    reference = np.column_stack([np.sin(2 * math.pi * 0.25 * t), np.cos(2 * math.pi * 0.25 * t)])
    late = np.column_stack(
        [np.sin(2 * math.pi * 0.25 * (t - 0.012)), np.cos(2 * math.pi * 0.25 * (t - 0.012))]
    )
    assert lag_in_window(t, reference, late, 0.25) == pytest.approx(0.012, abs=1e-9)
    assert lag_in_window(t, late, reference, 0.25) == pytest.approx(-0.012, abs=1e-9)


def test_circles_metrics_from_a_known_path_force_and_filter_delay():
    scenario = load_scenario(SCENARIOS / "circles.yaml", duration_s=12.0)
    t = np.arange(round(12.0 / DT) + 1) * DT
    w = 2 * math.pi / 4.0
    ref = np.column_stack([0.04 * np.cos(w * t), 0.04 * np.sin(w * t), np.zeros_like(t)])
    tip = ref + np.array([0.003, 0.0, 0.004])  # 5 mm off, everywhere
    hand = np.column_stack([3 * np.sin(w * t), 4 * np.cos(w * t), np.zeros_like(t)])
    delayed = np.column_stack(
        [3 * np.sin(w * (t - 0.02)), 4 * np.cos(w * (t - 0.02)), np.zeros_like(t)]
    )
    raw = np.column_stack(
        [3 * np.sin(w * (t - 0.005)), 4 * np.cos(w * (t - 0.005)), np.zeros_like(t)]
    )
    rec = recording(
        scenario,
        12.0,
        {
            "operator.p_ref_B": ref,
            "plant.p_BT_B": tip,
            "operator.F_hand_B": hand,
            "estimator.F_hand_B": delayed,
            "estimator.F_hand_meas_B": raw,
        },
    )
    m = compute_report(scenario, rec).metrics
    assert m["path_rms_error_m"] == pytest.approx(0.005, rel=1e-9)
    assert m["hand_force_rms_N"] == pytest.approx(math.sqrt((9 + 16) / 2), rel=1e-3)
    assert m["filter_lag_ms"] == pytest.approx(15.0, abs=1e-6)  # behind the raw, which is 5 late
    assert m["estimate_lag_ms"] == pytest.approx(20.0, abs=1e-6)
    assert m["realtime_factor"] == pytest.approx(12.0 / 2.0)
    assert m["wall_s"] == 2.0


def test_circles_too_short_for_one_circle_says_so():
    scenario = load_scenario(SCENARIOS / "circles.yaml", duration_s=6.0)
    report = compute_report(scenario, recording(scenario, 6.0, {}))
    assert report.metrics["path_rms_error_m"] is None
    assert "before one whole circle" in report.notes[0]


def test_static_noise_max_and_attenuation_after_the_rebias():
    scenario = load_scenario(SCENARIOS / "static_noise.yaml", duration_s=6.0)
    n = 6001
    t = np.arange(n) * DT
    ready = (t >= 2.0).astype(float)
    raw = np.zeros((n, 3))
    raw[t > 3.5] = [0.9, -0.6, 0.3]
    raw[t > 3.6] = 0.0
    raw[100] = [50.0, 50.0, 50.0]  # before ready + 1 s: not counted
    filtered = raw / 3.0
    rec = recording(
        scenario,
        6.0,
        {"estimator.ready": ready, "estimator.F_hand_meas_B": raw, "estimator.F_hand_B": filtered},
    )
    m = compute_report(scenario, rec).metrics
    np.testing.assert_allclose(m["noise_max_abs_raw_N"], [0.9, 0.6, 0.3])
    np.testing.assert_allclose(m["noise_max_abs_filtered_N"], [0.3, 0.2, 0.1])
    np.testing.assert_allclose(m["noise_attenuation"], [3.0, 3.0, 3.0])


def test_contact_losses_bounce_and_force_statistics():
    scenario = load_scenario(SCENARIOS / "contact_scan.yaml", duration_s=10.0)
    n = 10001
    t = np.arange(n) * DT
    depth = np.where(t < 3.0, -0.03 + 0.01 * t, 0.002)
    depth[(t > 6.0) & (t < 6.1)] = -0.0015  # one bounce, 1.5 mm up
    depth[(t > 7.0) & (t < 7.05)] = -0.0005  # and a second, smaller
    force = np.zeros((n, 3))
    force[:, 2] = np.where(depth > 0, 8.0 + np.sin(t), 0.0)  # up: the phantom pushes back
    rec = recording(scenario, 10.0, {"plant.penetration": depth, "plant.F_contact_B": force})
    m = compute_report(scenario, rec).metrics
    assert m["contact_losses"] == 2
    assert m["max_bounce_m"] == pytest.approx(0.0015)
    settled = t >= t[np.argmax(depth > 0)] + 2.0
    assert m["contact_force_mean_N"] == pytest.approx(np.mean(force[settled, 2]))
    assert m["contact_force_std_N"] == pytest.approx(np.std(force[settled, 2]))


def test_release_drift_and_settling_time():
    scenario = load_scenario(SCENARIOS / "release.yaml")
    n = round(scenario.duration_s / DT) + 1
    t = np.arange(n) * DT
    hand_on = ((t >= 3.0) & (t < 6.0)).astype(float)
    speed = np.where(t < 6.0, 0.05, 0.05 * np.exp(-(t - 6.0) / 0.1))
    speed[t < 3.0] = 0.0
    p = np.zeros((n, 3))
    p[:, 0] = np.cumsum(speed) * DT
    twist = np.zeros((n, 6))
    twist[:, 0] = speed
    rec = recording(
        scenario,
        scenario.duration_s,
        {"operator.hand_on": hand_on, "plant.p_BT_B": p, "plant.twist_B": twist},
    )
    m = compute_report(scenario, rec).metrics
    k = np.argmax(t >= 6.0)
    assert m["release_drift_m"] == pytest.approx(p[-1, 0] - p[k, 0])
    # 0.05 e^(-τ/0.1) falls under 1 mm/s at τ = 0.1 ln 50
    assert m["release_settle_s"] == pytest.approx(0.1 * math.log(0.05 / SETTLE_SPEED_M_S), abs=2e-3)


def test_release_that_never_happens_or_never_settles_is_none_with_a_note():
    scenario = load_scenario(SCENARIOS / "release.yaml")
    n = round(scenario.duration_s / DT) + 1
    report = compute_report(
        scenario, recording(scenario, scenario.duration_s, {"operator.hand_on": np.ones(n)})
    )
    assert report.metrics["release_drift_m"] is None
    assert "never let go" in report.notes[0]
    twist = np.zeros((n, 6))
    twist[:, 1] = 0.01
    hand_on = (np.arange(n) * DT < 6.0).astype(float)
    report = compute_report(
        scenario,
        recording(
            scenario, scenario.duration_s, {"operator.hand_on": hand_on, "plant.twist_B": twist}
        ),
    )
    assert report.metrics["release_settle_s"] is None
    assert "still moves" in report.notes[0]
