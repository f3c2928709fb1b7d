"""The benchmark scripts run and end with their figures as one JSON object (no timing asserted)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

BENCHMARKS = Path(__file__).resolve().parents[2] / "benchmarks"


def test_controller_cycle_prints_its_percentiles_as_json():
    result = subprocess.run(
        [sys.executable, str(BENCHMARKS / "controller_cycle.py"), "--cycles", "2000"],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert result.returncode == 0, result.stderr
    figures = json.loads(result.stdout.strip().splitlines()[-1])
    assert figures["cycles"] == 2000
    assert 0 < figures["p50_us"] <= figures["p99_us"] <= figures["p99_9_us"] <= figures["max_us"]


def test_cosim_speed_prints_its_figures_as_json():
    result = subprocess.run(
        [
            sys.executable,
            str(BENCHMARKS / "cosim_speed.py"),
            *("--duration", "1", "--steps", "300", "--repeats", "1"),
        ],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert result.returncode == 0, result.stderr
    figures = json.loads(result.stdout.strip().splitlines()[-1])
    assert figures["steps"] == 300
    assert figures["trivial_fmus"] == 4
    for key in ("fmu_realtime_factor", "inprocess_realtime_factor", "master_us_per_step"):
        assert figures[key] > 0


def test_engines_prints_each_engines_realtime_factor_as_json():
    result = subprocess.run(
        [sys.executable, str(BENCHMARKS / "engines.py"), "--duration", "0.3", "--repeats", "1"],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert result.returncode == 0, result.stderr
    figures = json.loads(result.stdout.strip().splitlines()[-1])
    assert figures["components"] == 6
    for engine in ("fmu", "fmu_jacobi", "libcosim", "libcosim_recorded", "ecos", "ecos_recorded"):
        assert figures[f"{engine}_realtime_factor"] > 0


def test_loaded_suite_runs_pytest_beside_its_hogs_and_prints_its_figures():
    result = subprocess.run(
        [
            sys.executable,
            str(BENCHMARKS / "loaded_suite.py"),
            *("--runs", "1", "--hogs", "1", "--"),
            *("tests/unit/test_modes.py", "-n", "0"),
        ],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert result.returncode == 0, result.stdout + result.stderr
    figures = json.loads(result.stdout.strip().splitlines()[-1])
    assert figures["hogs"] == 1
    assert figures["green"] == 1
    assert "passed" in result.stdout.splitlines()[1]


def test_view_cost_prints_both_arms_and_their_ratio_as_json():
    pytest.importorskip("rerun", reason="the view needs rerun-sdk (the view or test extra)")
    result = subprocess.run(
        [
            sys.executable,
            str(BENCHMARKS / "view_cost.py"),
            *("--cycles", "300", "--rounds", "1", "--no-live", "--rt-priority", "0"),
        ],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert result.returncode == 0, result.stderr
    figures = json.loads(result.stdout.strip().splitlines()[-1])
    assert figures["view_on"]["cycles"] == figures["view_off"]["cycles"] == 100
    assert figures["ratio_p99"] > 0
    assert figures["rows_shown"] == figures["rows_handed_to_view"] > 0
