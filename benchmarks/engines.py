"""Our FMUs in other engines: real-time factors of libcosim and ecos next to our master's.

    python benchmarks/engines.py [--scenario scenarios/circles.yaml] [--duration 10] [--repeats 3]

The same six FMUs (built once, from the cache) run `--duration` simulated seconds of the scenario:
- `fmu`: our master, fmpy's raw FMI calls from the main thread, Gauss-Seidel;
- `fmu_jacobi`: our master with libcosim's coupling (a copy of the outputs per tick more);
- `libcosim`, `ecos`: the engines stepping the scenario as translated for them
  (`hoh_cosim.cosim.external`), with no output read back (their own speed), and `*_recorded` with
  every output read after every step as a run does.
Each figure is simulated over wall-clock seconds of the stepping loop, set-up excluded; the best of
`--repeats` is kept (other load only ever slows a run down). The last line is the figures as one
JSON object.
"""

from __future__ import annotations

import argparse
import json
import platform
from pathlib import Path

from hoh_cosim.cosim.engines import simulate
from hoh_cosim.cosim.external import simulate_external
from hoh_cosim.cosim.scenario import load_scenario
from hoh_cosim.fmi.build import ensure_fmus

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", default=str(ROOT / "scenarios" / "circles.yaml"))
    parser.add_argument("--duration", type=float, default=10.0)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    scenario = load_scenario(args.scenario, duration_s=args.duration)
    fmus = ensure_fmus(sorted({c.kind.name for c in scenario.components.values()}))

    runs = {
        "fmu": lambda: simulate(scenario, "fmu", fmu_paths=fmus, progress=False),
        "fmu_jacobi": lambda: simulate(
            scenario, "fmu", fmu_paths=fmus, progress=False, coupling="jacobi"
        ),
        "libcosim": lambda: simulate_external(scenario, "libcosim", fmu_paths=fmus, record=False),
        "libcosim_recorded": lambda: simulate_external(scenario, "libcosim", fmu_paths=fmus),
        "ecos": lambda: simulate_external(scenario, "ecos", fmu_paths=fmus, record=False),
        "ecos_recorded": lambda: simulate_external(scenario, "ecos", fmu_paths=fmus),
    }
    figures: dict[str, object] = {
        "scenario": scenario.name,
        "duration_s": args.duration,
        "components": len(scenario.components),
        "machine": f"{platform.machine()}, {platform.python_implementation()} "
        f"{platform.python_version()}",
    }
    print(f"{scenario.name}, {args.duration:g} s simulated, best of {args.repeats}:")
    for name, run in runs.items():
        wall = min(run().wall_s for _ in range(args.repeats))
        rtf = args.duration / wall
        figures[f"{name}_realtime_factor"] = round(rtf, 3)
        figures[f"{name}_us_per_tick"] = round(1e6 * wall / scenario.n_ticks, 1)
        print(f"  {name:<18} x{rtf:6.2f} real time   {1e6 * wall / scenario.n_ticks:7.1f} µs/tick")
    print(json.dumps(figures))


if __name__ == "__main__":
    main()
