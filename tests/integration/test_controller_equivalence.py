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

from hoh_cosim.control.supervisor import Status
from tests.data import make_controller_reference as reference

RUNS = json.loads(reference.RUNS.read_text())


@pytest.fixture(scope="module")
def recorded() -> dict[str, np.ndarray]:
    with np.load(reference.SIGNALS) as data:
        return {name: data[name] for name in data.files}


HOLDING = int(Status.HOLDING)
RELEASED = int(Status.RELEASED)


def _first_hold_end(status: np.ndarray) -> int:
    """The first tick after a held one that holds no more but rests (a hold's guard ended it)."""
    held = (status & HOLDING) != 0
    resting = ((status & RELEASED) != 0) & ~held
    ends = np.flatnonzero(held[:-1] & resting[1:])
    return int(ends[0]) + 1 if ends.size else len(status)


@pytest.mark.parametrize("run", RUNS, ids=[run["name"] for run in RUNS])
def test_same_commands_as_before_the_mode_machine(run, recorded):
    """Every signal as the reference; a run marked `changed` (a fix since, its reason in the run
    list) as the reference up to the moment the fix acts, and the fix's effect after it."""
    now = reference.record(run, preset="seed")
    name = run["name"]
    upto = None
    if "changed" in run:
        status = recorded[f"{name}/status"].astype(int).ravel()
        upto = _first_hold_end(status)
        assert upto < len(status), "the run never ends a hold: nothing to compare the fix with"
        _rests_until_the_hand_pushes(now[f"{name}/status"].astype(int).ravel())
    for key, before in ((k, v) for k, v in recorded.items() if k.startswith(f"{name}/")):
        after = now[key]
        if upto is not None and not key.endswith("/p_BT_B"):
            after, before = after[:upto], before[:upto]
        elif upto is not None:  # the tip at its own rate: up to the same moment
            ticks = len(recorded[f"{name}/status"])
            after, before = (
                after[: upto * len(before) // ticks],
                before[: upto * len(before) // ticks],
            )
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


def _rests_until_the_hand_pushes(status: np.ndarray) -> None:
    """After a hold that ended without the hand, no hold begins before the robot guided again
    (a tick with neither HOLDING nor RELEASED: the hand pushed)."""
    held = (status & HOLDING) != 0
    resting = ((status & RELEASED) != 0) & ~held
    k = 1
    while k < len(status):
        if held[k - 1] and resting[k]:
            j = k
            while j < len(status) and resting[j]:
                j += 1
            assert j == len(status) or not held[j], f"held again at tick {j} with no push between"
            k = j
        k += 1
