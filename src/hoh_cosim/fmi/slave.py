"""One generic adapter from a block to a pythonfmu co-simulation slave.

An FMU's entry script in `fmus/` only names the block and its parameter class:

    from hoh_cosim.fmi.slave import BlockSlave as Fmi2Slave  # the wrapper finds "class X(Fmi2Slave):"

    class HohEstimator(Fmi2Slave):
        block = Estimator
        params = EstimatorParams

and the adapter does the rest, the same way for every block:
- every element of every port becomes a Real variable (`wrench_S[1]` … `wrench_S[6]`, a scalar port
  keeps its bare name), inputs starting where the build says (`INPUT_STARTS`: a world at rest,
  else 0), outputs calculated;
- every parameter leaf (see `hoh_cosim.params`) becomes a parameter, tunable where the parameter
  class says it may change while running, fixed otherwise; a block that draws random numbers gets an
  Integer parameter `seed`;
- the block is built when initialisation starts (and rebuilt if parameters change before it ends),
  and its outputs are computed right away, so they are valid during initialisation;
- `do_step` is read inputs -> `block.step(t, dt, inputs)` -> write outputs and nothing else; a tunable
  parameter set between steps reaches the block through its `retune` before the next step; a
  block that is not `variable_step` refuses a step other than its first;
- the FMU state (get, set, serialise) is the adapter's values and the block, pickled.

Reals come first in value-reference order (inputs, outputs, real parameters), so a value reference
indexes one float array and get/set are single numpy operations instead of pythonfmu's per-variable
Python loop.
"""

from __future__ import annotations

import ctypes
import importlib
import io
import json
import math
import pickle
import types
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar, Literal
from urllib.parse import unquote, urlparse

import numpy as np
from pythonfmu import Fmi2Slave as _PythonFmuSlave
from pythonfmu.enums import Fmi2Causality, Fmi2Status, Fmi2Variability
from pythonfmu.variables import Boolean, Integer, Real, String

from hoh_cosim.control.block import (
    copy_new_outputs,
    make_block,
    port_element_names,
    takes_rng,
    variable_step,
)
from hoh_cosim.errors import ConfigError
from hoh_cosim.fmi import exit_fix
from hoh_cosim.params import leaves, with_values

__all__ = [
    "INPUT_STARTS",
    "PARAMETERS",
    "BlockSlave",
    "VariableSpec",
    "block_interface",
    "pin_namespace",
    "port_element_names",
]

VarType = Literal["Real", "Integer", "Boolean", "String"]
_KIND_TO_TYPE: dict[str, VarType] = {
    "real": "Real",
    "integer": "Integer",
    "boolean": "Boolean",
    "string": "String",
}


@dataclass(frozen=True)
class VariableSpec:
    """One FMI scalar variable of a block's FMU, in value-reference order."""

    name: str
    type: VarType
    causality: Literal["input", "output", "parameter"]
    variability: Literal["continuous", "fixed", "tunable"]
    start: float | int | bool | str | None
    unit: str | None
    description: str


def block_interface(
    block_cls: type,
    params_cls: type,
    starts: Mapping[str, Any] | None = None,
    defaults: Any = None,
) -> list[VariableSpec]:
    """Every FMI variable of the FMU wrapping `block_cls`, in value-reference order; `starts`
    gives input ports' start values (`hoh_cosim.kinds.input_starts`), the others start at 0;
    `defaults` the parameters' start values (a `params_cls`; None: its defaults)."""
    specs: list[VariableSpec] = []
    starts = starts or {}
    for causality, ports in (("input", block_cls.inputs), ("output", block_cls.outputs)):
        for port in ports:
            values = np.zeros(port.size)
            if causality == "input" and port.name in starts:
                values = np.asarray(starts[port.name], dtype=float).reshape(port.size)
            for element, unit, value in zip(port.element_names, port.units, values, strict=True):
                specs.append(
                    VariableSpec(
                        element,
                        "Real",
                        causality,
                        "continuous",
                        float(value) if causality == "input" else None,
                        unit,
                        port.description,
                    )
                )
    params = leaves(params_cls() if defaults is None else defaults)
    extra = []
    if takes_rng(block_cls):
        extra.append(
            VariableSpec(
                "seed",
                "Integer",
                "parameter",
                "fixed",
                0,
                "1",
                "seed of the block's random numbers",
            )
        )
    for var_type in ("Real", "Integer", "Boolean", "String"):
        for leaf in params:
            if _KIND_TO_TYPE[leaf.kind] == var_type:
                specs.append(
                    VariableSpec(
                        leaf.name,
                        var_type,
                        "parameter",
                        "tunable" if leaf.tunable else "fixed",
                        leaf.value,
                        leaf.unit,
                        f"parameter of {params_cls.__name__}",
                    )
                )
        specs.extend(s for s in extra if s.type == var_type)
    names = [s.name for s in specs]
    duplicates = {n for n in names if names.count(n) > 1}
    if duplicates:
        raise ConfigError(f"{block_cls.__name__}: variable names used twice: {sorted(duplicates)}")
    return specs


