"""The master's runtime for FMI 3.0 co-simulation FMUs: `FmuRuntime`'s counterpart.

`hoh_cosim.cosim.engines` steps a component whose model description says fmiVersion 3.0 with
`Fmu3Runtime` (`fmi_version`), every other FMU with `FmuRuntime`, behind the same interface. fmpy
loads and initialises the FMU (`fmpy.fmi3.FMU3Slave`); the hot path calls `fmi3SetFloat64`,
`fmi3DoStep` and `fmi3GetFloat64` of the library fmpy loaded (its `dll`, with the argument and
result types fmpy gives them) with pointers into the master's buffers and doStep's four outputs
preallocated: one batched set and one batched get per FMU per step, from the main thread, every
status checked. A status above fmi3Warning becomes a one-line `RunError` naming the component,
the FMU, the call, the time and the FMU's last log message.

The differences from FMI 2 that show here: instantiation takes the logger itself (FMI 3 has no
callback structure), and its messages carry no instance name, so each runtime gives fmpy a logger
of its own that files them under its component's name, into the log the master shares between
FMUs (`_FmuLog` of the engines: `messages`, `last`, `error`); there is no setupExperiment, the start
time goes to enterInitializationMode; value references are uint32 and getters and setters also
take the number of values (a port's elements are scalars: as many values as references); doStep
also reports whether the FMU wants an event handled, the simulation ended or the step cut short,
with the time it reached. We ask for neither events nor early returns when instantiating, so only
a request to end the simulation can come back, and it stops the run like an error.
"""

from __future__ import annotations

import atexit
import contextlib
import ctypes
import shutil
import tempfile
import zipfile
from collections import deque
from pathlib import Path
from typing import Any, Protocol
from xml.etree import ElementTree as ET

import numpy as np

from hoh_cosim.cosim.scenario import ComponentSpec
from hoh_cosim.errors import ConfigError, RunError
from hoh_cosim.fmi import exit_fix
from hoh_cosim.params import leaves

__all__ = ["Fmu3Runtime", "fmi_version"]


class FmuLog(Protocol):
    """The master's log of every FMU's messages: (instance, status, message), newest last."""

    messages: deque[tuple[str, int, str]]

    def error(self, instance: str) -> str | None: ...
    def last(self, instance: str) -> str: ...


_STATUS = {0: "OK", 1: "Warning", 2: "Discard", 3: "Error", 4: "Fatal"}
_WARNING = 1  # a status above it is a failure


def fmi_version(fmu: Path) -> str | None:
    """The fmiVersion attribute of the FMU's model description (None if the file is no FMU): read
    from the archive's first tag, without unpacking it or parsing the variables."""
    try:
        with zipfile.ZipFile(fmu) as archive, archive.open("modelDescription.xml") as xml:
            for _, element in ET.iterparse(xml, events=("start",)):
                return element.get("fmiVersion")
    except (OSError, KeyError, zipfile.BadZipFile, ET.ParseError):
        return None
    return None


_EXTRACTED: dict[tuple[str, int, int], tuple[str, Any]] = {}


def _extracted(fmu: Path) -> tuple[str, Any]:
    """The FMU unpacked once per process, with its model description; its library stays loaded
    between runs, as the engines' FMI 2 FMUs' do (`hoh_cosim.fmi.exit_fix` releases pythonfmu3's
    state at exit, whose library keeps it as pythonfmu's does)."""
    from fmpy import extract, read_model_description

    stat = fmu.stat()
    key = (str(fmu.resolve()), stat.st_mtime_ns, stat.st_size)
    if key not in _EXTRACTED:
        directory = tempfile.mkdtemp(prefix=f"hoh-{fmu.stem}-")
        atexit.register(shutil.rmtree, directory, ignore_errors=True)
        _EXTRACTED[key] = (extract(str(fmu), unzipdir=directory), read_model_description(str(fmu)))
    return _EXTRACTED[key]


