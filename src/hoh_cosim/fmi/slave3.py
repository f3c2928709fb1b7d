"""The generic block adapter of `hoh_cosim.fmi.slave`, for FMI 3.0 co-simulation with pythonfmu3.

An FMI 3 entry script (written by `hoh_cosim.fmi.build3`) names the block and its parameter class
as the FMI 2 one does, with this adapter imported under the name pythonfmu3 looks for:

    from hoh_cosim.fmi.slave3 import BlockSlave3 as Fmi3Slave

    class HohEstimator(Fmi3Slave):
        block = Estimator
        params = EstimatorParams

The FMU says and does what the FMI 2 one does, variable for variable (`block_interface`: the same
names, value references, units, causalities, variabilities and start values, `INPUT_STARTS` and
`PARAMETERS` read the same way); the FMI 3 names are Float64 for Real and Int32 for Integer, and
one variable is added after the others: the independent variable `time` (FMI 3 requires exactly
one), the end of the last step.

Every element of a port stays its own Float64 scalar (`wrench_S[1]` ... `wrench_S[6]`) rather
than one FMI 3 array per port, because:
- an FMI 3 array has one unit, and ports mix them (a wrench is N, N, N, N.m, N.m, N.m; a twist
  m/s and rad/s): as arrays they would lose their units or split into pieces no block has;
- the names and value references are then those of the FMI 2 FMU, so the master, a scenario's
  element connections, recordings and SSP files address both versions the same way;
- it costs nothing where it matters: a master gets or sets all of an FMU's values in one call
  either way (pythonfmu3 turns the value references into one Python list per call, arrays or not).

Life cycle, errors and state are those of `BlockSlave`: the block is built when initialisation
starts (rebuilt if parameters change before it ends) and its `initial_outputs` are valid at once;
`do_step` is read inputs -> `block.step` -> write outputs; a tunable parameter set between steps
reaches the block through `retune` before the next step, a fixed one fails it; a block that is not
`variable_step` refuses a step other than its first (canHandleVariableCommunicationStepSize is
false); an error is logged (fmi3Error) and remembered, and the next fmi3DoStep returns
fmi3Discard. No exception may leave a method pythonfmu3 0.3.4 calls: its wrapper then releases
the instance's Python objects (`cleanPyObject`) and releases them again when the instance is
freed, as pythonfmu 0.7 does.

pythonfmu3 passes every message that `log` queues (debug=False, the default) to the importer's
logger whether or not debug logging is on, unless the importer narrowed the categories with
fmi3SetDebugLogging; the fatal message of a failed instantiation (an exception in `__init__`) goes
straight to the logger. Unlike pythonfmu 0.7 it imports the entry script as a module
(`PyImport_ImportModule`) rather than running it again at every instantiation, so its namespace
needs no pinning; but an exception raised while that module is imported is printed to standard
error and then crashes the process (the wrapper goes on with a NULL module): the entry scripts
that `build3` writes catch every import failure and raise it from `__init__` instead.
"""

from __future__ import annotations

import io
import math
import pickle
from typing import Any, ClassVar

import numpy as np
from pythonfmu3 import Fmi3Slave as _PythonFmu3Slave
from pythonfmu3.enums import Fmi3Causality, Fmi3Status, Fmi3Variability
from pythonfmu3.variables import Boolean, Float64, Int32, String

from hoh_cosim.control.block import copy_new_outputs, make_block, variable_step
from hoh_cosim.errors import ConfigError
from hoh_cosim.fmi import exit_fix
from hoh_cosim.fmi.slave import (
    INPUT_STARTS,
    PARAMETERS,
    VariableSpec,
    _declared_input_starts,
    _declared_parameters,
    _restore,
    _snapshot,
    _State,
    block_interface,
)
from hoh_cosim.params import with_values

__all__ = ["FMI3_TYPE", "INPUT_STARTS", "PARAMETERS", "TIME", "BlockSlave3"]

FMI3_TYPE = {"Real": "Float64", "Integer": "Int32", "Boolean": "Boolean", "String": "String"}
"""The FMI 3 type of each of `block_interface`'s FMI 2 types."""

TIME = "time"
"""The name of the independent variable, whose value reference follows every other's."""

_CAUSALITY = {
    "input": Fmi3Causality.input,
    "output": Fmi3Causality.output,
    "parameter": Fmi3Causality.parameter,
}
_VARIABILITY = {
    "continuous": Fmi3Variability.continuous,
    "fixed": Fmi3Variability.fixed,
    "tunable": Fmi3Variability.tunable,
}
_VARIABLE_CLASS = {"Real": Float64, "Integer": Int32, "Boolean": Boolean, "String": String}