_CAUSALITY = {
    "input": Fmi2Causality.input,
    "output": Fmi2Causality.output,
    "parameter": Fmi2Causality.parameter,
}
_VARIABILITY = {
    "continuous": Fmi2Variability.continuous,
    "fixed": Fmi2Variability.fixed,
    "tunable": Fmi2Variability.tunable,
}
_VARIABLE_CLASS = {"Real": Real, "Integer": Integer, "Boolean": Boolean, "String": String}


class BlockSlave(_PythonFmuSlave):
    """The adapter; an entry script subclasses it and sets `block` and `params`."""

    block: ClassVar[type]
    params: ClassVar[type]

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        exit_fix.protect_host()  # pythonfmu 0.7's double release at unload, in any host
        cls = type(self)
        self.description = (cls.block.__doc__ or cls.block.__name__).strip().splitlines()[0]
        self.specs = block_interface(
            cls.block, cls.params, defaults=_declared_parameters(self.resources, cls.params)
        )
        self._n_in = sum(p.size for p in cls.block.inputs)
        self._n_io = self._n_in + sum(p.size for p in cls.block.outputs)
        reals = [s for s in self.specs if s.type == "Real"]
        self._reals = np.array([0.0 if s.start is None else s.start for s in reals], dtype=float)
        for vr, start in _declared_input_starts(self.resources).items():
            if vr < self._n_in:  # as the model description says: an FMU run alone starts there
                self._reals[vr] = start
        self._others: dict[int, Any] = {}
        for vr, spec in enumerate(self.specs):
            var = _VARIABLE_CLASS[spec.type](
                spec.name,
                causality=_CAUSALITY[spec.causality],
                variability=_VARIABILITY[spec.variability],
                description=spec.description,
            )
            self.register_variable(var, nested=False)
            if spec.type != "Real":
                self._others[vr] = spec.start
        self._param_names = {
            vr: s.name
            for vr, s in enumerate(self.specs)
            if s.causality == "parameter" and s.name != "seed"
        }
        self._tunable = {vr for vr, s in enumerate(self.specs) if s.variability == "tunable"}
        offset = 0
        self._inputs: list[tuple[str, slice]] = []
        for port in cls.block.inputs:
            self._inputs.append((port.name, slice(offset, offset + port.size)))
            offset += port.size
        self._outputs: list[tuple[str, slice]] = []
        for port in cls.block.outputs:
            self._outputs.append((port.name, slice(offset, offset + port.size)))
            offset += port.size
        # views into the reals, refilled by set_real in place (see the block contract)
        self._input_views = {name: self._reals[sl] for name, sl in self._inputs}
        # and into the reals the outputs are copied to, with the arrays copied last (new arrays
        # only: see copy_new_outputs; reset whenever anything else writes there)
        self._output_views = [(name, self._reals[sl]) for name, sl in self._outputs]
        self._written: list[object] = [None] * len(self._outputs)
        self._input_vrs = list(range(self._n_in))
        self._output_vrs = list(range(self._n_in, self._n_io))
        self._instance: Any = None
        self._changed: set[int] = set()  # parameters set since the block was built
        self._failure: str | None = None  # the first error, if any (see _fail)
        self._variable_step = variable_step(cls.block)
        self._step: float | None = None  # a sampled block's period: its first step

    # --- errors ------------------------------------------------------------------------------
    #
    # No exception may leave a method that pythonfmu 0.7.0 calls: on one it releases the instance's
    # Python objects, and releases them again in fmi2FreeInstance, which corrupts the interpreter's
    # memory (a crash later, in some unrelated garbage collection). So every failure is logged as an
    # FMI error and remembered, and the next fmi2DoStep returns fmi2Discard.

    def _fail(self, where: str, exc: BaseException) -> None:
        message = f"{where}: {type(exc).__name__}: {exc}"
        if self._failure is None:
            self._failure = message
        self.log(message, status=Fmi2Status.error)

    # --- values ------------------------------------------------------------------------------

    def get_real(self, vrs: list[int]) -> list[float]:
        if vrs == self._output_vrs:  # what a master asks every step: a slice, not a gather
            return self._reals[self._n_in : self._n_io].tolist()
        try:
            return self._reals[vrs].tolist()
        except Exception as exc:
            self._fail("fmi2GetReal", exc)
            return [math.nan] * len(vrs)

    def set_real(self, vrs: list[int], values: list[float]) -> None:
        if vrs == self._input_vrs:  # every input, in order: what a master sets every step
            self._reals[: self._n_in] = values
            return
        try:
            self._reals[vrs] = values
        except Exception as exc:
            self._fail("fmi2SetReal", exc)
            return
        if any(self._n_in <= vr < self._n_io for vr in vrs):  # an output overwritten
            self._written = [None] * len(self._outputs)
        if max(vrs) >= self._n_io:
            self._changed.update(vr for vr in vrs if vr >= self._n_io)

    def _get_other(self, vrs: list[int]) -> list[Any]:
        try:
            return [self._others[vr] for vr in vrs]
        except KeyError as exc:
            self._fail("fmi2Get", ValueError(f"no such variable: value reference {exc}"))
            return [0] * len(vrs)

    def _set_other(self, vrs: list[int], values: list[Any]) -> None:
        for vr, value in zip(vrs, values, strict=True):
            if vr not in self._others:
                self._fail("fmi2Set", ValueError(f"no such variable: value reference {vr}"))
                return
            self._others[vr] = value
            self._changed.add(vr)

    get_integer = get_boolean = get_string = _get_other
    set_integer = set_boolean = set_string = _set_other

    # --- life cycle --------------------------------------------------------------------------

    def _parameters(self) -> Any:
        values: dict[str, Any] = {}
        for vr, name in self._param_names.items():
            value = self._reals[vr] if vr < len(self._reals) else self._others[vr]
            values[name] = value.item() if isinstance(value, np.generic) else value
        return with_values(type(self).params(), values)

    def _build(self) -> None:
        try:
            seed = next(
                (self._others[vr] for vr, s in enumerate(self.specs) if s.name == "seed"), 0
            )
            self._instance = make_block(type(self).block, self._parameters(), int(seed))
            self._changed.clear()
            initial = getattr(self._instance, "initial_outputs", None)
            if initial is not None:
                self._write_outputs(initial())
            if self._failure is not None and self._failure.startswith("initialisation"):
                self._failure = None  # parameters fixed before initialisation ended
        except Exception as exc:
            self._instance = None
            self._fail("initialisation", exc)

    def _write_outputs(self, outputs: dict[str, np.ndarray]) -> None:
        copy_new_outputs(outputs, self._output_views, self._written)

    def enter_initialization_mode(self) -> None:
        self._build()

    def exit_initialization_mode(self) -> None:
        if self._changed:
            self._build()

    def do_step(self, current_time: float, step_size: float) -> bool:
        if self._failure is not None:  # a failed block is not stepped again
            self.log(f"not stepped after an earlier error: {self._failure}", Fmi2Status.error)
            return False
        if not self._variable_step:
            if self._step is None:
                self._step = step_size
            elif abs(step_size - self._step) > 1e-9 * self._step:
                self._fail(
                    f"fmi2DoStep at t = {current_time:.6g} s",
                    ValueError(
                        f"{type(self).__name__} is a sampled block: its sample period is its first "
                        f"step, {self._step:g} s, and canHandleVariableCommunicationStepSize is "
                        f"false; got a step of {step_size:g} s"
                    ),
                )
                return False
        try:
            if self._changed:
                fixed = [self.specs[vr].name for vr in self._changed if vr not in self._tunable]
                if fixed:
                    raise ConfigError(
                        f"fixed parameters cannot change after initialisation: {sorted(fixed)}"
                    )
                self._instance.retune(self._parameters())
                self._changed.clear()
            self._write_outputs(self._instance.step(current_time, step_size, self._input_views))
        except Exception as exc:
            self._fail(f"fmi2DoStep at t = {current_time:.6g} s", exc)
            return False
        return True

    # --- FMU state (fmi2GetFMUstate, fmi2SetFMUstate, fmi2SerializeFMUstate, ...) ------------

    def _get_fmu_state(self) -> bytes:
        try:
            return _snapshot(self)
        except Exception as exc:
            self._fail("fmi2GetFMUstate", exc)
            return _State()

    def _set_fmu_state(self, state: bytes) -> None:
        try:
            _restore(self, state)
        except Exception as exc:
            self._fail("fmi2SetFMUstate", exc)

    @staticmethod
    def _fmu_state_to_bytes(state: bytes) -> bytes:
        return bytes(state)

    @staticmethod
    def _fmu_state_from_bytes(data: bytes) -> bytes:
        return _State(data)


