"""What the stages' tests share: one tick and one command built directly, and the check that a stage
reads only them (it imports no other stage, and leaves the tick as it found it)."""

from __future__ import annotations

import ast
import inspect
from types import ModuleType

import numpy as np

from hoh_cosim.control.guidance.tick import ZERO3, Command, Tick
from hoh_cosim.control.vectors import Vec3
from tests.estimates import controller_inputs

DT = 0.002  # [s] the controller's tick

# contact compensation, the contact's torque, a probe sensor, the raw packet, the onset, the
# probe's packet, axis and ages read, the lift-off's size squared
PLAIN = (False, False, True, False, 0.0, True, 2.25)


def make_tick(
    t: float = 0.0,
    *,
    dt: float = DT,
    last: tuple[Vec3, Vec3] = (ZERO3, ZERO3),
    reading: tuple[bool, bool, bool, bool, float, bool, float] = PLAIN,
    **inputs: object,
) -> Tick:
    """A tick without a stop flag from `controller_inputs(**inputs)`."""
    tick = Tick()
    tick.start(t, dt, 0, last, controller_inputs(**inputs), reading)
    return tick


def make_command(
    v: Vec3 = ZERO3, w: Vec3 = ZERO3, *, status: int = 0, steering: bool = True
) -> Command:
    """The law's request [v; ω] as the stages after the law receive it."""
    command = Command()
    command.start(status)
    command.v, command.w = np.array(v, dtype=float), np.array(w, dtype=float)
    command.law = np.concatenate([command.v, command.w])
    command.steering = steering
    return command


def guidance_imports(module: ModuleType) -> set[str]:
    """The modules of the controller and its guidance that `module` imports."""
    tree = ast.parse(inspect.getsource(module))
    names = {n.module for n in ast.walk(tree) if isinstance(n, ast.ImportFrom) and n.module}
    names |= {a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
    inside = ("hoh_cosim.control.guidance", "hoh_cosim.control.controller")
    return {name for name in names if name.startswith(inside)}


def tick_values(tick: Tick) -> dict[str, object]:
    """The tick's fields, copied, to tell whether a stage wrote to it."""
    out = {}
    for name in Tick.__slots__:
        value = getattr(tick, name, None)
        out[name] = value.copy() if isinstance(value, np.ndarray) else value
    return out


def assert_reads_only(module: ModuleType, stage: object, tick: Tick, command: Command) -> None:
    """The stage's module imports only the tick of the guidance, and its step leaves the tick as
    it was."""
    assert guidance_imports(module) == {"hoh_cosim.control.guidance.tick"}
    before = tick_values(tick)
    stage.step(tick, command)  # type: ignore[attr-defined]
    np.testing.assert_equal(tick_values(tick), before)


def same_state(a: object, b: object) -> None:
    """Two blocks' state (their attributes) equal, NaN equal to NaN."""
    left = {k: list(v) if hasattr(v, "popleft") else v for k, v in vars(a).items()}
    right = {k: list(v) if hasattr(v, "popleft") else v for k, v in vars(b).items()}
    np.testing.assert_equal(left, right)
