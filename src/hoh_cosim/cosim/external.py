"""A scenario run by co-simulation engines we did not write: OSP's libcosim and ecos.

The scenario is translated into each engine's own terms, from the same FMUs our master loads:
- libcosim (`libcosimpy`): an `OspSystemStructure.xml` with every component as a Simulator (its
  `stepSize` is `every · dt_s`), the parameters and the scenario's input values as InitialValues, one
  VariableConnection per connected element; the execution is created from that file and stepped with
  the fixed-step algorithm at the scenario's `dt_s`.
- ecos (`ecospy`): a simulation structure built by API calls, every model added with its step size as
  the step-size hint, one parameter set with the parameters and input values, one real connection per
  element; the simulation is stepped at `dt_s`.

Both engines couple their FMUs the Jacobi way, where our master is Gauss-Seidel in the file's order
(see `docs/decisions/0023-external-engines-coupling.md`): the FMUs due in a base step all step on
the values exchanged before it, and their outputs are exchanged after it, so every connection delays
by one step of its source. They differ for an FMU that steps every d > 1 base steps: libcosim
(`fixed_step_algorithm::impl::do_step`) passes its outputs on when its step ends, d base steps after
it began; ecos (`simulation::Impl::step`) exchanges every connection after every base step, so the
outputs at the step's end reach the others one base step after it began. Our master reproduces
either (`simulate(..., coupling="jacobi" | "jacobi-eager")`, `ENGINE_COUPLING`), so each engine is
checked to the last digits against our master with its coupling, and what the coupling alone
changes is our master's Gauss-Seidel run against its Jacobi run.

Every output of every component is read after every base step into the same `Recording` our master
makes, so metrics, plots and the comparison work on any engine's run. Scenario events (parameter
changes at a time) are applied between steps: ecos sets the variables, libcosim's override
manipulator holds them from then on.
"""

from __future__ import annotations

import contextlib
import ctypes
import math
import os
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any
from xml.etree import ElementTree as ET

import numpy as np

from hoh_cosim.cosim import ENGINE_COUPLING, EXTERNAL_ENGINES
from hoh_cosim.cosim.recording import Recording, recording_layout
from hoh_cosim.cosim.scenario import Scenario
from hoh_cosim.errors import ConfigError, RunError
from hoh_cosim.params import leaves

__all__ = [
    "ENGINE_COUPLING",
    "EXTERNAL_ENGINES",
    "FmiVariable",
    "System",
    "import_ecospy",
    "simulate_external",
    "system_of",
]

PARAMETER_SET = "scenario"  # the name of the one parameter set, in ecos and in an exported SSP

_INSTALL = 'install them with: pip install "hoh-cosim[engines]"'


@dataclass(frozen=True)
class FmiVariable:
    """One start value of one FMU instance: a parameter or an unconnected input."""

    name: str
    type: str  # Real, Integer, Boolean or String
    value: float | int | bool | str


@dataclass(frozen=True)
class System:
    """A scenario as FMI scalars: which FMU each component is, its start values, the element links
    and the outputs recorded, in the order of our master's `Recording`."""

    scenario: Scenario
    fmus: dict[str, Path]  # component -> .fmu
    start: dict[str, list[FmiVariable]]  # component -> parameters, seed and input values
    links: list[tuple[str, str, str, str]]  # (source, its output, destination, its input)
    outputs: dict[str, list[str]]  # component -> its output variables, in recording order
    value_refs: dict[str, dict[str, int]]  # component -> variable name -> value reference

    def step_size(self, component: str) -> float:
        return self.scenario.components[component].every * self.scenario.dt_s


_FMI2_TYPE = {"Float64": "Real", "Float32": "Real", "Int32": "Integer", "Int64": "Integer"}


def _fmi_value(var_type: str, value: Any) -> float | int | bool | str:
    return {"Real": float, "Integer": int, "Boolean": bool, "String": str}[var_type](value)


