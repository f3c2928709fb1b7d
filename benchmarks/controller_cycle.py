"""Cost of one control cycle: Estimator.step + HandGuidingController.step.

    python benchmarks/controller_cycle.py [--cycles N] [--packet-every K] [--new-laws]
                                          [--clock wall|cpu]

100 000 cycles at a 1 kHz tick with all three filters running and a packet from both sensors every 5
ticks (the worst case: on those ticks all three Kalman filters correct). The operator pushes in a slow
circle so the law, the clamps and the filters all do real work. Prints p50, p99, p99.9 and the max in
microseconds, then the same figures as one JSON object on the last line.

`--new-laws` times the issue-22 pieces (the lead_lowpass filter, the variable law, release detection
and the passivity controller) against the defaults, alternating in rounds so that both see the same
machine, and prints both, their ratios and the machine's load average. `--clock cpu` times each
cycle by this thread's processor time instead of the elapsed time: on a machine shared with other
jobs it shows what the code costs, where the elapsed time's tail shows the other jobs.

Target on the 2-core reference machine: p99 <= 100 µs, p99.9 <= 250 µs (a 500 Hz robot leaves 2000 µs a
cycle).
"""

from __future__ import annotations

import argparse
import dataclasses
import gc
import json
import os
import platform
import time
from typing import Any

import numpy as np

from hoh_cosim.control.controller import ControllerParams, HandGuidingController
from hoh_cosim.control.estimator import Estimator, EstimatorParams
from hoh_cosim.control.frames import R_BS_EQ1, R_SP_SEED
from hoh_cosim.control.gravity import SEED_TOOL, tool_weight_wrench_S

DT = 1e-3


def make_inputs(cycles: int, packet_every: int, rng: np.random.Generator) -> list[dict]:
    """Every tick's estimator inputs, made before timing starts."""
    weight = tool_weight_wrench_S(R_BS_EQ1, SEED_TOOL)
    R_BP = R_BS_EQ1 @ R_SP_SEED
    inputs, wrench, force_P, counter = [], weight.copy(), np.zeros(3), 0.0
    for k in range(cycles):
        if k % packet_every == 0:
            counter += 1.0
            t = k * DT
            hand_B = 6.0 * np.array([np.cos(0.5 * t), np.sin(0.5 * t), 0.2])
            wrench = weight + np.concatenate([R_BS_EQ1.T @ hand_B, rng.normal(0, 0.02, 3)])
            wrench[:3] += rng.normal(0.0, 0.3, 3)
            force_P = R_BP.T @ np.array([0.0, 0.0, 0.5]) + rng.normal(0.0, 0.05, 3)
        inputs.append(
            {
                "wrench_S": wrench.copy(),
                "ft_counter": np.array([counter]),
                "force_P": force_P.copy(),
                "probe_counter": np.array([counter]),
                "R_BS": R_BS_EQ1.reshape(9).copy(),
            }
        )
    return inputs


def new_laws() -> tuple[EstimatorParams, ControllerParams]:
    """The issue-22 pieces, all on."""
    from hoh_cosim.control.admittance import TRANSLATION_GAINS
    from hoh_cosim.control.passivity import PassivityParams
    from hoh_cosim.control.release import ReleaseParams

    return (
        EstimatorParams(ft_rebias_packets=0, probe_rebias_packets=0, filter="lead_lowpass"),
        ControllerParams(
            translation=dataclasses.replace(TRANSLATION_GAINS, law="variable"),
            release=ReleaseParams(enabled=True),
            passivity=PassivityParams(enabled=True),
        ),
    )


CLOCKS = {"wall": time.perf_counter_ns, "cpu": time.thread_time_ns}
"""wall: the time a cycle took; cpu: the processor time this thread spent on it, which leaves out
the time the other jobs of a busy machine had the processor (not their effect on the caches)."""


