"""Speed side by side: a reference commit against the working tree, interleaved in one run.

    python benchmarks/compare.py OLD_REF [--rounds 3] [--duration 10] [--cycles 30000]
                                         [--scenarios circles,contact_scan] [--preset NAME]
                                         [--sweep studies/slopes.yaml] [--report quick|full]
                                         [--workers 2] [--runs]

This machine's speed drifts by 2x within minutes, so a speed figure means something only as a ratio
against the old code measured in the same minutes. OLD_REF is checked out into a temporary git
worktree; then, `--rounds` times, the same probe runs once for the old tree and once for the
working tree (old first in odd rounds, new first in even ones), each in a fresh Python process
whose `hoh_cosim` and `plant_models` are that tree's:

- stepping: each scenario for `--duration` simulated seconds with the inprocess and the fmu engine
  (FMUs built beforehand, from each tree's own source); the engine's own wall time of the stepping
  loop (`Recording.wall_s`), so imports, building and results are not counted;
- the controller cycle: `benchmarks/controller_cycle.py`'s `run` from each tree (`--cycles` cycles
  of Estimator + HandGuidingController), its p50 and p99; with `--preset`, the same cycle again
  with the preset's values (those that differ from the defaults, read from the working tree's
  preset and set on each tree's parameters; a field the old tree lacks stays at its default there,
  and the result names it), `preset_p50_ratio` and `preset_p99_ratio` in the result.

- whole studies, when asked: `hoh-cosim sweep SWEEP --workers W` and `hoh-cosim report
  [--quick] --workers W`, each as its own command from the tree (its own local Dask cluster),
  the wall time from start to exit, so start-up, set-up, plots and tables count.

- the report's runs, when asked (`--runs`): a mix of the full report's two kinds of run in its
  proportions (circles 30 s and static_noise 15 s, five filter settings), through the tree's own
  `run_variant`, stepped by one process alone, by two processes at once (each the whole mix) and
  twice over by a two-worker Dask cluster as the tree's studies start it; per way the wall time
  and the CPU seconds a mix takes (with Dask, of every process of the cluster). A study's ratio is
  its runs' ratio on two cores, so this says where it goes: the runs themselves (alone), two
  processes sharing the machine (two), or the cluster's own work (dask).

Per tree the best round counts (the machine's other load only ever slows a run down): the highest
real-time factor and the lowest percentile. The last line is one JSON object: `inprocess_speedup`
and `fmu_speedup` (new real-time factor over old, the geometric mean over the scenarios; > 1: the
new is faster), the same per scenario, and `controller_p99_ratio` and `controller_p50_ratio` (new
over old; < 1: the new is faster), with the figures they come from; with `--sweep` and
`--report`, `sweep_speedup` and `report_speedup` (old wall time over new: > 1, the new is faster);
with `--runs`, `runs_alone_speedup`, `runs_two_speedup` and `runs_dask_speedup` (old wall time
over new), the same in CPU time (`runs_*_cpu_speedup`), and per tree
`runs_two_cpu_inflation_old|new` (CPU time a mix takes two at once over alone: > 1, two processes
slow each other).
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
    import numpy as np
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
    changes = json.loads(sys.argv[5])
    if changes:
        # the preset's values on this tree's parameters, where this tree has the field
        import dataclasses

        def changed(obj, path, value):
            head, _, rest = path.partition(".")
            if not dataclasses.is_dataclass(obj) or not hasattr(obj, head):
                return obj, False
            if not rest:
                return dataclasses.replace(obj, **{head: value}), True
            inner, done = changed(getattr(obj, head), rest, value)
            return dataclasses.replace(obj, **{head: inner}), done

        params = {
            "estimator": cycle.EstimatorParams(ft_rebias_packets=0, probe_rebias_packets=0),
            "controller": cycle.ControllerParams(),
        }
        missing = []
        for key, value in changes.items():
            block, _, path = key.partition(".")
            params[block], done = changed(params[block], path, value)
            if not done:
                missing.append(key)
        us = cycle.durations_us(cycles, 5, (params["estimator"], params["controller"]))
        figures["preset_p50_us"] = float(np.percentile(us, 50))
        figures["preset_p99_us"] = float(np.percentile(us, 99))
        figures["preset_missing"] = missing
    print(json.dumps(figures))
    """
)


