"""The master: steps a scenario's components, through FMUs or in-process, and records every output.

One stepping loop serves both engines, so the two can only differ in how a component is stepped:

    for tick k (t = k · dt):
        apply the scenario events due at t
        for each component in the scenario's order, if k is a multiple of its `every`:
            inputs <- the latest outputs they are connected to (a few slice copies or one gather)
            step the component from t to t + every · dt
        record every output (row k + 1, time t + dt)

Components earlier in the order see this tick's outputs of those before them; the others, last
tick's. With the standard order (operator, plant, sensors, estimator, controller) that makes one tick
of delay in the feedback from the controller to the plant (on top of the robot's own cycle of
latency), and none along the forward path from the hand to the command.

Buffers are flat float arrays: every component's outputs are a view into one array, each input buffer
is filled from precomputed indices (scenario input values sit in a constants area at the end of that
array): as a few copies of consecutive elements through memoryviews, or one `np.take` when its
elements come from more than a few places. The FMU runtime then calls `fmi2SetReal`, `fmi2DoStep` and
`fmi2GetReal` of the FMU's library as fmpy loads it (its public `dll`) with pointers into those
buffers: one batched set and one batched get per FMU per step, all from the main thread, every
status checked; a status above fmi2Warning becomes a one-line `RunError` naming the call and the
FMU's last log message.
"""

from __future__ import annotations

import atexit
import contextlib
import ctypes
import math
import shutil
import signal
import sys
import tempfile
import threading
import time
from collections import deque
from collections.abc import Callable, Sequence
from itertools import pairwise
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from hoh_cosim.control.block import copy_new_outputs, make_block
from hoh_cosim.cosim import COUPLINGS, ENGINES, EXTERNAL_ENGINES
from hoh_cosim.cosim.external import simulate_external
from hoh_cosim.cosim.recording import Recording, recording_layout
from hoh_cosim.cosim.scenario import ComponentSpec, Scenario
from hoh_cosim.errors import ConfigError, RunError
from hoh_cosim.fmi import exit_fix
from hoh_cosim.params import leaves

__all__ = ["COUPLINGS", "ENGINES", "simulate"]


class Runtime(Protocol):
    spec: ComponentSpec
    in_buf: np.ndarray

    def bind(self, outputs: np.ndarray) -> None: ...
    def initialize(self) -> None: ...
    def step(self, t: float, dt: float) -> None: ...
    def retune(self, params: Any, changes: dict[str, Any]) -> None: ...
    def close(self) -> None: ...


class InProcessRuntime:
    """A block stepped directly: the reference the FMUs must match."""

    def __init__(self, spec: ComponentSpec) -> None:
        self.spec = spec
        self.block = make_block(spec.kind.block, spec.params, spec.seed)
        self.in_buf = np.zeros(sum(p.size for p in spec.inputs))
        # views into the input buffer, refilled in place every step (see the block contract)
        self._inputs = {name: self.in_buf[sl] for name, sl in _slices(spec.inputs)}
        self._outputs = _slices(spec.outputs)

    def bind(self, outputs: np.ndarray) -> None:
        self.out = outputs
        self._out_views = [(name, outputs[sl]) for name, sl in self._outputs]
        self._written: list[object] = [None] * len(self._out_views)

    def initialize(self) -> None:
        initial = getattr(self.block, "initial_outputs", None)
        if initial is not None:
            self._write(initial())

    def _write(self, outputs: dict[str, np.ndarray]) -> None:
        copy_new_outputs(outputs, self._out_views, self._written)

    def step(self, t: float, dt: float) -> None:
        # copy_new_outputs, inlined: two calls fewer per component and tick
        outputs = self.block.step(t, dt, self._inputs)
        written = self._written
        for i, (name, view) in enumerate(self._out_views):
            value = outputs[name]
            if value is not written[i]:
                view[...] = value
                written[i] = value

    def retune(self, params: Any, changes: dict[str, Any]) -> None:
        self.block.retune(params)

    def close(self) -> None:
        pass


MAX_SLICES = 6
"""The most runs of consecutive elements an input buffer is gathered from as slice copies; one with
more is one `take`. A slice copy through memoryviews costs about a quarter of a `take` (75-100
against 400 ns here), so up to six of them are no dearer."""


