"""Fault-free rehearsals on a loaded machine: do they stop, and do the emulated devices keep their rates?

    python benchmarks/loaded_rehearsals.py [--runs 50] [--seconds 5] [--hogs-per-core 2]
                                           [--ur-emulator HOST] [--rt-priority P]

Runs `hoh-cosim hw rehearse --seconds S` `--runs` times, one after the other, while `--hogs-per-core`
busy processes per core (0: none) run at the default priority for the whole time, as a report or a
build beside a session would. A rehearsal has no fault: any stop is a spurious one. Per run it
prints how the session ended, the rates the rebias measured, and the rates and longest gaps of the
streams as the runner received them (from the session log); then the number of stops and the
lowest and highest of each figure. The last line is the figures as one JSON object. Exit status 1
when any run stopped.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
from pathlib import Path

REBIAS = re.compile(r"rebias done: FT-150 .*?, ([\d.]+) Hz; probe .*?, ([\d.]+) Hz")
ENDED = re.compile(r"^session ended: (.*)$", re.M)


def main(argv: list[str] | None = None) -> int:
    from hoh_cosim.hardware.session_log import read_session
    from hoh_cosim.rehearsal.campaign import stream_figures

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=50)
    parser.add_argument("--seconds", type=float, default=5.0)
    parser.add_argument("--hogs-per-core", type=int, default=2)
    parser.add_argument("--ur-emulator", metavar="HOST", default=None)
    parser.add_argument("--rt-priority", default=None, help="passed on to hw rehearse")
    args = parser.parse_args(argv)
    cores = os.cpu_count() or 1
    hogs = [
        subprocess.Popen([sys.executable, "-S", "-c", "while True: pass"])
        for _ in range(args.hogs_per_core * cores)
    ]
    print(
        f"{len(hogs)} busy processes on {cores} cores; {args.runs} rehearsals of {args.seconds:g} s"
    )
    rows = []
    try:
        with tempfile.TemporaryDirectory(prefix="hoh-loaded-") as tmp:
            for run in range(args.runs):
                log = Path(tmp) / f"run-{run}.mcap"
                command = [
                    *(sys.executable, "-m", "hoh_cosim", "hw", "rehearse"),
                    *("--seconds", f"{args.seconds:g}", "--log", str(log)),
                ]
                if args.ur_emulator:
                    command += ["--ur-emulator", args.ur_emulator]
                if args.rt_priority is not None:
                    command += ["--rt-priority", args.rt_priority]
                done = subprocess.run(command, capture_output=True, text=True, timeout=300)
                said = done.stdout + done.stderr
                ended = ENDED.search(said)
                rebias = REBIAS.search(said)
                streams = stream_figures(read_session(log)) if log.exists() else {}
                row = {
                    "run": run,
                    "status": done.returncode,
                    "ended": ended.group(1) if ended else said.strip().splitlines()[-1:],
                    "rebias_ft150_hz": float(rebias.group(1)) if rebias else None,
                    "rebias_fse103_hz": float(rebias.group(2)) if rebias else None,
                    **{f"{name}_hz": round(rate, 1) for name, (rate, _) in streams.items()},
                    **{f"{name}_gap_ms": round(1e3 * gap, 1) for name, (_, gap) in streams.items()},
                }
                rows.append(row)
                print(" ".join(f"{key} {value}" for key, value in row.items()), flush=True)
    finally:
        for hog in hogs:
            hog.kill()
            hog.wait()
    stops = [row for row in rows if row["status"] != 0]
    figures: dict[str, object] = {
        "runs": len(rows),
        "stops": len(stops),
        "busy_processes": len(hogs),
        "seconds": args.seconds,
    }
    for key in (
        "rebias_ft150_hz",
        "rebias_fse103_hz",
        "ft150_hz",
        "fse103_hz",
        "ft150_gap_ms",
        "fse103_gap_ms",
    ):
        values = [row[key] for row in rows if row.get(key) is not None]
        if values:
            figures[key] = [min(values), max(values)]
            print(f"{key}: lowest {min(values)}, highest {max(values)}")
    print(f"{len(stops)} of {len(rows)} rehearsals stopped")
    for row in stops:
        print(f"  run {row['run']}: {row['ended']}")
    print(json.dumps(figures))
    return 1 if stops else 0


if __name__ == "__main__":
    sys.exit(main())
