"""benchmarks/fuzz.py runs, prints its table and ends with its figures as one JSON object; a saved
input runs again with --reproduce. (hypothesis' engine: the same with or without atheris.)"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

SCRIPT = Path(__file__).resolve().parents[2] / "benchmarks" / "fuzz.py"


def test_a_short_campaign_prints_its_figures(tmp_path):
    command = [sys.executable, str(SCRIPT), "--minutes", "0.06", "--engine", "hypothesis"]
    command += ["--target", "ft150", "--target", "calibration", "--out", str(tmp_path)]
    result = subprocess.run(command, capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stdout + result.stderr
    lines = result.stdout.strip().splitlines()
    assert lines[1].split() == ["target", "inputs", "failures", "distinct", "hangs", "what"]
    figures = json.loads(lines[-1])
    assert figures["engine"] == "hypothesis"
    assert (figures["failures"], figures["hangs"]) == (0, 0)
    for name in ("ft150", "calibration"):
        assert figures["targets"][name]["inputs"] > 0
        assert figures["targets"][name]["failures"] == 0


def test_reproduce_runs_a_saved_input_through_its_invariants(tmp_path):
    saved = tmp_path / "calibration-failure-1.json"
    saved.write_bytes(b'{"format": ' + b"[" * 50_000 + b"]" * 50_000 + b"}")
    result = subprocess.run(
        [sys.executable, str(SCRIPT), "--reproduce", str(saved)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert result.returncode == 0, result.stderr
    assert result.stdout == f"{saved}: the invariants of calibration hold\n"