def _runs(
    index: np.ndarray, source: np.ndarray, buf: np.ndarray
) -> tuple[tuple[memoryview, memoryview], ...] | None:
    """`source.take(index, out=buf)` as copies of consecutive elements (destination, source
    memoryviews), or None when it takes more than `MAX_SLICES` of them: the same values, copied."""
    if index.size == 0:
        return ()
    # a run starts where the source index does not follow the previous one
    starts = [0, *(np.flatnonzero(np.diff(index) != 1) + 1).tolist(), index.size]
    if len(starts) - 1 > MAX_SLICES:
        return None
    dst, src = memoryview(buf), memoryview(source)
    return tuple(
        (dst[a:b], src[int(index[a]) : int(index[a]) + b - a]) for a, b in pairwise(starts)
    )


def _inline(rt: Runtime) -> tuple[Any, ...]:
    """What the master needs to run an in-process runtime's `step` inline (the block's step, its
    input views, its output views, the arrays copied there last, and the block if it keeps
    `idle_until`: the block contract); Nones for any other."""
    if type(rt) is InProcessRuntime:
        idles = rt.block if hasattr(rt.block, "idle_until") else None
        return rt.block.step, rt._inputs, rt._out_views, rt._written, idles
    return None, None, None, None, None


def _slices(ports: Sequence[Any]) -> list[tuple[str, slice]]:
    out, offset = [], 0
    for port in ports:
        out.append((port.name, slice(offset, offset + port.size)))
        offset += port.size
    return out


class _FmuLog:
    """Keeps the last messages every FMU logged, to name the cause when a call fails."""

    def __init__(self) -> None:
        from fmpy import calloc, free
        from fmpy.fmi2 import (
            fmi2CallbackAllocateMemoryTYPE,
            fmi2CallbackFreeMemoryTYPE,
            fmi2CallbackFunctions,
            fmi2CallbackLoggerTYPE,
        )

        self.messages: deque[tuple[str, int, str]] = deque(maxlen=50)
        self.callbacks = fmi2CallbackFunctions()
        self.callbacks.logger = fmi2CallbackLoggerTYPE(self._log)
        self.callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
        self.callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)

    def _log(self, env: Any, instance: bytes, status: int, category: bytes, message: bytes) -> None:
        self.messages.append(
            (
                (instance or b"").decode(errors="replace"),
                status,
                (message or b"").decode(errors="replace"),
            )
        )

    def error(self, instance: str) -> str | None:
        """The last error `instance` logged, if any."""
        for name, status, message in reversed(self.messages):
            if name == instance and status >= 3:
                return " ".join(message.split())
        return None

    def last(self, instance: str) -> str:
        for name, _, message in reversed(self.messages):
            if name == instance:
                return " ".join(message.split())
        return "no message"


_STATUS = {0: "OK", 1: "Warning", 2: "Discard", 3: "Error", 4: "Fatal", 5: "Pending"}
_WARNING = 1  # a status above it is a failure


_EXTRACTED: dict[tuple[str, int, int], tuple[str, Any]] = {}


def _extracted(fmu: Path) -> tuple[str, Any]:
    """The FMU unpacked once per process, with its model description.

    An FMU file is unpacked once and its library stays loaded: later runs instantiate it again
    rather than load and unload it each time (pythonfmu's state is released at exit, see
    `hoh_cosim.fmi.exit_fix`).
    """
    from fmpy import extract, read_model_description

    stat = fmu.stat()
    key = (str(fmu.resolve()), stat.st_mtime_ns, stat.st_size)
    if key not in _EXTRACTED:
        directory = tempfile.mkdtemp(prefix=f"hoh-{fmu.stem}-")
        atexit.register(shutil.rmtree, directory, ignore_errors=True)
        _EXTRACTED[key] = (extract(str(fmu), unzipdir=directory), read_model_description(str(fmu)))
    return _EXTRACTED[key]