def durations_us(
    cycles: int,
    packet_every: int,
    params: tuple[EstimatorParams, ControllerParams] | None = None,
    clock_name: str = "wall",
) -> np.ndarray:
    """Each cycle's duration [µs] on `clock_name`'s clock: the defaults, or the given parameters."""
    if params is None:
        params = (EstimatorParams(ft_rebias_packets=0, probe_rebias_packets=0), ControllerParams())
    estimator = Estimator(params[0])
    controller = HandGuidingController(params[1])
    inputs = make_inputs(cycles, packet_every, np.random.default_rng(1))
    p_BT_B = np.array([0.3, 0.0, 0.3])
    durations = np.empty(cycles, dtype=np.int64)
    clock = CLOCKS[clock_name]
    gc.collect()
    gc.freeze()  # what a real-time loop does after set-up: no GC pass walks the set-up objects
    for k in range(cycles):
        t = k * DT
        start = clock()
        est = estimator.step(t, DT, inputs[k])
        est["p_BT_B"] = p_BT_B
        controller.step(t, DT, est)
        durations[k] = clock() - start
    gc.unfreeze()
    return durations / 1000.0


def summary(us: np.ndarray, cycles: int, packet_every: int) -> dict[str, float]:
    return {
        "cycles": cycles,
        "packet_every": packet_every,
        "p50_us": round(float(np.percentile(us, 50)), 2),
        "p99_us": round(float(np.percentile(us, 99)), 2),
        "p99_9_us": round(float(np.percentile(us, 99.9)), 2),
        "max_us": round(float(us.max()), 2),
        "python": platform.python_version(),
        "numpy": np.__version__,
    }


def run(cycles: int, packet_every: int, clock_name: str = "wall") -> dict[str, float]:
    return summary(durations_us(cycles, packet_every, clock_name=clock_name), cycles, packet_every)


def compare_new_laws(
    cycles: int, packet_every: int, rounds: int = 4, clock_name: str = "wall"
) -> dict[str, Any]:
    """The defaults and the new laws in alternating rounds of cycles / rounds each, and the
    machine's load average (1 min) before and after: a percentile means little on a busy machine."""
    per = max(1, cycles // rounds)
    old, new = [], []
    load_before = os.getloadavg()[0]
    for _ in range(rounds):
        old.append(durations_us(per, packet_every, clock_name=clock_name))
        new.append(durations_us(per, packet_every, new_laws(), clock_name))
    a = summary(np.concatenate(old), per * rounds, packet_every)
    b = summary(np.concatenate(new), per * rounds, packet_every)
    return {
        "defaults": a,
        "new_laws": b,
        "ratio_p50": round(b["p50_us"] / a["p50_us"], 3),
        "ratio_p99": round(b["p99_us"] / a["p99_us"], 3),
        "ratio_p99_9": round(b["p99_9_us"] / a["p99_9_us"], 3),
        "load_average": [round(load_before, 2), round(os.getloadavg()[0], 2)],
        "clock": clock_name,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cycles", type=int, default=100_000)
    parser.add_argument("--packet-every", type=int, default=5)
    parser.add_argument("--new-laws", action="store_true", help="the new laws against the defaults")
    parser.add_argument(
        "--clock",
        choices=sorted(CLOCKS),
        default="wall",
        help="wall: elapsed time (the default); cpu: this thread's processor time",
    )
    args = parser.parse_args()
    if args.new_laws:
        both = compare_new_laws(args.cycles, args.packet_every, clock_name=args.clock)
        for name in ("defaults", "new_laws"):
            r = both[name]
            print(
                f"{name:>9}: p50 {r['p50_us']:.2f} / p99 {r['p99_us']:.2f} / "
                f"p99.9 {r['p99_9_us']:.2f} / max {r['max_us']:.2f} µs"
            )
        print(
            f"new/defaults: p50 {both['ratio_p50']}x, p99 {both['ratio_p99']}x, "
            f"p99.9 {both['ratio_p99_9']}x (load average {both['load_average'][0]} before, "
            f"{both['load_average'][1]} after)"
        )
        print(json.dumps(both))
        return
    result = run(args.cycles, args.packet_every, args.clock)
    print(f"{result['cycles']} cycles, a packet from both sensors every {args.packet_every} ticks")
    for key in ("p50_us", "p99_us", "p99_9_us", "max_us"):
        print(f"  {key[:-3]:>6}: {result[key]:8.2f} µs")
    print(json.dumps(result))


if __name__ == "__main__":
    main()
