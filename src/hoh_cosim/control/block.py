"""The block contract (DESIGN.md §4): named vector ports with sizes and units, `reset()`, `step()`.

A block keeps its parameters in a frozen, validated dataclass and its state explicit. It never reads a
clock, sleeps, does I/O or knows FMI: `step(t, dt, inputs)` gets the master's time (an integer tick
times dt) and a mapping from input port names to float arrays, and returns the outputs the same way.
The FMU wrappers, the in-process engine and the hardware runner are adapters of that one shape.

The input arrays belong to the caller and are refilled in place every step: a block reads them
during `step` and neither changes them nor keeps them. The caller copies the output arrays it keeps;
a block may return the same array objects again while their values stay the same, and never changes
an array after returning it.

A block's step is its sample period unless the block says otherwise: a controller or a filter is a
sampled system, and ten steps of 1 ms are not one of 10 ms. A block whose `step` gives the same
result for one step as for many shorter ones with the inputs held (it runs its own inner cycles and
integrates at its own rate) sets `variable_step = True`; its FMU then says
canHandleVariableCommunicationStepSize, and the others refuse a step that differs from their first.

A block that knows it will idle may keep a float attribute `idle_until` [s]: a step from t to t + dt
with t + dt < idle_until neither reads the inputs nor changes anything, and returns the same
outputs as the last step (the packet sensors between packets). The in-process master then does not
call it for such a step; any other caller may, with the same result.
"""

from __future__ import annotations

import enum
import inspect
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import ClassVar, Protocol

import numpy as np

from hoh_cosim.control.vectors import Vec
from hoh_cosim.errors import ConfigError

__all__ = [
    "TWIST_UNITS",
    "WRENCH_UNITS",
    "Block",
    "Port",
    "check_inputs",
    "copy_new_outputs",
    "make_block",
    "port_element_names",
    "takes_rng",
    "variable_step",
    "zero_inputs",
]

# Units of a wrench [f; τ] and of a twist [v; ω], element by element; defined once for every port.
WRENCH_UNITS = ("N", "N", "N", "N.m", "N.m", "N.m")
TWIST_UNITS = ("m/s",) * 3 + ("rad/s",) * 3


@dataclass(frozen=True)
class Port:
    """One vector port of `size` scalars.

    `unit` is one SI unit string for every element, or one per element (a wrench is N, N, N, N.m,
    N.m, N.m). Units are plain ASCII as FMI tools expect: 'N.m', 'm/s', 'rad/s', '1' for none.
    `flags`: for a scalar bit field, the `enum.IntFlag` whose members name its bits; for a scalar
    that takes one of a few values, the `enum.IntEnum` that names them (results show them by name).
    """

    name: str
    size: int
    unit: str | tuple[str, ...]
    description: str
    flags: type[enum.IntFlag] | type[enum.IntEnum] | None = None

    def __post_init__(self) -> None:
        if isinstance(self.unit, tuple) and len(self.unit) != self.size:
            raise ConfigError(f"port {self.name}: {len(self.unit)} units for {self.size} values")

    @property
    def units(self) -> tuple[str, ...]:
        """The unit of every element."""
        return self.unit if isinstance(self.unit, tuple) else (self.unit,) * self.size

    @property
    def element_names(self) -> list[str]:
        """The name of every element, as FMUs and recordings name them."""
        return port_element_names(self.name, self.size)


def port_element_names(name: str, size: int) -> list[str]:
    """`name` for a scalar port, `name[1]` … `name[size]` otherwise (FMI structured naming)."""
    return [name] if size == 1 else [f"{name}[{i + 1}]" for i in range(size)]


class Block(Protocol):
    inputs: ClassVar[tuple[Port, ...]]
    outputs: ClassVar[tuple[Port, ...]]
    variable_step: ClassVar[bool]  # optional, False if absent (the module's docstring)

    def reset(self) -> None: ...

    def step(self, t: float, dt: float, inputs: Mapping[str, Vec]) -> dict[str, Vec]: ...


def check_inputs(block: Block, inputs: Mapping[str, object]) -> dict[str, Vec]:
    """`inputs` as float arrays, checked against the block's ports: every port present, sizes right,
    nothing unknown. For adapters and tests; blocks do not re-check in their hot path."""
    known = {p.name: p for p in block.inputs}
    unknown = sorted(set(inputs) - set(known))
    if unknown:
        raise ConfigError(
            f"{type(block).__name__}: unknown input port {unknown[0]!r} (ports: {', '.join(known)})"
        )
    out: dict[str, Vec] = {}
    for name, port in known.items():
        if name not in inputs:
            raise ConfigError(f"{type(block).__name__}: input port {name!r} is missing")
        value = np.asarray(inputs[name], dtype=np.float64).reshape(-1)
        if value.size != port.size:
            raise ConfigError(
                f"{type(block).__name__}.{name}: expected {port.size} values, got {value.size}"
            )
        out[name] = value
    return out


def copy_new_outputs(
    outputs: Mapping[str, Vec], views: Sequence[tuple[str, Vec]], written: list[object]
) -> None:
    """Copy each output port's array into its view, unless it is the array copied there last.

    An array a block returns again holds the values it held (the contract above), so the view
    still has them. `written` holds, per view, the array last copied into it; an adapter sets the
    entries to None when anything else writes into the views.
    """
    for i, (name, view) in enumerate(views):
        value = outputs[name]
        if value is not written[i]:
            view[...] = value
            written[i] = value


def zero_inputs(block: Block) -> dict[str, Vec]:
    """A zero array for every input port of `block`."""
    return {p.name: np.zeros(p.size) for p in block.inputs}


def variable_step(block_cls: type) -> bool:
    """Whether a step of any length gives what shorter steps give (the module's docstring)."""
    return bool(getattr(block_cls, "variable_step", False))


def takes_rng(block_cls: type) -> bool:
    """Whether a block draws random numbers: its constructor takes a generator `rng`."""
    return "rng" in inspect.signature(block_cls).parameters


def make_block(block_cls: type, params: object, seed: int) -> object:
    """A block of `block_cls` with `params`; its random numbers, if any, seeded with `seed`."""
    if takes_rng(block_cls):
        return block_cls(params, rng=np.random.default_rng(seed))
    return block_cls(params)