class FmuRuntime:
    """A component as an FMU loaded, initialised and stepped through fmpy."""

    def __init__(self, spec: ComponentSpec, fmu: Path, log: _FmuLog) -> None:
        from fmpy.fmi2 import FMU2Slave

        exit_fix.install()
        self.spec = spec
        self.log = log
        self.fmu_path = fmu
        try:
            self._unzipped, md = _extracted(fmu)
        except Exception as exc:  # not a zip, no modelDescription.xml, not FMI 2.0 ...
            raise ConfigError(f"{fmu}: cannot read the FMU: {exc}") from None
        self.fmu = FMU2Slave(
            guid=md.guid,
            unzipDirectory=self._unzipped,
            modelIdentifier=md.coSimulation.modelIdentifier,
            instanceName=spec.name,
        )
        self.vrs = {v.name: (v.valueReference, v.type) for v in md.modelVariables}
        for port in (*spec.inputs, *spec.outputs):
            for name in port.element_names:
                if self.vrs.get(name, (None, "Real"))[1] != "Real" or name not in self.vrs:
                    raise ConfigError(
                        f"{fmu}: has no Real variable {name!r}, which a {spec.kind.name} "
                        f"component needs (port {port.name}[{port.size}])"
                    )
        self.in_buf = np.zeros(sum(p.size for p in spec.inputs))
        self._in_vr = self._vr_array([n for p in spec.inputs for n in p.element_names])
        self._out_vr = self._vr_array([n for p in spec.outputs for n in p.element_names])
        self._n_in, self._n_out = len(self._in_vr), len(self._out_vr)
        self._in_ptr = self.in_buf.ctypes.data_as(ctypes.POINTER(ctypes.c_double))
        self._sent: bytes | None = None  # the input values last set, as bytes
        # The hot path calls the C functions of the FMU's library, which fmpy loads and types
        # (argtypes, restype) as its public `dll`, and checks each status here: fmpy's wrapper
        # methods (`fmi2SetReal`, ...) cost 0.15-0.25 us a call more, 2.7 % of circles on the fmu
        # engine (alternate runs, 3.43 against 3.52 s). Errors read as they would through fmpy.
        self._set = self.fmu.dll.fmi2SetReal
        self._get = self.fmu.dll.fmi2GetReal
        self._do_step = self.fmu.dll.fmi2DoStep
        self.fmu.instantiate(callbacks=log.callbacks, loggingOn=True)
        self._component = self.fmu.component
        self._alive = True

    def _vr_array(self, names: list[str]) -> Any:
        return (ctypes.c_uint * len(names))(*[self.vrs[n][0] for n in names])

    def _failed(self, function: str, status: int, t: float | None = None) -> RunError:
        """The error a call that returned more than fmi2Warning becomes: which component, FMU and
        call, when, and why (the FMU's last log message: ours log the exception they caught)."""
        at = f" at t = {t:.6g} s" if t is not None else ""
        return RunError(
            f"{self.spec.name} ({self.fmu.modelIdentifier}): {function}{at} returned "
            f"{_STATUS.get(status, status)}: {self.log.last(self.spec.name)}"
        )

    def _set_leaves(self, values: dict[str, Any]) -> None:
        by_type: dict[str, tuple[list[int], list[Any]]] = {}
        for name, value in values.items():
            if name not in self.vrs:
                raise ConfigError(
                    f"{self.fmu_path}: has no parameter {name!r}, which the scenario sets "
                    f"for {self.spec.name}"
                )
            vr, var_type = self.vrs[name]
            vrs, vals = by_type.setdefault(var_type, ([], []))
            vrs.append(vr)
            vals.append(value)
        setters = {
            "Real": self.fmu.setReal,
            "Integer": self.fmu.setInteger,
            "Boolean": self.fmu.setBoolean,
            "String": self.fmu.setString,
        }
        for var_type, (vrs, vals) in by_type.items():
            try:
                setters[var_type](vrs, vals)
            except Exception as exc:  # fmpy raises on a failed status
                raise RunError(
                    f"{self.spec.name}: setting parameters failed: "
                    f"{self.log.last(self.spec.name) or exc}"
                ) from None

    def bind(self, outputs: np.ndarray) -> None:
        self.out = outputs
        self._out_ptr = outputs.ctypes.data_as(ctypes.POINTER(ctypes.c_double))

    def initialize(self) -> None:
        values = {leaf.name: leaf.value for leaf in leaves(self.spec.params)}
        if "seed" in self.vrs:
            values["seed"] = self.spec.seed
        self._set_leaves(values)
        try:
            self.fmu.setupExperiment(startTime=0.0)
            self.fmu.enterInitializationMode()
            self.fmu.exitInitializationMode()
        except Exception:
            raise RunError(
                f"{self.spec.name}: initialisation failed: {self.log.last(self.spec.name)}"
            ) from None
        error = self.log.error(self.spec.name)
        if error is not None:  # our FMUs log a failure and carry on; stop here
            raise RunError(f"{self.spec.name} ({self.fmu.modelIdentifier}): {error}")
        status = self._get(self._component, self._out_vr, self._n_out, self._out_ptr)
        if status > _WARNING:
            raise self._failed("fmi2GetReal", status)

    def step(self, t: float, dt: float) -> None:
        c = self._component
        # An FMU holds an input at its last set value, so inputs are set only when their bits
        # changed: a sensor stepped every tick reads a plant stepped every other tick, an
        # estimator reads packets held over several ticks.
        sent = self.in_buf.tobytes()
        if sent != self._sent:
            status = self._set(c, self._in_vr, self._n_in, self._in_ptr)
            if status > _WARNING:
                raise self._failed("fmi2SetReal", status, t)
            self._sent = sent
        status = self._do_step(c, t, dt, 1)
        if status > _WARNING:
            raise self._failed("fmi2DoStep", status, t)
        status = self._get(c, self._out_vr, self._n_out, self._out_ptr)
        if status > _WARNING:
            raise self._failed("fmi2GetReal", status, t)

    def retune(self, params: Any, changes: dict[str, Any]) -> None:
        self._set_leaves(changes)

    def close(self) -> None:
        if self._alive:
            self._alive = False
            with contextlib.suppress(Exception):  # a failed FMU may refuse; free it anyway
                self.fmu.terminate()
            # the instance only: fmpy's freeInstance() would unload the library too, which stays
            # loaded for the next run (see _extracted)
            self.fmu.fmi2FreeInstance(self.fmu.component)


