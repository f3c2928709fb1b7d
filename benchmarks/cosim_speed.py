"""How fast the co-simulation runs: real-time factors and the master's own cost per step.

    python benchmarks/cosim_speed.py [--duration 30] [--steps 20000] [--repeats 3]

1. `scenarios/circles.yaml` for `--duration` simulated seconds with each engine: the real-time
   factor (simulated / wall-clock seconds) of the stepping loop, FMUs already built. Targets on the
   2-core reference machine: fmu >= 5x, inprocess >= 15x.
2. The master's overhead: four trivial pass-through Python FMUs (pythonfmu, through the same
   adapter as ours, y = u on one Real) chained one after another and stepped `--steps` times by the fmu
   engine: microseconds per master step for all four. Target <= 30 µs. For comparison the same four
   FMUs through fmpy's high-level `setReal` / `doStep` / `getReal` calls, measured here too.

The best of `--repeats` runs is reported (the machine's other load only ever slows a run down). The
last line is the figures as one JSON object.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import platform
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from hoh_cosim.cosim.engines import simulate
from hoh_cosim.cosim.scenario import ComponentSpec, Connection, Scenario, load_scenario
from hoh_cosim.fmi import exit_fix
from hoh_cosim.fmi.build import build_fmu, ensure_fmus
from hoh_cosim.kinds import ComponentKind

ROOT = Path(__file__).resolve().parents[1]
N_TRIVIAL = 4

TRIVIAL_SCRIPT = '''\
"""A trivial pass-through FMU for measuring the master: y = u."""
from dataclasses import dataclass
from typing import ClassVar

from hoh_cosim.control.block import Port
from hoh_cosim.fmi.slave import BlockSlave as Fmi2Slave
from hoh_cosim.fmi.slave import pin_namespace

pin_namespace(globals())


@dataclass(frozen=True)
class PassParams:
    pass


class PassThrough:
    inputs: ClassVar = (Port("u", 1, "1", "input"),)
    outputs: ClassVar = (Port("y", 1, "1", "the input, unchanged"),)

    def __init__(self, params=None):
        self.params = params

    def reset(self):
        pass

    def step(self, t, dt, inputs):
        return {"y": inputs["u"]}


class {name}(Fmi2Slave):
    block = PassThrough
    params = PassParams
'''


def best_wall(run, repeats: int) -> float:
    return min(run() for _ in range(repeats))


def circles_rtf(engine: str, duration: float, repeats: int) -> tuple[float, float]:
    scenario = load_scenario(ROOT / "scenarios" / "circles.yaml", duration_s=duration)

    def run() -> float:
        return simulate(scenario, engine, progress=False).wall_s

    wall = best_wall(run, repeats)
    return duration / wall, wall


def build_trivial(directory: Path) -> tuple[list[Path], type, type]:
    paths = []
    module = None
    for i in range(N_TRIVIAL):
        name = f"PassThrough{i + 1}"
        script = directory / f"pass_through_{i + 1}.py"
        script.write_text(TRIVIAL_SCRIPT.replace("{name}", name))
        if module is None:  # the master's side needs the block's ports: the same class
            spec = importlib.util.spec_from_file_location("pass_through_ports", script)
            module = importlib.util.module_from_spec(spec)
            spec.loader.exec_module(module)
        out = directory / f"{name}.fmu"
        build_fmu(script, out, module.PassThrough, module.PassParams, "y = u")
        paths.append(out)
    return paths, module.PassThrough, module.PassParams


def trivial_scenario(block: type, params: type, steps: int, paths: list[Path]) -> Scenario:
    components = {}
    for i, path in enumerate(paths):
        kind = ComponentKind(f"pass{i + 1}", block, params, path.stem, "y = u")
        components[kind.name] = ComponentSpec(kind.name, kind, 1, params(), i, path)
    names = list(components)
    connections = tuple(
        Connection(names[i], "y", (0,), names[i + 1], "u", (0,)) for i in range(len(names) - 1)
    )
    return Scenario(
        path=Path("trivial.yaml"),
        name="trivial",
        description="four pass-through FMUs in a chain, the first fed a constant 1",
        duration_s=steps * 1e-3,
        dt_s=1e-3,
        seed=0,
        metrics="none",
        components=components,
        connections=connections,
        input_defaults={(names[0], "u"): np.array([1.0])},
        events=(),
        record=(),
    )


def master_overhead_us(scenario: Scenario, steps: int, repeats: int) -> float:
    def run() -> float:
        return simulate(scenario, "fmu", progress=False).wall_s

    return 1e6 * best_wall(run, repeats) / steps


def fmpy_high_level_us(paths: list[Path], steps: int, repeats: int) -> float:
    """The same four FMUs through fmpy's FMU2Slave calls, one value each, the way a script would."""
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave

    exit_fix.install()  # freeInstance() unloads pythonfmu's library: see hoh_cosim.fmi.exit_fix

    slaves = []
    for i, path in enumerate(paths):
        md = read_model_description(str(path))
        fmu = FMU2Slave(
            guid=md.guid,
            unzipDirectory=extract(str(path)),
            modelIdentifier=md.coSimulation.modelIdentifier,
            instanceName=f"hl{i}",
        )
        fmu.instantiate()
        fmu.setupExperiment(startTime=0.0)
        fmu.enterInitializationMode()
        fmu.exitInitializationMode()
        vrs = {v.name: v.valueReference for v in md.modelVariables}
        slaves.append((fmu, [vrs["u"]], [vrs["y"]]))

    def run() -> float:
        values = [0.0] * len(slaves)
        start = time.perf_counter()
        for k in range(steps):
            t = k * 1e-3
            for j, (fmu, u, y) in enumerate(slaves):
                fmu.setReal(u, [values[j - 1]])
                fmu.doStep(t, 1e-3)
                values[j] = fmu.getReal(y)[0]
        return time.perf_counter() - start

    try:
        return 1e6 * best_wall(run, repeats) / steps
    finally:
        for fmu, _, _ in slaves:
            fmu.terminate()
            fmu.freeInstance()


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=30.0, help="simulated s of circles")
    parser.add_argument("--steps", type=int, default=20_000, help="master steps, trivial FMUs")
    parser.add_argument("--repeats", type=int, default=3, help="runs per figure; the best counts")
    args = parser.parse_args(argv)

    ensure_fmus(["operator", "plant", "ft150", "fse103", "estimator", "controller"])
    fmu_rtf, fmu_wall = circles_rtf("fmu", args.duration, args.repeats)
    inprocess_rtf, inprocess_wall = circles_rtf("inprocess", args.duration, args.repeats)
    with tempfile.TemporaryDirectory(prefix="hoh-bench-") as tmp:
        paths, block, params = build_trivial(Path(tmp))
        scenario = trivial_scenario(block, params, args.steps, paths)
        master_us = master_overhead_us(scenario, args.steps, args.repeats)
        high_level_us = fmpy_high_level_us(paths, args.steps, args.repeats)
        rec = simulate(scenario, "fmu", progress=False)
        # the 1 went through all four FMUs
        assert rec[f"pass{N_TRIVIAL}.y"][-1, 0] == 1.0, "the pass-through chain did not pass"

    print(f"python {platform.python_version()} on {platform.machine()}, best of {args.repeats}")
    print(f"circles.yaml, {args.duration:g} s simulated:")
    print(f"  fmu engine        {fmu_rtf:6.1f}x real time  ({fmu_wall:.2f} s)   target >= 5x")
    print(
        f"  inprocess engine  {inprocess_rtf:6.1f}x real time  ({inprocess_wall:.2f} s)   target >= 15x"
    )
    print(f"{N_TRIVIAL} trivial pass-through FMUs, {args.steps} steps:")
    print(f"  hoh-cosim master  {master_us:6.1f} µs per step   target <= 30 µs")
    print(f"  fmpy high-level   {high_level_us:6.1f} µs per step")
    figures = {
        "duration_s": args.duration,
        "fmu_realtime_factor": round(fmu_rtf, 2),
        "inprocess_realtime_factor": round(inprocess_rtf, 2),
        "trivial_fmus": N_TRIVIAL,
        "steps": args.steps,
        "master_us_per_step": round(master_us, 2),
        "fmpy_high_level_us_per_step": round(high_level_us, 2),
    }
    print(json.dumps(figures))
    return 0


if __name__ == "__main__":
    sys.exit(main())
