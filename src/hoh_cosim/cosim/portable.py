"""An exported system in libcosim and ecos, in a host that never installed hoh-cosim.

`hoh-cosim export SCENARIO --out DIR --check --engines` adds to the FMUs' own check
(`hoh_cosim.fmi.hostcheck`): a clean virtual environment with the FMUs' declared requirements and
the engines (`libcosimpy`, `ecospy` with the TBB runtime it links), where a short script that knows
nothing of this project loads the exported SSP archive in each engine, steps it at the scenario's
base step and reads every output after every step. Our master runs the same scenario with each
engine's coupling (libcosim: Jacobi; ecos: Jacobi, exchanging after every base step;
`hoh_cosim.cosim.external`), and each FMU's outputs are compared, relative to each signal's peak.
"""

from __future__ import annotations

import importlib.metadata
import json
import os
import subprocess
import tempfile
from pathlib import Path

import numpy as np

from hoh_cosim.cosim import ENGINE_COUPLING, EXTERNAL_ENGINES
from hoh_cosim.cosim.engines import simulate
from hoh_cosim.cosim.external import PARAMETER_SET, system_of
from hoh_cosim.cosim.scenario import Scenario
from hoh_cosim.errors import RunError
from hoh_cosim.fmi.hostcheck import (
    CheckRow,
    declared_requirements,
    fmi_version,
    host_python,
    worst_difference,
)

__all__ = ["check_engines", "compared_rows"]

_ENGINE = r"""
import ctypes, json, sys
from pathlib import Path
import numpy as np

spec = json.loads(Path(sys.argv[1]).read_text())
engine, n, dt = spec["engine"], spec["steps"], spec["dt"]
reads = spec["reads"]  # [component, [variable names], [value references]]
values = np.full((n + 1, sum(len(r[1]) for r in reads)), np.nan)
if engine == "libcosim":
    from libcosimpy import CosimExecution, CosimLogging, CosimObserver

    CosimLogging.log_output_level(CosimLogging.CosimLogLevel.ERROR)
    execution = CosimExecution.CosimExecution.from_ssp_file(spec["ssp"])
    observer = CosimObserver.CosimObserver.create_last_value()
    execution.add_observer(observer)
    index = {info.name.decode(): info.index for info in execution.slave_infos()}
    for k in range(n):
        if not execution.step(1):
            raise SystemExit(f"libcosim: step {k} failed")
        offset = 0
        for component, names, refs in reads:
            values[k + 1, offset : offset + len(refs)] = observer.last_real_values(
                index[component], refs
            )
            offset += len(refs)
    execution.stop()
else:
    lib = Path(sys.prefix) / "lib" / "libtbb.so.12"  # ecospy links it and does not declare it
    if lib.is_file():
        ctypes.CDLL(str(lib), mode=ctypes.RTLD_GLOBAL)
    import ecospy
    from ecospy.lib import dll

    sim = ecospy.EcosSimulation(ssp_path=spec["ssp"], step_size=dt)
    if not sim.init(parameter_set=spec["parameter_set"]):
        raise SystemExit("ecos: initialisation failed")
    value = ctypes.c_double()
    ids = [f"{c}::{name}".encode() for c, names, _ in reads for name in names]

    def read(row):
        for i, identifier in enumerate(ids):
            if not dll.ecos_simulation_get_real(sim.sim, identifier, ctypes.byref(value)):
                raise SystemExit(f"ecos: reading {identifier.decode()} failed")
            row[i] = value.value

    read(values[0])
    for k in range(n):
        sim.step(1)
        read(values[k + 1])
    sim.terminate()
    sim.free()
np.save(spec["out"], values)
"""
"""Steps an SSP archive in libcosim or ecos and saves every output read after every step."""

_ENGINE_PACKAGES = ("libcosimpy", "ecospy", "tbb")


def _engine_packages() -> list[str]:
    return [f"{name}=={importlib.metadata.version(name)}" for name in _ENGINE_PACKAGES]


