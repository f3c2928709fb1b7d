"""Speed side by side: a reference commit against the working tree, interleaved in one run.

    python benchmarks/compare.py OLD_REF [--rounds 3] [--duration 10] [--cycles 30000]
                                         [--scenarios circles,contact_scan]
                                         [--sweep studies/slopes.yaml] [--report quick|full]
                                         [--workers 2]

This machine's speed drifts by 2x within minutes, so a speed figure means something only as a ratio
against the old code measured in the same minutes. OLD_REF is checked out into a temporary git
worktree; then, `--rounds` times, the same probe runs once for the old tree and once for the
working tree (old first in odd rounds, new first in even ones), each in a fresh Python process
whose `hoh_cosim` and `plant_models` are that tree's:

- stepping: each scenario for `--duration` simulated seconds with the inprocess and the fmu engine
  (FMUs built beforehand, from each tree's own source); the engine's own wall time of the stepping
  loop (`Recording.wall_s`), so imports, building and results are not counted;
- the controller cycle: `benchmarks/controller_cycle.py`'s `run` from each tree (`--cycles` cycles
  of Estimator + HandGuidingController), its p50 and p99.

- whole studies, when asked: `hoh-cosim sweep SWEEP --workers W` and `hoh-cosim report
  [--quick] --workers W`, each as its own command from the tree (its own local Dask cluster),
  the wall time from start to exit, so start-up, set-up, plots and tables count.

Per tree the best round counts (the machine's other load only ever slows a run down): the highest
real-time factor and the lowest percentile. The last line is one JSON object: `inprocess_speedup`
and `fmu_speedup` (new real-time factor over old, the geometric mean over the scenarios; > 1: the
new is faster), the same per scenario, and `controller_p99_ratio` and `controller_p50_ratio` (new
over old; < 1: the new is faster), with the figures they come from; with `--sweep` and
`--report`, `sweep_speedup` and `report_speedup` (old wall time over new: > 1, the new is faster).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
import textwrap
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

PROBE = textwrap.dedent(
    """
    import importlib.util, json, sys
    from pathlib import Path

    root, duration, cycles, scenarios = Path(sys.argv[1]), float(sys.argv[2]), int(sys.argv[3]), sys.argv[4]
    import hoh_cosim, plant_models
    for module in (hoh_cosim, plant_models):
        assert Path(module.__file__).resolve().is_relative_to(root.resolve()), module.__file__
    from hoh_cosim.cosim.engines import simulate
    from hoh_cosim.cosim.scenario import load_scenario

    figures = {"stepping": {}}
    for name in scenarios.split(","):
        path = root / "scenarios" / f"{name}.yaml"
        scenario = load_scenario(path, duration_s=duration)
        for engine in ("inprocess", "fmu"):
            # once briefly first: FMUs built, modules imported and warm
            simulate(load_scenario(path, duration_s=0.2), engine, progress=False)
            wall = simulate(scenario, engine, progress=False).wall_s
            figures["stepping"][f"{name}/{engine}"] = duration / wall
    spec = importlib.util.spec_from_file_location("cycle", root / "benchmarks" / "controller_cycle.py")
    cycle = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(cycle)
    result = cycle.run(cycles, 5)
    figures["controller_p50_us"] = result["p50_us"]
    figures["controller_p99_us"] = result["p99_us"]
    print(json.dumps(figures))
    """
)


def _probe(tree: Path, args: argparse.Namespace) -> dict:
    environment = _environment(tree)
    done = subprocess.run(
        [
            *(sys.executable, "-c", PROBE, str(tree)),
            *(str(args.duration), str(args.cycles), args.scenarios),
        ],
        capture_output=True,
        text=True,
        env=environment,
        cwd=tree,
    )
    if done.returncode != 0:
        raise SystemExit(f"compare: the probe failed in {tree}:\n{done.stderr[-3000:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def _environment(tree: Path) -> dict[str, str]:
    return {
        **os.environ,
        # both packages from the tree: the editable install's path comes after these
        "PYTHONPATH": os.pathsep.join([str(tree / "src"), str(tree)]),
        "HOH_COSIM_FMU_CACHE": str(tree / ".fmu-cache"),
    }


def _studies(tree: Path, args: argparse.Namespace) -> dict[str, float]:
    """Wall seconds of each whole-study command asked for, run from `tree`."""
    commands: dict[str, list[str]] = {}
    if args.sweep:
        commands["sweep"] = ["sweep", str(tree / args.sweep)]
    if args.report:
        commands["report"] = ["report", *(["--quick"] if args.report == "quick" else [])]
    walls = {}
    for name, command in commands.items():
        with tempfile.TemporaryDirectory(prefix=f"hoh-compare-{name}-") as out:
            start = time.perf_counter()
            done = subprocess.run(
                [
                    *(sys.executable, "-m", "hoh_cosim", *command, "--quiet"),
                    *("--workers", str(args.workers), "--out", str(Path(out) / name)),
                ],
                capture_output=True,
                text=True,
                env=_environment(tree),
                cwd=tree,
            )
            walls[name] = time.perf_counter() - start
        if done.returncode != 0:
            raise SystemExit(f"compare: {name} failed in {tree}:\n{done.stderr[-3000:]}")
    return walls


def _best(rounds: list[dict]) -> dict:
    stepping = {key: max(r["stepping"][key] for r in rounds) for key in rounds[0]["stepping"]}
    best = {
        "stepping": stepping,
        "controller_p50_us": min(r["controller_p50_us"] for r in rounds),
        "controller_p99_us": min(r["controller_p99_us"] for r in rounds),
    }
    for key in rounds[0]["studies_s"]:
        best[f"{key}_s"] = min(r["studies_s"][key] for r in rounds)
    return best


def _geometric_mean(values: list[float]) -> float:
    return math.exp(sum(math.log(v) for v in values) / len(values))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("old_ref", metavar="OLD_REF", help="a commit, branch or tag")
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--duration", type=float, default=10.0, help="simulated s per scenario")
    parser.add_argument("--cycles", type=int, default=30_000, help="controller cycles")
    parser.add_argument("--scenarios", default="circles,contact_scan")
    parser.add_argument("--sweep", help="also time `hoh-cosim sweep` of this file (in the tree)")
    parser.add_argument(
        "--report", choices=("quick", "full"), help="also time `hoh-cosim report [--quick]`"
    )
    parser.add_argument("--workers", type=int, default=2, help="Dask workers of the studies")
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="hoh-compare-") as tmp:
        old = Path(tmp) / "old"
        subprocess.run(
            [
                "git",
                "-C",
                str(ROOT),
                "worktree",
                "add",
                "--detach",
                "--quiet",
                str(old),
                args.old_ref,
            ],
            check=True,
        )
        try:
            runs: dict[str, list[dict]] = {"old": [], "new": []}
            for round_ in range(args.rounds):
                pair = [("old", old), ("new", ROOT)]
                for label, tree in pair if round_ % 2 == 0 else pair[::-1]:  # neither always first
                    figures = _probe(tree, args)
                    figures["studies_s"] = _studies(tree, args)
                    runs[label].append(figures)
                    steps = " ".join(f"{k} {v:.2f}x" for k, v in figures["stepping"].items())
                    studies = "".join(f"; {k} {v:.1f} s" for k, v in figures["studies_s"].items())
                    print(
                        f"round {round_ + 1} {label}: {steps}; controller p50 "
                        f"{figures['controller_p50_us']:.1f} / p99 {figures['controller_p99_us']:.1f} µs"
                        f"{studies}",
                        flush=True,
                    )
        finally:
            subprocess.run(
                ["git", "-C", str(ROOT), "worktree", "remove", "--force", str(old)], check=False
            )
    old_best, new_best = _best(runs["old"]), _best(runs["new"])
    ratios = {
        key: new_best["stepping"][key] / old_best["stepping"][key] for key in old_best["stepping"]
    }
    result: dict[str, object] = {"old_ref": args.old_ref, "rounds": args.rounds}
    for engine in ("inprocess", "fmu"):
        mine = [v for k, v in ratios.items() if k.endswith(f"/{engine}")]
        result[f"{engine}_speedup"] = round(_geometric_mean(mine), 3)
    result["speedups"] = {k: round(v, 3) for k, v in ratios.items()}
    for figure in ("p50", "p99"):
        key = f"controller_{figure}_us"
        result[f"controller_{figure}_ratio"] = round(new_best[key] / old_best[key], 3)
    for key in runs["old"][0]["studies_s"]:
        result[f"{key}_speedup"] = round(old_best[f"{key}_s"] / new_best[f"{key}_s"], 3)
    result["old"], result["new"] = old_best, new_best
    print(
        f"best of {args.rounds}: inprocess x{result['inprocess_speedup']}, fmu "
        f"x{result['fmu_speedup']}, controller p99 new/old {result['controller_p99_ratio']}"
    )
    print(json.dumps(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