class _Progress:
    """A one-line progress bar on a terminal, for runs that take more than a couple of seconds."""

    def __init__(self, name: str, duration: float, enabled: bool) -> None:
        self.name, self.duration = name, duration
        self.enabled = enabled and sys.stderr.isatty()
        self.start = time.perf_counter()
        self.last = self.start
        self.shown = False

    def update(self, t: float) -> None:
        now = time.perf_counter()
        if not self.enabled or now - self.last < 0.5 or now - self.start < 2.0:
            return
        self.last, self.shown = now, True
        done = t / self.duration
        bar = "#" * int(30 * done)
        rtf = t / (now - self.start)
        sys.stderr.write(
            f"\r{self.name} [{bar:<30}] {100 * done:5.1f}% {t:.1f}/{self.duration:.1f}"
            f" s  x{rtf:.1f} real time"
        )
        sys.stderr.flush()

    def close(self) -> None:
        if self.shown:
            sys.stderr.write("\r" + " " * 79 + "\r")
            sys.stderr.flush()


class _InterruptLatch:
    """Ctrl-C during stepping, taken between two ticks instead of inside a component.

    A KeyboardInterrupt raised inside an FMU's Python code fails its fmi2DoStep (the FMU reports it
    as a Fatal status), and inside a block it could leave the block half-stepped: so while the
    master steps, SIGINT only sets `requested`, and the loop raises KeyboardInterrupt at its next
    check. Only in the main thread and when Python's own handler is in place (a sweep's workers and
    a caller with its own handler are left alone)."""

    def __init__(self) -> None:
        self.requested = False
        self._previous: Any = None
        if threading.current_thread() is not threading.main_thread():
            return
        if signal.getsignal(signal.SIGINT) is not signal.default_int_handler:
            return
        self._previous = signal.signal(signal.SIGINT, self._handle)

    def _handle(self, signum: int, frame: Any) -> None:
        self.requested = True

    def restore(self) -> None:
        if self._previous is not None:
            signal.signal(signal.SIGINT, self._previous)
            self._previous = None


