"""The benchmark scripts run and end with their figures as one JSON object (no timing asserted)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

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
