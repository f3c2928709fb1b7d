"""The controller as a mode machine over stages commands what the controller before it commanded.

The reference (`tests/data/controller_reference.*`, made by `make_controller_reference.py` on main
before the redesign) holds, per run, the controller's twist, the law's twist, the status and the
brake's acceleration at every controller tick and the tip's position every 20 ms, for every
scenario with a hand-guiding controller and the clinical study's modes. Each run here is the same
scenario, overrides, seed and duration, with the seed's preset (the block defaults the reference
was recorded on); every signal must equal the reference within 1e-12 of its peak, the status bits
exactly. The runs are recorded by the reference's own script, in a process of their own with the
OpenBLAS kernels the reference was recorded with (`BLAS_ENV`: OpenBLAS otherwise picks them by the
CPU, and another CPU's kernels round differently in the last bit, which a contact amplifies).
"""

from __future__ import annotations

import json
import platform
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from hoh_cosim.control.supervisor import Status
from tests.data import make_controller_reference as reference

RUNS = json.loads(reference.RUNS.read_text())

# one worker records every run once (tests/xdist_groups.py)
pytestmark = pytest.mark.xdist_group(__name__)


def _has_haswell_kernels() -> bool:
    """Whether this CPU runs OpenBLAS's Haswell kernels (x86-64 with AVX2 and FMA)."""
    if platform.machine().lower() not in ("x86_64", "amd64"):
        return False
    try:
        flags = Path("/proc/cpuinfo").read_text().split()
    except OSError:
        return False
    return "avx2" in flags and "fma" in flags


@pytest.fixture(scope="module")
def recorded() -> dict[str, np.ndarray]:
    with np.load(reference.SIGNALS) as data:
        return {name: data[name] for name in data.files}


@pytest.fixture(scope="module")
def now(tmp_path_factory) -> dict[str, np.ndarray]:
    """Every listed run recorded now, with the seed's preset, as the reference was."""
    if not _has_haswell_kernels():
        pytest.skip("the reference is bit-exact with OpenBLAS's Haswell kernels: needs x86-64 AVX2")
    out = tmp_path_factory.mktemp("controller_reference") / "now.npz"
    script = Path(reference.__file__)
    command = [sys.executable, str(script), "--signals-only", "--preset", "seed", "--out", str(out)]
    done = subprocess.run(command, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    with np.load(out) as data:
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
def test_same_commands_as_before_the_mode_machine(run, recorded, now):
    """Every signal as the reference; a run marked `changed` (a fix since, its reason in the run
    list) as the reference up to the moment the fix acts, and the fix's effect after it."""
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
