"""The controller as a mode machine over stages commands what the controller before it commanded.

The reference (`tests/data/controller_reference.*`, made by `make_controller_reference.py` on main
before the redesign) holds, per run, the controller's twist, the law's twist, the status and the
brake's acceleration at every controller tick and the tip's position every 20 ms, for every
scenario with a hand-guiding controller and the clinical study's modes. Each run here is the same
scenario, overrides, seed and duration, with the seed's preset (the block defaults the reference
was recorded on); every signal must equal the reference within 1e-12 of its peak, the status bits
exactly.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from tests.data import make_controller_reference as reference

RUNS = json.loads(reference.RUNS.read_text())


@pytest.fixture(scope="module")
def recorded() -> dict[str, np.ndarray]:
    with np.load(reference.SIGNALS) as data:
        return {name: data[name] for name in data.files}


@pytest.mark.parametrize("run", RUNS, ids=[run["name"] for run in RUNS])
def test_same_commands_as_before_the_mode_machine(run, recorded):
    now = reference.record(run, preset="seed")
    for key, before in ((k, v) for k, v in recorded.items() if k.startswith(f"{run['name']}/")):
        after = now[key]
        assert after.shape == before.shape, f"{key}: {after.shape} samples, {before.shape} before"
        if key.endswith("/status"):
            changed = np.flatnonzero(after != before)
            assert changed.size == 0, (
                f"{key}: {changed.size} ticks differ, the first at tick {changed[0]}: "
                f"{int(after.flat[changed[0]])} against {int(before.flat[changed[0]])}"
            )
            continue
        peak = float(np.max(np.abs(before))) or 1.0
        error = np.abs(after - before)
        worst = int(np.argmax(error))
        assert error.flat[worst] <= 1e-12 * peak, (
            f"{key}: differs by {error.flat[worst]:.3g} at sample {worst // before.shape[-1]} "
            f"(peak {peak:.3g})"
        )
