"""The test suite on a busy machine: does it stay green, and how long does it take?

    python benchmarks/loaded_suite.py [--runs 5] [--hogs 2] [-- PYTEST ARGS]

Runs the whole suite (`python -m pytest`, as the README's second command does, with any PYTEST
ARGS after `--`) `--runs` times, one after the other, while `--hogs` busy processes (0: none, a
quiet machine) run at the default priority for the whole time, as a build or another job beside
the suite would. Per run it prints pytest's closing line and the wall time; then how many runs
were green, the slowest and the quickest. The last line is the figures as one JSON object. Exit
status 1 when any run failed.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CLOSING = re.compile(r"^=* ?(\d+ (passed|failed).*?) ?=*$", re.M)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=5)
    parser.add_argument("--hogs", type=int, default=2, help="busy processes (default: 2)")
    parser.add_argument("pytest_args", nargs="*", help="after --: passed on to pytest")
    args = parser.parse_args(argv)
    hogs = [
        subprocess.Popen([sys.executable, "-S", "-c", "while True: pass"]) for _ in range(args.hogs)
    ]
    print(f"{len(hogs)} busy processes on {os.cpu_count()} cores; {args.runs} suite runs")
    # a suite of its own, also when this script runs under pytest-xdist
    env = {k: v for k, v in os.environ.items() if not k.startswith("PYTEST_")}
    rows = []
    try:
        for run in range(args.runs):
            start = time.monotonic()
            done = subprocess.run(
                [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", *args.pytest_args],
                cwd=ROOT,
                env=env,
                capture_output=True,
                text=True,
                check=False,
            )
            wall = time.monotonic() - start
            closing = CLOSING.findall(done.stdout)
            line = closing[-1][0] if closing else f"exit {done.returncode}, no closing line"
            rows.append({"run": run, "exit": done.returncode, "wall_s": round(wall, 1)})
            print(
                f"run {run}: exit {done.returncode}, {wall / 60:.0f} min {wall % 60:.0f} s: {line}"
            )
            if done.returncode:
                failed = [s for s in done.stdout.splitlines() if s.startswith(("FAILED", "ERROR"))]
                print("\n".join(f"  {s}" for s in failed))
    finally:
        for hog in hogs:
            hog.kill()
            hog.wait()
    walls = [r["wall_s"] for r in rows]
    green = sum(r["exit"] == 0 for r in rows)
    print(f"green {green} of {len(rows)}; wall {min(walls):.0f}-{max(walls):.0f} s")
    print(json.dumps({"hogs": len(hogs), "green": green, "runs": rows}))
    return 0 if green == len(rows) else 1


if __name__ == "__main__":
    sys.exit(main())