def system_of(scenario: Scenario, fmu_paths: dict[str, Path] | None = None) -> System:
    """The scenario's components, start values and links as the FMUs name them."""
    from fmpy import read_model_description

    components = list(scenario.components.values())
    if fmu_paths is None:
        from hoh_cosim.fmi.build import ensure_fmus

        fmu_paths = ensure_fmus(sorted({c.kind.name for c in components if c.fmu is None}))
    fmus = {c.name: c.fmu or fmu_paths[c.kind.name] for c in components}
    start: dict[str, list[FmiVariable]] = {}
    outputs: dict[str, list[str]] = {}
    value_refs: dict[str, dict[str, int]] = {}
    for c in components:
        try:
            md = read_model_description(str(fmus[c.name]))
        except Exception as exc:
            raise ConfigError(f"{fmus[c.name]}: cannot read the FMU: {exc}") from None
        # FMI 3.0's types under the names of FMI 2.0's (SSP 1.0 and the engines speak those)
        types = {v.name: _FMI2_TYPE.get(v.type, v.type) for v in md.modelVariables}
        value_refs[c.name] = {v.name: v.valueReference for v in md.modelVariables}
        values: list[FmiVariable] = []
        wanted = [(leaf.name, leaf.value) for leaf in leaves(c.params)]
        if "seed" in types:
            wanted.append(("seed", c.seed))
        for port in c.inputs:
            default = scenario.input_defaults.get((c.name, port.name))
            if default is not None:
                wanted += list(zip(port.element_names, map(float, default), strict=True))
        for name, value in wanted:
            if name not in types:
                raise ConfigError(
                    f"{fmus[c.name]}: has no variable {name!r}, which the scenario sets for {c.name}"
                )
            values.append(FmiVariable(name, types[name], _fmi_value(types[name], value)))
        start[c.name] = values
        outputs[c.name] = [n for p in c.outputs for n in p.element_names]
        missing = [n for n in outputs[c.name] if types.get(n) != "Real"]
        if missing:
            raise ConfigError(f"{fmus[c.name]}: has no Real output {missing[0]!r} ({c.name})")
    links = []
    for conn in scenario.connections:
        src_port = next(p for p in scenario.components[conn.src].outputs if p.name == conn.src_port)
        dst_port = next(p for p in scenario.components[conn.dst].inputs if p.name == conn.dst_port)
        for s, d in zip(conn.src_elements, conn.dst_elements, strict=True):
            links.append((conn.src, src_port.element_names[s], conn.dst, dst_port.element_names[d]))
    return System(scenario, fmus, start, links, outputs, value_refs)


# --- libcosim ---------------------------------------------------------------------------------

OSP_NAMESPACE = "http://opensimulationplatform.com/MSMI/OSPSystemStructure"