RUNS_PROBE = textwrap.dedent(
    """
    import json, sys, time
    from pathlib import Path

    root, mode, mix = Path(sys.argv[1]), sys.argv[2], json.loads(sys.argv[3])
    import hoh_cosim, plant_models
    for module in (hoh_cosim, plant_models):
        assert Path(module.__file__).resolve().is_relative_to(root.resolve()), module.__file__
    from hoh_cosim.study import sweep
    from hoh_cosim.study.sweep import Variant, run_variant

    variants = [
        Variant(i, str(root / "scenarios" / name), tuple(sets), seed=seed, duration_s=duration)
        for i, (name, sets, seed, duration) in enumerate(mix)
    ]
    brief = [Variant(0, v.scenario, v.overrides, seed=v.seed, duration_s=0.2) for v in variants]


    def warm(mix):
        # as a worker is after its first runs: modules imported, kernels loaded, and
        # scipy.signal, which circles' metrics import at their first call
        import scipy.signal  # noqa: F401

        return [run_variant(v).ok for v in mix]


    if mode == "dask":
        import logging
        import os
        from distributed import Client, LocalCluster

        def cpu_s():
            return os.times()[0] + os.times()[1]  # this process's threads, user and system

        if hasattr(sweep, "RunPool"):  # the study's own cluster, as the report starts it
            pool = sweep.RunPool(workers=2, progress=False).__enter__()
            client, close = pool.client, pool.close
        else:  # the reference's: run_variants' local cluster
            cluster = LocalCluster(
                n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                dashboard_address=":0", silence_logs=logging.ERROR,
            )
            client = Client(cluster)
            def close():
                client.close()
                cluster.close()
        try:
            client.run(warm, brief)
            before, main = client.run(cpu_s), cpu_s()
            start = time.perf_counter()
            futures = [client.submit(run_variant, v, pure=False) for v in variants + variants]
            outcomes = client.gather(futures)
            wall = time.perf_counter() - start
            after, main = client.run(cpu_s), cpu_s() - main
        finally:
            close()
        # every process of the cluster (the workers; the scheduler and nannies in this one)
        cpu = (sum(after[w] - before[w] for w in after) + main) / 2
    else:
        warm(brief)
        print("ready", flush=True)
        sys.stdin.readline()  # every process starts its runs at once
        start, cpu0 = time.perf_counter(), time.process_time()
        outcomes = [run_variant(v) for v in variants]
        wall, cpu = time.perf_counter() - start, time.process_time() - cpu0
    assert all(o.ok for o in outcomes), [o.error for o in outcomes if not o.ok]
    print(json.dumps({"wall_s": wall, "cpu_s": cpu}))
    """
)

RUN_MIX = [
    # the full report's two kinds of run, in its proportions of simulated time (circles 30 s:
    # 6390 s, static_noise 15 s: 3420 s): five of its filter settings, a run of each
    (scenario, sets, seed, duration)
    for sets in (
        [],
        ["estimator.hand_force_kalman.q=[0.1, 0.1, 0.1]"],
        ["estimator.filter=butterworth", "estimator.butterworth.cutoff_hz=5.0"],
        ["estimator.filter=one_euro", "estimator.one_euro_force.min_cutoff_hz=1.0"],
        ["estimator.filter=none"],
    )
    for scenario, seed, duration in (("static_noise.yaml", 1, 15.0), ("circles.yaml", None, 30.0))
]
RUN_MODES = ("alone", "two", "dask")


def _runs(tree: Path) -> dict[str, dict[str, float]]:
    """The run mix stepped from `tree` three ways: by one process alone; by two processes at
    once (each the whole mix); twice over by a two-worker Dask cluster (the study's own, with its
    settings). Per way the wall seconds and the CPU seconds per mix (with Dask, every process of
    the cluster counted)."""
    env, pipe = _environment(tree), subprocess.PIPE
    figures = {}
    for mode, processes in (("alone", 1), ("two", 2), ("dask", 1)):
        command = [sys.executable, "-c", RUNS_PROBE, str(tree), mode, json.dumps(RUN_MIX)]
        started = [
            subprocess.Popen(
                command, stdin=pipe, stdout=pipe, stderr=pipe, text=True, env=env, cwd=tree
            )
            for _ in range(processes)
        ]
        if mode != "dask":
            for p in started:  # all warm, then all go
                if p.stdout.readline().strip() != "ready":
                    raise SystemExit(f"compare: the run probe failed in {tree}:\n{p.stderr.read()}")
            for p in started:
                p.stdin.write("go\n")
                p.stdin.flush()
        outs = []
        for p in started:
            out, err = p.communicate()
            if p.returncode != 0:
                raise SystemExit(f"compare: the run probe failed in {tree}:\n{err[-3000:]}")
            outs.append(json.loads(out.strip().splitlines()[-1]))
        figures[mode] = {
            "wall_s": max(o["wall_s"] for o in outs),
            "cpu_s": sum(o["cpu_s"] for o in outs) / len(outs),
        }
    return figures