def simulate(
    scenario: Scenario,
    engine: str = "fmu",
    *,
    fmu_paths: dict[str, Path] | None = None,
    progress: bool = True,
    observer: Callable[[int, float, np.ndarray], None] | None = None,
    coupling: str = "gauss-seidel",
    fmi: int = 2,
) -> Recording:
    """Run `scenario` with `engine` and record every output.

    `observer(k, t, outputs)` is called after every tick k of our master (from t to t + dt) with
    the row the recording keeps for t + dt: every output of every component, in the layout of
    `recording_layout` (a view of the recording: read it, copy what is kept).

    "fmu" and "inprocess" are our master, with `coupling` "gauss-seidel" (the file's order, the
    default), "jacobi" or "jacobi-eager" (libcosim's and ecos's); "libcosim" and "ecos" run the
    same FMUs in those engines (`hoh_cosim.cosim.external`), with their own coupling. `fmi`: the
    version of the FMUs the "fmu" engine builds (2 or 3; a scenario's own FMU is what it is).
    """
    if engine not in ENGINES:
        raise ConfigError(f"--engine: expected one of {', '.join(ENGINES)}, got {engine!r}")
    if coupling not in COUPLINGS:
        raise ConfigError(f"--coupling: expected one of {', '.join(COUPLINGS)}, got {coupling!r}")
    if engine in EXTERNAL_ENGINES:
        if coupling != "gauss-seidel" or observer is not None:
            raise ConfigError(
                f"--engine {engine}: the engine has its own coupling and steps on its own"
            )
        bar = _Progress(scenario.name, scenario.duration_s, progress)
        try:
            return simulate_external(scenario, engine, fmu_paths=fmu_paths, progress=bar.update)
        finally:
            bar.close()
    components = list(scenario.components.values())
    runtimes: list[Runtime] = []
    try:
        if engine == "fmu":
            if fmu_paths is None:
                from hoh_cosim.fmi.build import ensure_fmus

                kinds = sorted({c.kind.name for c in components if c.fmu is None})
                fmu_paths = ensure_fmus(kinds, fmi=fmi)
            from hoh_cosim.cosim.fmi3_runtime import Fmu3Runtime, fmi_version

            log = _FmuLog()
            for c in components:  # FMI 3.0 FMUs by Fmu3Runtime, the others by FmuRuntime
                path = c.fmu or fmu_paths[c.kind.name]
                fmu_runtime = Fmu3Runtime if fmi_version(path) == "3.0" else FmuRuntime
                runtimes.append(fmu_runtime(c, path, log))
        else:
            runtimes = [InProcessRuntime(c) for c in components]
        return _run(scenario, engine, runtimes, progress, observer, coupling)
    finally:
        for runtime in runtimes:
            runtime.close()