class BlockSlave3(_PythonFmu3Slave):
    """The adapter; an entry script subclasses it and sets `block` and `params`."""

    block: ClassVar[type]
    params: ClassVar[type]

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        # pythonfmu3's library keeps its interpreter state as pythonfmu 0.7's does (a static
        # shared_ptr reset again by the library's destructor): the same double release at unload
        # or exit, the same cure (hoh_cosim.fmi.exit_fix)
        exit_fix.protect_host()
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
            self._register(spec)
            if spec.type != "Real":
                self._others[vr] = spec.start
        self._time_vr = len(self.specs)
        self.register_variable(
            Float64(
                TIME,
                causality=Fmi3Causality.independent,
                variability=Fmi3Variability.continuous,
                description="simulation time: the end of the last step",
                unit="s",
                getter=lambda: self._time,
            ),
            nested=False,
        )
        self._time = 0.0  # the end of the last step
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
        # views into the reals, refilled by set_float64 in place (see the block contract)
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

    def _register(self, spec: VariableSpec) -> None:
        """Declare `spec` to pythonfmu3 as a scalar; its getter gives the start value the builder
        writes (values are read and written through the get_/set_ methods below)."""
        vr = len(self.vars)
        extra = {"unit": spec.unit} if spec.type == "Real" else {}
        self.register_variable(
            _VARIABLE_CLASS[spec.type](
                spec.name,
                causality=_CAUSALITY[spec.causality],
                variability=_VARIABILITY[spec.variability],
                description=spec.description,
                getter=lambda: self._value(vr),
                setter=lambda value: None,
                **extra,
            ),
            nested=False,
        )

    def _value(self, vr: int) -> Any:
        return float(self._reals[vr]) if vr < len(self._reals) else self._others[vr]

    # --- errors (see the module's docstring) ------------------------------------------------

    def _fail(self, where: str, exc: BaseException) -> None:
        message = f"{where}: {type(exc).__name__}: {exc}"
        if self._failure is None:
            self._failure = message
        self.log(message, status=Fmi3Status.error)

    # --- values ------------------------------------------------------------------------------

    def get_float64(self, vrs: list[int]) -> list[float]:
        if vrs == self._output_vrs:  # what a master asks every step: a slice, not a gather
            return self._reals[self._n_in : self._n_io].tolist()
        try:
            if self._time_vr in vrs:
                return [self._time if vr == self._time_vr else self._real(vr) for vr in vrs]
            self._check(vrs)
            return self._reals[vrs].tolist()
        except Exception as exc:
            self._fail("fmi3GetFloat64", exc)
            return [math.nan] * len(vrs)  # as many as asked for: the wrapper reads them all

    def _real(self, vr: int) -> float:
        self._check([vr])
        return float(self._reals[vr])

    def _check(self, vrs: list[int], what: str = "Float64 variable") -> None:
        """Only the reals' own value references (pythonfmu3 passes them as C ints: a value
        reference above 2^31 arrives negative, and numpy would count it from the end)."""
        if vrs and (min(vrs) < 0 or max(vrs) >= len(self._reals)):
            bad = next(vr for vr in vrs if not 0 <= vr < len(self._reals))
            raise ValueError(f"no {what} has value reference {bad}")

    def set_float64(self, vrs: list[int], values: list[float]) -> None:
        if vrs == self._input_vrs:  # every input, in order: what a master sets every step
            self._reals[: self._n_in] = values
            return
        try:
            self._check(vrs, "Float64 variable that may be set")  # not `time`
            self._reals[vrs] = values
        except Exception as exc:
            self._fail("fmi3SetFloat64", exc)
            return
        if any(self._n_in <= vr < self._n_io for vr in vrs):  # an output overwritten
            self._written = [None] * len(self._outputs)
        if max(vrs, default=-1) >= self._n_io:
            self._changed.update(vr for vr in vrs if vr >= self._n_io)

    def _get_other(self, vrs: list[int]) -> list[Any]:
        try:
            return [self._others[vr] for vr in vrs]
        except KeyError as exc:
            self._fail("fmi3Get", ValueError(f"no such variable: value reference {exc}"))
            return [0] * len(vrs)

    def _set_other(self, vrs: list[int], values: list[Any]) -> None:
        for vr, value in zip(vrs, values, strict=True):
            if vr not in self._others:
                self._fail("fmi3Set", ValueError(f"no such variable: value reference {vr}"))
                return
            self._others[vr] = value
            self._changed.add(vr)

    get_int32 = get_boolean = get_string = _get_other
    set_int32 = set_boolean = set_string = _set_other

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
                copy_new_outputs(initial(), self._output_views, self._written)
            if self._failure is not None and self._failure.startswith("initialisation"):
                self._failure = None  # parameters fixed before initialisation ended
        except Exception as exc:
            self._instance = None
            self._fail("initialisation", exc)

    def enter_initialization_mode(self) -> None:
        self._build()

    def exit_initialization_mode(self) -> None:
        if self._changed:
            self._build()

    def do_step(self, current_time: float, step_size: float) -> bool:
        """One step; False (fmi3Discard) once anything failed."""
        if self._failure is not None:  # a failed block is not stepped again
            self.log(f"not stepped after an earlier error: {self._failure}", Fmi3Status.error)
            return False
        if not self._variable_step:
            if self._step is None:
                self._step = step_size
            elif abs(step_size - self._step) > 1e-9 * self._step:
                self._fail(
                    f"fmi3DoStep at t = {current_time:.6g} s",
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
            outputs = self._instance.step(current_time, step_size, self._input_views)
            copy_new_outputs(outputs, self._output_views, self._written)
        except Exception as exc:
            self._fail(f"fmi3DoStep at t = {current_time:.6g} s", exc)
            return False
        self._time = current_time + step_size
        return True

    # --- FMU state (fmi3GetFMUState, fmi3SetFMUState, fmi3SerializeFMUState, ...) ------------
    #
    # `BlockSlave`'s snapshot (values, block, flags; pickled), with the time beside it.

    def _get_fmu_state(self) -> bytes:
        try:
            return _State(pickle.dumps((self._time, bytes(_snapshot(self)))))
        except Exception as exc:
            self._fail("fmi3GetFMUState", exc)
            return _State()

    def _set_fmu_state(self, state: bytes) -> None:
        try:
            time, inner = pickle.load(io.BytesIO(state))
            _restore(self, inner)
            self._time = float(time)
        except Exception as exc:
            self._fail("fmi3SetFMUState", exc)

    @staticmethod
    def _fmu_state_to_bytes(state: bytes) -> bytes:
        return bytes(state)

    @staticmethod
    def _fmu_state_from_bytes(data: bytes) -> bytes:
        return _State(data)