class Fmu3Runtime:
    """A component as an FMI 3.0 FMU loaded, initialised and stepped through fmpy."""

    def __init__(self, spec: ComponentSpec, fmu: Path, log: FmuLog) -> None:
        from fmpy.fmi3 import FMU3Slave

        exit_fix.install()
        self.spec = spec
        self.log = log
        self.fmu_path = fmu
        try:
            self._unzipped, md = _extracted(fmu)
        except Exception as exc:  # not a zip, no modelDescription.xml ...
            raise ConfigError(f"{fmu}: cannot read the FMU: {exc}") from None
        if md.coSimulation is None:
            raise ConfigError(f"{fmu}: not a co-simulation FMU")
        self.fmu = FMU3Slave(
            guid=md.guid,
            unzipDirectory=self._unzipped,
            modelIdentifier=md.coSimulation.modelIdentifier,
            instanceName=spec.name,
        )
        self.vrs = {v.name: (v.valueReference, v.type) for v in md.modelVariables}
        scalars = {v.name for v in md.modelVariables if v.type == "Float64" and not v.dimensions}
        for port in (*spec.inputs, *spec.outputs):
            for name in port.element_names:
                if name not in scalars:
                    raise ConfigError(
                        f"{fmu}: has no Float64 scalar {name!r}, which a {spec.kind.name} "
                        f"component needs (port {port.name}[{port.size}])"
                    )
        self.in_buf = np.zeros(sum(p.size for p in spec.inputs))
        self._in_vr = self._vr_array([n for p in spec.inputs for n in p.element_names])
        self._out_vr = self._vr_array([n for p in spec.outputs for n in p.element_names])
        self._n_in, self._n_out = len(self._in_vr), len(self._out_vr)
        self._in_ptr = self.in_buf.ctypes.data_as(ctypes.POINTER(ctypes.c_double))
        self._sent: bytes | None = None  # the input values last set, as bytes
        # the C functions as fmpy loaded and typed them; doStep's outputs, allocated once
        self._set = self.fmu.dll.fmi3SetFloat64
        self._get = self.fmu.dll.fmi3GetFloat64
        self._do_step = self.fmu.dll.fmi3DoStep
        self._terminate = ctypes.c_bool(False)
        self._flags = (
            ctypes.byref(ctypes.c_bool(False)),  # eventHandlingNeeded
            ctypes.byref(self._terminate),
            ctypes.byref(ctypes.c_bool(False)),  # earlyReturn
            ctypes.byref(ctypes.c_double(0.0)),  # lastSuccessfulTime
        )
        try:
            self.fmu.instantiate(loggingOn=True, logMessage=self._logged)
        except Exception:  # fmpy: "Failed to instantiate FMU"; the FMU logged why
            raise RunError(
                f"{spec.name} ({self.fmu.modelIdentifier}): fmi3InstantiateCoSimulation failed: "
                f"{log.last(spec.name)}"
            ) from None
        self._component = self.fmu.component
        self._alive = True

    def _logged(self, env: Any, status: int, category: bytes, message: bytes) -> None:
        """The FMU's logger: its messages filed under this component's name."""
        text = (message or b"").decode(errors="replace")
        self.log.messages.append((self.spec.name, status, text))

    def _vr_array(self, names: list[str]) -> Any:
        return (ctypes.c_uint32 * len(names))(*[self.vrs[n][0] for n in names])

    def _failed(self, function: str, status: int, t: float | None = None) -> RunError:
        """The error a call that returned more than fmi3Warning becomes: which component, FMU and
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
        for var_type, (vrs, vals) in by_type.items():
            setter = getattr(self.fmu, f"set{var_type}", None)  # setFloat64, setInt32, ...
            if setter is None:
                raise ConfigError(
                    f"{self.fmu_path}: cannot set {var_type} parameters, which the scenario sets "
                    f"for {self.spec.name}"
                )
            try:
                setter(vrs, vals)
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
            self.fmu.enterInitializationMode(startTime=0.0)
            self.fmu.exitInitializationMode()
        except Exception:
            raise RunError(
                f"{self.spec.name}: initialisation failed: {self.log.last(self.spec.name)}"
            ) from None
        error = self.log.error(self.spec.name)
        if error is not None:  # our FMUs log a failure and carry on; stop here
            raise RunError(f"{self.spec.name} ({self.fmu.modelIdentifier}): {error}")
        status = self._get(self._component, self._out_vr, self._n_out, self._out_ptr, self._n_out)
        if status > _WARNING:
            raise self._failed("fmi3GetFloat64", status)

    def step(self, t: float, dt: float) -> None:
        c = self._component
        # An FMU holds an input at its last set value, so inputs are set only when their bits
        # changed (as FmuRuntime does).
        sent = self.in_buf.tobytes()
        if sent != self._sent:
            status = self._set(c, self._in_vr, self._n_in, self._in_ptr, self._n_in)
            if status > _WARNING:
                raise self._failed("fmi3SetFloat64", status, t)
            self._sent = sent
        status = self._do_step(c, t, dt, True, *self._flags)
        if status > _WARNING:
            raise self._failed("fmi3DoStep", status, t)
        if self._terminate.value:
            raise RunError(
                f"{self.spec.name} ({self.fmu.modelIdentifier}): fmi3DoStep at t = {t:.6g} s "
                f"ended the simulation (terminateSimulation): {self.log.last(self.spec.name)}"
            )
        status = self._get(c, self._out_vr, self._n_out, self._out_ptr, self._n_out)
        if status > _WARNING:
            raise self._failed("fmi3GetFloat64", status, t)

    def retune(self, params: Any, changes: dict[str, Any]) -> None:
        self._set_leaves(changes)

    def close(self) -> None:
        if self._alive:
            self._alive = False
            with contextlib.suppress(Exception):  # a failed FMU may refuse; free it anyway
                self.fmu.terminate()
            # the instance only: fmpy's freeInstance() would unload the library too, which stays
            # loaded for the next run (see _extracted)
            self.fmu.fmi3FreeInstance(self.fmu.component)
