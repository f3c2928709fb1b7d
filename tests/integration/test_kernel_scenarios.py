"""Every scenario's metrics with the compiled kernels against the pure (numpy, pinocchio) path.

The kernels agree with their references to rounding (tests/unit/test_kernels.py); a closed loop
carries that rounding on. Where the loop forgets it, every metric agrees within 1e-12 relative.
Where it amplifies it (a probe sliding on the phantom under the hand's force feedback: a rounding
difference grows about tenfold a second), no two codes that round differently can agree to 1e-12,
however exact each is; there the difference must stay within what the pure path itself does when
the start moves by one unit in the last place (a joint angle of the arm, a coordinate of the
freehand probe; the most of three such moves) (docs/decisions/0034-compiled-kernels.md).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from hoh_cosim.control.kernels import use_kernels
from hoh_cosim.cosim.engines import simulate
from hoh_cosim.cosim.report import compute_report
from hoh_cosim.cosim.scenario import load_scenario
from plant_models.arm import HOME_Q
from plant_models.freehand import HOME_TIP_B
from tests.integration.test_scenarios import SCENARIOS, SHORT

REL = 1e-12
AMPLIFYING = ("clinical_assisted", "clinical_freehand", "contact_scan", "contact_scan_online")
"""Scenarios whose loop amplifies rounding (measured: the pure path's own metrics move by up to
2e-4 relative for a one-ulp change of q0 over 30 s of contact_scan; clinical_assisted is a scan
of the same kind on a breathing abdomen, whose image-plane jitter, a few micrometres, moved by 0.15
relative between the two paths; clinical_freehand is that scan with the probe in the hand alone,
its lateral jitter, 0.02 µm, moved by 6e-11)."""


def _one_ulp_starts(name: str) -> list[tuple[str, ...]]:
    """Overrides that move the start by one unit in the last place, three ways: one joint angle
    of the arm's start pose, or for the freehand probe one coordinate of its start."""
    if name == "clinical_freehand":
        key, start, moves = "freehand.p_BT0_B", HOME_TIP_B, ((0, np.inf), (1, -np.inf), (2, np.inf))
    else:
        key, start, moves = "plant.arm.q0", HOME_Q, ((0, np.inf), (0, -np.inf), (1, np.inf))
    out = []
    for i, direction in moves:
        moved = start.copy()
        moved[i] = np.nextafter(moved[i], direction)
        out.append((f"{key}=[{', '.join(repr(x) for x in moved.tolist())}]",))
    return out


def _options(name: str) -> tuple[list[str], float | None]:
    args, overrides, duration = SHORT[name], [], None
    for flag, value in zip(args[::2], args[1::2], strict=True):
        if flag == "--duration":
            duration = float(value)
        else:
            overrides.append(value)
    return overrides, duration


def _metrics(name: str, compiled: bool, extra: tuple[str, ...] = ()) -> dict[str, float]:
    overrides, duration = _options(name)
    scenario = load_scenario(SCENARIOS / f"{name}.yaml", [*overrides, *extra], duration)
    with use_kernels(compiled):
        metrics = compute_report(scenario, simulate(scenario, "inprocess", progress=False)).metrics
    flat: dict[str, float] = {}
    for key, value in metrics.items():
        if key in ("wall_s", "realtime_factor") or isinstance(value, str | bool):
            continue
        for i, v in enumerate(np.atleast_1d(np.asarray(value, dtype=np.float64)).tolist()):
            flat[f"{key}[{i}]"] = v
    return flat


def _worst(a: dict[str, float], b: dict[str, float]) -> tuple[str, float]:
    assert a.keys() == b.keys()
    worst, name = 0.0, ""
    for key, x in a.items():
        y = b[key]
        if x == y or (math.isnan(x) and math.isnan(y)):
            continue
        rel = abs(x - y) / max(abs(x), abs(y), 1e-300)
        if rel > worst:
            worst, name = rel, key
    return name, worst


@pytest.mark.parametrize("name", sorted(set(SHORT) - set(AMPLIFYING)))
def test_metrics_match_the_pure_path(name):
    pure, compiled = _metrics(name, False), _metrics(name, True)
    assert pure, "no metric to compare"
    key, worst = _worst(pure, compiled)
    assert worst <= REL, f"{name}: {key} differs by {worst:.3g} relative"


@pytest.mark.parametrize("name", AMPLIFYING)
def test_where_the_loop_amplifies_rounding_the_difference_is_the_loops(name):
    pure = _metrics(name, False)
    spread = 0.0  # the most one ulp of the start moves the pure path's metrics
    for one_ulp in _one_ulp_starts(name):
        spread = max(spread, _worst(pure, _metrics(name, False, one_ulp))[1])
    key, worst = _worst(pure, _metrics(name, True))
    assert worst <= max(REL, 10.0 * spread), (
        f"{name}: {key} differs by {worst:.3g} relative; one ulp of the start moves the pure "
        f"path's metrics by {spread:.3g}"
    )