class _State(bytes):
    """An FMU state: the instance's values and its block, pickled (so a snapshot, never a live
    object, and its own serialised form). Only for this process or another of the same build:
    unpickling runs code, as loading the FMU itself does."""


class _Pickler(pickle.Pickler):
    """A block may hold a module (its library, e.g. pinocchio): pickled by name."""

    def persistent_id(self, obj: Any) -> str | None:
        return obj.__name__ if isinstance(obj, types.ModuleType) else None


class _Unpickler(pickle.Unpickler):
    def persistent_load(self, pid: str) -> Any:
        return importlib.import_module(pid)


def _snapshot(slave: BlockSlave) -> _State:
    values = (slave._reals, slave._others, slave._instance)
    flags = (slave._changed, slave._failure, slave._step)
    buffer = io.BytesIO()
    _Pickler(buffer, protocol=pickle.HIGHEST_PROTOCOL).dump((values, flags))
    return _State(buffer.getvalue())


def _restore(slave: BlockSlave, state: bytes) -> None:
    (reals, others, instance), (changed, failure, step) = _Unpickler(io.BytesIO(state)).load()
    if reals.shape != slave._reals.shape:
        raise ValueError(f"a state of {reals.size} reals for an FMU of {slave._reals.size}")
    slave._reals[:] = reals  # in place: the input views stay valid
    slave._written = [None] * len(slave._outputs)
    slave._others = others
    slave._instance, slave._changed, slave._failure, slave._step = instance, changed, failure, step