def _probe(tree: Path, args: argparse.Namespace) -> dict:
    environment = _environment(tree)
    done = subprocess.run(
        [
            *(sys.executable, "-c", PROBE, str(tree)),
            *(str(args.duration), str(args.cycles), args.scenarios),
            json.dumps(_preset_changes(args.preset)),
        ],
        capture_output=True,
        text=True,
        env=environment,
        cwd=tree,
    )
    if done.returncode != 0:
        raise SystemExit(f"compare: the probe failed in {tree}:\n{done.stderr[-3000:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def _preset_changes(name: str | None) -> dict[str, object]:
    """The working tree's preset `name` as the values that differ from the defaults (dotted keys,
    JSON values): the same changes for both trees; {} without a preset."""
    if not name:
        return {}
    from hoh_cosim.presets import BLOCKS, changed_from, load_preset

    preset = load_preset(name)
    changes = {}
    for block, cls in BLOCKS.items():
        for key, value in changed_from(cls(), preset.params[block]).items():
            changes[f"{block}.{key}"] = list(value) if isinstance(value, tuple) else value
    return changes


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
    if "preset_p99_us" in rounds[0]:
        best["preset_p50_us"] = min(r["preset_p50_us"] for r in rounds)
        best["preset_p99_us"] = min(r["preset_p99_us"] for r in rounds)
        best["preset_missing"] = rounds[0]["preset_missing"]
    for key in rounds[0]["studies_s"]:
        best[f"{key}_s"] = min(r["studies_s"][key] for r in rounds)
    if "runs" in rounds[0]:
        best["runs"] = {
            mode: {key: min(r["runs"][mode][key] for r in rounds) for key in ("wall_s", "cpu_s")}
            for mode in RUN_MODES
        }
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
    parser.add_argument(
        "--preset",
        help="also time the controller cycle with this preset's values (each tree, where it has "
        "the field)",
    )
    parser.add_argument("--sweep", help="also time `hoh-cosim sweep` of this file (in the tree)")
    parser.add_argument(
        "--report", choices=("quick", "full"), help="also time `hoh-cosim report [--quick]`"
    )
    parser.add_argument("--workers", type=int, default=2, help="Dask workers of the studies")
    parser.add_argument(
        "--runs",
        action="store_true",
        help="also step the report's run mix alone, two processes at once and on Dask",
    )
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
                    if args.runs:
                        figures["runs"] = _runs(tree)
                    runs[label].append(figures)
                    steps = " ".join(f"{k} {v:.2f}x" for k, v in figures["stepping"].items())
                    studies = "".join(f"; {k} {v:.1f} s" for k, v in figures["studies_s"].items())
                    studies += "".join(
                        f"; runs {mode} {m['wall_s']:.1f} s (CPU {m['cpu_s']:.1f} s a mix)"
                        for mode, m in figures.get("runs", {}).items()
                    )
                    print(
                        f"round {round_ + 1} {label}: {steps}; controller p50 "
                        f"{figures['controller_p50_us']:.1f} / p99 {figures['controller_p99_us']:.1f} µs"
                        + (
                            f"; with {args.preset} p50 {figures['preset_p50_us']:.1f} / p99 "
                            f"{figures['preset_p99_us']:.1f} µs"
                            if args.preset
                            else ""
                        )
                        + studies,
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
        if args.preset:
            key = f"preset_{figure}_us"
            result[f"preset_{figure}_ratio"] = round(new_best[key] / old_best[key], 3)
    for key in runs["old"][0]["studies_s"]:
        result[f"{key}_speedup"] = round(old_best[f"{key}_s"] / new_best[f"{key}_s"], 3)
    if args.runs:
        o, n = old_best["runs"], new_best["runs"]
        for mode in RUN_MODES:
            result[f"runs_{mode}_speedup"] = round(o[mode]["wall_s"] / n[mode]["wall_s"], 3)
            result[f"runs_{mode}_cpu_speedup"] = round(o[mode]["cpu_s"] / n[mode]["cpu_s"], 3)
        for label, best in (("old", o), ("new", n)):
            # > 1: a mix costs more CPU time when two processes step at once than alone
            result[f"runs_two_cpu_inflation_{label}"] = round(
                best["two"]["cpu_s"] / best["alone"]["cpu_s"], 3
            )
    result["old"], result["new"] = old_best, new_best
    print(
        f"best of {args.rounds}: inprocess x{result['inprocess_speedup']}, fmu "
        f"x{result['fmu_speedup']}, controller p99 new/old {result['controller_p99_ratio']}"
        + (
            f", with {args.preset} {result['preset_p99_ratio']} (fields the old tree lacks, "
            f"left at its defaults: {', '.join(old_best['preset_missing']) or 'none'})"
            if args.preset
            else ""
        )
    )
    print(json.dumps(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
