"""How long the command line takes to start: `hoh-cosim --help`, and a scenario run's imports.

    python benchmarks/startup.py [--repeats 5]

1. `hoh-cosim --help` in a fresh process, wall time. Target on the 2-core reference machine: < 0.3 s.
2. The imports a scenario run needs before its first step (`hoh_cosim.cli` and what
   `hoh-cosim SCENARIO.yaml --engine inprocess` imports to load, build and step circles.yaml), in a
   fresh process: the wall time of those imports alone. Target: < 1 s.

Each is the best of `--repeats` fresh processes (the machine's other load only ever slows one
down). The last line is the figures as one JSON object.
"""

from __future__ import annotations

import argparse
import json
import platform
import subprocess
import sys
import time

# what a scenario run imports before it steps: the command line, the scenario loader and the
# registry (every block kind), the engines, metrics and results (plots come after the run)
RUN_IMPORTS = (
    "import time; t = time.perf_counter(); "
    "import hoh_cosim.cli, hoh_cosim.commands.cosim, hoh_cosim.cosim.run, hoh_cosim.cosim.engines, "
    "hoh_cosim.cosim.scenario, hoh_cosim.kinds, hoh_cosim.cosim.report; "
    "print(time.perf_counter() - t)"
)


def best_wall(command: list[str], repeats: int) -> float:
    best = float("inf")
    for _ in range(repeats):
        start = time.perf_counter()
        subprocess.run(command, check=True, capture_output=True)
        best = min(best, time.perf_counter() - start)
    return best


def best_imports(repeats: int) -> float:
    return min(
        float(
            subprocess.run(
                [sys.executable, "-c", RUN_IMPORTS], check=True, capture_output=True, text=True
            ).stdout
        )
        for _ in range(repeats)
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    helps = best_wall([sys.executable, "-m", "hoh_cosim", "--help"], args.repeats)
    python = best_wall([sys.executable, "-c", "pass"], args.repeats)
    imports = best_imports(args.repeats)
    print(f"python {platform.python_version()} on {platform.machine()}, best of {args.repeats}")
    print(f"  hoh-cosim --help      {helps:.3f} s   (the interpreter alone {python:.3f} s)")
    print(f"  a scenario's imports  {imports:.3f} s")
    print(
        json.dumps(
            {
                "help_s": round(helps, 4),
                "python_s": round(python, 4),
                "scenario_imports_s": round(imports, 4),
            }
        )
    )


if __name__ == "__main__":
    main()