def check_engines(
    scenario: Scenario, export_dir: Path, cache: Path, tolerance: float = 1e-6
) -> list[CheckRow]:
    """The exported SSP of `scenario` (in `export_dir`) in libcosim and ecos in a clean
    environment, against our master with each engine's coupling: a row per engine and FMU."""
    if scenario.events:
        raise RunError(
            f"{scenario.path}: has events (parameter changes at a time), which an SSP archive "
            "cannot carry: the engines' check takes a scenario without them"
        )
    ssp = export_dir / f"{scenario.name}.ssp"
    fmus = sorted((export_dir / "fmus").glob("*.fmu"))
    packages = [*declared_requirements(fmus), _fmpy(), *_engine_packages()]
    python = host_python(packages, cache / "hosts")
    system = system_of(scenario, _kind_paths(scenario, export_dir))
    reads = [
        [c, system.outputs[c], [system.value_refs[c][v] for v in system.outputs[c]]]
        for c in scenario.components
    ]
    rows = []
    versions = {c: fmi_version(system.fmus[c]) for c in scenario.components}
    for engine in EXTERNAL_ENGINES:
        if engine == "libcosim" and set(versions.values()) != {"2.0"}:
            rows += [
                CheckRow(
                    engine,
                    system.fmus[c].stem,
                    versions[c],
                    True,
                    f"libcosim (libcosimpy {importlib.metadata.version('libcosimpy')}) loads "
                    "FMI 1.0 and 2.0 FMUs only (its issue 741)",
                    float("nan"),
                    skipped=True,
                )
                for c in scenario.components
            ]
            continue
        there = _run_engine(python, engine, ssp, scenario, reads)
        ours = simulate(
            scenario,
            "fmu",
            fmu_paths=_kind_paths(scenario, export_dir),
            progress=False,
            coupling=ENGINE_COUPLING[engine],
        )
        offset = 0
        for component, names, _ in reads:
            columns = slice(offset, offset + len(names))
            offset += len(names)
            fmu = system.fmus[component].stem
            if isinstance(there, str):
                rows.append(CheckRow(engine, fmu, versions[component], False, there, float("nan")))
                continue
            rows_ = compared_rows(engine, ours.values)
            worst = worst_difference(
                _structured(there[rows_, columns], names),
                _structured(ours.values[rows_, columns], names),
            )
            left = int((~rows_).sum())
            what = (
                f"{component}, {scenario.duration_s:g} s against our master "
                f"({ENGINE_COUPLING[engine]}), {left} of {len(rows_)} ticks left out"
            )
            rows.append(CheckRow(engine, fmu, versions[component], worst <= tolerance, what, worst))
    return rows


def compared_rows(engine: str, master: np.ndarray) -> np.ndarray:
    """The ticks (rows of our master's `values`) on which `engine` must agree with our master to
    rounding.

    libcosim shows no values before its first step: row 0 is left out. ecos's clock is a running
    sum of the base step, 2e-13 s behind k·dt after 3000 steps, so a switch that falls exactly on a
    whole second (the hand takes the handle at 3 s) comes one step of its component later there:
    the 4 ticks after a 0/1 output of our master switches are left out for ecos (measured: all
    differences lie within them, 2999-3002 on contact_scan)."""
    rows = np.ones(master.shape[0], dtype=bool)
    if engine == "libcosim":
        rows[0] = False
    if engine == "ecos":
        for column in master.T:
            if set(np.unique(column)) <= {0.0, 1.0}:
                for switch in np.nonzero(np.diff(column))[0] + 1:
                    rows[switch : switch + 5] = False
    return rows


def _fmpy() -> str:
    return f"fmpy=={importlib.metadata.version('fmpy')}"


def _fmus(scenario: Scenario, export_dir: Path) -> dict[str, Path]:
    manifest = json.loads((export_dir / "export.json").read_text())
    return {c: export_dir / entry["fmu"] for c, entry in manifest["components"].items()}


def _kind_paths(scenario: Scenario, export_dir: Path) -> dict[str, Path]:
    files = _fmus(scenario, export_dir)
    return {spec.kind.name: files[name] for name, spec in scenario.components.items()}


def _structured(values: np.ndarray, names: list[str]) -> np.ndarray:
    """Columns as `worst_difference` takes them (a time column, here the row)."""
    rows = values.shape[0]
    table = np.zeros(rows, dtype=[("time", float)] + [(n, float) for n in names])
    table["time"] = np.arange(rows)
    for i, name in enumerate(names):
        table[name] = values[:, i]
    return table


def _run_engine(
    python: Path, engine: str, ssp: Path, scenario: Scenario, reads: list
) -> np.ndarray | str:
    """The engine's outputs after every step, or what it said when it failed."""
    with tempfile.TemporaryDirectory(prefix=f"hoh-{engine}-") as tmp:
        spec = {
            "engine": engine,
            "ssp": str(ssp),
            "steps": scenario.n_ticks,
            "dt": scenario.dt_s,
            "reads": reads,
            "parameter_set": PARAMETER_SET,
            "out": str(Path(tmp) / "values.npy"),
        }
        (Path(tmp) / "spec.json").write_text(json.dumps(spec))
        env = {k: v for k, v in os.environ.items() if not k.startswith(("PYTHON", "HOH_COSIM"))}
        env["TMPDIR"] = tmp  # ecos unpacks the archive there and leaves it
        done = subprocess.run(
            [str(python), "-c", _ENGINE, str(Path(tmp) / "spec.json")],
            capture_output=True,
            text=True,
            timeout=1800,
            cwd=tmp,
            env=env,
        )
        out = Path(tmp) / "values.npy"
        if not out.is_file():  # ecos may die unloading the FMUs after a complete run: read it
            said = [line for line in (done.stderr + done.stdout).splitlines() if line.strip()]
            return (
                f"{engine} failed (exit {done.returncode}): {said[-1] if said else 'nothing said'}"
            )
        return np.load(out)