def _run(
    scenario: Scenario,
    engine: str,
    runtimes: list[Runtime],
    progress: bool,
    observer: Callable[[int, float, np.ndarray], None] | None,
    coupling: str,
) -> Recording:
    # one array for every output, then the constant input values
    columns, names = recording_layout([rt.spec for rt in runtimes])
    n_outputs = offset = sum(s.stop - s.start for s in columns.values())
    constants = [v for v in scenario.input_defaults.values()]
    n_const = sum(v.size for v in constants)
    store = np.zeros(n_outputs + n_const)
    const_at: dict[tuple[str, str], int] = {}
    for key, value in scenario.input_defaults.items():
        const_at[key] = offset
        store[offset : offset + value.size] = value
        offset += value.size
    for rt in runtimes:
        start = columns[f"{rt.spec.name}.{rt.spec.outputs[0].name}"].start
        rt.bind(store[start : start + sum(p.size for p in rt.spec.outputs)])

    # every input element's source in `store`
    gather: list[np.ndarray] = []
    for rt in runtimes:
        index = np.full(rt.in_buf.size, -1, dtype=np.intp)
        port_offset = dict((name, sl.start) for name, sl in _slices(rt.spec.inputs))
        for (comp, port), at in const_at.items():
            if comp == rt.spec.name:
                size = next(p.size for p in rt.spec.inputs if p.name == port)
                index[port_offset[port] : port_offset[port] + size] = np.arange(at, at + size)
        for conn in scenario.connections:
            if conn.dst != rt.spec.name:
                continue
            src = columns[f"{conn.src}.{conn.src_port}"].start
            for s, d in zip(conn.src_elements, conn.dst_elements, strict=True):
                index[port_offset[conn.dst_port] + d] = src + s
        if np.any(index < 0):
            raise RunError(f"{scenario.path}: an input of {rt.spec.name} has no source")
        gather.append(index)

    for rt in runtimes:
        rt.initialize()
    # Jacobi: inputs come from `published`, and a component's outputs are published when its step
    # has ended ("jacobi") or one tick after it began ("jacobi-eager"); Gauss-Seidel reads `store`,
    # where they are the moment the component has stepped
    jacobi = coupling != "gauss-seidel"
    shift = 1 if coupling == "jacobi" else 0
    published = store.copy() if jacobi else store
    take = published.take
    runs = [_runs(index, published, rt.in_buf) for index, rt in zip(gather, runtimes, strict=True)]
    n = scenario.n_ticks
    dt = scenario.dt_s
    values = np.empty((n + 1, n_outputs))
    outputs = store[:n_outputs]
    values[0] = outputs
    events = deque(sorted(scenario.events, key=lambda e: e.time_s))
    by_name = {rt.spec.name: rt for rt in runtimes}
    # the components due at each tick of the pattern that repeats every `cycle` ticks, in order
    # (at most one entry per tick of the run: a pattern longer than the run is never repeated)
    cycle = min(math.lcm(*(rt.spec.every for rt in runtimes)), max(scenario.n_ticks, 1))
    plan = [
        [
            (rt.step, rt.spec.every * dt, gather[i], rt.in_buf, runs[i], *_inline(rt))
            for i, rt in enumerate(runtimes)
            if phase % rt.spec.every == 0
        ]
        for phase in range(cycle)
    ]
    spans = [
        (rt.spec.every, columns[f"{rt.spec.name}.{rt.spec.outputs[0].name}"].start, rt.out.size)
        for rt in runtimes
    ]
    bar = _Progress(scenario.name, scenario.duration_s, progress)
    start = time.perf_counter()
    interrupt = _InterruptLatch()
    try:
        for k in range(n):
            t = k * dt
            if k % 100 == 0 and interrupt.requested:
                raise KeyboardInterrupt
            while events and events[0].time_s <= t + 0.5 * dt:
                event = events.popleft()
                by_name[event.component].retune(event.params, event.changes)
            for (
                step_component,
                step,
                index,
                buf,
                copies,
                block_step,
                inputs,
                views,
                written,
                idles,
            ) in plan[k % cycle]:
                if idles is not None and t + step < idles.idle_until:
                    continue  # the step would do nothing (the block contract): not called
                if copies is None:
                    take(index, out=buf)
                else:
                    for dst, src in copies:
                        dst[:] = src
                if block_step is None:
                    step_component(t, step)
                    continue
                # InProcessRuntime.step, inline: a call fewer per component and tick
                returned = block_step(t, step, inputs)
                for i, (name, view) in enumerate(views):
                    value = returned[name]
                    if value is not written[i]:
                        view[...] = value
                        written[i] = value
            if jacobi:
                for every, at, size in spans:
                    if (k + shift) % every == 0:
                        published[at : at + size] = store[at : at + size]
                values[k + 1] = published[:n_outputs]
            else:
                values[k + 1] = outputs
            if observer is not None:
                observer(k, t, values[k + 1])
            if k % 1000 == 0:
                bar.update(t)
    except RunError:
        raise
    except Exception as exc:
        raise RunError(
            f"{scenario.path}: the run failed at t = {t:.6g} s: {type(exc).__name__}: {exc}"
        ) from exc
    finally:
        interrupt.restore()
        bar.close()
    if interrupt.requested:  # pressed during the last ticks
        raise KeyboardInterrupt
    wall = time.perf_counter() - start
    timeline = np.arange(n + 1) * dt
    if not math.isfinite(wall):
        wall = float("nan")
    return Recording(timeline, values, columns, names, wall, engine, coupling)