INPUT_STARTS = "input_starts.json"
"""The file in an FMU's resources/ with its inputs' start values, as its model description gives
them: {value reference: start} for those that are not 0 (hosts need not extract the model
description beside the resources, fmpy's simulate_fmu does not)."""


PARAMETERS = "parameters.json"
"""The file in an FMU's resources/ with the parameters' start values where the build gave others
than the block's defaults (a preset's, `hoh-cosim export --preset`): {leaf: value}."""


def _resource(resources: str | None, name: str) -> Any:
    """A JSON file of the FMU's resources/, None if there is none."""
    if not resources:
        return None
    location = urlparse(resources)
    folder = Path(unquote(location.path) if location.scheme == "file" else resources)
    try:
        return json.loads((folder / name).read_text())
    except (OSError, ValueError):
        return None


def _declared_input_starts(resources: str | None) -> dict[int, float]:
    """The inputs' start values that the build wrote (`INPUT_STARTS`), by value reference, so a
    master that sets no input runs the block from them. Nothing found: {} (the inputs start at 0)."""
    data = _resource(resources, INPUT_STARTS) or {}
    return {int(vr): float(value) for vr, value in data.items()}


def _declared_parameters(resources: str | None, params_cls: type) -> Any:
    """The parameters' start values that the build wrote (`PARAMETERS`), as a `params_cls`, so
    the FMU run alone runs the block with them; None: the block's defaults."""
    data = _resource(resources, PARAMETERS)
    return None if not data else with_values(params_cls(), data)


def pin_namespace(namespace: dict[str, Any]) -> None:
    """Balance pythonfmu 0.7.0's release of an FMU entry script's module namespace.

    At every instantiation pythonfmu runs the entry script again in its module's namespace, to find
    the slave class, and then releases a reference to that namespace it never owned
    (`Py_DECREF(pGlobals)` on the borrowed result of `PyModule_GetDict`). Left alone, the second
    `fmi2Instantiate` in a process crashes on the freed namespace. The script calls this at its top
    level, so once per run: each call adds the one reference the release takes away, owned by
    nobody, so that it is never given back either (holding references in a Python object instead
    is undone at interpreter exit, which then frees the namespace twice).
    """
    ctypes.pythonapi.Py_IncRef(ctypes.py_object(namespace))
