"""The hardware runner's timing in a rehearsal: cycle compute time and start jitter.

    python benchmarks/runner_timing.py [--seconds 60] [--rate 500] [--rt-priority 50|none]

Runs the real runner, drivers and session log for `--seconds` against the emulated UR5 (500 Hz, an
e-series), FT-150 stream and FSE103 (`hoh-cosim hw rehearse`), the operator drawing circles, and
prints per cycle the compute time (state read to command sent, logging included) and the start
jitter (how late each cycle began), as p50, p99, p99.9 and max, with the overruns (cycles that began
more than a period late). Target: p99 jitter <= 0.5 ms and no overruns.

The emulators share this machine's cores with the runner (on a rig they are separate hardware), so
they run above it where the system permits (`hoh_cosim.rehearsal.priorities`); `--rt-priority`
gives the loop and its readers SCHED_FIFO, as a rig's configuration would
(`robot.realtime_priority`); without the right to it the run says so and goes on without.

To tell the runner's delays from the machine's, the same pacing (same period, same priority) also
runs bare for `--baseline` seconds, doing nothing but wait for each cycle: a virtual machine whose
host takes its cores away now and then shows overruns there too. The last line is the figures as
one JSON object.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

from hoh_cosim.rehearsal.rehearse import Rehearsal, rehearse


def bare_pacing(seconds: float, period_s: float, priority: int | None) -> dict[str, float]:
    """The pacer alone: how late cycles start when nothing else is done."""
    import os

    import numpy as np

    from hoh_cosim.hardware.robot import Pacer

    if priority is not None:
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
        except (OSError, AttributeError):
            priority = None
    pacer = Pacer(period_s)
    late = np.array([pacer.wait() for _ in range(round(seconds / period_s))])
    if priority is not None:
        os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
    return {
        "baseline_overruns": pacer.overruns,
        "baseline_jitter_p99_ms": float(1e3 * np.percentile(late, 99)),
        "baseline_jitter_max_ms": float(1e3 * late.max()),
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=60.0)
    parser.add_argument("--rate", type=float, default=500.0, choices=(125.0, 500.0))
    parser.add_argument("--rt-priority", default="50", help="a priority, or 'none'")
    parser.add_argument("--rebias-samples", type=int, default=200)
    parser.add_argument(
        "--baseline", type=float, default=30.0, metavar="S", help="seconds of bare pacing (0: none)"
    )
    args = parser.parse_args(argv)
    priority = None if args.rt_priority == "none" else int(args.rt_priority)
    notes: list[str] = []
    with tempfile.TemporaryDirectory(prefix="hoh-timing-") as tmp:
        setup = Rehearsal(
            seconds=args.seconds,
            log_path=Path(tmp) / "timing.mcap",
            robot_rate_hz=args.rate,
            rebias_samples=args.rebias_samples,
            realtime_priority=priority,
        )
        result = rehearse(
            setup,
            announce=lambda message: notes.append(message) if message.startswith("note") else None,
        )
    session = result.session
    figures = session.timing.summary()
    for note in notes:
        print(note)
    print(
        f"rehearsal at {args.rate:g} Hz for {args.seconds:g} s, real-time priority "
        f"{'refused' if notes else priority}: {session.cause}"
    )
    print(session.timing.report())
    baseline = bare_pacing(args.baseline, 1.0 / args.rate, priority) if args.baseline > 0 else {}
    if baseline:
        print(
            f"bare pacing for {args.baseline:g} s: {baseline['baseline_overruns']} overruns, "
            f"jitter p99 {baseline['baseline_jitter_p99_ms']:.3f} / max "
            f"{baseline['baseline_jitter_max_ms']:.3f} ms"
        )
    out = {
        "seconds": args.seconds,
        "rate_hz": args.rate,
        "realtime_priority": None if notes else priority,
        "ended": session.cause,
        **{k: round(v, 4) for k, v in figures.items()},
        **{k: round(v, 4) for k, v in baseline.items()},
    }
    print(json.dumps(out))
    return 0 if session.clean else 1


if __name__ == "__main__":
    sys.exit(main())