def xml_value(value: float | int | bool | str) -> str:
    """A start value as XML text: booleans in lower case, floats with every digit."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return repr(value)  # 17 significant digits: the value exactly
    return str(value)


def write_osp_system_structure(
    system: System, directory: Path, sources: dict[str, str] | None = None
) -> Path:
    """`OspSystemStructure.xml` for `system` in `directory`, the FMU of each component at
    `sources[component]` (relative to `directory`), by default its absolute file URI."""
    scenario = system.scenario
    root = ET.Element("OspSystemStructure", {"xmlns": OSP_NAMESPACE, "version": "0.1"})
    ET.SubElement(root, "StartTime").text = "0.0"
    ET.SubElement(root, "BaseStepSize").text = repr(scenario.dt_s)
    ET.SubElement(root, "Algorithm").text = "fixedStep"
    simulators = ET.SubElement(root, "Simulators")
    for name in scenario.components:
        simulator = ET.SubElement(
            simulators,
            "Simulator",
            {
                "name": name,
                "source": (
                    sources[name] if sources is not None else system.fmus[name].resolve().as_uri()
                ),
                "stepSize": repr(system.step_size(name)),
            },
        )
        initial = ET.SubElement(simulator, "InitialValues")
        for var in system.start[name]:
            node = ET.SubElement(initial, "InitialValue", {"variable": var.name})
            ET.SubElement(node, var.type, {"value": xml_value(var.value)})
    connections = ET.SubElement(root, "Connections")
    for src, src_var, dst, dst_var in system.links:
        link = ET.SubElement(connections, "VariableConnection")
        ET.SubElement(link, "Variable", {"simulator": src, "name": src_var})
        ET.SubElement(link, "Variable", {"simulator": dst, "name": dst_var})
    ET.indent(root, space="  ")
    path = directory / "OspSystemStructure.xml"
    ET.ElementTree(root).write(path, encoding="utf-8", xml_declaration=True)
    return path


def _import_libcosim() -> Any:
    try:
        from libcosimpy import CosimExecution, CosimLogging, CosimManipulator, CosimObserver
    except ImportError as exc:
        raise ConfigError(
            f"--engine libcosim: libcosimpy is not installed ({exc}); {_INSTALL}"
        ) from None
    CosimLogging.log_output_level(CosimLogging.CosimLogLevel.ERROR)
    return CosimExecution, CosimManipulator, CosimObserver


class _Libcosim:
    def __init__(self, system: System, workdir: Path, ssp: Path | None) -> None:
        CosimExecution, CosimManipulator, CosimObserver = _import_libcosim()
        from libcosimpy.CosimExecution import get_last_error_message

        self._error = get_last_error_message
        try:
            if ssp is not None:  # its base step comes from the archive's OSP annotation
                self.execution = CosimExecution.CosimExecution.from_ssp_file(str(ssp))
            else:
                config = write_osp_system_structure(system, workdir)
                self.execution = CosimExecution.CosimExecution.from_osp_config_file(
                    str(config.parent)
                )
        except AssertionError:  # libcosimpy's way of saying that creation failed
            raise RunError(f"libcosim cannot load the system: {self._error()}") from None
        self.observer = CosimObserver.CosimObserver.create_last_value()
        self.execution.add_observer(self.observer)
        self.override = CosimManipulator.CosimManipulator.create_override()
        self.execution.add_manipulator(self.override)
        self.index = {info.name.decode(): info.index for info in self.execution.slave_infos()}
        self.system = system
        self._reads = [
            (self.index[c], [system.value_refs[c][v] for v in system.outputs[c]])
            for c in system.scenario.components
        ]

    def read_initial(self, row: np.ndarray) -> None:
        """libcosim initialises its FMUs in the first step and shows no values before it."""
        row[:] = math.nan

    def read(self, row: np.ndarray) -> None:
        offset = 0
        for index, refs in self._reads:
            row[offset : offset + len(refs)] = self.observer.last_real_values(index, refs)
            offset += len(refs)

    def step(self) -> None:
        if not self.execution.step(1):
            raise RunError(f"libcosim: a step failed: {self._error()}")

    def set(self, component: str, values: list[FmiVariable]) -> None:
        """An override from now on: libcosim sets it before every later step of the FMU (our
        adapter then retunes the block each time, to the same values); resetting it would put the
        old value back."""
        index = self.index[component]
        refs = self.system.value_refs[component]
        setters = {
            "Real": self.override.slave_real_values,
            "Integer": self.override.slave_integer_values,
            "Boolean": self.override.slave_boolean_values,
            "String": self.override.slave_string_values,
        }
        for var in values:
            if not setters[var.type](index, [refs[var.name]], [var.value]):
                raise RunError(f"libcosim: setting {component}.{var.name} failed: {self._error()}")

    def close(self) -> None:
        with contextlib.suppress(Exception):
            self.execution.stop()
        # freed now, as ecos's simulation is below, while the interpreter that runs our Python
        # FMUs is whole: left to the garbage collector, the last references may go only at the
        # interpreter's shutdown, and the FMUs' instances with them (libcosimpy's __del__)
        self.execution = self.observer = self.override = None


# --- ecos -------------------------------------------------------------------------------------


def import_ecospy() -> Any:
    """`ecospy`, with the TBB runtime it links against (`libtbb.so.12`, from the `tbb` package,
    which ecospy does not declare) loaded first from this environment's `lib/`."""
    if "ecospy" not in sys.modules and sys.platform.startswith("linux"):
        for lib in (Path(sys.prefix) / "lib", Path(sys.base_prefix) / "lib"):
            if (lib / "libtbb.so.12").is_file():
                ctypes.CDLL(str(lib / "libtbb.so.12"), mode=ctypes.RTLD_GLOBAL)
                break
    try:
        import ecospy
    except (ImportError, OSError) as exc:
        raise ConfigError(f"--engine ecos: ecospy cannot be loaded ({exc}); {_INSTALL}") from None
    return ecospy


@contextlib.contextmanager
def _temporary_directory(directory: Path) -> Iterator[None]:
    """`TMPDIR` set to `directory` meanwhile (read by the C++ library's `temp_directory_path`)."""
    before = os.environ.get("TMPDIR")
    os.environ["TMPDIR"] = str(directory)
    try:
        yield
    finally:
        if before is None:
            del os.environ["TMPDIR"]
        else:
            os.environ["TMPDIR"] = before


class _Ecos:
    def __init__(self, system: System, workdir: Path, ssp: Path | None) -> None:
        ecospy = import_ecospy()
        from ecospy.lib import EcosLib, dll

        EcosLib.set_log_level("warn")
        self.system = system
        scenario = system.scenario
        structure = None
        try:
            if ssp is not None:  # ecos takes the base step from us, the FMUs' from the archive
                # ecos unpacks an archive under the system's temporary directory and never
                # removes it: under our work directory instead, which goes with the run
                with _temporary_directory(workdir):
                    self.sim = ecospy.EcosSimulation(ssp_path=str(ssp), step_size=scenario.dt_s)
            else:
                structure = ecospy.EcosSimulationStructure()
                for name in scenario.components:
                    structure.add_model(name, system.fmus[name], system.step_size(name))
                params = {f"{c}::{v.name}": v.value for c, vs in system.start.items() for v in vs}
                structure.add_parameter_set(PARAMETER_SET, params)
                for src, src_var, dst, dst_var in system.links:
                    structure.make_real_connection(f"{src}::{src_var}", f"{dst}::{dst_var}")
                self.sim = ecospy.EcosSimulation(structure=structure, step_size=scenario.dt_s)
        except Exception as exc:
            raise RunError(f"ecos cannot load the system: {exc}") from None
        self._structure = structure  # the simulation refers to it
        # ecos applies a parameter set only when it is named here
        if not self.sim.init(parameter_set=PARAMETER_SET):
            error = EcosLib.get_last_error()
            self.close()
            raise RunError(f"ecos: initialisation failed: {error}")
        self._error = EcosLib.get_last_error
        self._get_real = dll.ecos_simulation_get_real
        self._ids = [f"{c}::{v}".encode() for c in scenario.components for v in system.outputs[c]]
        self._value = ctypes.c_double()

    def read_initial(self, row: np.ndarray) -> None:
        self.read(row)

    def read(self, row: np.ndarray) -> None:
        sim, value, get = self.sim.sim, self._value, self._get_real
        ref = ctypes.byref(value)
        for i, identifier in enumerate(self._ids):
            if not get(sim, identifier, ref):
                raise RunError(f"ecos: reading {identifier.decode()} failed: {self._error()}")
            row[i] = value.value

    def step(self) -> None:
        self.sim.step(1)

    def set(self, component: str, values: list[FmiVariable]) -> None:
        setters = {
            "Real": self.sim.set_real,
            "Integer": self.sim.set_integer,
            "Boolean": self.sim.set_bool,
            "String": self.sim.set_string,
        }
        for var in values:
            setters[var.type](f"{component}::{var.name}", var.value)

    def close(self) -> None:
        with contextlib.suppress(Exception):
            self.sim.terminate()
        self.sim.free()
        if self._structure is not None:
            self._structure.free()


def simulate_external(
    scenario: Scenario,
    engine: str,
    *,
    fmu_paths: dict[str, Path] | None = None,
    progress: Callable[[float], None] | None = None,
    record: bool = True,
    ssp: Path | None = None,
) -> Any:
    """Run `scenario` in `engine` ("libcosim" or "ecos") and read every output after every step
    (`record=False` reads none: the engine's own speed). With `ssp`, the engine loads the system
    from that archive (made by `hoh-cosim export`) instead of from our translation."""

    if engine not in EXTERNAL_ENGINES:
        raise ConfigError(f"expected one of {', '.join(EXTERNAL_ENGINES)}, got {engine!r}")
    system = system_of(scenario, fmu_paths)
    components = list(scenario.components.values())
    columns, names = recording_layout(components)
    n_out = sum(len(v) for v in system.outputs.values())
    n = scenario.n_ticks
    dt = scenario.dt_s
    values = np.full((n + 1 if record else 1, n_out), math.nan)
    events = sorted(scenario.events, key=lambda e: e.time_s)
    with tempfile.TemporaryDirectory(prefix=f"hoh-{engine}-") as tmp:
        runner = (_Libcosim if engine == "libcosim" else _Ecos)(system, Path(tmp), ssp)
        try:
            if record:  # what initialisation left: our master's row 0
                runner.read_initial(values[0])
            start = time.perf_counter()
            k = 0
            try:
                for k in range(n):
                    t = k * dt
                    while events and events[0].time_s <= t + 0.5 * dt:
                        event = events.pop(0)
                        types = {v.name: v.type for v in system.start[event.component]}
                        runner.set(
                            event.component,
                            [
                                FmiVariable(name, types[name], _fmi_value(types[name], value))
                                for name, value in event.changes.items()
                            ],
                        )
                    runner.step()
                    if record:
                        runner.read(values[k + 1])
                    if progress is not None and k % 1000 == 0:
                        progress(t)
            except RunError:
                raise
            except Exception as exc:
                raise RunError(
                    f"{scenario.path}: {engine} failed at t = {k * dt:.6g} s: "
                    f"{type(exc).__name__}: {exc}"
                ) from exc
            wall = time.perf_counter() - start
        finally:
            runner.close()
    return Recording(
        np.arange(values.shape[0]) * dt,
        values,
        columns,
        names,
        wall,
        engine,
        ENGINE_COUPLING[engine],
    )
